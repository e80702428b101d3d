"""Stress cases for the gap estimator (issue 20's failure modes), on a small speed-controlled two-mass drive.

Not a validation drive model (those are jident_ros.second_drive and the zoo's): a compact test bench for the
estimator alone, with what the issue names:

* a speed controller (PI on the lagging speed feedback) behind a first-order torque (current) loop, so the
  torque ramps through the entry;
* a two-mass coupling with a backlash dead zone (spring-damper in contact), bearing friction on the motor
  (Coulomb + viscous), a load with Coulomb + viscous friction and an optional active load torque;
* events: a speed step (100 -> 80 rad/s), a speed reversal (+60 -> -60 rad/s), a load reversal (the active load
  torque changes sign at light load);
* recorded as a drive records: the motor encoder (2^16 counts/rev, arbitrary offset), the drive's torque
  estimate with a scale error (``torque_scale_error``), the speed feedback lagging by a first-order filter
  (``speed_lag_s``), optionally a1 (an Imu) and white noise at ``snr_db`` on the torque, speed and a1;
* the detector's coarse entry and re-contact rows offset from the truth by ``entry_offset`` and
  ``recontact_offset`` samples (the issue's -14 .. +23).

``python -m jident_ros.research.evaluation.gap_stress`` prints the table of docs/results.md ("Gap estimator: stress
cases").  Research code (evaluation): the runtime path never imports it.
"""
from __future__ import annotations

import argparse
import math
from dataclasses import dataclass

import numpy as np

from jident_ros.config import load_system_config
from jident_ros.identify.fusion import fuse_verdict
from jident_ros.identify.gap import NoGapError, estimate_inertia, nearest_class
from jident_ros.identify.gap_free import GapModel
from jident_ros.identify.verdict import VerdictPolicy, decide_gap
from jident_ros.research.evaluation.raw_inputs import evaluate_condition, evaluate_second_drive, raw_recordings, without

CLASSES = (1.16, 1.131, 1.102, 1.073, 0.957, 1.189, 1.218)
EVENTS = ("speed_step", "speed_reversal", "load_reversal")


@dataclass(frozen=True)
class StressDrive:
    j1_kgm2: float = 1.16
    j2_kgm2: float = 2.0
    backlash_rad: float = 0.03              # flank to flank
    contact_stiffness_nm_per_rad: float = 2.0e5
    contact_damping_nms_per_rad: float = 40.0
    motor_coulomb_nm: float = 0.6
    motor_viscous_nms_per_rad: float = 0.004
    load_coulomb_nm: float = 20.0
    load_viscous_nms_per_rad: float = 0.3
    kp_nms: float = 60.0
    ki_nm: float = 600.0
    torque_loop_s: float = 1.5e-3
    torque_limit_nm: float = 400.0
    sample_period_s: float = 5e-4
    substeps: int = 20


