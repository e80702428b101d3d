"""Markdown and PNG figures of the robustness evaluation (:mod:`jident_ros.research.evaluation.robustness`).

``render_robustness(rob, figures)`` returns a markdown block for docs/results.md's generated
section; ``write_robustness_figures(rob, outdir)`` writes the PNGs (matplotlib, Agg; imported
only when called) and returns {title: relative path}.
"""
from __future__ import annotations

import datetime
from collections import Counter
from pathlib import Path

import numpy as np

from jident_ros.identify.fusion import BETWEEN_Z
from jident_ros.research.evaluation.robustness import CHANNEL_SETS, PRIMARY, RobustnessResult, Sweep


def _pct(x, nd=1) -> str:
    return "–" if x is None or not np.isfinite(x) else f"{100 * x:.{nd}f} %"


def _num(x, nd=3) -> str:
    return "–" if x is None or not np.isfinite(x) else f"{100 * x:.{nd}f}"


def _snr_name(s: Sweep) -> str:
    return "noise-free" if s.snr_db is None else f"{s.snr_db:g} dB"


def _by_snr(sweeps):
    """{snr (None first): [sweeps]} preserving order."""
    out = {}
    for s in sweeps:
        out.setdefault(s.snr_db, []).append(s)
    return out


def _pool(sweeps: list[Sweep], key: str = PRIMARY, mask_fn=None) -> dict:
    """Gap statistics pooled over several sweeps (same kind of cases)."""
    err, cov, half = [], [], []
    for s in sweeps:
        g = s.gap[key]
        m = np.ones(len(s.cases), bool) if mask_fn is None else mask_fn(s)
        e = np.abs(g["rel_error"][m])
        err.append(e)
        cov.append(g["covered"][m])
        half.append((0.5 * (g["hi"] - g["lo"]) / s.true_inertia_kgm2)[m])
    e, c, h = np.concatenate(err), np.concatenate(cov), np.concatenate(half)
    ok = np.isfinite(e)
    return {"n": int(e.size), "failed": int((~ok).sum()),
            "median": float(np.median(e[ok])) if ok.any() else np.nan,
            "p95": float(np.percentile(e[ok], 95)) if ok.any() else np.nan,
            "max": float(e[ok].max()) if ok.any() else np.nan, "coverage": float(c.mean()) if c.size else np.nan,
            "ci_half": float(np.median(h[ok])) if ok.any() else np.nan}


def _cell(text: str) -> str:
    """Escape the pipes of a markdown table cell."""
    return str(text).replace("|", "\\|")


def _targets(rob: RobustnessResult) -> list[str]:
    out = ["| target (issue) | measured | met? |", "|---|---|---|"]
    for t in rob.targets:
        out.append(f"| {_cell(t['name'])}: {_cell(t['target'])} | {_cell(t['measured'])} | "
                   f"{'**yes**' if t['met'] else '**no**'} |")
    return out


def _grid_row(s: Sweep, rob: RobustnessResult) -> str:
    """One data set's row of the grid table: image method, gap estimate and fused verdict side by side."""
    classes = rob.classes_kgm2
    a = s.accuracy(classes)
    h = s.accuracy(classes, ~s.pattern_mask(rob.pattern_eta))
    g = s.gap_summary()
    return (f"| {s.label} | {_pct(a.get('image'))} | {_pct(h.get('image'))} | {_pct(a['gap'])} | "
            f"**{_pct(a.get('fused'))}** | {_pct(a.get('between'))} | {_num(g['median'])} % / {_num(g['max'])} % | "
            f"{_pct(g['coverage'])} | {_num(g['ci_half'])} % |")


def _grid_side_by_side(rob: RobustnessResult) -> list[str]:
    classes = rob.classes_kgm2
    out = ["| data | paper image method, fused class (all 168) | same, 126 cases at η_k ≠ 0.025 | "
           "gap estimate's nearest class | **fused verdict** | flagged between classes | gap median / max \\|J1 error\\| | "
           "95 % CI covers J1 | median CI half-width |",
           "|---|---|---|---|---|---|---|---|---|"]
    extra = _by_snr(rob.grid_extra)
    for s in rob.grid:
        out.append(_grid_row(s, rob))
        more = [x for x in extra.get(s.snr_db, []) if x.verdict is not None]
        if more:
            sws = [s] + more
            accs = [x.accuracy(classes) for x in sws]
            n = sum(x["n"] for x in accs)
            gacc = sum(x["gap"] * x["n"] for x in accs) / n
            facc = sum(x["fused"] * x["n"] for x in accs) / n
            btw = sum(x["between"] * x["n"] for x in accs) / n
            st = _pool(sws)
            out.append(f"| {s.snr_db:g} dB, all {len(sws)} seeds ({n} windows; verdict without image answers on the "
                       f"extra seeds) | – | – | {_pct(gacc)} | **{_pct(facc)}** | {_pct(btw)} | "
                       f"{_num(st['median'])} % / {_num(st['max'])} % | {_pct(st['coverage'])} | {_num(st['ci_half'])} % |")
    for s in getattr(rob, "sensors", []):   # sensors in physical terms beside the awgn rows
        out.append(_grid_row(s, rob))
    if getattr(rob, "sensors", None):
        out += ["", f"'default sensor set' = `sim.sensors.DEFAULT_SENSORS` ({rob.sensor_set}); × k multiplies every "
                "noise level (encoder and accelerometer range unchanged). The SNR rows are MATLAB's awgn 'measured'."]
    return out


