"""The paper's identification method, end to end, for one or many windows.

window (2048 samples per signal)
  -> scalogram (MATLAB-classic CWT, per-signal wavelet)         scalogram.py
  -> 343 x 436 gray image X1 (only its level histogram is formed) image.py
  -> normalised X3 on [k3, 2 k3 - h3] (eqs. 2-22)               normalise.py
  -> 7 KHM centres S from the weighted level histogram (23-30)  khm.py
  -> H(f) = h5 sum_i |N2(f, i) - N3(i)|, J1 = K1[argmin H]       this module (31-35)

Plain numpy/scipy/PyWavelets; never imports rclpy.
"""
from __future__ import annotations

import dataclasses
from dataclasses import dataclass, field
from typing import Sequence

import numpy as np

from jident_ros.method import normalise as nz
from jident_ros.method.image import drawn_cells, level_histogram_from_cells
from jident_ros.method.khm import khm_fit_batch
from jident_ros.method.scalogram import READINGS, percentage_energy_cells, wavelet_coefficients
from jident_ros.sim.sensors import DEFAULT_SENSORS, SensorSpec

SIGNALS = ("a1", "m_el", "omega1", "a2", "v2")
VARIANTS = ("paper", "load_scaled", "sensor_matched")
#: Fields of :class:`jident_ros.sim.sensors.SensorSpec` that ``MethodConfig.matched_sensors`` may override.
MATCHED_SENSOR_FIELDS = tuple(f.name for f in dataclasses.fields(SensorSpec))


@dataclass(frozen=True)
class MethodConfig:
    """Parameters of the identification method (config/method.yaml, section ``method``).

    Attributes
    ----------
    wavelets : tuple of (signal, wavelet name)
        Paper section 3: a1 sym5, m_el db6, omega1 sym5, a2 db6, v2 sym5.
    scale_reading : str
        Reading of "decomposition level 10": 'dyadic', 'linear' or 'swt'.
    wavefun_precision : int
        Iterations of the wavelet-function cascade (MATLAB's precis = 10).
    image_rows, image_cols : int
        Size of the intensity matrix X1 (the paper's 343 x 436).
    n_colors : int
        Length of the gray colormap (MATLAB's default 64).
    n_clusters : int
        KHM centres (7 = the number of J1 classes).
    p_values : tuple of float
        KHM exponents p >= 2 the pattern library is built for.
    eq12 : str
        'corrected' or 'literal' reading of eq. (12).
    variant : str
        'paper' (faithful), 'load_scaled' or 'sensor_matched' (docs/method.md, section "variant").
    khm_max_iter : int
    khm_tol : float
    matched_seeds : int
        Variant 'sensor_matched' (beyond the paper): how many noise realisations (seeds) of each pattern
        run the library averages; N2 is their mean centres, the scatter their seed-to-seed spread.
    matched_sensors : tuple of (SensorSpec field, value)
        Variant 'sensor_matched': the sensor set the pattern runs are recorded through, as overrides of
        the documented default set (:data:`jident_ros.sim.sensors.DEFAULT_SENSORS`); empty = that set.
    """

    wavelets: tuple = (("a1", "sym5"), ("m_el", "db6"), ("omega1", "sym5"), ("a2", "db6"), ("v2", "sym5"))
    scale_reading: str = "dyadic"
    wavefun_precision: int = 10
    image_rows: int = 343
    image_cols: int = 436
    n_colors: int = 64
    n_clusters: int = 7
    p_values: tuple = (2.0, 3.0, 6.0, 9.0)
    eq12: str = "corrected"
    variant: str = "paper"
    khm_max_iter: int = 3000
    khm_tol: float = 1e-7
    matched_seeds: int = 16
    matched_sensors: tuple = ()

    def __post_init__(self):
        if self.scale_reading not in READINGS:
            raise ValueError(f"method.scale_reading: expected one of {READINGS}, got {self.scale_reading!r}")
        if self.eq12 not in ("corrected", "literal"):
            raise ValueError(f"method.eq12: expected 'corrected' or 'literal', got {self.eq12!r}")
        if self.variant not in VARIANTS:
            raise ValueError(f"method.variant: expected one of {VARIANTS}, got {self.variant!r}")
        names = [s for s, _ in self.wavelets]
        if sorted(names) != sorted(SIGNALS):
            raise ValueError(f"method.wavelets: need one wavelet for each of {SIGNALS}, got {names}")
        for p in self.p_values:
            if not p >= 2:
                raise ValueError(f"method.p_values: every p must be >= 2, got {p!r}")
        if isinstance(self.matched_seeds, bool) or not isinstance(self.matched_seeds, int) or self.matched_seeds < 2:
            raise ValueError(f"method.matched_seeds: must be an integer >= 2 (the scatter needs two seeds), "
                             f"got {self.matched_seeds!r}")
        spec = self.sensor_spec()   # validates matched_sensors
        # canonical form (one library hash per sensor set): the fields that differ from the default set, sorted
        canonical = tuple((f, float(getattr(spec, f))) for f in MATCHED_SENSOR_FIELDS
                          if float(getattr(spec, f)) != float(getattr(DEFAULT_SENSORS, f)))
        object.__setattr__(self, "matched_sensors", canonical)

    def sensor_spec(self) -> SensorSpec:
        """The sensor set of variant 'sensor_matched': the default set with ``matched_sensors`` applied."""
        try:
            over = dict(self.matched_sensors)
        except (TypeError, ValueError):
            raise ValueError(f"method.matched_sensors: expected (sensor field, value) pairs, "
                             f"got {self.matched_sensors!r}") from None
        for name in over:
            if name not in MATCHED_SENSOR_FIELDS:
                raise ValueError(f"method.matched_sensors.{name}: unknown sensor field "
                                 f"(known: {', '.join(MATCHED_SENSOR_FIELDS)})")
        if "encoder_counts_per_rev" in over:
            over["encoder_counts_per_rev"] = int(over["encoder_counts_per_rev"])
        try:
            return dataclasses.replace(DEFAULT_SENSORS, **over)
        except ValueError as exc:
            raise ValueError(f"method.matched_sensors: {exc}") from None

    @property
    def wavelet(self) -> dict:
        return dict(self.wavelets)

    def replace(self, **kw) -> "MethodConfig":
        return dataclasses.replace(self, **kw)


