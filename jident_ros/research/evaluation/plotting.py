"""Pictures for users (matplotlib, Agg backend; never imported by the method core)."""
from __future__ import annotations

from pathlib import Path

import numpy as np

from jident_ros.sim.simulate import UNITS, WindowSet

_LABELS = {
    "a1": r"$a_1$ linear acceleration of the drive",
    "m_el": r"$m_{el}$ electromagnetic torque",
    "omega1": r"$\omega_1$ rotor speed",
    "a2": r"$a_2$ acceleration of the mass",
    "v2": r"$v_2$ speed of the mass",
}


def plot_case(windows: WindowSet, index: int, path: str | Path) -> Path:
    """Five state signals of one case against time, backlash entry and gap marked."""
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    c = windows.case(index)
    case = windows.cases[index]
    t_ms = windows.t * 1e3
    e = windows.entry_index
    contact = np.flatnonzero(np.abs(c["clutch_torque"][e:]) > 0)
    t_recontact = t_ms[e + contact[0]] if contact.size else None
    fig, axes = plt.subplots(5, 1, figsize=(9, 10), sharex=True, constrained_layout=True)
    for ax, name in zip(axes, _LABELS):
        ax.plot(t_ms, c[name], lw=1.0, color="C0")
        ax.set_ylabel(f"[{UNITS[name]}]")
        ax.set_title(_LABELS[name], fontsize=9, loc="left")
        ax.axvline(0.0, color="C3", lw=1.0, ls="--")
        if t_recontact is not None:
            ax.axvspan(0.0, t_recontact, color="C3", alpha=0.12, lw=0)
        ax.grid(True, alpha=0.3)
    axes[0].annotate("backlash entry (eq. 1)", xy=(0, 1), xycoords=("data", "axes fraction"),
                     xytext=(4, -10), textcoords="offset points", color="C3", fontsize=8)
    axes[-1].set_xlabel("time from backlash entry [ms]")
    fig.suptitle(f"J1 = {case.inertia_kgm2:g} kg m², backlash width = {case.backlash_width_m:g} m, "
                 f"η_k = {case.consistency_pa_sn:g} Pa·sⁿ   (shaded: inside the backlash zone)",
                 fontsize=10)
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(path, dpi=110)
    plt.close(fig)
    return path
