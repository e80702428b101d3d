"""Pattern library (the paper's N2 matrices) and identification of J1 (eqs. 31–35).

A library holds, for every backlash width (the paper's index e), signal and p,
the 7 x 7 matrix N2 whose row f is the sorted KHM centres S of the pattern run
with J1 = K1[f] at eta_k = 0.025, and the factor h5 (eq. 34).  It is saved as
one .npz file with a JSON metadata record (format version, the system and
method configurations and their hashes); loading a library built for another
configuration is refused with a message that names what differs.
"""
from __future__ import annotations

import dataclasses
import functools
import hashlib
import json
import time
from dataclasses import dataclass
from pathlib import Path
from typing import Sequence

import numpy as np

from jident_ros.method import normalise as nz
from jident_ros.method.pipeline import (
    SIGNALS,
    MethodConfig,
    batch_features,
    h_vector,
    margin,
    pre_entry_reference,
    window_features,
    windows_features,
)
from jident_ros.sim import Case, WindowSet, simulate_grid
from jident_ros.sim.params import SystemConfig
from jident_ros.sim.sensors import apply_sensors

FORMAT_VERSION = 1
#: Variant 'sensor_matched': the noise seeds of the library's pattern runs are MATCHED_SEED_BASE + 1, 2, ...
#: (apart from the seeds the evaluation tests with, 1-5 and 1000-1100).
MATCHED_SEED_BASE = 5000
#: How a window's backlash width picks its patterns: the paper's nearest library width, or (variants
#: beyond the paper, issue 13) the N2 matrices and h5 interpolated linearly in width to the window's width
#: (``width_interp``), or the pattern runs simulated at the window's width (``width_simulated``,
#: :func:`simulated_width_library`; needs the system configuration).
WIDTH_MODES = ("nearest", "width_interp", "width_simulated")
#: ``width_simulated``: the window's width is rounded to this many significant digits before the pattern runs
#: are simulated (one library per rounded width, cached): a relative rounding of at most 0.005 %, well below
#: the 0.1 % width error that already costs accuracy (docs/method.md, "Width-aware patterns").
WIDTH_SIMULATED_DIGITS = 5


class LibraryMismatch(ValueError):
    """The library was built for another configuration."""


def method_config_to_dict(cfg: MethodConfig) -> dict:
    return json.loads(json.dumps(dataclasses.asdict(cfg)))


def config_to_dict(cfg: SystemConfig) -> dict:
    """Plain nested dict (tuples as lists) of a SystemConfig."""
    return json.loads(json.dumps(dataclasses.asdict(cfg)))


def config_hash(obj) -> str:
    """SHA-256 of a canonical JSON form of a (dataclass) configuration (the library's metadata; also
    :func:`jident_ros.identify.library.default_library_path`)."""
    if dataclasses.is_dataclass(obj):
        obj = dataclasses.asdict(obj)
    text = json.dumps(obj, sort_keys=True, separators=(",", ":"), default=str)
    return hashlib.sha256(text.encode()).hexdigest()