@dataclass
class SignalFeatures:
    """What the method keeps of one signal window.

    centres : dict p -> ndarray (n_clusters,), the KHM centres S sorted ascending (N3)
    ranges : RangeParams (h4, k4 -> h3, k3)
    """

    centres: dict
    ranges: nz.RangeParams
    khm_info: dict = field(default_factory=dict)


def prepare_signal(x: np.ndarray, signal: str, reference: float | None, variant: str,
                   entry_index: int = 48) -> np.ndarray:
    """Variant hook: what enters the scalogram and the range statistics.

    'paper' and 'sensor_matched' (which changes only the library and the distance,
    :mod:`jident_ros.method.patterns`) use the window as recorded.  'load_scaled' takes the window's
    deviation from its own pre-entry mean and divides it by the pre-entry load
    torque ``reference`` (N m), making the features per unit of load (see
    docs/method.md, "variant").
    """
    if variant in ("paper", "sensor_matched"):
        return x
    if reference is None or not np.isfinite(reference) or reference == 0:
        raise ValueError(f"reference: variant {variant!r} needs a finite non-zero pre-entry load torque, "
                         f"got {reference!r}")
    if not 1 <= entry_index < x.size:
        raise ValueError(f"entry_index: must be in [1, {x.size - 1}], got {entry_index}")
    return (x - x[:entry_index].mean()) / reference


def image_levels(x: np.ndarray, signal: str, cfg: MethodConfig):
    """Scalogram -> image -> (level values (N,), counts ([B,] N), image min ([B]), image max ([B])).

    ``x`` is one window (n_samples,) or a batch (B, n_samples).  The numbers are
    those of ``level_histogram(render_intensity(wavelet_scalogram(x)))`` and the
    image's min/max, computed from the drawn scalogram cells only.
    """
    coefs = wavelet_coefficients(x, cfg.wavelet[signal], reading=cfg.scale_reading,
                                 precision=cfg.wavefun_precision)
    return coefficient_levels(coefs, cfg)


def coefficient_levels(coefs: np.ndarray, cfg: MethodConfig):
    """Wavelet coefficients ([B,] n_scales, n_samples) -> the image's level histogram.

    Returns level values (N,), pixel counts ([B,] N) (int64), image min ([B]) and
    image max ([B]), equal to rendering the scalogram into the cfg.image_rows x
    cfg.image_cols image X1 and histogramming it; ``coefs`` is overwritten
    (squared in place).
    """
    rows, row_pixels, columns, column_pixels = drawn_cells(coefs.shape, (cfg.image_rows, cfg.image_cols))
    cells, cmin, cmax = percentage_energy_cells(coefs, rows, columns, overwrite=True)
    return level_histogram_from_cells(cells, cmin, cmax, row_pixels, column_pixels, cfg.n_colors)


