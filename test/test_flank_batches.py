"""The flank detector gives the same windows whatever the batch size: a whole recording in one batch, as a replay
or a large drive/signals message hands it, raised ValueError (list.remove) when a capture completed in that batch
opened a traversal back that replaced a later capture (FlankDetector._open_return) which the same loop then fed."""
from __future__ import annotations

import numpy as np
import pytest


@pytest.fixture(scope="module")
def second_drive_recording():
    from jident_ros.research.second_drive import record as sd_record
    from jident_ros.research.second_drive.model import DriveParams
    cases = sd_record.grid_cases(("forward",), (1.16,), (0.0025,))
    r = next(iter(sd_record.build_grid(DriveParams(), cases, sd_record.SensorConfig(encoder_counts=65536),
                                       steady_s=1.0, post_s=1.3, seed=7)))
    ch = ("t", "alpha1", "alpha2", "omega1", "omega2", "m_el")
    return r.truth, ch, np.column_stack([r.signals[c] for c in ch])


def _entries(truth, ch, data, batch):
    from jident_ros.stream.flank import FlankDetector
    det = FlankDetector(truth["reference_radius_m"], 5e-4, channels=ch, gear_ratio=truth["gear_ratio"],
                        nominal_inertia_kgm2=1.16)
    events = []
    for i in range(0, len(data), batch):
        events += det.push(data[i:i + batch], ch)
    events += det.finish()
    return [round((e.window.entry_time_s - data[0, 0]) / 5e-4) for e in events if e.kind == "window"]


def test_one_batch_gives_the_windows_of_small_batches(second_drive_recording):
    truth, ch, data = second_drive_recording
    small = _entries(truth, ch, data, 50)
    assert len(small) == 2, small                    # the traversal and the traversal back
    assert _entries(truth, ch, data, len(data)) == small
    assert _entries(truth, ch, data, 997) == small
