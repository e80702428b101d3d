"""Recordings of the vector drive as a real drive records them, and their truth files.

* sampled at ``sample_period_s`` (2 kHz) from the control-period log of :func:`model.simulate`;
* ``alpha1``, ``alpha2``: motor and load encoders, ``encoder_counts`` per revolution (floor), each
  with an arbitrary offset (uniform in [0, 2 pi), redrawn while the zone centre in the recorded
  alpha1 - N alpha2 lies within 0.5 rad of 0);
* ``omega1``: the drive's speed feedback as its speed PI sees it (encoder difference over the
  control period, first-order filter: it lags); ``omega2`` the same on the load encoder;
* ``m_el``: the drive's torque estimate 1.5 n_p |psi_R,est| i_sq from its flux observer and
  measured current (its own error against the true air-gap torque, in the truth file);
* ``a1``: r dw_M/dt of the true motor (an accelerometer on the coupling hub; JointState bags carry it
  as sensor_msgs/Imu linear_acceleration.x only with ``imu``);
* noise: white, 'measured' SNR (noise power = mean(x^2)/10^(SNR/10)) on omega1, omega2, m_el, a1;
  the angles are only quantised.

Writers: the second drive's (``jident_ros.research.second_drive.record``: rosbags JointState/Imu MCAP bags,
CSV with the documented header), so the files are what ``jident diagnose`` reads.  Ground truth goes
only to ``<name>.truth.json`` and the directory's ``truth.json``.
"""
from __future__ import annotations

import hashlib
import json
import math
from dataclasses import asdict, dataclass, replace
from pathlib import Path
from typing import Optional

import numpy as np
from scipy.interpolate import CubicSpline
from scipy.signal import lfilter

from jident_ros.research.second_drive.record import write_csv, write_jointstate

from .dol import DOL_TRAVERSING_EVENTS, SLIP_EVENTS, dol_scenario, estimate_error_nm, gamma_pars, load_inertia, simulate_dol
from .model import TRAVERSING_EVENTS, DriveParams, Run, gaps, scenario, simulate

NOISY_CHANNELS = ("omega1", "omega2", "m_el", "a1")
CHANNELS = ("t", "alpha1", "alpha2", "omega1", "omega2", "m_el", "a1")
#: recording formats: JointState bag without / with Imu, CSV
INPUTS = ("jointstate", "jointstate_imu", "csv")


@dataclass(frozen=True)
class Sensors:
    encoder_counts: int = 65536
    snr_db: Optional[float] = None
    min_off_centre_rad: float = 0.5
    #: rms jitter of the sampling instants, s (clipped at 3 rms): a loop that reads the drive when it runs and
    #: stamps each reading with its own clock, so the stamps are the true instants (0: the drive's own clock)
    sample_jitter_s: float = 0.0
    #: rms jitter of the stamps alone, s (clipped at 3 rms): the drive samples on its own clock, a loop stamps the
    #: samples when it passes them on
    stamp_jitter_s: float = 0.0
    #: the drive reports its torque estimate in units of this share of its rated torque and its speed in units of
    #: speed_quantum_rad_s (0: unquantised), as a CiA 402 drive does (0x6077 torque actual value in 0.1 % of rated,
    #: 0x606C velocity actual value in rpm); applied after the noise
    torque_quantum_rel_rated: float = 0.0
    speed_quantum_rad_s: float = 0.0
    #: -1: the load encoder counts the other way (a reversing gear stage, an encoder facing the motor's): alpha2 and
    #: omega2 change sign (diagnosed with a negative gear_ratio)
    load_encoder_sign: float = 1.0
    #: amplitude of each encoder's once-per-revolution angle error, rad (a disc mounted off centre; real optical
    #: encoders: tens of arc seconds), with a twice-per-revolution error of half of it (an elliptic disc); the phases
    #: are drawn per encoder.  0: an ideal disc
    encoder_error_rad: float = 0.0
    #: the torque estimate reported this many samples late (a drive that publishes the previous cycle's estimate
    #: beside the current angles)
    torque_delay_samples: int = 0
    #: time constant of a first-order low-pass on the reported torque estimate, s (drives often smooth their "actual
    #: torque" value for display; 0: unfiltered), applied at the sample rate before the delay
    torque_filter_s: float = 0.0