#: Windows per chunk in the scalogram/image stage (bounds memory for the 1024-scale reading).
_CHUNK = {"linear": 4}


def batch_features(windows: np.ndarray, signal: str, cfg: MethodConfig, p_values=None,
                   references=None, entry_index: int = 48):
    """KHM centres of many windows of one signal.

    Parameters
    ----------
    windows : ndarray, shape (B, n_samples)
    references : ndarray (B,) or None
        Pre-entry load references (variant 'load_scaled').

    Returns
    -------
    centres : ndarray (n_p, B, n_clusters), sorted ascending (rows of N2 / N3)
    ranges : list of RangeParams (B,)
    info : dict p -> {'n_iter', 'converged' (B,)}
    """
    x = np.asarray(windows, dtype=float)
    if x.ndim != 2:
        raise ValueError(f"windows: expected shape (n_windows, n_samples), got {x.shape}")
    B = x.shape[0]
    refs = [None] * B if references is None else list(references)
    values, counts, ranges = _histograms(x, signal, cfg, refs, entry_index)
    ps = cfg.p_values if p_values is None else p_values
    centres, info = _cluster(values, counts, ranges, cfg, ps)
    return centres, ranges, info


def _histograms(x, signal, cfg, refs, entry_index):
    """Scalogram -> image -> mapped level values (B, N), pixel counts (B, N), ranges (B,)."""
    B = x.shape[0]
    x = np.stack([prepare_signal(nz._check_window(x[b], signal), signal, refs[b], cfg.variant, entry_index)
                  for b in range(B)])
    ranges = [nz.range_params(x[b], signal, cfg.eq12) for b in range(B)]
    chunk = _CHUNK.get(cfg.scale_reading, 64)
    counts, values = [], []
    for a in range(0, B, chunk):
        levels, cnt, lo, hi = image_levels(x[a:a + chunk], signal, cfg)
        counts.append(cnt)
        values.extend(nz.map_levels(levels, float(lo[i]), float(hi[i]), ranges[a + i])
                      for i in range(cnt.shape[0]))
    return np.stack(values), np.concatenate(counts), ranges


def _cluster(values, counts, ranges, cfg, ps):
    """Batched KHM (eqs. 23-30) for every p: centres (n_p, B, n_clusters)."""
    init = np.array([nz.initial_centre(r) for r in ranges])
    centres = np.zeros((len(ps), values.shape[0], cfg.n_clusters))
    info = {}
    for k, p in enumerate(ps):
        centres[k], info[float(p)] = khm_fit_batch(values, counts, init, n_clusters=cfg.n_clusters, p=float(p),
                                                   max_iter=cfg.khm_max_iter, tol=cfg.khm_tol)
    return centres, info


def window_features(window: dict, cfg: MethodConfig, p_values, signals=SIGNALS, reference=None,
                    entry_index: int = 48):
    """Centres of several signals of ONE window, clustered in one batch (the per-window hot path).

    Returns centres of shape (n_p, n_signals, n_clusters) and the ranges per signal.
    """
    xs = [prepare_signal(nz._check_window(window[name], name), name, reference, cfg.variant, entry_index)
          for name in signals]
    rngs = [nz.range_params(x, name, cfg.eq12) for x, name in zip(xs, signals)]
    n = len(signals)
    cnts = np.zeros((n, cfg.n_colors), dtype=np.int64)
    lo, hi = np.zeros(n), np.zeros(n)
    # one transform per wavelet (sym5: a1, omega1, v2; db6: m_el, a2), all its signals at once
    by_wavelet = {}
    for j, name in enumerate(signals):
        by_wavelet.setdefault(cfg.wavelet[name], []).append(j)
    for wavelet, idx in by_wavelet.items():
        coefs = wavelet_coefficients(np.stack([xs[j] for j in idx]), wavelet, reading=cfg.scale_reading,
                                     precision=cfg.wavefun_precision)
        levels, cnts[idx], lo[idx], hi[idx] = coefficient_levels(coefs, cfg)
    vals = [nz.map_levels(levels, float(lo[j]), float(hi[j]), rngs[j]) for j in range(n)]
    centres, _ = _cluster(np.stack(vals), cnts, rngs, cfg, [float(p) for p in p_values])
    return centres, rngs