def _gap_channels(rob: RobustnessResult) -> list[str]:
    out = ["| data | channels | windows | median \\|error\\| | 95th pct. | max \\|error\\| | 95 % CI covers J1 | "
           "median CI half-width | no gap found |", "|---|---|---|---|---|---|---|---|---|"]
    extra = _by_snr(rob.grid_extra)
    for s in rob.grid:
        rows = [(s.label, [s])]
        if s.snr_db in extra:
            seeds = ", ".join(str(x.seed) for x in extra[s.snr_db])
            rows.append((f"{s.snr_db:g} dB, all {1 + len(extra[s.snr_db])} seeds ({s.seed}, {seeds})",
                         [s] + extra[s.snr_db]))
        for label, sws in rows:
            for key in CHANNEL_SETS:
                if key not in s.gap:
                    continue
                st = _pool(sws, key)
                out.append(f"| {label} | {CHANNEL_SETS[key][2]} | {st['n']} | {_num(st['median'])} % | "
                           f"{_num(st['p95'])} % | {_num(st['max'])} % | {_pct(st['coverage'])} | "
                           f"{_num(st['ci_half'])} % | {st['failed']} |")
    return out


def _offgrid_j1(rob: RobustnessResult) -> list[str]:
    classes = rob.classes_kgm2
    out = ["| J1 [kg m²] | nearest class | data | gap median / max \\|error\\| | CI covers J1 | "
           "fused: between classes | fused: nearest class | fused: other class | image method: nearest class | "
           "image method's answers (count) |", "|---|---|---|---|---|---|---|---|---|---|"]
    if not rob.offgrid_j1:
        return []
    values = sorted({c.inertia_kgm2 for c in rob.offgrid_j1[0].cases}, reverse=True)
    for j in values:
        for s in rob.offgrid_j1:
            m = s.true_inertia_kgm2 == j
            g = s.gap_summary(PRIMARY, m)
            o = s.offclass_outcomes(classes, m)
            near = classes[s.nearest_true_class(classes)[m][0]]
            ans = ""
            if s.image is not None:
                mi = m & s.image["evaluated"]
                cnt = Counter(classes[k] for k in s.image["fused_class"][mi])
                ans = ", ".join(f"{c:g} ({n})" for c, n in sorted(cnt.items(), key=lambda t: -t[1]))
            out.append(f"| {j:.4g} ({(j / near - 1) * 100:+.1f} % from {near:g}) | {near:g} | {_snr_name(s)} | "
                       f"{_num(g['median'])} % / {_num(g['max'])} % | {_pct(g['coverage'])} | {_pct(o.get('between'))} | "
                       f"{_pct(o.get('nearest'))} | {_pct(o.get('other'))} | {_pct(o.get('image_nearest'))} | {ans} |")
    return out


def _offgrid_width(rob: RobustnessResult) -> list[str]:
    classes = rob.classes_kgm2
    if not rob.offgrid_width:
        return []
    out = ["| width [m] | library width used by the image method [m] | data | gap max \\|J1 error\\| | "
           "width estimate median / max \\|error\\| | fused verdict | image method (all) | image method (η_k ≠ 0.025) |",
           "|---|---|---|---|---|---|---|---|"]
    widths = sorted({c.backlash_width_m for c in rob.offgrid_width[0].cases})
    for w in widths:
        for s in rob.offgrid_width:
            m = s.true_width_m == w
            g = s.gap_summary(PRIMARY, m)
            ws = s.width_summary(m)
            a = s.accuracy(classes, m)
            h = s.accuracy(classes, m & ~s.pattern_mask(rob.pattern_eta))
            used = ""
            if s.image is not None:
                u = s.image["width_used"][m & s.image["evaluated"]]
                used = ", ".join(f"{x:g}" for x in sorted(set(u[np.isfinite(u)])))
            out.append(f"| {w:g} | {used} | {_snr_name(s)} | {_num(g['max'])} % | "
                       f"{_num(ws.get('median'), 2)} % / {_num(ws.get('max'), 2)} % | {_pct(a.get('fused'))} | "
                       f"{_pct(a.get('image'))} | {_pct(h.get('image'))} |")
    return out