def simulate(drive: StressDrive, event: str, seed: int = 0, speed_lag_s: float = 4e-4, torque_scale_error: float = 0.0,
             counts: int = 65536, snr_db: float | None = None, light_load: bool = True) -> dict:
    """One recording around the event: dict of channels and the truth (entry, recontact rows of the first gap
    after the event, J1)."""
    rng = np.random.default_rng(seed)
    ts, ns = drive.sample_period_s, drive.substeps
    h = ts / ns
    n = 1600
    t_event = 0.3
    w_ref0, w_ref1 = {"speed_step": (100.0, 80.0), "speed_reversal": (60.0, -60.0), "load_reversal": (50.0, 50.0)}[event]
    active0 = 0.0
    active1 = 0.0
    if event == "load_reversal":
        # an overhauling load: the load torque changes sign (light load), the motor goes from driving to braking
        active0, active1 = (-10.0, 30.0) if light_load else (-100.0, 200.0)
    load_coulomb = drive.load_coulomb_nm if event != "load_reversal" else 2.0
    # state: th1, w1, th2, w2, m (torque), integ (PI), wf (filtered speed feedback)
    w0 = w_ref0
    # steady state: the motor drives the load through the far flank (or is driven, load reversal)
    load0 = load_coulomb * np.sign(w0) + drive.load_viscous_nms_per_rad * w0 - active0
    fric1 = drive.motor_coulomb_nm * np.sign(w0) + drive.motor_viscous_nms_per_rad * w0
    m0 = load0 + fric1
    half = drive.backlash_rad / 2
    pen0 = load0 / drive.contact_stiffness_nm_per_rad
    th1, w1 = 0.0, w0
    th2 = th1 - (half + pen0) * np.sign(load0)
    w2 = w0
    m = m0
    integ = m0
    wf = w0
    rows = {k: np.empty(n) for k in ("alpha1", "omega1", "m_el", "a1", "alpha2", "delta")}
    k_c, c_c = drive.contact_stiffness_nm_per_rad, drive.contact_damping_nms_per_rad
    for i in range(n):
        t = i * ts
        w_ref = w_ref0 if t < t_event else w_ref1
        if event == "speed_reversal" and t >= t_event:
            w_ref = max(w_ref1, w_ref0 - 2000.0 * (t - t_event)) if w_ref1 < w_ref0 else w_ref1
        active = active0 + (active1 - active0) * min(max((t - t_event) / 0.1, 0.0), 1.0)
        acc1 = 0.0
        for _ in range(ns):
            err = w_ref - wf
            cmd = drive.kp_nms * err + integ
            cmd_c = min(max(cmd, -drive.torque_limit_nm), drive.torque_limit_nm)
            integ += h * drive.ki_nm * err + h * (cmd_c - cmd) / 0.05
            m += h * (cmd_c - m) / drive.torque_loop_s
            d = th1 - th2
            pen = abs(d) - half
            if pen > 0:
                s = np.sign(d)
                tc = s * max(k_c * pen + c_c * s * (w1 - w2), 0.0)
            else:
                tc = 0.0
            f1 = drive.motor_coulomb_nm * np.tanh(w1 / 0.05) + drive.motor_viscous_nms_per_rad * w1
            f2 = load_coulomb * np.tanh(w2 / 0.05) + drive.load_viscous_nms_per_rad * w2 - active
            acc1 = (m - f1 - tc) / drive.j1_kgm2
            acc2 = (tc - f2) / drive.j2_kgm2
            th1 += h * w1 + 0.5 * h * h * acc1
            w1 += h * acc1
            th2 += h * w2 + 0.5 * h * h * acc2
            w2 += h * acc2
            wf += h * (w1 - wf) / speed_lag_s if speed_lag_s > 0 else (w1 - wf)
        rows["alpha1"][i], rows["omega1"][i], rows["m_el"][i] = th1, wf, m
        rows["a1"][i], rows["alpha2"][i], rows["delta"][i] = acc1, th2, th1 - th2
    inside = np.abs(rows["delta"]) < half
    after = int(t_event / ts)
    idx = np.flatnonzero(inside[after:])
    if idx.size == 0:
        raise RuntimeError(f"{event}: no backlash traversal")
    entry = after + int(idx[0])
    out_idx = np.flatnonzero(~inside[entry:])
    recontact = entry + int(out_idx[0]) if out_idx.size else n
    q = 2 * math.pi / counts
    off1 = rng.uniform(0, 2 * math.pi)
    chans = {"alpha1": np.floor((rows["alpha1"] + off1) / q) * q,
             "omega1": rows["omega1"].copy(), "m_el": rows["m_el"] * (1.0 + torque_scale_error),
             "a1": 0.08 * rows["a1"]}        # a1 at the wheel radius r = 0.08 m, m/s^2
    if snr_db is not None:
        for c in ("omega1", "m_el", "a1"):
            p = float(np.mean(chans[c][entry - 200:entry + 200] ** 2)) / 10 ** (snr_db / 10)
            chans[c] = chans[c] + rng.standard_normal(n) * math.sqrt(p)
    chans["t"] = np.arange(n) * ts
    # the load encoder (its offset fixed: no draw from rng, so the other channels' noise is as before), for the
    # gap stage's load-side bound (identify/gap_load.py: bench/bench_gap.py's "with load encoder")
    load_angle = np.floor((rows["alpha2"] + 1.234) / q) * q
    return {"window": chans, "entry": entry, "recontact": recontact, "j1": drive.j1_kgm2, "event": event,
            "load_angle": load_angle}


