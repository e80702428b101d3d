"""What the data hold over the TRUE gap samples, with the torque estimate's lag and offset (issue 20 item 3).

``python -m jident_ros.research.evaluation.zoo_oracle [--out out/zoo] [--models "vector drive"]``

For every traversal of the zoo's clean 2^16 CSV recordings (:mod:`jident_ros.research.evaluation.zoo`, cached under
``--out``), over the truth's gap rows [entry, re-contact), with the drive's declared b1 ω1 taken off m_el
(:func:`zoo.declared`): J1's error of the double-integral fit α1 = θ0 + ω0 t + Φ/J1 (Φ = ∬ m_el), with a fitted lag
(+ (τ/J1) ∫m_el dt), with a free constant torque (+ T t²/2 /J1), and J1's sensitivity to a 1 N m offset and to a
1 ms lag (|r_κ · t²/2| and |r_κ · ∫m_el dt|, relative): the numbers behind docs/method.md's "Torque offset" and
"Torque lag" and docs/results.md's "The zoo configured per drive".  Research code (no thresholds chosen here).
"""
from __future__ import annotations

import argparse
import sys
from pathlib import Path

import numpy as np

from jident_ros.research.evaluation import zoo


def _cum(x: np.ndarray, ts: float) -> np.ndarray:
    return np.concatenate([[0.0], np.cumsum(0.5 * (x[1:] + x[:-1])) * ts])


def gap_oracle(t, alpha1, m_el, omega1, first: int, end: int, b1: float = 0.0) -> dict:
    """Errors are relative J1 values (1/κ); see the module docstring.  Keys: j1, j1_lag, lag_s, j1_offset,
    per_nm, per_ms."""
    ts = float(t[1] - t[0])
    m = np.asarray(m_el[first:end], float) - b1 * np.asarray(omega1[first:end], float)
    tt = np.arange(end - first) * ts
    phi, psi, q = _cum(_cum(m, ts), ts), _cum(m, ts), 0.5 * tt * tt
    y = np.asarray(alpha1[first:end], float) - float(alpha1[first])
    base = np.column_stack([np.ones(tt.size), tt, phi])

    def fit(extra=None):
        X = base if extra is None else np.column_stack([base, extra])
        pinv = np.linalg.pinv(X)
        return pinv @ y, pinv[2]
    c, row = fit()
    cl, _ = fit(psi)
    co, _ = fit(q)
    return {"j1": 1.0 / c[2], "j1_lag": 1.0 / cl[2], "lag_s": cl[3] / cl[2], "j1_offset": 1.0 / co[2],
            "per_nm": abs(float(row @ q)) * 1.0, "per_ms": abs(float(row @ psi)) * 1e-3}


def rows(out: Path, models=("vector drive",)) -> list:
    recs = zoo.generate(out, models=models, log=lambda text: print(text, file=sys.stderr))
    result = []
    for zr in recs:
        if zr.snr_db is not None or zr.counts != 65536 or "csv" not in zr.files:
            continue
        with open(zr.files["csv"]) as f:
            header = f.readline().strip().split(",")
        if "omega1" not in header:
            continue
        d = np.loadtxt(zr.files["csv"], delimiter=",", skiprows=1,
                       usecols=[header.index(c) for c in ("t", "alpha1", "m_el", "omega1")])
        b1 = zoo.declared(zr.model).get("bearing_friction_nms_per_rad", 0.0)
        for g in zr.gaps:
            if not g["traversal"] or g["recontact_index"] is None:
                continue
            o = gap_oracle(d[:, 0], d[:, 1], d[:, 2], d[:, 3], g["entry_index"], g["recontact_index"], b1)
            result.append((zr, g, o))
    return result


def main(argv=None) -> int:
    p = argparse.ArgumentParser(prog="python -m jident_ros.research.evaluation.zoo_oracle",
                                description=__doc__.split("\n\n")[0])
    p.add_argument("--out", default="out/zoo", help="the zoo's recordings (default out/zoo)")
    p.add_argument("--models", default="vector drive", help=f"comma-separated, of {', '.join(zoo.MODELS)}")
    a = p.parse_args(argv)
    models = tuple(m.strip() for m in a.models.split(",") if m.strip())
    bad = [m for m in models if m not in zoo.MODELS]
    if bad:
        sys.stderr.write(f"zoo_oracle: error: argument --models: not one of {', '.join(zoo.MODELS)}: {bad[0]!r}\n")
        return 2
    print("| recording | gap rows | J1 error | with fitted lag (lag) | with a free constant torque | J1 per N m offset | "
          "J1 per ms lag |")
    print("|---|---|---|---|---|---|---|")
    for zr, g, o in rows(Path(a.out), models):
        j = zr.inertia_kgm2
        print(f"| {zr.name} | {g['entry_index']}–{g['recontact_index']} | {100 * (o['j1'] / j - 1):+.1f} % | "
              f"{100 * (o['j1_lag'] / j - 1):+.1f} % ({1e3 * o['lag_s']:.2f} ms) | {100 * (o['j1_offset'] / j - 1):+.1f} % | "
              f"{100 * o['per_nm']:.2f} % | {100 * o['per_ms']:.2f} % |")
    return 0


if __name__ == "__main__":
    sys.exit(main())