def _quantisation(rob: RobustnessResult, wheel_radius_m: float | None) -> list[str]:
    ref = rob.grid[0]
    out = ["| encoder | quantum [mrad] | quantum ÷ smallest K2/r | gap end moved (cases, max shift) | "
           "J1 median / max \\|error\\| | width median / max \\|error\\| | "
           + " | ".join(f"{CHANNEL_SETS[k][2]}: J1 median / max \\|error\\|, CI covers, no gap found"
                        for k in ANGLE_KEYS) + " |",
           "|---|---|---|---|---|---|" + "---|" * len(ANGLE_KEYS)]
    g, w = ref.gap_summary(), ref.width_summary()
    out.append(f"| unquantised | 0 | 0 | – | {_num(g['median'])} % / {_num(g['max'])} % | "
               f"{_num(w['median'], 2)} % / {_num(w['max'], 2)} % | " + " | ".join(_angle_cell(ref, k) for k in ANGLE_KEYS)
               + " |")
    theta_min = min(rob.widths_m) / wheel_radius_m if wheel_radius_m else np.nan
    e0 = ref.gap[PRIMARY]["gap_end"]
    for s in rob.quantisation:
        q = 2 * np.pi / s.counts_per_rev
        e = s.gap[PRIMARY]["gap_end"]
        moved = (e != e0) & (e >= 0) & (e0 >= 0)
        shift = int(np.max(np.abs(e - e0)[moved])) if moved.any() else 0
        g, w = s.gap_summary(), s.width_summary()
        exp = int(round(np.log2(s.counts_per_rev)))
        out.append(f"| 2^{exp} = {s.counts_per_rev} counts/rev | {q * 1e3:.3f} | {q / theta_min:.3f} | "
                   f"{int(moved.sum())} of {len(e)}, {shift} sample(s) | {_num(g['median'])} % / {_num(g['max'])} % | "
                   f"{_num(w['median'], 2)} % / {_num(w['max'], 2)} % | "
                   + " | ".join(_angle_cell(s, k) for k in ANGLE_KEYS) + " |")
    return out


#: Channel sets of the angle fit shown in the encoder table.
ANGLE_KEYS = ("angle_eq1", "angle")


def _angle_cell(s, key: str) -> str:
    if key not in s.gap:
        return "–"
    a = s.gap_summary(key)
    if a["failed"] == a["n"]:
        return f"– (no gap found in all {a['n']})"
    return (f"{_num(a['median'])} % / {_num(a['max'])} %, {_pct(a['coverage'])}, {a['failed']}")


def _sample_periods(rob: RobustnessResult) -> list[str]:
    out = ["| data | channels | gap length [samples] | median \\|error\\| | max \\|error\\| | 95 % CI covers J1 | "
           "no gap found |", "|---|---|---|---|---|---|---|"]
    ref = rob.grid[0]
    for s in [ref] + [x for x in rob.grid if x.snr_db == 30.0] + rob.sample_period:
        label = s.label if s.kind == "sample_period" else f"Ts = {s.sample_period_s * 1e3:g} ms, {s.label}"
        for key in CHANNEL_SETS:
            if key not in s.gap:
                continue
            g = s.gap_summary(key)
            out.append(f"| {label} | {CHANNEL_SETS[key][2]} | {g['gap_samples'][0]}–{g['gap_samples'][1]} | "
                       f"{_num(g['median'])} % | {_num(g['max'])} % | {_pct(g['coverage'])} | {g['failed']} |")
    return out


def _attribution(rob: RobustnessResult) -> list[str]:
    if not rob.attribution:
        return []
    out = ["| noise on | channels | windows | median \\|error\\| | 95th pct. | max \\|error\\| |", "|---|---|---|---|---|---|"]
    snr = rob.attribution[0].snr_db
    full = [s for s in rob.grid + rob.grid_extra if s.snr_db == snr]
    groups = [("a1, m_el, ω1, a2, v2, ω2 (as in (a))", full)]
    for chans in dict.fromkeys(s.noised for s in rob.attribution):
        groups.append((f"{'+'.join(chans)} only", [s for s in rob.attribution if s.noised == chans]))
    for label, sws in groups:
        for key in (PRIMARY, "no_angles"):
            if sws and key in sws[0].gap:
                st = _pool(sws, key)
                out.append(f"| {label} | {CHANNEL_SETS[key][2]} | {st['n']} | {_num(st['median'])} % | "
                           f"{_num(st['p95'])} % | {_num(st['max'])} % |")
    return out