def run(model: GapModel, *, snr_db=None, with_imu=False, torque_scale_errors=(0.0, 0.01), offsets=((-14, -3), (0, 0),
        (23, 2), (5, -5)), inertias=(1.16, 1.073, 1.218), log=None) -> dict:
    """Every event x J1 x torque scale error x entry/re-contact offset: published, error, coverage, refusals."""
    policy = VerdictPolicy()
    rows = []
    for event in EVENTS:
        for j1 in inertias:
            for k, err in enumerate(torque_scale_errors):
                rec = simulate(StressDrive(j1_kgm2=j1), event, seed=k + int(j1 * 1000), torque_scale_error=err,
                               snr_db=snr_db)
                w = dict(rec["window"])
                if not with_imu:
                    w.pop("a1")
                for off_e, off_r in offsets:
                    e0 = rec["entry"] + off_e
                    r0 = max(rec["recontact"] + off_r, e0 + 4)
                    row = {"event": event, "j1": j1, "torque_error": err, "offset": (off_e, off_r),
                           "gap_samples": rec["recontact"] - rec["entry"]}
                    try:
                        g = estimate_inertia(w, e0, 0.005, 0.08, 5e-4, recontact_index=r0,
                                             bearing_friction_nms_per_rad=0.0, model=model)
                    except NoGapError as exc:
                        row.update(published=False, reason=str(exc)[:70])
                        rows.append(row)
                        continue
                    dec = decide_gap(g, CLASSES, 1.16, policy, None, 0.005)
                    v = fuse_verdict(CLASSES, None, None, g)
                    row.update(est=g.inertia_kgm2, rel_error=g.inertia_kgm2 / j1 - 1,
                               covered=bool(g.ci95_kgm2[0] <= j1 <= g.ci95_kgm2[1]),
                               published=dec.publish, reason=dec.reason[:70],
                               between=v.between_classes, class_ok=CLASSES[nearest_class(g.inertia_kgm2, CLASSES)] == j1,
                               fit=(g.fit_start - rec["entry"], g.fit_end - rec["recontact"]), se=g.std_error_kgm2 / j1,
                               method=g.method)
                    rows.append(row)
    return summarise(rows)


def summarise(rows: list) -> dict:
    pub = [r for r in rows if r.get("published")]
    est = [r for r in rows if "est" in r]
    err = np.array([abs(r["rel_error"]) for r in pub]) if pub else np.zeros(0)
    reasons: dict = {}
    for r in rows:
        if not r.get("published"):
            key = (r.get("reason") or "not published").split(":")[0][:28]
            reasons[key] = reasons.get(key, 0) + 1
    return {"windows": len(rows), "published": len(pub),
            "published_off_10pct": int(sum(abs(r["rel_error"]) > 0.10 for r in pub)),
            "published_off_3pct": int(sum(abs(r["rel_error"]) > 0.03 for r in pub)),
            "median_abs_error": float(np.median(err)) if err.size else None,
            "max_abs_error": float(err.max()) if err.size else None,
            "coverage": (sum(r["covered"] for r in est), len(est)),
            "between_classes_on_class": int(sum(r["between"] and r["class_ok"] for r in est)),
            "refusals": reasons, "rows": rows}


JOINTSTATE_ABSENT = ("a1", "a2", "v2")
IMU_ABSENT = ("a2", "v2")


