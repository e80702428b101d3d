"""Recordings of the second drive, written the way a drive's data logger would.

* the grid: one recording per (direction, J1, K2): a steady stretch, one
  speed-reference step (the event), and the rest of the run;
* the sensor model: encoder angles with arbitrary offsets and quantisation,
  optional white noise ('measured' SNR) and sensor-style noise;
* writers: ``csv``, ``jointstate`` (rosbag2/MCAP, sensor_msgs/JointState per
  sample, optional sensor_msgs/Imu), ``signals`` (rosbag2/MCAP,
  std_msgs/Float64MultiArray batches on drive/signals);
* ground truth goes to ``truth.json`` only, never into the signal files.

Uses ``rosbags`` for the bags (not jident_ros.recording), so the bags are an
independent check of the product's reader as well.
"""
from __future__ import annotations

import csv
import json
import math
from dataclasses import asdict, dataclass
from pathlib import Path

import numpy as np
from rosbags.rosbag2 import StoragePlugin, Writer
from rosbags.typesys import Stores, get_typestore

from jident_ros.research.second_drive import __doc__ as pkg_doc

from .model import PAPER_INERTIAS_KGM2, PAPER_WIDTHS_M, Drive, DriveParams, gaps, simulate

SIGNAL_CHANNELS = ("t", "alpha1", "alpha2", "omega2", "a1", "m_el", "omega1", "a2", "v2")
CSV_CHANNELS = ("t", "alpha1", "alpha2", "omega1", "omega2", "m_el", "a1", "a2", "v2")
NOISY_CHANNELS = ("omega1", "omega2", "m_el", "a1", "a2", "v2")   # angles: quantisation only
FORMATS = ("jointstate", "csv", "signals")
DIRECTIONS = {"forward": 1.0, "reverse": -1.0}
BATCH = 50


@dataclass
class SensorConfig:
    encoder_counts: int = 65536          # counts per revolution, both encoders; 0 = ideal
    wrap_encoders: bool = False          # single-turn absolute encoders (angle mod 2 pi)
    snr_db: float | None = None          # awgn 'measured' on NOISY_CHANNELS; None = off
    speed_noise_rad_s: float = 0.0       # extra white noise std on omega1, omega2
    torque_noise_pct: float = 0.0        # extra white noise std on m_el, % of rated torque


@dataclass
class Recording:
    name: str
    signals: dict          # channel -> 1-D array (SI)
    truth: dict


def _wrap_pi(x):
    return (x + math.pi) % (2 * math.pi) - math.pi


def draw_offsets(rng, gear_ratio, min_off_centre_rad=0.5):
    """Encoder offsets, uniform in [0, 2 pi) each; redrawn while the recorded
    relative angle at the zone centre, off1 - N off2 (mod 2 pi), is within
    ``min_off_centre_rad`` of 0, so a detector cannot rely on zone-centred angles."""
    while True:
        o1, o2 = rng.uniform(0.0, 2 * math.pi, 2)
        if abs(_wrap_pi(o1 - gear_ratio * o2)) >= min_off_centre_rad:
            return float(o1), float(o2)


def encoder(angle, offset, counts, wrap):
    x = angle + offset
    if counts:
        q = 2 * math.pi / counts
        x = np.floor(x / q) * q
    if wrap:
        x = np.mod(x, 2 * math.pi)
    return x


def awgn_measured(x, snr_db, rng):
    """MATLAB awgn(x, snr, 'measured'): noise power = mean(x^2)/10^(snr/10)."""
    p = np.mean(x * x) / 10.0 ** (snr_db / 10.0)
    return x + rng.standard_normal(x.shape) * math.sqrt(p)


def grid_cases(directions, inertias=PAPER_INERTIAS_KGM2, widths=PAPER_WIDTHS_M):
    return [(d, float(j), float(k)) for d in directions for j in inertias for k in widths]


def case_name(direction, j1, k2):
    return f"{'fwd' if direction == 'forward' else 'rev'}_J{j1:.3f}_K{k2 * 1e3:.3f}mm"