@dataclass
class PatternLibrary:
    """N2 matrices and h5 factors.

    Attributes
    ----------
    centres : ndarray, shape (n_p, n_widths, n_signals, n_classes, n_clusters)
        centres[p, e, s, f] = sorted KHM centres of pattern run f (N2 row f).
    h5 : ndarray, shape (n_p, n_widths, n_signals)
    ranges : ndarray, shape (n_widths, n_signals, n_classes, 2)
        (h3, k3) of each pattern run.
    p_values, widths_m, classes_kgm2, signals : tuples indexing the axes
    metadata : dict (format, configs, hashes, created)
    scatter : ndarray, shape (n_p, n_widths, n_signals, n_clusters), or None
        Variant 'sensor_matched' only (beyond the paper): the seed-to-seed standard deviation of each
        sorted centre of the pattern runs under the sensor noise, pooled over the J1 classes; H is then
        measured in units of it (:func:`pipeline.h_vector`) and the signals are fused by the plain sum.
    """

    centres: np.ndarray
    h5: np.ndarray
    ranges: np.ndarray
    p_values: tuple
    widths_m: tuple
    classes_kgm2: tuple
    signals: tuple
    metadata: dict
    scatter: np.ndarray | None = None

    # -------------------------------------------------------------- building
    @classmethod
    def build(cls, system: SystemConfig, method: MethodConfig, windows=None, progress=None) -> "PatternLibrary":
        """Build from the eta_k = 0.025 runs of every J1 class and width.

        ``windows`` may be a precomputed WindowSet holding exactly those runs
        (any order); otherwise they are simulated.
        """
        wanted = pattern_run_cases(system)
        if windows is None:
            windows = simulate_grid(system, wanted)
        index = {c: i for i, c in enumerate(windows.cases)}
        missing = [c for c in wanted if c not in index]
        if missing:
            raise ValueError(f"windows: missing pattern runs, e.g. {missing[0]}")
        order = [index[c] for c in wanted]
        if method.variant == "sensor_matched":
            return cls.sensor_matched(take_windows(windows, order), system, method, progress)
        return cls.from_windows(windows, order, system, method, progress)

    @classmethod
    def sensor_matched(cls, windows: WindowSet, system: SystemConfig, method: MethodConfig,
                       progress=None) -> "PatternLibrary":
        """Variant 'sensor_matched' (beyond the paper): the library of the noise-free pattern runs
        ``windows`` (class-major, width-minor) as recorded through ``method.sensor_spec()``, with
        ``method.matched_seeds`` noise seeds (MATCHED_SEED_BASE + 1, ...).  N2 = the mean of the seeds' centres,
        ``scatter`` = their standard deviation (docs/method.md, "Variant sensor_matched")."""
        spec = method.sensor_spec()
        feats, ranges = [], []
        n = method.matched_seeds
        for k, seed in enumerate(matched_seeds(method)):
            noisy = apply_sensors(windows, spec, seed, system.motor.base.torque_nm)
            lib = cls.from_windows(noisy, range(len(noisy.cases)), system, method.replace(variant="paper"))
            feats.append(lib.centres)
            ranges.append(lib.ranges)
            if progress:
                progress(k + 1, n)
        return cls.from_seed_libraries(np.array(feats), np.array(ranges), system, method)

    @classmethod
    def from_seed_libraries(cls, centres: np.ndarray, ranges: np.ndarray, system: SystemConfig,
                            method: MethodConfig) -> "PatternLibrary":
        """Variant 'sensor_matched' library from per-seed pattern centres (n_seeds, n_p, n_widths, n_signals,
        n_classes, K) and ranges (n_seeds, n_widths, n_signals, n_classes, 2): N2 = the seed mean of the
        centres, scatter = their seed-to-seed standard deviation pooled (averaged) over the J1 classes."""
        centres, ranges = np.asarray(centres, dtype=float), np.asarray(ranges, dtype=float)
        if centres.shape[0] < 2:
            raise ValueError(f"centres: need >= 2 seeds for the scatter, got {centres.shape[0]}")
        mean = centres.mean(axis=0)
        scatter = centres.std(axis=0, ddof=1).mean(axis=3)            # (n_p, n_widths, n_signals, K)
        floor = 1e-9 * np.maximum(np.abs(mean).max(axis=3), 1e-300)   # a centre that never moves: tiny, not 0
        scatter = np.maximum(scatter, floor)
        rng = ranges.mean(axis=0)
        g = system.grid
        return cls(np.ascontiguousarray(mean), h5_table(mean, rng), rng, tuple(float(p) for p in method.p_values),
                   tuple(g.backlash_widths_m), tuple(g.inertia_classes_kgm2), SIGNALS,
                   library_metadata(system, method), np.ascontiguousarray(scatter))

    @classmethod
    def from_windows(cls, windows, order: Sequence[int], system: SystemConfig, method: MethodConfig,
                     progress=None) -> "PatternLibrary":
        """Library from windows; ``order`` lists window indices class-major, width-minor."""
        ps = tuple(float(p) for p in method.p_values)
        centres = np.zeros((len(ps), len(order), len(SIGNALS), method.n_clusters))
        ranges = np.zeros((len(order), len(SIGNALS), 2))
        refs = np.array([pre_entry_reference(windows.case(i), windows.entry_index) for i in order])
        for s, name in enumerate(SIGNALS):
            batch = np.stack([windows.signals[name][i] for i in order])
            centres[:, :, s], rps, _ = batch_features(batch, name, method, ps, refs, windows.entry_index)
            ranges[:, s] = [(r.h3, r.k3) for r in rps]
            if progress:
                progress(s + 1, len(SIGNALS))
        return cls.from_features(centres, ranges, range(len(order)), system, method)

    @classmethod
    def from_features(cls, centres: np.ndarray, ranges: np.ndarray, order: Sequence[int], system: SystemConfig,
                      method: MethodConfig) -> "PatternLibrary":
        """Library from features already computed for a set of windows (e.g. a whole evaluation grid).

        Parameters
        ----------
        centres : ndarray, shape (n_p, n_windows, n_signals, n_clusters)
            Sorted KHM centres of every window (signals in SIGNALS order, p in
            ``method.p_values`` order), as :func:`pipeline.batch_features` gives them.
        ranges : ndarray, shape (n_windows, n_signals, 2)
            (h3, k3) of every window and signal.
        order : sequence of int
            Window indices of the pattern runs, class-major, width-minor.

        Equal to :meth:`from_windows` on the same windows (each window's features
        do not depend on the other windows of its batch).
        """
        g = system.grid
        ps = tuple(float(p) for p in method.p_values)
        nw, nc = len(g.backlash_widths_m), len(g.inertia_classes_kgm2)
        order = np.asarray(list(order), dtype=int)
        if order.shape != (nw * nc,):
            raise ValueError(f"order: expected {nw * nc} pattern windows (class-major, width-minor), got {order.size}")
        centres, ranges = np.asarray(centres, dtype=float), np.asarray(ranges, dtype=float)
        if centres.shape[0] != len(ps) or centres.shape[2:] != (len(SIGNALS), method.n_clusters):
            raise ValueError(f"centres: expected shape ({len(ps)}, n_windows, {len(SIGNALS)}, {method.n_clusters}), "
                             f"got {centres.shape}")
        # window order[f * nw + e] -> [..., e, s, f]: (n_p, nc, nw, ns, K) -> (n_p, nw, ns, nc, K)
        lib_centres = centres[:, order].reshape(len(ps), nc, nw, len(SIGNALS), -1).transpose(0, 2, 3, 1, 4)
        lib_ranges = ranges[order].reshape(nc, nw, len(SIGNALS), 2).transpose(1, 2, 0, 3)
        lib_centres, lib_ranges = np.ascontiguousarray(lib_centres), np.ascontiguousarray(lib_ranges)
        h5 = h5_table(lib_centres, lib_ranges)
        meta = library_metadata(system, method)
        return cls(lib_centres, h5, lib_ranges, ps, tuple(g.backlash_widths_m), tuple(g.inertia_classes_kgm2),
                   SIGNALS, meta)

    # ------------------------------------------------------------ persistence
    def save(self, path) -> Path:
        path = Path(path)
        path.parent.mkdir(parents=True, exist_ok=True)
        tmp = path.with_suffix(path.suffix + ".tmp")
        with open(tmp, "wb") as f:
            np.savez_compressed(f, centres=self.centres, h5=self.h5, ranges=self.ranges,
                                p_values=np.array(self.p_values), widths_m=np.array(self.widths_m),
                                classes_kgm2=np.array(self.classes_kgm2),
                                signals=np.array(self.signals), metadata=np.array(json.dumps(self.metadata)),
                                **({} if self.scatter is None else {"scatter": self.scatter}))
        tmp.replace(path)  # atomic: a reader never sees half a library
        return path

    @classmethod
    def load(cls, path, system: SystemConfig | None = None, method: MethodConfig | None = None) -> "PatternLibrary":
        """Load a library; with configurations given, refuse one built for others."""
        path = Path(path)
        if not path.is_file():
            raise FileNotFoundError(f"pattern library: no such file {str(path)!r} (build it with `jident build-patterns`)")
        where = f"pattern library {str(path)!r}"
        if path.stat().st_size == 0:
            raise LibraryMismatch(f"{where}: empty file; rebuild it with `jident build-patterns`")
        try:
            with np.load(path, allow_pickle=False) as z:
                meta = json.loads(str(z["metadata"]))
                lib = cls(z["centres"], z["h5"], z["ranges"], tuple(float(p) for p in z["p_values"]),
                          tuple(float(w) for w in z["widths_m"]), tuple(float(c) for c in z["classes_kgm2"]),
                          tuple(str(s) for s in z["signals"]), meta,
                          z["scatter"] if "scatter" in z.files else None)
        except KeyError as exc:  # a readable .npz without the library's arrays
            raise LibraryMismatch(f"{where}: not a jident pattern library ({exc})") from None
        except Exception as exc:  # zip (truncated, bad CRC), zlib, npy format, JSON: all "unreadable"
            raise LibraryMismatch(f"{where}: unreadable ({type(exc).__name__}: {exc}); rebuild it with "
                                  "`jident build-patterns`") from None
        if not isinstance(meta, dict) or meta.get("format") != FORMAT_VERSION:
            got = meta.get("format") if isinstance(meta, dict) else meta
            raise LibraryMismatch(f"{where}: format {got!r}, "
                                  f"this version reads format {FORMAT_VERSION}; rebuild it")
        lib.check_consistent(where)
        if system is not None and method is not None:
            lib.check_matches(system, method, str(path))
        return lib

    def check_consistent(self, where: str = "pattern library") -> None:
        """LibraryMismatch naming the problem when the arrays disagree with each other (shapes) or hold
        non-finite values: a damaged or hand-edited file is never used."""
        n_p, n_w, n_s, n_c = len(self.p_values), len(self.widths_m), len(self.signals), len(self.classes_kgm2)
        want = {"centres": (n_p, n_w, n_s, n_c), "h5": (n_p, n_w, n_s), "ranges": (n_w, n_s, n_c, 2)}
        if self.scatter is not None:
            want["scatter"] = (n_p, n_w, n_s, np.asarray(self.centres).shape[-1])
            if not np.all(np.asarray(self.scatter) > 0):
                raise LibraryMismatch(f"{where}: scatter holds values <= 0; rebuild it")
        for name, shape in want.items():
            arr = np.asarray(getattr(self, name))
            got = arr.shape[:len(shape)] if name == "centres" else arr.shape
            if got != shape or (name == "centres" and arr.ndim != 5):
                raise LibraryMismatch(f"{where}: {name} has shape {arr.shape}, expected {shape}"
                                      f"{' + (n_clusters,)' if name == 'centres' else ''} for {n_c} J1 classes, "
                                      f"{n_w} widths, {n_s} signals, {n_p} p values; rebuild it")
            if not np.issubdtype(arr.dtype, np.number):
                raise LibraryMismatch(f"{where}: {name} is not numeric ({arr.dtype}); rebuild it")
            bad = int(np.size(arr) - np.count_nonzero(np.isfinite(arr)))
            if bad:
                raise LibraryMismatch(f"{where}: {name} holds {bad} non-finite value(s) (NaN/Inf); rebuild it")
        for name, vals in (("p_values", self.p_values), ("widths_m", self.widths_m),
                           ("classes_kgm2", self.classes_kgm2)):
            if not vals or not all(np.isfinite(v) and v > 0 for v in vals):
                raise LibraryMismatch(f"{where}: {name} {list(vals)} must be finite numbers > 0; rebuild it")
        if tuple(self.signals) != tuple(SIGNALS):
            raise LibraryMismatch(f"{where}: signals {list(self.signals)}, expected {list(SIGNALS)}; rebuild it")

    def check_matches(self, system: SystemConfig, method: MethodConfig, where: str = "pattern library") -> None:
        want = library_metadata(system, method)
        diffs = []
        # a simulated library holds the configuration's classes and widths; a calibration library
        # (source "recordings") the labels of its recordings (its shapes are checked by check_consistent)
        simulated = self.metadata.get("source") != "recordings"
        if simulated and sorted(self.classes_kgm2) != sorted(float(c) for c in system.grid.inertia_classes_kgm2):
            diffs.append(f"{len(self.classes_kgm2)} J1 classes {list(self.classes_kgm2)}, configuration "
                         f"{len(system.grid.inertia_classes_kgm2)} (grid.inertia_classes_kgm2)")
        if simulated and sorted(self.widths_m) != sorted(float(w) for w in system.grid.backlash_widths_m):
            diffs.append(f"widths {list(self.widths_m)}, configuration {list(system.grid.backlash_widths_m)} "
                         "(grid.backlash_widths_m)")
        if sorted(self.p_values) != sorted(float(p) for p in method.p_values):
            diffs.append(f"p values {list(self.p_values)}, configuration {list(method.p_values)} (method.p_values)")
        for part in ("system", "method"):
            if self.metadata.get(f"{part}_hash") != want[f"{part}_hash"]:
                diffs += [f"{part}.{k}: library {a!r}, configuration {b!r}"
                          for k, a, b in _dict_diff(self.metadata.get(part, {}), want[part])]
        if diffs:
            shown = "; ".join(diffs[:5]) + (f"; … {len(diffs) - 5} more" if len(diffs) > 5 else "")
            raise LibraryMismatch(f"{where}: built for another configuration ({shown}); rebuild it "
                                  f"with `jident build-patterns`")

    # ---------------------------------------------------------- identification
    def width_index(self, width_m: float) -> int:
        """Index e of the library width nearest to a window's backlash width."""
        if not np.isfinite(width_m) or width_m <= 0:
            raise ValueError(f"backlash_width_m: must be a finite number > 0, got {width_m!r}")
        return int(np.argmin(np.abs(np.array(self.widths_m) - width_m)))

    def h_vector(self, k: int, s: int, width_m: float, tested_centres: np.ndarray,
                 mode: str = "nearest") -> np.ndarray:
        """H of one signal's tested centres N3 against the patterns at ``width_m`` (``patterns_at``):
        eq. (33), or with a scatter (variant 'sensor_matched') the distance in units of the scatter."""
        n2, h5 = self.patterns_at(k, s, width_m, mode)
        scatter = None if self.scatter is None else self.scatter_at(k, s, width_m, mode)
        return h_vector(n2, tested_centres, h5, scatter)

    def fuse(self, h_vectors: Sequence[np.ndarray]) -> tuple[int, float]:
        """Fused class and margin over signals: the paper's :func:`fuse` (each H over its own sum), or with a
        scatter (variant 'sensor_matched') the plain sum of the H vectors, each already in units of its
        signal's noise scatter, so a signal the noise scrambles weighs less by itself."""
        if self.scatter is None:
            return fuse(h_vectors)
        total = np.sum([np.asarray(h, dtype=float) for h in h_vectors], axis=0)
        return int(np.argmin(total)), margin(total)

    def scatter_at(self, k: int, s: int, width_m: float, mode: str = "nearest") -> np.ndarray:
        """The scatter (variant 'sensor_matched') at ``width_m``, picked or interpolated as ``patterns_at``."""
        if self.scatter is None:
            raise ValueError("scatter: this library has none (variant 'sensor_matched' only)")
        return self._at(self.scatter[k, :, s], width_m, mode)

    def _at(self, per_width: np.ndarray, width_m: float, mode: str) -> np.ndarray:
        """Row of ``per_width`` (indexed by library width) at ``width_m`` by ``mode`` (see patterns_at)."""
        if mode == "nearest":
            return per_width[self.width_index(width_m)]
        if mode == "width_simulated":
            raise ValueError("width mode 'width_simulated' simulates its patterns: identify_window(..., system=...) "
                             "or simulated_width_library()")
        if mode != "width_interp":
            raise ValueError(f"width mode: one of {', '.join(WIDTH_MODES)}, got {mode!r}")
        self.width_index(width_m)  # validates width_m
        w = np.asarray(self.widths_m, dtype=float)
        order = np.argsort(w)
        ws = w[order]
        if width_m <= ws[0] or width_m >= ws[-1] or ws.size == 1:
            return per_width[self.width_index(width_m)]
        j = int(np.searchsorted(ws, width_m))
        lo, hi = int(order[j - 1]), int(order[j])
        t = (width_m - ws[j - 1]) / (ws[j] - ws[j - 1])
        return (1.0 - t) * per_width[lo] + t * per_width[hi]

    def patterns_at(self, k: int, s: int, width_m: float, mode: str = "nearest") -> tuple[np.ndarray, float]:
        """(N2, h5) of p index ``k`` and signal index ``s`` for a window of backlash width ``width_m``.

        ``nearest`` (the paper: patterns and tests at the same width e): the library width nearest to
        ``width_m``.  ``width_interp`` (beyond the paper): N2 (the KHM centres of the seven pattern runs)
        and h5 interpolated linearly in width between the two library widths around ``width_m``; outside
        the library's widths the nearest end is used (no extrapolation)."""
        return self._at(self.centres[k, :, s], width_m, mode), float(self._at(self.h5[k, :, s], width_m, mode))

    def p_index(self, p: float) -> int:
        for k, q in enumerate(self.p_values):
            if q == float(p):
                return k
        raise ValueError(f"p: the library has p in {list(self.p_values)}, got {p!r}")