def windows_features(windows: Sequence[dict], cfg: MethodConfig, p_values, signals=SIGNALS, references=None,
                     entry_index: int = 48, chunk: int = 32):
    """:func:`window_features` of many windows, batched: centres of shape (n_p, n_windows, n_signals,
    n_clusters) and the ranges (n_windows lists of n_signals), equal, bit for bit, to stacking
    ``window_features(window, ...)`` of every window (every step works row by row: the transforms, the image
    cells, the histograms and the KHM fit, whose rows are independent, khm.khm_fit_batch; test_method).
    ``chunk`` windows go through the wavelet transform at a time (memory).  The robustness sweeps identify
    thousands of windows: one batch costs a fraction of the per-window calls' numpy overhead."""
    windows = list(windows)
    n_w, n = len(windows), len(signals)
    refs = [None] * n_w if references is None else list(references)
    xs = [[prepare_signal(nz._check_window(w[name], name), name, refs[i], cfg.variant, entry_index)
           for name in signals] for i, w in enumerate(windows)]
    rngs = [[nz.range_params(x, name, cfg.eq12) for x, name in zip(xs[i], signals)] for i in range(n_w)]
    cnts = np.zeros((n_w, n, cfg.n_colors), dtype=np.int64)
    lo, hi = np.zeros((n_w, n)), np.zeros((n_w, n))
    by_wavelet = {}
    for j, name in enumerate(signals):
        by_wavelet.setdefault(cfg.wavelet[name], []).append(j)
    levels = None
    for wavelet, idx in by_wavelet.items():
        for a in range(0, n_w, chunk):
            b = min(a + chunk, n_w)
            coefs = wavelet_coefficients(np.stack([xs[i][j] for i in range(a, b) for j in idx]), wavelet,
                                         reading=cfg.scale_reading, precision=cfg.wavefun_precision)
            levels, c, low, high = coefficient_levels(coefs, cfg)
            cnts[a:b, idx] = c.reshape(b - a, len(idx), -1)
            lo[a:b, idx], hi[a:b, idx] = low.reshape(b - a, len(idx)), high.reshape(b - a, len(idx))
    vals = [nz.map_levels(levels, float(lo[i, j]), float(hi[i, j]), rngs[i][j]) for i in range(n_w) for j in range(n)]
    centres, _ = _cluster(np.stack(vals), cnts.reshape(n_w * n, -1), [r for row in rngs for r in row], cfg,
                          [float(p) for p in p_values])
    return centres.reshape(centres.shape[0], n_w, n, -1), rngs


def signal_features(x, signal: str, cfg: MethodConfig, p_values=None, reference=None,
                    entry_index: int = 48) -> SignalFeatures:
    """KHM centres of one signal window for every p (the paper's N3 row)."""
    x = nz._check_window(x, signal)
    ps = [float(p) for p in (cfg.p_values if p_values is None else p_values)]
    centres, ranges, info = batch_features(x[None, :], signal, cfg, ps,
                                           None if reference is None else [reference], entry_index)
    return SignalFeatures({p: centres[k, 0] for k, p in enumerate(ps)}, ranges[0],
                          {p: {"n_iter": info[p]["n_iter"], "converged": bool(info[p]["converged"][0])}
                           for p in ps})


def pre_entry_reference(window: dict, entry_index: int) -> float:
    """Load reference of a window: mean electromagnetic torque before the entry, N m."""
    m = np.asarray(window["m_el"], dtype=float)
    if entry_index < 1:
        raise ValueError(f"entry_index: need >= 1 pre-entry sample for the reference, got {entry_index}")
    return float(np.mean(m[:entry_index]))


def h_vector(pattern_centres: np.ndarray, tested_centres: np.ndarray, h5: float, scatter=None) -> np.ndarray:
    """Eq. (33): H(f) = h5 * sum_i |N2(f, i) - N3(i)|, shape (n_classes,).

    With ``scatter`` (variant 'sensor_matched', shape (n_clusters,)): H(f) = sum_i |N2(f, i) - N3(i)| / scatter(i),
    each centre's distance in units of its seed-to-seed spread under the sensor noise (h5 is not used)."""
    n2 = np.asarray(pattern_centres, dtype=float)
    n3 = np.asarray(tested_centres, dtype=float)
    if scatter is not None:
        return (np.abs(n2 - n3[None, :]) / np.asarray(scatter, dtype=float)[None, :]).sum(axis=1)
    return h5 * np.abs(n2 - n3[None, :]).sum(axis=1)


def margin(h: np.ndarray) -> float:
    """Second-smallest over smallest H (inf when the smallest is exactly 0)."""
    s = np.sort(np.asarray(h, dtype=float))
    if s.size < 2:
        return float("inf")
    return float("inf") if s[0] == 0 else float(s[1] / s[0])