def _line(label: str, res: dict) -> str:
    n = res["gap_windows"]
    return (f"{label}: event windows {n}, published {res['published']} ({res['published_off']} > 10 % off), "
            f"class {res['class_correct']}/{n}, 95 % CI covers {res['ci_covers']}/{res['gap_fitted']} fitted, "
            f"ambiguous {res['ambiguous']}, |err| median {100 * (res['j1_median_abs_error'] or 0):.2f} % max "
            f"{100 * (res['j1_max_abs_error'] or 0):.2f} %, fits {res['fits']}")


def other_models(second_drive_dirs=(), ours: bool = False) -> None:
    """The default gap fit (the diagnostic node's model choice, default GapModel: the drives' torque is exact)
    through the flank detector on the second drive's CSV directories and on our simulator's raw recordings."""
    system = load_system_config()
    for d in second_drive_dirs:
        for label, absent in (("JointState", JOINTSTATE_ABSENT), ("with a1", IMU_ABSENT)):
            print(_line(f"second drive {d} {label}", evaluate_second_drive(system, d, absent=absent)))
    if ours:
        for snr in (None, 30.0):
            recs = raw_recordings(system, snr_db=snr, steady_s=1.0, seed=12 + (0 if snr is None else 1))
            for label, absent in (("JointState", JOINTSTATE_ABSENT), ("with a1", IMU_ABSENT)):
                res = evaluate_condition(system, [without(r, absent) for r in recs], 65536, "flank")
                print(_line(f"ours {'clean' if snr is None else '30 dB'} {label}", res))


def main(argv=None) -> int:
    p = argparse.ArgumentParser(prog="python -m jident_ros.research.evaluation.gap_stress", description=__doc__.split("\n\n")[0])
    p.add_argument("--torque-accuracy", type=float, default=0.02)
    p.add_argument("--coulomb-max-nm", type=float, default=1.5)
    p.add_argument("--verbose", action="store_true")
    p.add_argument("--second-drive", nargs="*", default=(), metavar="DIR",
                   help="also the second drive's CSV recordings (python -m jident_ros.second_drive --format csv): as "
                        "JointState (motor angle, speed, torque; load angle, speed) and with a1 (an Imu)")
    p.add_argument("--ours", action="store_true", help="also our simulator's raw recordings (raw_inputs), clean and "
                                                       "30 dB, as JointState and with a1")
    a = p.parse_args(argv)
    model = GapModel(torque_accuracy=a.torque_accuracy, coulomb_friction_max_nm=a.coulomb_max_nm)
    other_models(a.second_drive, a.ours)
    for imu in (False, True):
        for snr in (None, 30.0):
            s = run(model, snr_db=snr, with_imu=imu)
            cov = s["coverage"]
            print(f"{'Imu' if imu else 'JointState'} {'clean' if snr is None else f'{snr:g} dB'}: published "
                  f"{s['published']}/{s['windows']}, > 10 % off {s['published_off_10pct']}, > 3 % off "
                  f"{s['published_off_3pct']}, |err| median {100 * (s['median_abs_error'] or 0):.2f} % max "
                  f"{100 * (s['max_abs_error'] or 0):.2f} %, 95 % coverage {cov[0]}/{cov[1]}, 'between classes' on "
                  f"class {s['between_classes_on_class']}, refusals {s['refusals']}")
            per = {}
            for r in s["rows"]:
                d = per.setdefault(r["event"], [0, 0, 0])
                d[0] += 1
                d[1] += bool(r.get("published"))
                d[2] += bool(r.get("published")) and abs(r["rel_error"]) <= 0.03
            print("    per event (windows, published, published within 3 %): " + ", ".join(
                f"{k} {v[0]}/{v[1]}/{v[2]}" for k, v in per.items()))
            if a.verbose:
                for r in s["rows"]:
                    print("   ", {k: (round(v, 4) if isinstance(v, float) else v) for k, v in r.items()})
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