def _jittered(st: dict, jitter_s: float, seed: int) -> tuple:
    """(states, stamps): the simulation's states at jittered instants t_k + e_k (cubic interpolation of the
    decimated log; the truth's gaps follow them) and those instants as the recording's stamps."""
    t = st["t"]
    n = t.size
    e = np.clip(np.random.default_rng([seed, 7]).normal(0.0, jitter_s, n), -3 * jitter_s, 3 * jitter_s)
    tj = np.clip(t + e, t[0], t[-1])
    # a channel the model does not have is NaN throughout (the DOL mode's speed and torque references): kept as it is
    out = {k: (CubicSpline(t, v)(tj) if k != "t" and isinstance(v, np.ndarray) and v.shape == (n,)
               and np.isfinite(v).all() else v) for k, v in st.items()}
    return out, tj - t[0]


@dataclass
class Recording:
    name: str
    signals: dict
    truth: dict
    #: the true relative angle theta_M - N theta_L at the recorded instants (rad; the truth's gaps are read from it;
    #: not written with the recording: entry_oracle reads it)
    delta_rad: Optional[np.ndarray] = None


def _wrap_pi(x):
    return (x + math.pi) % (2 * math.pi) - math.pi


def draw_offsets(rng, gear_ratio: float, min_off_centre_rad: float = 0.5):
    while True:
        o1, o2 = (float(x) for x in rng.uniform(0.0, 2 * math.pi, 2))
        if abs(_wrap_pi(o1 - gear_ratio * o2)) >= min_off_centre_rad:
            return o1, o2


def encoder(angle, offset, counts, error_rad=0.0, phases=(0.0, 0.0)):
    """What an encoder of ``counts`` per revolution reads for the shaft ``angle`` (rad, its own zero at
    ``offset``): floor-quantised, with a once-per-revolution error of ``error_rad`` and a twice-per-revolution one of
    half of it at ``phases`` (rad)."""
    x = np.asarray(angle, float) + offset
    if error_rad:
        x = x + error_rad * np.sin(x + phases[0]) + 0.5 * error_rad * np.sin(2.0 * x + phases[1])
    if not counts:
        return x
    q = 2 * math.pi / counts
    return np.floor(x / q) * q


def awgn_measured(x, snr_db, rng):
    p = float(np.mean(x * x)) / 10.0 ** (snr_db / 10.0)
    return x + rng.standard_normal(x.shape) * math.sqrt(p)


def decimate(run: Run) -> dict:
    """The control-period log at the recording's sample period (every d-th control sample)."""
    d = run.params.decimation
    return {k: v[::d].copy() for k, v in run.data.items()}


def params_key(p: DriveParams, *extra) -> str:
    text = json.dumps([asdict(p), list(extra)], sort_keys=True, default=str)
    return hashlib.sha256(text.encode()).hexdigest()[:16]


def simulate_cached(p: DriveParams, event: str, direction: str, duration_s: float, event_time_s: float,
                    cache_dir: Optional[Path] = None) -> dict:
    """Decimated states of one run (dict of arrays), from ``cache_dir`` when there (npz keyed by every
    parameter), else simulated (and saved there)."""
    key = params_key(p, event, direction, duration_s, event_time_s, asdict(scenario(p, event, direction, event_time_s)))
    path = None if cache_dir is None else Path(cache_dir) / f"vector_drive_{event}_{direction}_{key}.npz"
    return _cached(path, lambda: simulate(p, scenario(p, event, direction, event_time_s), duration_s))


def _cached(path: Optional[Path], simulate_run) -> dict:
    """The decimated run at ``path`` (an npz) if there, else ``simulate_run()`` decimated and saved there (atomically;
    ``path`` None: not saved): the vector and the DOL mode's simulation caches."""
    if path is not None and path.exists():
        with np.load(path) as z:
            return {k: z[k] for k in z.files if k != "motulator_version"} | \
                {"motulator_version": str(z["motulator_version"])}
    run = simulate_run()
    out = decimate(run)
    out["motulator_version"] = run.motulator_version
    if path is not None:
        path.parent.mkdir(parents=True, exist_ok=True)
        tmp = path.with_suffix(".tmp.npz")
        np.savez(tmp, **{k: v for k, v in out.items()})
        tmp.replace(path)
    return out