def h5_table(centres: np.ndarray, ranges: np.ndarray) -> np.ndarray:
    """Eq. (34) for every pattern set: ``centres`` (n_p, n_widths, n_signals, n_classes, 7) and
    ``ranges`` (n_widths, n_signals, n_classes, 2) holding (h3, k3) -> h5, shape (n_p, n_widths, n_signals)."""
    n_p, nw, ns, nc = centres.shape[:4]
    h5 = np.zeros((n_p, nw, ns))
    for e in range(nw):
        for s in range(ns):
            rps = [nz.RangeParams(float(ranges[e, s, f, 0]), float(ranges[e, s, f, 1])) for f in range(nc)]
            for k in range(n_p):
                h5[k, e, s] = nz.h5_factor(centres[k, e, s], rps)
    return h5


def library_metadata(system: SystemConfig, method: MethodConfig) -> dict:
    sysd, methd = config_to_dict(system), method_config_to_dict(method)
    return {"format": FORMAT_VERSION, "system": sysd, "method": methd,
            "system_hash": config_hash(sysd), "method_hash": config_hash(methd),
            "created": time.strftime("%Y-%m-%dT%H:%M:%SZ", time.gmtime())}


def _dict_diff(a, b, prefix=""):
    keys = sorted(set(a) | set(b)) if isinstance(a, dict) and isinstance(b, dict) else []
    if not keys:
        if a != b:
            yield prefix.rstrip("."), a, b
        return
    for k in keys:
        yield from _dict_diff(a.get(k) if isinstance(a, dict) else None,
                              b.get(k) if isinstance(b, dict) else None, f"{prefix}{k}.")