def _findings(rob: RobustnessResult) -> list[str]:
    """Plain statements computed from the numbers (no fixed claims)."""
    lines = []
    met = [t for t in rob.targets if t["met"]]
    missed = [t for t in rob.targets if not t["met"]]
    lines.append(f"* Targets met: {len(met)} of {len(rob.targets)}"
                 + (f" ({'; '.join(t['name'] for t in met)})" if met else "") + ".")
    if missed:
        lines.append("* **Not met**: " + "; ".join(f"{t['name']} ({t['measured']})" for t in missed) + ".")
    snr30 = [s for s in rob.grid if s.snr_db == 30.0]
    if snr30:
        s = snr30[0]
        a = s.accuracy(rob.classes_kgm2)
        g = s.gap_summary()
        lines.append(
            f"* At 30 dB the fused verdict takes its class from the gap estimate whenever there is one, so its accuracy "
            f"({_pct(a.get('fused'))}) equals the gap estimate's nearest-class accuracy ({_pct(a['gap'])}); the image "
            "vote cannot overrule it. Neighbouring J1 classes are 2.5 % apart, so an error above ≈ 1.25 % picks the "
            f"neighbour; the gap estimator's 95th-percentile error is {_num(g['p95'])} %, its median 95 % CI half-width "
            f"{_num(g['ci_half'])} %"
            + (f". 'Between classes' needs no class within {BETWEEN_Z:g} standard errors of the estimate; it is "
               f"flagged in {_pct(a.get('between'))} of these on-class windows."))
    if rob.attribution:
        snr = rob.attribution[0].snr_db
        parts = {c: _pool([s for s in rob.attribution if s.noised == c]) for c in dict.fromkeys(s.noised for s in rob.attribution)}
        full = _pool([s for s in rob.grid + rob.grid_extra if s.snr_db == snr])
        worst = max(parts, key=lambda c: parts[c]["p95"])
        gs = rob.grid[0].gap_summary()["gap_samples"]
        why = (" The 'measured' SNR of m_el is relative to its mean square, dominated by the load torque, and the "
               f"fit has to model m_el across a gap of only {gs[0]}–{gs[1]} samples from those noisy samples."
               if worst == ("m_el",) else "")
        lines.append(f"* The noise that limits the gap estimator at {snr:g} dB is the one on {'+'.join(worst)}: with "
                     "noise on " + " or ".join(f"{'+'.join(c)} alone the 95th-percentile |error| is {_num(v['p95'])} % "
                                               f"(max {_num(v['max'])} %)" for c, v in parts.items())
                     + f", against {_num(full['p95'])} % (max {_num(full['max'])} %) with all channels noised." + why)
    noisy = [s for s in rob.grid + rob.grid_extra if s.snr_db is not None]
    if noisy:
        st = _pool(noisy)
        lines.append(f"* The gap estimator's 95 % interval covers J1 in {_pct(st['coverage'])} of "
                     f"{st['n']} noisy grid windows (nominal 95 %).")
    if rob.quantisation:
        e0 = rob.grid[0].gap[PRIMARY]["gap_end"]
        parts, shift = [], 0
        for q in rob.quantisation:
            e = q.gap[PRIMARY]["gap_end"]
            both = (e >= 0) & (e0 >= 0)
            shift = max(shift, int(np.max(np.abs(e[both] - e0[both]))) if both.any() else 0)
            late = (e > e0) & (e0 >= 0)
            early = (e < e0) & (e >= 0)
            err = np.abs(q.gap[PRIMARY]["rel_error"])
            parts.append(f"{q.counts_per_rev} counts/rev: {int(late.sum())} late, {int(early.sum())} early"
                         + (f" (max |J1 error| of the late ones {np.nanmax(err[late]) * 100:.2f} %)" if late.any() else ""))
        lines.append(f"* Encoder quantisation moves the end of the gap interval by at most {shift} sample"
                     f"{'' if shift == 1 else 's'}. A gap end one "
                     "sample late puts a sample with flank contact into the fit and biases J1; one sample early only "
                     "drops a sample. " + "; ".join(parts) + ".")
        enc = [q for q in rob.quantisation if "angle" in q.gap and "angle_eq1" in q.gap]
        if enc:
            def angle_part(q, key):
                a = q.gap_summary(key)
                if a["failed"] == a["n"]:
                    return f"{q.counts_per_rev} counts/rev: no gap found"
                return (f"{q.counts_per_rev} counts/rev: median {_num(a['median'])} %, max {_num(a['max'])} %, "
                        f"CI covers {_pct(a['coverage'])}" + (f", {a['failed']} without a gap" if a["failed"] else ""))
            lines.append("* Without an accelerometer (fit `angle`: α1 against the double integral of the fitted m_el, "
                         "no differentiation), with the gap from inequality (1) (α1+α2+m_el, what the node sees): "
                         + "; ".join(angle_part(q, "angle_eq1") for q in enc) + ". With a motor encoder only (α1+m_el, "
                         "the gap end from the smoothed second derivative of α1): "
                         + "; ".join(angle_part(q, "angle") for q in enc) + ". The interval is not reliable for every "
                         "encoder: the quantisation error of a steadily turning shaft is a deterministic sawtooth, not "
                         "the white noise the least-squares standard error assumes, and how it averages out depends "
                         "on the resolution; below about 2^16 counts/rev the quantised angle's second derivative hides "
                         "the gap and a motor-encoder-only window is refused.")
    sp = [s for s in rob.grid if s.snr_db is not None]
    if sp and "speed" in sp[0].gap:
        rms = rob.notes.get("omega1_rms_rad_s", (np.nan, np.nan))
        dw = rob.notes.get("gap_speed_change_rad_s", (np.nan, np.nan))
        fails = "; ".join(f"{_snr_name(s)}: {s.gap_summary('speed')['failed']} of {len(s.cases)} without a gap, "
                          f"median error {_num(s.gap_summary('speed')['median'], 1)} %" for s in sp)
        worst = max(sp, key=lambda s: s.gap_summary("speed")["failed"])
        verdict = ("collapses under this noise model" if worst.gap_summary("speed")["failed"] > len(worst.cases) / 2
                   else "degrades under this noise model")
        lines.append(
            f"* The ω1+m_el speed fit is exact noise-free but {verdict}: the 'measured' SNR is "
            f"relative to the mean square of ω1 (RMS {rms[0]:.0f}–{rms[1]:.0f} rad/s, the running speed), so at 30 dB "
            f"the ω1 noise has an RMS of {rms[0] / 10 ** 1.5:.1f}–{rms[1] / 10 ** 1.5:.1f} rad/s, more than the whole "
            f"speed change across the gap ({dw[0]:.2f}–{dw[1]:.2f} rad/s), and the gap signature (smoothed dω1/dt) is "
            f"lost ({fails}). A real encoder-derived speed is far less noisy than this. Noise-free, the speed fit's CI "
            "ignores its small integration bias and rarely covers J1.")
    clean = rob.grid[0]
    if clean.width is not None:
        w = clean.true_width_m
        errs = {x: float(np.nanmax(np.abs(clean.width["rel_error"][w == x]))) for x in sorted(set(w))}
        offw = [s for s in rob.offgrid_width if s.snr_db is None]
        if offw:
            s = offw[0]
            errs.update({x: float(np.nanmax(np.abs(s.width["rel_error"][s.true_width_m == x])))
                         for x in sorted(set(s.true_width_m))})
        how = clean.width["method"]
        n_contact = int(np.sum(how == "contact"))
        lines.append(f"* Noise-free, the width comes from the contact-torque fit in {n_contact} of {how.size} grid "
                     "windows (the rest: the midpoint of the sample bracket around re-contact, whose error can reach "
                     "half the relative-angle step of one sample). Max |error| by width, noise-free: "
                     + ", ".join(f"{x:g} m {v * 100:.2f} %" for x, v in sorted(errs.items())) + ".")
        noisy_w = [s for s in rob.grid if s.snr_db is not None and s.width is not None]
        if noisy_w:
            lines.append("* With noise on a1 and m_el the contact fit's uncertainty grows and the bracket answer takes "
                         "over: contact-fit share " + ", ".join(
                             f"{_snr_name(s)} {np.mean(s.width['method'] == 'contact') * 100:.0f} % "
                             f"(max |error| {np.nanmax(np.abs(s.width['rel_error'])) * 100:.2f} %)" for s in noisy_w)
                         + ".")
    return lines