def _t(x):
    return round(float(x), 9)


#: How far before the zone entry the coupling's separation is looked for, samples.
SEPARATION_SEARCH_SAMPLES = 40


def _separation(tau_c: np.ndarray, b: int) -> int:
    """The first sample of the run, ending at the zone entry ``b``, in which the coupling transmits no torque: a damped
    contact separates when its force k·x + c·ẋ reaches zero, before x does (the zone entry, the truth's entry_index),
    and from there both masses run free (docs/vector_drive.md).  ``b`` itself for an undamped coupling (or a
    torque that is not zero right before b).  Zero: |T_c| at most 1e-9 of its largest (the interpolated states of
    a jittered recording are not exactly zero)."""
    tol = 1e-9 * max(float(np.max(np.abs(tau_c))), 1e-300)
    k = b
    while k > max(b - SEPARATION_SEARCH_SAMPLES, 1) and abs(float(tau_c[k - 1])) <= tol:
        k -= 1
    return int(k)


def _gap_torques(st: dict, b: int, e: int) -> dict:
    """What the gap's samples hold: the true air-gap torque, the drive's estimate's error against it and the
    motor's bearing friction (means over the gap, N m)."""
    sl = slice(b, e)
    tau, est, fr = st["tau_M"][sl], st["tau_est"][sl], st["tau_f1"][sl]
    if tau.size == 0:
        return {}
    return {"true_torque_mean_nm": float(np.mean(tau)),
            "torque_estimate_error_mean_nm": float(np.mean(est - tau)),
            "bearing_friction_mean_nm": float(np.mean(fr))}


def case_name(event: str, direction: str, j1: float, k2: float, sensors: Sensors) -> str:
    noise = "clean" if sensors.snr_db is None else f"{sensors.snr_db:g}dB"
    return (f"vd_{event}_{'fwd' if direction == 'forward' else 'rev'}_J{j1:.3f}_K{k2 * 1e3:.2f}mm_"
            f"{sensors.encoder_counts}c_{noise}")


def _sensed(st: dict, p, sensors: Sensors, seed: int) -> tuple:
    """(signals, delta, o1, o2): a simulation ``st`` as the drive records it (encoders with drawn offsets, the
    drive's speed feedback and torque estimate, a1 at the reference radius, noise), the true relative angle delta and
    the two encoder offsets; the vector and the DOL mode's recordings alike."""
    ts = p.sample_period_s
    mech = p.mechanics
    n = st["t"].size
    stamps = np.arange(n) * ts
    if sensors.sample_jitter_s > 0:
        st, stamps = _jittered(st, sensors.sample_jitter_s, seed)
    if sensors.stamp_jitter_s > 0:
        j = sensors.stamp_jitter_s
        stamps = stamps + 3 * j + np.clip(np.random.default_rng([seed, 8]).normal(0.0, j, n), -3 * j, 3 * j)
    rng = np.random.default_rng([seed, sensors.encoder_counts, 0 if sensors.snr_db is None else int(sensors.snr_db)])
    o1, o2 = draw_offsets(rng, mech.gear_ratio, sensors.min_off_centre_rad)
    r = mech.reference_radius_m
    ph = (np.random.default_rng([seed, 9]).uniform(0.0, 2 * math.pi, 4) if sensors.encoder_error_rad
          else np.zeros(4))
    m_el = st["tau_est"].copy()
    if sensors.torque_filter_s > 0:
        a = math.exp(-ts / sensors.torque_filter_s)
        m_el = lfilter([1.0 - a], [1.0, -a], m_el, zi=[a * m_el[0]])[0]
    if sensors.torque_delay_samples:
        k = int(sensors.torque_delay_samples)
        m_el = np.concatenate([np.full(k, m_el[0]), m_el[:-k]])
    sig = {"t": stamps,
           "alpha1": encoder(st["theta_M"], o1, sensors.encoder_counts, sensors.encoder_error_rad, ph[:2]),
           "alpha2": encoder(sensors.load_encoder_sign * st["theta_L"], o2, sensors.encoder_counts,
                             sensors.encoder_error_rad, ph[2:]),
           "omega1": st["w_fbk"].copy(), "omega2": sensors.load_encoder_sign * st["w_L_fbk"],
           "m_el": m_el, "a1": r * st["dw_M"]}
    if sensors.snr_db is not None:
        for k in NOISY_CHANNELS:
            sig[k] = awgn_measured(sig[k], sensors.snr_db, rng)
    for keys, q in ((("m_el",), sensors.torque_quantum_rel_rated * p.machine.rated_torque_nm),
                    (("omega1", "omega2"), sensors.speed_quantum_rad_s)):
        for k in keys if q > 0 else ():
            sig[k] = q * np.round(sig[k] / q)
    return sig, st["theta_M"] - mech.gear_ratio * st["theta_L"], o1, o2


