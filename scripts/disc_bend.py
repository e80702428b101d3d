"""What an encoder's disc error does to a short free angle fit: DOL set 10's d10-04 (docs/results.md, "Stop 36").

Its slip reversal's simulation (zoo_draws' cache, simulated when missing), the motor's true angle and its true torque
less the declared viscous friction, fitted by the free angle fit (jident_ros.identify.gap_free.free_angle_fit, the
rows fixed) over the 19 rows the published window kept (1305–1324) and over 1274–1355: without a disc error, and with
the drawn one (0.2 mrad once, 0.1 mrad twice per revolution) at four phases; then the drive's torque estimate with the
30 dB recording's noise, 200 draws, over the 19 rows (the J1 scatter the noise alone gives).

    .venv/bin/python scripts/disc_bend.py
"""
import math
from pathlib import Path

import numpy as np

from jident_ros.identify.gap_free import GapModel, free_angle_fit
from jident_ros.research.evaluation import zoo_draws
from jident_ros.research.vector_drive import record

SHORT, LONG = (1305, 1324), (1274, 1355)


def main() -> None:
    d = zoo_draws.draw(10, 4, "dol")
    p, m = d.params, d.params.mechanics
    st = record.simulate_dol_cached(p, "slip_reversal", d.direction, 2.2, 0.6, Path("out/zoo_draws/cache"))
    ts, j1 = p.sample_period_s, m.motor_inertia_kgm2
    model = GapModel(coulomb_friction_max_nm=1.25 * m.motor_coulomb_nm)
    torque = st["tau_M"] - m.motor_viscous_nms_per_rad * st["w_M"]

    def rel(angle, tq, rows):
        return free_angle_fit(angle, tq, ts, *rows, model=model, fixed=True)["j1"] / j1 - 1

    print(f"d10-04: J1 {j1} kg m^2, slip reversal, {d.sensor_fields['encoder_counts']} counts")
    for rows in (SHORT, LONG):
        exact = rel(st["theta_M"], torque, rows)
        bent = [rel(record.encoder(st["theta_M"], 0.3, 0, 2e-4, np.random.default_rng(k).uniform(0, 2 * math.pi, 4)[:2]),
                    torque, rows) for k in range(4)]
        print(f"rows {rows[0]}..{rows[1]}: exact disc {100 * exact:+.2f} %; 0.2 / 0.1 mrad at four phases "
              + ", ".join(f"{100 * b:+.1f} %" for b in bent))
    est = st["tau_est"] - m.motor_viscous_nms_per_rad * st["w_M"]
    sd = math.sqrt(float(np.mean(st["tau_est"] ** 2)) / 10.0 ** 3)          # 30 dB of the estimate's power
    js = [rel(st["theta_M"], est + np.random.default_rng(k).standard_normal(est.size) * sd, SHORT) for k in range(200)]
    print(f"rows {SHORT[0]}..{SHORT[1]}, the torque estimate with 30 dB noise ({sd:.2f} N m), 200 draws: "
          f"mean {100 * np.mean(js):+.2f} %, scatter {100 * np.std(js):.2f} %")


if __name__ == "__main__":
    main()