@dataclass
class SignalAnswer:
    """Identification from one signal: H vector, class index, J1, margin."""

    signal: str
    p: float
    h: np.ndarray
    class_index: int
    inertia_kgm2: float
    margin: float


@dataclass
class Identification:
    """All five signals' answers and the fused class for one window."""

    answers: dict          # signal -> SignalAnswer
    fused_class_index: int
    fused_inertia_kgm2: float
    fused_margin: float
    width_index: int
    p: float


def identify_window(window: dict, entry_index: int, backlash_width_m: float, library: PatternLibrary,
                    method: MethodConfig, p: float, signals: Sequence[str] = SIGNALS,
                    width_mode: str = "nearest", system: SystemConfig | None = None) -> Identification:
    """Identify J1 from one window (dict of 1-D arrays per signal).

    ``width_mode`` (:data:`WIDTH_MODES`): ``nearest`` compares with the patterns of the library width
    nearest to ``backlash_width_m`` (the paper); ``width_interp`` with the patterns interpolated to it
    (give the window's estimated width, e.g. :func:`jident_ros.identify.gap.estimate_backlash_width`);
    ``width_simulated`` with pattern runs simulated at that width (``system`` needed;
    :func:`simulated_width_library`, ``library`` is then not used)."""
    if width_mode == "width_simulated":
        if system is None:
            raise ValueError("system: width_mode 'width_simulated' simulates the pattern runs, give the SystemConfig")
        library = simulated_width_library(system, method, backlash_width_m)
        width_mode = "nearest"
    library.width_index(backlash_width_m)    # refuse a bad width or a library without this p before any
    library.p_index(p)                       # transform, as before
    ref = pre_entry_reference(window, entry_index) if "m_el" in window else None
    centres, _ = window_features(window, method, [p], signals, ref, entry_index)
    return _identification(centres[0], backlash_width_m, library, p, signals, width_mode)