def simulate_grid(params: DriveParams, cases, steady_s=1.0, post_s=1.3, t0=0.0):
    """One vectorised run of every case; the event (speed step) at t0 + steady_s, on a sample."""
    ts = params.sample_period_s
    n_steady = int(round(steady_s / ts))
    t_event = t0 + n_steady * ts
    sgn = np.array([DIRECTIONS[d] for d, _, _ in cases])
    j1 = np.array([c[1] for c in cases])
    th = np.array([c[2] for c in cases]) / params.coupling.reference_radius_m
    w0 = sgn * params.speed_reference_rad_s
    dw = -w0 * params.step_fraction
    drive = Drive(params, j1, w0, th, steps=[(t_event, dw)])
    res = simulate(drive, n_steady * ts + post_s, t0=t0)
    return res, n_steady, drive


def measure(res, c, params: DriveParams, sensors: SensorConfig, rng, offsets):
    """Sensor signals of case c as a drive records them (dict of 1-D arrays)."""
    r = params.coupling.reference_radius_m
    sig = {
        "t": res.t.copy(),
        "alpha1": encoder(res.alpha1[:, c], offsets[0], sensors.encoder_counts, sensors.wrap_encoders),
        "alpha2": encoder(res.alpha2[:, c], offsets[1], sensors.encoder_counts, sensors.wrap_encoders),
        "omega1": res.omega1[:, c].copy(),
        "omega2": res.omega2[:, c].copy(),
        "m_el": res.m_el[:, c].copy(),
        "a1": r * res.domega1[:, c],
        "a2": res.dv2[:, c].copy(),
        "v2": res.v2[:, c].copy(),
    }
    if sensors.snr_db is not None:
        for k in NOISY_CHANNELS:
            sig[k] = awgn_measured(sig[k], sensors.snr_db, rng)
    if sensors.speed_noise_rad_s:
        for k in ("omega1", "omega2"):
            sig[k] = sig[k] + rng.standard_normal(sig[k].shape) * sensors.speed_noise_rad_s
    if sensors.torque_noise_pct:
        s = sensors.torque_noise_pct / 100.0 * params.motor.rated_torque_nm
        sig["m_el"] = sig["m_el"] + rng.standard_normal(sig["m_el"].shape) * s
    return sig


def _t(x):
    """A sample time for truth.json, rounded to the nanosecond (the bags' stamp resolution)."""
    return round(float(x), 9)


def _sensor_truth(sensors: SensorConfig, params: DriveParams, offsets, seed) -> dict:
    """The truth file's ``encoder`` and ``noise`` entries: what the recording's sensors did to the states."""
    return {"encoder": {"counts_per_rev": sensors.encoder_counts, "wrapped": sensors.wrap_encoders,
                        "alpha1_offset_rad": offsets[0], "alpha2_offset_rad": offsets[1],
                        "relative_offset_rad": offsets[0] - params.gear_ratio * offsets[1],
                        "quantisation": "floor"},
            "noise": {"snr_db": sensors.snr_db, "speed_noise_rad_s": sensors.speed_noise_rad_s,
                      "torque_noise_pct_of_rated": sensors.torque_noise_pct,
                      "rated_torque_nm": params.motor.rated_torque_nm, "seed": seed}}


def _gap_list(res, c, gl):
    """Every gap of case c: where it starts and ends, which flank it leaves and which it meets
    (from_flank == to_flank: a bounce off one flank; otherwise a traversal of the zone)."""
    n = res.t.size
    return [{"entry_index": b, "entry_time_s": _t(res.t[b]),
             "end_index": e, "end_time_s": _t(res.t[e]) if e < n else None,
             "from_flank": int(np.sign(res.delta[b - 1, c])) if b > 0 else 0,
             "to_flank": int(np.sign(res.delta[e, c])) if e < n else 0,
             "samples": e - b} for b, e in gl]