def build(p: DriveParams, event: str, direction: str, sensors: Sensors, seed: int = 0, duration_s: float = 2.2,
          event_time_s: float = 0.6, cache_dir: Optional[Path] = None) -> Recording:
    """One recording (signals + truth) of ``event`` in ``direction``."""
    st = simulate_cached(p, event, direction, duration_s, event_time_s, cache_dir)
    ts, mech, n = p.sample_period_s, p.mechanics, st["t"].size
    r = mech.reference_radius_m
    sig, delta, o1, o2 = _sensed(st, p, sensors, seed)
    th = mech.half_zone_rad
    k_ev = int(round(event_time_s / ts))
    gl = gaps(delta, th)
    gap_list = [{"entry_index": b, "entry_time_s": _t(sig["t"][b]),
                 "recontact_index": e if e < n else None, "recontact_time_s": _t(sig["t"][e]) if e < n else None,
                 "from_flank": int(np.sign(delta[b - 1])) if b > 0 else 0,
                 "to_flank": int(np.sign(delta[e])) if e < n else 0,
                 "traversal": bool(b > 0 and e < n and np.sign(delta[b - 1]) != np.sign(delta[e])),
                 "separation_index": _separation(st["tau_c"], b),
                 "samples": e - b, **_gap_torques(st, b, e)} for b, e in gl]
    steady = slice(min(int(0.1 / ts), k_ev // 2), k_ev)   # the start of the log is the pre-roll's end
    tau = st["tau_M"]
    err = st["tau_est"] - tau
    big = np.abs(tau) > 0.2 * p.machine.rated_torque_nm
    name = case_name(event, direction, mech.motor_inertia_kgm2, mech.backlash_width_m, sensors)
    first = gap_list[0] if gap_list else None
    truth = {
        "name": name, "model": "jident_ros.research.vector_drive", "event": {"type": event, "index": k_ev,
                                                                     "time_s": _t(k_ev * ts),
                                                                     "traversing": event in TRAVERSING_EVENTS},
        "direction": direction, "inertia_kgm2": mech.motor_inertia_kgm2,
        "load_inertia_kgm2": mech.load_inertia_kgm2, "backlash_width_m": mech.backlash_width_m,
        "reference_radius_m": r, "half_zone_rad": th, "flank_to_flank_rad": 2 * th, "gear_ratio": mech.gear_ratio,
        "bearing_friction": {"coulomb_nm": mech.motor_coulomb_nm, "viscous_nms_per_rad": mech.motor_viscous_nms_per_rad,
                             "smoothing_rad_s": mech.friction_smoothing_rad_s},
        "entry_index": first["entry_index"] if first else None,
        "entry_time_s": first["entry_time_s"] if first else None,
        "recontact_index": first["recontact_index"] if first else None,
        "recontact_time_s": first["recontact_time_s"] if first else None,
        "gaps": gap_list, "steady_rows": k_ev,
        "torque_estimate_error": {
            "steady_relative": float(np.mean(err[steady]) / np.mean(tau[steady])) if np.mean(np.abs(tau[steady])) > 0
            else None,
            "median_abs_relative_where_loaded": float(np.median(np.abs(err[big] / tau[big]))) if big.any() else None,
            "max_abs_nm": float(np.max(np.abs(err)))},
        "speed_feedback": {"filter_s": p.controller.speed_filter_s, "control_period_s": p.controller.control_period_s},
        "encoder": {"counts_per_rev": sensors.encoder_counts, "alpha1_offset_rad": o1, "alpha2_offset_rad": o2,
                    "relative_offset_rad": o1 - mech.gear_ratio * o2, "quantisation": "floor"},
        "noise": {"snr_db": sensors.snr_db, "channels": list(NOISY_CHANNELS), "seed": seed},
        "sample_period_s": ts, "n_samples": int(n), "t0_s": 0.0,
        "motulator_version": st.get("motulator_version", "?"),
    }
    return Recording(name, sig, truth, delta)


def write(out_dir: Path, rec: Recording, fmt: str) -> str:
    """Write one recording in ``fmt`` (:data:`INPUTS`); returns its path relative to out_dir."""
    out_dir = Path(out_dir)
    out_dir.mkdir(parents=True, exist_ok=True)
    if fmt == "csv":
        rel = f"{rec.name}.csv"
        if not (out_dir / rel).exists():
            write_csv(out_dir / rel, {k: rec.signals[k] for k in CHANNELS})
    elif fmt in ("jointstate", "jointstate_imu"):
        rel = rec.name + ("_imu" if fmt == "jointstate_imu" else "")
        if not (out_dir / rel).exists():
            sig = dict(rec.signals)
            sig["omega2"] = rec.signals["omega2"]
            write_jointstate(out_dir / rel, sig, imu=fmt == "jointstate_imu")
    else:
        raise ValueError(f"format: expected one of {', '.join(INPUTS)}, got {fmt!r}")
    tr = out_dir / f"{rec.name}.truth.json"
    if not tr.exists():
        tr.write_text(json.dumps(rec.truth, indent=1, allow_nan=False) + "\n")
    return rel


def with_inertia(p: DriveParams, j1: float) -> DriveParams:
    return replace(p, mechanics=replace(p.mechanics, motor_inertia_kgm2=float(j1)))


def with_width(p: DriveParams, k2: float) -> DriveParams:
    return replace(p, mechanics=replace(p.mechanics, backlash_width_m=float(k2)))


# ------------------------------------------------------------------------------------------ the DOL mode
def simulate_dol_cached(p, event: str, direction: str, duration_s: float, event_time_s: float,
                        cache_dir: Optional[Path] = None) -> dict:
    """:func:`simulate_cached` of the DOL mode (dol.DolParams; npz files ``dol_<event>_<direction>_<key>.npz``)."""
    sc = dol_scenario(p, event, direction, event_time_s)
    key = params_key(p, event, direction, duration_s, event_time_s, asdict(sc))
    path = None if cache_dir is None else Path(cache_dir) / f"dol_{event}_{direction}_{key}.npz"
    return _cached(path, lambda: simulate_dol(p, sc, duration_s))


def dol_case_name(event: str, direction: str, j1: float, k2: float, sensors: Sensors) -> str:
    return "dol" + case_name(event, direction, j1, k2, sensors)[2:]


def build_dol(p, event: str, direction: str, sensors: Sensors, seed: int = 0, duration_s: float = 2.2,
              event_time_s: float = 0.6, cache_dir: Optional[Path] = None) -> Recording:
    """One recording (signals + truth) of the DOL mode (dol.DolParams, dol.DOL_EVENTS), written as :func:`build`
    writes the vector drive's: the same channels, encoders, noise and truth keys; ``m_el`` is the voltage-model
    torque estimate (dol.TorqueEstimate), ``omega1``/``omega2`` the encoder-difference speeds."""
    st = simulate_dol_cached(p, event, direction, duration_s, event_time_s, cache_dir)
    ts, mech, n = p.sample_period_s, p.mechanics, st["t"].size
    r = mech.reference_radius_m
    sig, delta, o1, o2 = _sensed(st, p, sensors, seed)
    th = mech.half_zone_rad
    k_ev = int(round(event_time_s / ts))
    traversing = event in DOL_TRAVERSING_EVENTS
    gl = gaps(delta, th)
    gap_list = []
    for b, e in gl:
        g = {"entry_index": b, "entry_time_s": _t(sig["t"][b]),
             "recontact_index": e if e < n else None, "recontact_time_s": _t(sig["t"][e]) if e < n else None,
             "from_flank": int(np.sign(delta[b - 1])) if b > 0 else 0,
             "to_flank": int(np.sign(delta[e])) if e < n else 0,
             "traversal": bool(b > 0 and e < n and np.sign(delta[b - 1]) != np.sign(delta[e])),
             "samples": e - b, **_gap_torques(st, b, e)}
        # the gap the event opens (the first after it): a flank-to-flank traversal, or slip_drop's excursion from
        # the driving flank and back to it (the paper's case)
        g["event_gap"] = bool(traversing and b >= k_ev and not any(x.get("event_gap") for x in gap_list))
        gap_list.append(g)
    steady = slice(min(int(0.1 / ts), k_ev // 2), k_ev)
    tau = st["tau_M"]
    err = st["tau_est"] - tau
    big = np.abs(tau) > 0.2 * p.machine.rated_torque_nm
    sc = dol_scenario(p, event, direction, event_time_s)
    pred = estimate_error_nm(p, st["i_s_abs"], sc.direction)
    name = dol_case_name(event, direction, mech.motor_inertia_kgm2, mech.backlash_width_m, sensors)
    first = next((g for g in gap_list if g["event_gap"]), gap_list[0] if gap_list else None)
    gpar = gamma_pars(p)
    truth = {
        "name": name, "model": "jident_ros.research.vector_drive.dol",
        "event": {"type": event, "index": k_ev, "time_s": _t(k_ev * ts), "traversing": traversing,
                  "slip": event in SLIP_EVENTS, "load_before_nm": sc.load_before_nm, "load_after_nm": sc.load_after_nm,
                  "ramp_s": sc.ramp_s, "load_inertia_after_kgm2": load_inertia(p, sc, event_time_s + 1.0)},
        "direction": direction, "inertia_kgm2": mech.motor_inertia_kgm2,
        "load_inertia_kgm2": mech.load_inertia_kgm2, "backlash_width_m": mech.backlash_width_m,
        "reference_radius_m": r, "half_zone_rad": th, "flank_to_flank_rad": 2 * th, "gear_ratio": mech.gear_ratio,
        "bearing_friction": {"coulomb_nm": mech.motor_coulomb_nm, "viscous_nms_per_rad": mech.motor_viscous_nms_per_rad,
                             "smoothing_rad_s": mech.friction_smoothing_rad_s},
        "supply": {"kind": "direct on line (stiff grid)", "line_voltage_v": p.grid_line_voltage_v,
                   "frequency_hz": p.grid_frequency_hz, "rated_torque_nm": p.machine.rated_torque_nm},
        "entry_index": first["entry_index"] if first else None,
        "entry_time_s": first["entry_time_s"] if first else None,
        "recontact_index": first["recontact_index"] if first else None,
        "recontact_time_s": first["recontact_time_s"] if first else None,
        "gaps": gap_list, "steady_rows": k_ev,
        "torque_estimate": {"kind": "voltage model: psi_s = leaky integral of (u_s - R_s,est i_s), corrected at the grid "
                                    "frequency; tau = 1.5 n_p Im(conj(psi_s) i_s)",
                            "stator_resistance_ohm": gpar["R_s"],
                            "stator_resistance_estimate_ohm": gpar["R_s"] * p.stator_resistance_estimate_ratio,
                            "highpass_hz": p.flux_highpass_hz},
        "torque_estimate_error": {
            "steady_relative": float(np.mean(err[steady]) / np.mean(tau[steady])) if np.mean(np.abs(tau[steady])) > 0
            else None,
            "steady_nm": float(np.mean(err[steady])),
            "median_abs_relative_where_loaded": float(np.median(np.abs(err[big] / tau[big]))) if big.any() else None,
            "max_abs_nm": float(np.max(np.abs(err))),
            "max_abs_minus_resistance_term_nm": float(np.max(np.abs(err - pred))),
            "resistance_term_max_nm": float(np.max(np.abs(pred)))},
        "speed_feedback": {"filter_s": p.speed_filter_s, "control_period_s": p.control_period_s,
                           "kind": "encoder difference (2^20 counts) over the control period, first-order filter"},
        "encoder": {"counts_per_rev": sensors.encoder_counts, "alpha1_offset_rad": o1, "alpha2_offset_rad": o2,
                    "relative_offset_rad": o1 - mech.gear_ratio * o2, "quantisation": "floor"},
        "noise": {"snr_db": sensors.snr_db, "channels": list(NOISY_CHANNELS), "seed": seed},
        "sample_period_s": ts, "n_samples": int(n), "t0_s": 0.0,
        "motulator_version": st.get("motulator_version", "?"),
    }
    return Recording(name, sig, truth, delta)