def identify_windows(windows: Sequence[dict], entry_index: int, backlash_widths_m: Sequence[float],
                     library: PatternLibrary, method: MethodConfig, p: float,
                     signals: Sequence[str] = SIGNALS) -> list:
    """:func:`identify_window` (width mode 'nearest') of many windows with their widths, the features computed
    in one batch (:func:`pipeline.windows_features`): the same Identification objects, bit for bit, at a
    fraction of the per-window cost (test_method)."""
    windows = list(windows)
    library.p_index(p)
    refs = [pre_entry_reference(w, entry_index) if "m_el" in w else None for w in windows]
    centres, _ = windows_features(windows, method, [p], signals, refs, entry_index)
    return [_identification(centres[0, i], float(w), library, p, signals, "nearest")
            for i, w in enumerate(backlash_widths_m)]


def _identification(centres: np.ndarray, backlash_width_m: float, library: PatternLibrary, p: float,
                    signals: Sequence[str], width_mode: str) -> Identification:
    """The answers and the fused class of one window from its KHM centres (n_signals, n_clusters) at p."""
    e = library.width_index(backlash_width_m)
    k = library.p_index(p)
    answers = {}
    for j, name in enumerate(signals):
        s = library.signals.index(name)
        h = library.h_vector(k, s, backlash_width_m, centres[j], width_mode)
        c = int(np.argmin(h))
        answers[name] = SignalAnswer(name, float(p), h, c, library.classes_kgm2[c], margin(h))
    fc, fm = library.fuse([a.h for a in answers.values()])
    return Identification(answers, fc, library.classes_kgm2[fc], fm, e, float(p))