def build_grid(params: DriveParams, cases, sensors: SensorConfig, steady_s=1.0, post_s=1.3, seed=0,
               t0=0.0, min_after_entry_s=1.2):
    """Simulate the cases and return one Recording per case (signals + truth)."""
    res, n_steady, drive = simulate_grid(params, cases, steady_s, post_s, t0)
    ts = params.sample_period_s
    r = params.coupling.reference_radius_m
    out = []
    for c, (direction, j1, k2) in enumerate(cases):
        rng = np.random.default_rng([seed, c])
        offsets = draw_offsets(rng, params.gear_ratio)
        sig = measure(res, c, params, sensors, rng, offsets)
        gl = gaps(res.delta[:, c], res.theta_b[:, c])
        if any(b < n_steady for b, _ in gl):
            raise RuntimeError(f"case {c}: spurious entry in the steady stretch")
        if not gl:
            raise RuntimeError(f"case {c}: no entry after the event")
        entry, recontact = gl[0]
        n = res.t.size
        if (n - 1 - entry) * ts < min_after_entry_s - 1e-9:
            raise RuntimeError(f"case {c}: only {(n - 1 - entry) * ts:.3f} s after the entry")
        th = k2 / r
        truth = {
            "name": case_name(direction, j1, k2),
            "direction": direction,
            "inertia_kgm2": j1,
            "backlash_width_m": k2,
            "reference_radius_m": r,
            "half_zone_rad": th,
            "flank_to_flank_rad": 2 * th,
            "gear_ratio": params.gear_ratio,
            "drum_radius_m": params.drum_radius_m,
            "bearing_friction_nms": params.motor.bearing_friction_nms,
            "event": {"type": "speed_reference_step", "time_s": _t(res.t[n_steady]), "index": n_steady,
                      "omega_ref_before_rad_s": float(drive.w0[c]),
                      "omega_ref_after_rad_s": float(drive.w0[c] + drive.steps[0][1][c])},
            "entry_index": entry,
            "entry_time_s": _t(res.t[entry]),
            "entry_from_flank": int(np.sign(res.delta[entry - 1, c])),
            "recontact_index": recontact,
            "recontact_time_s": _t(res.t[recontact]) if recontact < n else None,
            "gaps": _gap_list(res, c, gl),
            **_sensor_truth(sensors, params, offsets, [seed, c]),
            "sample_period_s": ts,
            "n_samples": int(n),
            "t0_s": _t(res.t[0]),
            "steady_s": float(n_steady * ts),
        }
        out.append(Recording(truth["name"], sig, truth))
    return out


# ---------------------------------------------------------------------------------------------- writers
def write_csv(path: Path, sig: dict):
    cols = [c for c in CSV_CHANNELS if c in sig]
    data = np.column_stack([sig[c] for c in cols])
    with open(path, "w", newline="") as f:
        f.write(",".join(cols) + "\n")
        np.savetxt(f, data, fmt="%.15g", delimiter=",")


def read_csv(path: Path) -> dict:
    with open(path, newline="") as f:
        header = next(csv.reader(f))
    data = np.loadtxt(path, delimiter=",", skiprows=1, ndmin=2)
    return {h: data[:, i] for i, h in enumerate(header)}


def _typestore(distro):
    return get_typestore({"humble": Stores.ROS2_HUMBLE, "jazzy": Stores.ROS2_JAZZY}[distro])


def _ns_topic(namespace, topic):
    ns = namespace.strip("/")
    return f"/{ns}/{topic}" if ns else f"/{topic}"


def _stamp_ns(t):
    return np.round(np.asarray(t) * 1e9).astype(np.int64)