def render_robustness(rob: RobustnessResult, figures: dict | None = None) -> str:
    """Markdown block for the generated section of docs/results.md."""
    figures = figures or {}
    g0 = rob.grid[0]
    n_img = int(g0.image["evaluated"].sum()) if g0.image is not None else 0
    tim = ", ".join(f"{k} {v:.1f} s" for k, v in rob.timings.items())
    n_extra = max((len(v) for v in _by_snr(rob.grid_extra).values()), default=0)
    lines = ["### Robustness: off the grid, noise, encoders, sample periods (\"Beyond the paper\", item 4)", "",
             f"Regenerated by `{rob.command}` on {datetime.date.today().isoformat()} in {rob.seconds:.0f} s ({tim}). "
             "The paper's image method (fused class over the five signals, p = 2, library from the noise-free "
             "η_k = 0.025 runs), the gap estimator (`gap.py`) and the fused verdict (`fusion.fuse_verdict`: image "
             "answers + the gap estimate from α1+α2+a1+m_el) answer **the same simulated windows**. Noise: MATLAB's "
             "`awgn(x, snr, 'measured')` per window on a1, m_el, ω1, a2, v2, ω2 (angles are not noised; encoders are "
             "quantised separately), one seed per level (in the table). "
             + (f"The gap estimator and the fused verdict also run on {n_extra} more seeds per level without the "
                "image method: where a gap estimate exists the verdict's class and 'between classes' flag do not "
                "depend on the image answers (`fuse_verdict`), so these rows are the full verdict's. "
                if n_extra else "")
             + f"The image method ran on {n_img} of {len(g0.cases)} grid windows per data set"
             + (" (every window)." if rob.image_stride == 1 else
                f" (every {rob.image_stride}th window; the verdict of the others uses the gap estimate alone).")
             + " Relative errors are (estimate − true)/true.", ""]
    lines += ["#### Targets", ""] + _targets(rob) + [""]
    lines += ["#### (a) The 168 grid cases: paper method, gap estimator and fused verdict side by side", ""]
    lines += _grid_side_by_side(rob) + [""]
    lines += ["Gap estimator by channel set (α1+α2 give the gap interval from inequality 1; without them the "
              "acceleration signature does):", ""] + _gap_channels(rob) + [""]
    if rob.offgrid_j1:
        n = len(rob.offgrid_j1[0].cases) // max(len({c.inertia_kgm2 for c in rob.offgrid_j1[0].cases}), 1)
        lines += ["#### (b) J1 off the seven classes", "",
                  f"Each J1 at every grid width and η_k ({n} windows per value and data set). The classes are "
                  + ", ".join(f"{c:g}" for c in sorted(rob.classes_kgm2)) + " kg m². 'between classes': the gap "
                  f"estimate is farther than {BETWEEN_Z:g} of its standard errors from every class.", ""]
        lines += _offgrid_j1(rob) + [""]
    if rob.offgrid_width:
        lines += ["#### (c) Backlash widths off the six", "",
                  "Grid J1 and η_k; the gap estimator uses the true width for inequality (1); the image method has "
                  "patterns only for the six grid widths and uses the nearest one (column 2). Library widths: "
                  + ", ".join(f"{w:g}" for w in rob.library_widths_m) + " m.", ""]
        lines += _offgrid_width(rob) + [""]
    if rob.quantisation:
        lines += ["#### (d) Encoder quantisation of α1, α2 (168 grid cases, noise-free)", "",
                  "α = floor(α/q)·q with q = 2π/counts. The gap interval (inequality 1) and the width estimate read "
                  "the quantised angles; 'gap end moved' compares with the unquantised windows.", ""]
        lines += _quantisation(rob, rob.wheel_radius_m) + [""]
    if rob.sample_period:
        lines += ["#### (e) Other sample periods: the gap estimator only", "",
                  "Same 168 cases simulated at Ts = 0.25 ms and 1 ms (48 + 2000 samples each; the window then covers "
                  "0.5 s or 2 s, which changes the window's mean square and with it the 'measured' noise level). "
                  "The pattern library exists for 0.5 ms only, so the image method is not run here.", ""]
        lines += _sample_periods(rob) + [""]
    if rob.attribution:
        lines += [f"#### (f) Which noise limits the gap estimator at {rob.attribution[0].snr_db:g} dB", "",
                  "The 168 grid cases with the same SNR on one channel only (other channels noise-free), "
                  f"{len(_by_snr(rob.attribution)[rob.attribution[0].snr_db]) // 2} seeds each.", ""]
        lines += _attribution(rob) + [""]
    lines += ["#### Findings", ""] + _findings(rob) + [""]
    if figures:
        lines += ["#### Robustness figures", ""]
        for title, path in figures.items():
            lines += [f"**{title}** ([`{path}`]({path}))", "", f"![{title}]({path})", ""]
        lines.append("")
    return "\n".join(lines)