def fuse(h_vectors: Sequence[np.ndarray]) -> tuple[int, float]:
    """Fused class: argmin of the sum of each signal's H divided by its own sum.

    Each H profile is made scale-free (H / sum H) so that no signal dominates
    by its units; returns (class index, margin of the fused profile).
    """
    total = np.zeros_like(np.asarray(h_vectors[0], dtype=float))
    for h in h_vectors:
        h = np.asarray(h, dtype=float)
        sm = h.sum()
        total += h / sm if sm > 0 else h
    return int(np.argmin(total)), margin(total)


def pattern_run_cases(system: SystemConfig) -> list[Case]:
    """The library's pattern runs: every J1 class and width at the pattern eta_k, class-major, width-minor."""
    g = system.grid
    return [Case(j, w, g.pattern_consistency_pa_sn) for j in g.inertia_classes_kgm2 for w in g.backlash_widths_m]


def rounded_width(width_m: float) -> float:
    """A window's width rounded to WIDTH_SIMULATED_DIGITS significant digits."""
    if not np.isfinite(width_m) or width_m <= 0:
        raise ValueError(f"backlash_width_m: must be a finite number > 0, got {width_m!r}")
    return float(f"{width_m:.{WIDTH_SIMULATED_DIGITS}g}")



def simulated_width_library(system: SystemConfig, method: MethodConfig, width_m: float) -> "PatternLibrary":
    """Variant ``width_simulated`` (beyond the paper): the library of the seven pattern runs (eta_k = 0.025)
    simulated at the window's backlash width (:func:`rounded_width`), built as :meth:`PatternLibrary.build`
    (so also with the variant 'sensor_matched'); cached per (system, method, rounded width)."""
    return _simulated_width_library(system, method, rounded_width(width_m))


@functools.lru_cache(maxsize=32)
def _simulated_width_library(system: SystemConfig, method: MethodConfig, width_m: float) -> "PatternLibrary":
    return PatternLibrary.build(with_widths(system, (width_m,)), method)


def with_widths(system: SystemConfig, widths_m: Sequence[float]) -> SystemConfig:
    """``system`` with the pattern library's backlash widths replaced by ``widths_m``."""
    return dataclasses.replace(system, grid=dataclasses.replace(system.grid, backlash_widths_m=tuple(widths_m)))


def matched_seeds(method: MethodConfig) -> list[int]:
    """The noise seeds of variant 'sensor_matched''s pattern runs."""
    return [MATCHED_SEED_BASE + 1 + k for k in range(method.matched_seeds)]


def take_windows(windows: WindowSet, order: Sequence[int]) -> WindowSet:
    """The windows ``order`` of a WindowSet, in that order."""
    idx = np.asarray(list(order), dtype=int)
    return WindowSet(windows.t, {k: v[idx] for k, v in windows.signals.items()}, [windows.cases[i] for i in idx],
                     windows.entry_index, windows.sample_period_s, np.asarray(windows.initial_slip)[idx],
                     dict(windows.metadata))