def write_jointstate(path: Path, sig: dict, namespace="", imu=False, distro="humble"):
    """rosbag2 (MCAP) with one sensor_msgs/JointState per sample on <ns>/joint_states."""
    store = _typestore(distro)
    JointState = store.types["sensor_msgs/msg/JointState"]
    Header = store.types["std_msgs/msg/Header"]
    Time = store.types["builtin_interfaces/msg/Time"]
    stamps = _stamp_ns(sig["t"])
    nan = float("nan")
    with Writer(path, version=9, storage_plugin=StoragePlugin.MCAP) as w:
        conn = w.add_connection(_ns_topic(namespace, "joint_states"), "sensor_msgs/msg/JointState",
                                typestore=store)
        if imu:
            Imu = store.types["sensor_msgs/msg/Imu"]
            Quat = store.types["geometry_msgs/msg/Quaternion"]
            Vec = store.types["geometry_msgs/msg/Vector3"]
            iconn = w.add_connection(_ns_topic(namespace, "imu"), "sensor_msgs/msg/Imu", typestore=store)
            unknown = np.zeros(9)
            unknown[0] = -1.0          # REP 145: orientation not provided
            zero9 = np.zeros(9)
        a1, a2, w1, w2, me = (sig[k] for k in ("alpha1", "alpha2", "omega1", "omega2", "m_el"))
        for i, ns in enumerate(stamps):
            hdr = Header(stamp=Time(sec=int(ns // 1_000_000_000), nanosec=int(ns % 1_000_000_000)),
                         frame_id="")
            msg = JointState(header=hdr, name=["motor", "load"],
                             position=np.array([a1[i], a2[i]]), velocity=np.array([w1[i], w2[i]]),
                             effort=np.array([me[i], nan]))
            w.write(conn, int(ns), store.serialize_cdr(msg, "sensor_msgs/msg/JointState"))
            if imu:
                m = Imu(header=Header(stamp=hdr.stamp, frame_id="motor_coupling"),
                        orientation=Quat(x=0.0, y=0.0, z=0.0, w=1.0), orientation_covariance=unknown,
                        angular_velocity=Vec(x=0.0, y=0.0, z=0.0), angular_velocity_covariance=unknown,
                        linear_acceleration=Vec(x=float(sig["a1"][i]), y=0.0, z=0.0),
                        linear_acceleration_covariance=zero9)
                w.write(iconn, int(ns), store.serialize_cdr(m, "sensor_msgs/msg/Imu"))


def write_signals(path: Path, sig: dict, namespace="", distro="humble", batch=BATCH,
                  channels=SIGNAL_CHANNELS):
    """rosbag2 (MCAP): std_msgs/Float64MultiArray batches on <ns>/drive/signals
    (docs/interfaces.md layout), log time = t of the batch's last sample."""
    store = _typestore(distro)
    F64MA = store.types["std_msgs/msg/Float64MultiArray"]
    Layout = store.types["std_msgs/msg/MultiArrayLayout"]
    Dim = store.types["std_msgs/msg/MultiArrayDimension"]
    data = np.column_stack([sig[c] for c in channels])
    nc = len(channels)
    label = ",".join(channels)
    stamps = _stamp_ns(sig["t"])
    with Writer(path, version=9, storage_plugin=StoragePlugin.MCAP) as w:
        conn = w.add_connection(_ns_topic(namespace, "drive/signals"), "std_msgs/msg/Float64MultiArray",
                                typestore=store)
        for s in range(0, data.shape[0], batch):
            block = data[s:s + batch]
            n = block.shape[0]
            msg = F64MA(layout=Layout(dim=[Dim(label="sample", size=n, stride=n * nc),
                                           Dim(label=label, size=nc, stride=nc)], data_offset=0),
                        data=np.ascontiguousarray(block).ravel())
            w.write(conn, int(stamps[s + n - 1]), store.serialize_cdr(msg, "std_msgs/msg/Float64MultiArray"))


def write_recording(out_dir: Path, rec: Recording, fmt: str, namespace="", imu=False, distro="humble"):
    """Write one recording; returns its path relative to out_dir."""
    if fmt == "csv":
        rel = f"{rec.name}.csv"
        write_csv(out_dir / rel, rec.signals)
    elif fmt == "jointstate":
        rel = rec.name
        write_jointstate(out_dir / rel, rec.signals, namespace, imu, distro)
    elif fmt == "signals":
        rel = rec.name
        write_signals(out_dir / rel, rec.signals, namespace, distro)
    else:
        raise ValueError(f"unknown format {fmt!r}")
    return rel


def truth_document(params: DriveParams, sensors: SensorConfig, recordings, fmt, files, command=None,
                   namespace="", scenario="grid"):
    return {
        "schema": "jident_ros.research.second_drive/truth/1",
        "model": "jident_ros.research.second_drive (vector-controlled IM, Hertz/Hunt-Crossley backlash, belt conveyor)",
        "description": (pkg_doc or "").strip().splitlines()[0],
        "convention": ("K2 = backlash width in m at reference_radius_m r; half_zone_rad = K2/r; the zone is "
                       "|alpha1 - N*alpha2 - relative_offset_rad| < K2/r (angles as recorded, before "
                       "quantisation), flank-to-flank travel 2*K2/r"),
        "format": fmt,
        "scenario": scenario,
        "namespace": namespace,
        "command": command,
        "parameters": asdict(params),
        "sensors": asdict(sensors),
        "recordings": [dict(r.truth, file=f) for r, f in zip(recordings, files)],
    }


def write_truth(path: Path, doc: dict):
    with open(path, "w") as f:
        json.dump(doc, f, indent=1, allow_nan=False)
        f.write("\n")


# ---------------------------------------------------------------------------------------------- wear scenario
WEAR_WIDTHS_M = (0.0025, 0.0031, 0.00375, 0.0044, 0.005, 0.0062, 0.0075, 0.0083, 0.009, 0.01)


def build_wear(params: DriveParams, directions, inertias, sensors: SensorConfig, widths=WEAR_WIDTHS_M,
               steady_s=1.0, period_s=3.0, seed=0, t0=0.0):
    """One long recording per (direction, J1): the zone widens between events.

    Event k at t_k = t0 + steady_s + k period_s: |omega_ref| steps down by
    step_fraction (entry); at t_k + 1.5 s it steps back up; between t_k + 2.0 s
    and t_k + 2.5 s, with the drive steady on its driving flank, the half-zone
    grows linearly from widths[k]/r to widths[k+1]/r (wear). The run ends 1.5 s
    after the last event.
    """
    if period_s < 3.0:
        raise ValueError("period_s must be >= 3 s (1.5 s after the entry, 0.5 s wear ramp, 0.5 s steady)")
    ts = params.sample_period_s
    r = params.coupling.reference_radius_m
    cases = [(d, float(j)) for d in directions for j in inertias]
    sgn = np.array([DIRECTIONS[d] for d, _ in cases])
    w0 = sgn * params.speed_reference_rad_s
    dw = -w0 * params.step_fraction
    n_per = int(round(period_s / ts))
    k_ev = [int(round(steady_s / ts)) + k * n_per for k in range(len(widths))]
    t_ev = [t0 + k * ts for k in k_ev]
    steps, ramps = [], []
    for k, te in enumerate(t_ev):
        steps.append((te, dw))
        steps.append((te + int(round(1.5 / ts)) * ts, -dw))         # back up 1.5 s later
        if k + 1 < len(widths):
            ramps.append((te + 2.0, 0.5, (widths[k + 1] - widths[k]) / r))
    drive = Drive(params, [j for _, j in cases], w0, widths[0] / r, steps=steps, ramps=ramps)
    res = simulate(drive, k_ev[-1] * ts + 1.5, t0=t0)
    n = res.t.size
    out = []
    for c, (direction, j1) in enumerate(cases):
        rng = np.random.default_rng([seed, 1000 + c])
        offsets = draw_offsets(rng, params.gear_ratio)
        sig = measure(res, c, params, sensors, rng, offsets)
        gl = gaps(res.delta[:, c], res.theta_b[:, c])
        if any(b < k_ev[0] for b, _ in gl):
            raise RuntimeError(f"case {c}: spurious entry in the steady stretch")
        events = []
        for k, (ke, te) in enumerate(zip(k_ev, t_ev)):
            nxt = k_ev[k + 1] if k + 1 < len(k_ev) else n
            mine = [(b, e) for b, e in gl if ke <= b < nxt]
            events.append({"index": ke, "time_s": _t(te), "type": "speed_reference_step",
                           "backlash_width_m": widths[k], "half_zone_rad": widths[k] / r,
                           "on_paper_grid": any(abs(widths[k] - g) < 1e-12 for g in PAPER_WIDTHS_M),
                           "entry_index": mine[0][0] if mine else None,
                           "entry_time_s": _t(res.t[mine[0][0]]) if mine else None,
                           "gaps": _gap_list(res, c, mine)})
        name = f"{'fwd' if direction == 'forward' else 'rev'}_J{j1:.3f}_wear"
        truth = {
            "name": name, "scenario": "wear", "direction": direction, "inertia_kgm2": j1,
            "reference_radius_m": r, "gear_ratio": params.gear_ratio, "drum_radius_m": params.drum_radius_m,
            "bearing_friction_nms": params.motor.bearing_friction_nms,
            "omega_ref_rad_s": [float(w0[c]), float(w0[c] + dw[c])],
            "wear_ramps": [{"start_s": _t(s_[c]), "duration_s": float(d_[c]),
                            "from_width_m": widths[k], "to_width_m": widths[k + 1]}
                           for k, (s_, d_, _) in enumerate(drive.ramps)],
            "events": events,
            **_sensor_truth(sensors, params, offsets, [seed, 1000 + c]),
            "sample_period_s": ts, "n_samples": int(n), "t0_s": _t(res.t[0]), "steady_s": steady_s,
        }
        out.append(Recording(name, sig, truth))
    return out