def write_robustness_figures(rob: RobustnessResult, outdir: str | Path = "docs/figures") -> dict:
    """Error vs SNR, off-grid J1 error distribution, width error vs encoder resolution, width error vs width."""
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    out = Path(outdir)
    out.mkdir(parents=True, exist_ok=True)
    figs = {}
    classes = rob.classes_kgm2

    def rel(p):
        return str(Path(p).relative_to(out.parent)) if out.parent != Path("") else str(p)

    # 1. error and accuracy vs SNR -----------------------------------------------------------
    inf_x = 70.0
    xs = [inf_x if s.snr_db is None else s.snr_db for s in rob.grid]
    extra = _by_snr(rob.grid_extra)
    fig, (ax1, ax2) = plt.subplots(1, 2, figsize=(12, 4.6), constrained_layout=True)
    colours = {"angles": "C0", "no_angles": "C1", "speed": "C2", "anchored": "C3", "angle": "C4", "angle_eq1": "C5",
               "gap_only": "C6"}
    for key in CHANNEL_SETS:
        if key not in rob.grid[0].gap:
            continue
        st = [_pool([s] + extra.get(s.snr_db, []), key) for s in rob.grid]
        med = [max(x["median"], 1e-6) * 100 for x in st]
        mx = [max(x["max"], 1e-6) * 100 for x in st]
        ax1.semilogy(xs, med, "o-", color=colours[key], label=f"{CHANNEL_SETS[key][2]}: median")
        ax1.semilogy(xs, mx, "s--", color=colours[key], label=f"{CHANNEL_SETS[key][2]}: max")
    ax1.plot([inf_x - 3, inf_x + 3], [0.5, 0.5], "k-", lw=2)
    ax1.plot([27, 33], [2, 2], "k-", lw=2)
    ax1.annotate("targets", (30, 2), textcoords="offset points", xytext=(5, 5), fontsize=8)
    ax1.set_xlabel("SNR [dB] (right: noise-free)")
    ax1.set_ylabel("|J1 error| [%]")
    ax1.set_title("Gap estimator, 168 grid cases (all seeds pooled)")
    ax1.set_xticks(xs, ["∞" if x == inf_x else f"{x:g}" for x in xs])
    ax1.grid(True, which="both", alpha=0.3)
    ax1.legend(fontsize=7, ncol=1)
    acc = [s.accuracy(classes) for s in rob.grid]
    head = [s.accuracy(classes, ~s.pattern_mask(rob.pattern_eta)) for s in rob.grid]
    ax2.plot(xs, [a.get("fused", np.nan) * 100 for a in acc], "o-", lw=2, label="fused verdict")
    pooled = []
    for s in rob.grid:
        more = [x for x in extra.get(s.snr_db, []) if x.verdict is not None]
        aa = [x.accuracy(classes) for x in [s] + more]
        pooled.append(sum(x.get("fused", np.nan) * x["n"] for x in aa) / sum(x["n"] for x in aa) * 100)
    if rob.grid_extra:
        ax2.plot(xs, pooled, "o:", color="C0", alpha=0.6, label="fused verdict, all seeds")
    ax2.plot(xs, [a["gap"] * 100 for a in acc], "s--", label="gap estimate's nearest class")
    ax2.plot(xs, [a.get("image", np.nan) * 100 for a in acc], "^-", label="paper image method (all 168)")
    ax2.plot(xs, [a.get("image", np.nan) * 100 for a in head], "v:", label="paper image method (126, η_k ≠ 0.025)")
    ax2.plot([inf_x - 3, inf_x + 3], [100, 100], "k-", lw=2)
    ax2.plot([27, 33], [98, 98], "k-", lw=2)
    ax2.set_xticks(xs, ["∞" if x == inf_x else f"{x:g}" for x in xs])
    ax2.set_ylim(0, 102)
    ax2.set_xlabel("SNR [dB] (right: noise-free)")
    ax2.set_ylabel("class accuracy [%]")
    ax2.set_title("Class accuracy on the same windows (black bars: targets)")
    ax2.grid(True, alpha=0.3)
    ax2.legend(fontsize=8, loc="lower right")
    p = out / "robustness_snr.png"
    fig.savefig(p, dpi=90)
    plt.close(fig)
    figs["Gap-estimator error and class accuracy vs SNR"] = rel(p)

    # 2. off-grid J1 error distribution ------------------------------------------------------
    if rob.offgrid_j1:
        values = sorted({c.inertia_kgm2 for c in rob.offgrid_j1[0].cases})
        fig, ax = plt.subplots(figsize=(11, 4.4), constrained_layout=True)
        data, pos, labels, cols = [], [], [], []
        for k, j in enumerate(values):
            for d, s in enumerate(rob.offgrid_j1):
                e = s.gap[PRIMARY]["rel_error"][s.true_inertia_kgm2 == j] * 100
                data.append(e[np.isfinite(e)])
                pos.append(k * 3 + d)
                cols.append(f"C{d}")
            labels.append((k * 3 + 0.5, f"{j:.4g}"))
        bp = ax.boxplot(data, positions=pos, widths=0.8, showfliers=False, patch_artist=True)
        for patch, c in zip(bp["boxes"], cols):
            patch.set_facecolor(c)
            patch.set_alpha(0.35)
        rng = np.random.default_rng(0)
        for d, x, c in zip(data, pos, cols):
            ax.plot(x + rng.uniform(-0.25, 0.25, d.size), d, ".", color=c, ms=3)
        for y in (-2, 2):
            ax.axhline(y, color="k", ls=":", lw=1)
        for y in (-0.5, 0.5):
            ax.axhline(y, color="k", ls="--", lw=0.8)
        ax.set_xticks([x for x, _ in labels], [t for _, t in labels])
        ax.set_xlabel("true J1 [kg m²] (off the classes)")
        ax.set_ylabel("gap estimate error [%]")
        handles = [plt.Line2D([], [], color=f"C{d}", marker="s", ls="", label=_snr_name(s))
                   for d, s in enumerate(rob.offgrid_j1)]
        ax.legend(handles=handles, fontsize=8)
        ax.set_title("Gap estimator (α1+α2+a1+m_el) for J1 off the classes, 24 windows per box "
                     "(dashed ±0.5 %, dotted ±2 %)")
        ax.grid(True, axis="y", alpha=0.3)
        p = out / "robustness_offgrid_j1.png"
        fig.savefig(p, dpi=90)
        plt.close(fig)
        figs["Error distribution of the gap estimate for J1 off the classes"] = rel(p)

    # 3. encoder resolution ------------------------------------------------------------------
    if rob.quantisation:
        ref = rob.grid[0]
        bits = [np.log2(s.counts_per_rev) for s in rob.quantisation]
        xinf = max(bits) + 2
        xs = bits + [xinf]
        sws = rob.quantisation + [ref]
        fig, (ax1, ax2) = plt.subplots(1, 2, figsize=(11, 4.2), constrained_layout=True)
        ax1.plot(xs, [s.width_summary()["median"] * 100 for s in sws], "o-", label="median")
        ax1.plot(xs, [s.width_summary()["max"] * 100 for s in sws], "s--", label="max")
        ax1.axhline(5, color="k", ls=":", lw=1, label="5 % target")
        ax1.set_ylabel("|width error| [%]")
        ax1.set_title("Backlash width estimate, 168 grid cases, noise-free")
        ax2.semilogy(xs, [max(s.gap_summary()["median"], 1e-7) * 100 for s in sws], "o-", label="median")
        ax2.semilogy(xs, [max(s.gap_summary()["max"], 1e-7) * 100 for s in sws], "s--", label="max")
        ax2.axhline(0.5, color="k", ls=":", lw=1, label="0.5 % target")
        ax2.set_ylabel("|J1 error| [%]")
        ax2.set_title("Gap estimate J1 (interval from the quantised angles)")
        for ax in (ax1, ax2):
            ax.set_xticks(xs, [f"2^{b:g}" for b in bits] + ["exact"])
            ax.set_xlabel("encoder counts per revolution")
            ax.grid(True, which="both", alpha=0.3)
            ax.legend(fontsize=8)
        p = out / "robustness_encoder.png"
        fig.savefig(p, dpi=90)
        plt.close(fig)
        figs["Width and J1 error vs encoder resolution"] = rel(p)

    # 4. width error vs width -----------------------------------------------------------------
    sws = [s for s in [rob.grid[0]] + rob.offgrid_j1 + rob.offgrid_width if s.snr_db is None and s.width is not None]
    if sws:
        fig, ax = plt.subplots(figsize=(8, 4), constrained_layout=True)
        for s, mk in zip(sws, "os^"):
            ax.plot(s.true_width_m * 1e3, s.width["rel_error"] * 100, mk, ms=4, alpha=0.6,
                    label={"grid": "grid", "offgrid_j1": "off-grid J1", "offgrid_width": "off-grid widths"}[s.kind])
        for y in (-5, 5):
            ax.axhline(y, color="k", ls=":", lw=1)
        ax.set_xlabel("true backlash width [mm]")
        ax.set_ylabel("width estimate error [%]")
        ax.set_title("Backlash width estimate, noise-free (dotted: ±5 % target)")
        ax.grid(True, alpha=0.3)
        ax.legend(fontsize=8)
        p = out / "robustness_width.png"
        fig.savefig(p, dpi=90)
        plt.close(fig)
        figs["Width estimate error vs width, noise-free"] = rel(p)
    return figs
