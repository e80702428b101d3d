"""The detector's arguments of a captured window (:class:`jident_ros.identify.diagnosis.WindowInput`): what a flank or
dynamics detector's window says beside its samples -- its re-contact row, its K2 estimate, that its angles are raw
encoder angles, a shallow gap, an entry row known only to some samples.  Split from diagnosis.py (its size)."""
from __future__ import annotations

import math

from jident_ros.identify.gap import WidthEstimate
from jident_ros.stream.layout import FLAG_BOUNCE, FLAG_SECOND_ENTRY, FLAG_SHALLOW_GAP, RAW_ANGLE_DETECTORS

#: The dynamics detector's entry row without a1 (from the motor angle) is known to +- this many samples
#: (docs/results.md, "Entries from the dynamics": -5 ... +1 on our simulator, -9 ... -3 on the second drive).
ENTRY_UNCERTAINTY_WITHOUT_A1 = 10


#: A flank window without a K2 estimate is diagnosed from its gap (True) or refused (False).  It was off until
#: the gap fit's intervals were honest: on our simulator's JointState 30 dB recordings (no a1) it then published two
#: such windows 36 % and 19 % off (0.688 for 1.073, 0.938 for 1.16: the angle fit over 17 samples; zoo report on the
#: detector branch).  On since the estimator's branch (the torque offset band, the +-10 % interval cap): the zoo
#: (`python -m jident_ros.research.evaluation.zoo --report`, declared and --undeclared) then refuses those windows
#: for the gap's own reasons, with the same counts as with the switch off (0 published > 10 % off on all three
#: models; coverage 36/36, 58/58, 34/34), and "backlash_width_m ... nan" is no longer a refusal (issue 20: a
#: missing K2 never blocks a J1).
FLANK_WINDOWS_WITHOUT_K2 = True


def detector_arguments(window) -> dict:
    """:class:`WindowInput`'s ``recontact_index`` and ``width_estimate`` for a captured
    :class:`~jident_ros.stream.layout.Window`: a flank- or dynamics-detector window's own (and, for a dynamics
    window without a1, ``entry_uncertainty_samples``); none for the paper detector's."""
    kind = getattr(window, "detector", "paper")
    if kind not in RAW_ANGLE_DETECTORS:
        return {}
    est = None
    if math.isfinite(window.backlash_width_estimate_m):
        est = WidthEstimate(float(window.backlash_width_estimate_m), float(window.backlash_width_se_m),
                            int(window.recontact_index), "flank")
    flags = int(getattr(window, "flags", 0))
    out = {"recontact_index": window.recontact_index if window.recontact_index >= 0 else None,
           "width_estimate": est, "raw_angles": True, "shallow_gap": bool(flags & FLAG_SHALLOW_GAP),
           "bounce": bool(flags & FLAG_BOUNCE), "second_entry": bool(flags & FLAG_SECOND_ENTRY)}
    if kind == "dynamics" and "a1" not in window.channels:
        out["entry_uncertainty_samples"] = ENTRY_UNCERTAINTY_WITHOUT_A1
    if not math.isfinite(window.backlash_width_m) and (kind == "dynamics" or FLANK_WINDOWS_WITHOUT_K2):
        # no load encoder (dynamics), or no traversal in this window (a one-sided excursion): no K2, and a
        # missing K2 does not block the gap's J1 (issue 20)
        out["backlash_width_unknown"] = True
    return out
