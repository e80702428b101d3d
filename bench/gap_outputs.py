"""Every gap estimate, as text, to compare two versions of the gap stage bit for bit (a speed change must change none).

    .venv/bin/python bench/gap_outputs.py stress OUT.txt            # the stress bench's windows (~10 s)
    .venv/bin/python bench/gap_outputs.py steady OUT.txt            # steady entries, the node's defaults (~20 s)
    .venv/bin/python bench/gap_outputs.py zoo OUT.txt [zoo options]   # every estimate_inertia call of the zoo report

``stress``: 24 stress-bench recordings (gap_stress.simulate: speed step, speed reversal, light and heavy load reversal;
J1 1.16 and 1.073; clean, 30 dB, 2^13 and 2^16 counts; cached in out/gap_outputs_stress.pkl), each as JointState and
with an Imu, the detector's rows moved by six offsets, three drive declarations (GapModel), with and without bearing
friction, every fit of ``estimate_inertia`` (the model choice, 'angle', 'acceleration', 'gap_only'), and the free and
kink fits alone: one line per call, the GapEstimate's repr (every float to the last bit) or the refusal's text.
``steady``: our simulator's slip as a JointState drive records it (bench_gap.py's steady-entry window: raw 2^16 and
2^13 encoders, clean and 30 dB, the flank detector's windows; J1 0.9, 1.131 and 1.4 kg m^2, two backlash widths),
the detector's entry moved by -2..+2 rows, five drive declarations (the node's defaults for a drive that declares
nothing, lag and release alone, none, the offset and drift bands): the steady-entry fit with its unloading and lag
refits, which the stress windows never take.
``zoo``: runs ``python -m jident_ros.research.evaluation.zoo`` with the options after OUT (e.g. ``--report --results -
--json out/zoo.json``; recordings cached under out/zoo) and writes one line per estimate_inertia call: a hash of the
window, the arguments, the result or the refusal.  Compare two runs with ``cmp``: run the old version with its tree on
PYTHONPATH (``git archive <commit> jident_ros config | tar -x -C /tmp/old``; ``cd /tmp && PYTHONPATH=/tmp/old
<repo>/.venv/bin/python <repo>/bench/gap_outputs.py ...``), the new one in the checkout.
"""
from __future__ import annotations

import atexit
import hashlib
import pickle
import sys
from pathlib import Path

import numpy as np

STRESS_CACHE = Path("out") / "gap_outputs_stress.pkl"


def _plain(d: dict) -> dict:
    return {k: (v.tolist() if isinstance(v, np.ndarray) else v) for k, v in d.items() if not k.startswith("_")}


def stress(out_path: str) -> None:
    from jident_ros.identify.gap import NoGapError, estimate_inertia
    from jident_ros.identify.gap_free import FreeFitError, GapModel, free_angle_fit
    from jident_ros.identify.gap_kink import kink_fit
    from jident_ros.research.evaluation.gap_stress import StressDrive, simulate
    if STRESS_CACHE.exists():
        recs = pickle.loads(STRESS_CACHE.read_bytes())
    else:
        recs = []
        for event in ("speed_step", "speed_reversal", "load_reversal"):
            for j1 in (1.16, 1.073):
                for snr in (None, 30.0):
                    for light in ((True, False) if event == "load_reversal" else (True,)):
                        for counts in ((65536, 8192) if snr is None else (65536,)):
                            recs.append(simulate(StressDrive(j1_kgm2=j1), event, seed=int(j1 * 1000), snr_db=snr,
                                                 light_load=light, counts=counts))
        STRESS_CACHE.parent.mkdir(parents=True, exist_ok=True)
        STRESS_CACHE.write_bytes(pickle.dumps(recs))
    models = [GapModel(torque_accuracy=0.01, coulomb_friction_max_nm=1.5), GapModel(),
              GapModel(torque_accuracy=0.02, coulomb_friction_max_nm=0.5, viscous_friction_band_nms_per_rad=0.01,
                       torque_offset_nm=0.5, torque_lag_s=1e-3)]
    lines = []
    for ri, rec in enumerate(recs):
        for imu in (False, True):
            w = dict(rec["window"])
            if not imu:
                w.pop("a1")
            for off_e, off_r in ((-14, -3), (0, 0), (23, 2), (5, -5), (-5, 2), (-3, 8)):
                e0 = rec["entry"] + off_e
                r0 = max(rec["recontact"] + off_r, e0 + 4)
                for mi, model in enumerate(models):
                    for b1 in ((0.0, 0.01) if mi == 0 else (0.0,)):
                        for method in ((None, "angle", "acceleration", "gap_only") if imu and mi == 0 else (None,)):
                            tag = f"r{ri} imu={imu} off={off_e},{off_r} m{mi} b1={b1} {method}"
                            try:
                                g = estimate_inertia(w, e0, 0.005, 0.08, 5e-4, recontact_index=r0, model=model,
                                                     bearing_friction_nms_per_rad=b1, method=method)
                                lines.append(f"{tag} -> {g!r}")
                            except NoGapError as exc:
                                lines.append(f"{tag} -> NoGapError {exc}")
        a, m = rec["window"]["alpha1"], rec["window"]["m_el"]
        for fixed in (False, True):
            try:
                f = free_angle_fit(a, m, 5e-4, rec["entry"], rec["recontact"], models[2], fixed=fixed)
                lines.append(f"free r{ri} fixed={fixed} -> {_plain(f)!r}")
            except FreeFitError as exc:
                lines.append(f"free r{ri} fixed={fixed} -> FreeFitError {exc}")
        try:
            k = kink_fit(a, m, 5e-4, range(rec["entry"] - 4, rec["entry"] + 5), rec["recontact"], 0.5, 0.2, 1e-3)
            lines.append(f"kink r{ri} -> {_plain(k)!r}")
        except FreeFitError as exc:
            lines.append(f"kink r{ri} -> FreeFitError {exc}")
    Path(out_path).write_text("\n".join(lines) + "\n")
    print(f"{len(recs)} recordings, {len(lines)} results -> {out_path}")


def steady(out_path: str) -> None:
    from jident_ros.config import load_system_config
    from jident_ros.identify.gap import NoGapError, estimate_inertia
    from jident_ros.identify.gap_free import GapModel
    from jident_ros.identify.monitor import DetectorConfig, make_detector
    from jident_ros.research.evaluation.raw_inputs import raw_recordings, run_detector, without
    system = load_system_config()
    models = [GapModel(torque_accuracy=0.03, coulomb_friction_max_nm=1.5, torque_lag_s=1e-3, coupling_release_s=4e-3),
              GapModel(torque_lag_s=5e-4, coupling_release_s=2e-3), GapModel(coupling_release_s=4e-3),
              GapModel(torque_accuracy=0.03, coulomb_friction_max_nm=1.5),
              GapModel(torque_accuracy=0.02, coulomb_friction_max_nm=0.5, torque_offset_nm=0.5, torque_lag_s=1e-3,
                       coupling_release_s=3e-3)]
    lines, n_win = [], 0
    for counts, snr in ((65536, None), (8192, None), (65536, 30.0)):
        for seed in (12, 13):
            recs = raw_recordings(system, [0.9, 1.131, 1.4], [0.003, 0.0075], steady_s=0.2, seed=seed, counts=counts,
                                  snr_db=snr)
            for ri, rec in enumerate(recs):
                rec = without(rec, ("a1", "a2", "v2"))
                det = make_detector(system, DetectorConfig("flank", channels=rec.channels,
                                                           encoder_counts_per_rev=counts))
                for w in [e.window for e in run_detector(det, rec) if e.kind == "window"][:1]:
                    n_win += 1
                    d = w.as_dict()
                    for off in (-2, -1, 0, 1, 2):
                        for mi, model in enumerate(models):
                            tag = f"c{counts} snr={snr} s{seed} r{ri} off={off} m{mi}"
                            try:
                                g = estimate_inertia(d, w.entry_index + off, w.backlash_width_m, w.wheel_radius_m,
                                                     w.sample_period_s, recontact_index=w.recontact_index,
                                                     model=model)
                                lines.append(f"{tag} -> {g!r}")
                            except NoGapError as exc:
                                lines.append(f"{tag} -> NoGapError {exc}")
    Path(out_path).write_text("\n".join(lines) + "\n")
    print(f"{n_win} windows, {len(lines)} results ({sum('steady entry' in x for x in lines)} steady entries) "
          f"-> {out_path}")


def zoo(out_path: str, argv: list) -> int:
    import jident_ros.identify.gap as gap
    real = gap.estimate_inertia
    lines = []

    def recorded(window, entry_index, *a, **k):
        h = hashlib.sha1()
        for key in sorted(window):
            h.update(key.encode())
            h.update(np.ascontiguousarray(np.asarray(window[key], float)).tobytes())
        tag = (f"{h.hexdigest()[:12]} e={entry_index} a={a!r} k={ {x: v for x, v in k.items() if x != 'model'}!r} "
               f"model={k.get('model')!r}")
        try:
            r = real(window, entry_index, *a, **k)
        except gap.NoGapError as exc:
            lines.append(f"{tag} -> NoGapError {exc}")
            raise
        lines.append(f"{tag} -> {r!r}")
        return r

    gap.estimate_inertia = recorded          # before the zoo's modules import it by name
    atexit.register(lambda: Path(out_path).write_text("\n".join(lines) + "\n"))
    from jident_ros.research.evaluation import zoo as zoo_module
    return zoo_module.main(argv)


def main(argv=None) -> int:
    argv = sys.argv[1:] if argv is None else argv
    if len(argv) < 2 or argv[0] not in ("stress", "steady", "zoo"):
        print(__doc__.strip().splitlines()[0] + "\nusage: gap_outputs.py stress OUT.txt | steady OUT.txt | zoo OUT.txt [zoo options]",
              file=sys.stderr)
        return 2
    if argv[0] == "stress":
        stress(argv[1])
        return 0
    if argv[0] == "steady":
        steady(argv[1])
        return 0
    return zoo(argv[1], argv[2:])


if __name__ == "__main__":
    sys.exit(main())
