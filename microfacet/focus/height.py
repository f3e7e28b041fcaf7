"""Height from focus: streaming peak search over one or more focus windows, sub-slice peak
fit, per-pixel height uncertainty, reliability and the all-in-focus composite.

The stack is read **once**, slice by slice in increasing ``z``; per pixel and window only a
fixed number of image-sized buffers is kept (:class:`~microfacet.focus.stream.PeakTracker`),
so peak memory is ``O(H·W)`` whatever the number of slices.

Method (defaults chosen from the measurements of ``docs/height-from-focus.md``: the RMSE on
the Cou & Guennebaud (2023) ground-truth stacks and the coverage on rendered stacks of known
relief and texture contrast, ``pipelines/focus_coverage.py``):

1. Focus measure per slice (:mod:`microfacet.focus.measures`) in the main window
   (``window_px``, default 7) and a coarse one (``coarse_window_px``, default 15, on a grid
   downsampled by 2), optionally a fine one (``fine_window_px``).
2. Per window, the running arg-max over slices with the focus values of the ``2r+1`` slices
   around the best one (``r = fit_radius``), the running sum of the focus values and of their
   squared second differences along ``z``.
3. Sub-slice peak (:mod:`microfacet.focus.peaks`): weighted least squares over those slices
   of a parabola in ``F^(-1/2)`` (``interpolation="lorentz"``, default: the focus curve of
   Gaussian-blurred texture), or in ``log F`` (``"lsq"``, a Gaussian; the earlier default),
   the classic 3-point Gaussian (``"gauss3"``) or the arg-max slice (``"none"``). Non-uniform
   and unsorted ``z`` are handled.
4. Significance of the peak against the noise of the curve's tails (a false-peak rate of
   1e-5 per pixel and window under Gaussian noise) and the height uncertainty σ
   (:mod:`microfacet.focus.uncertainty`): the fit's own variance plus what relief does to a
   window (slope, curvature, a widened curve). Each pixel takes the window with the smallest
   σ among those with a significant peak.
5. Reliability (``reliability="sigma"``, default): ``−20·log10(σ / z step)`` dB, at most 0 dB
   without a significant peak; pixels below ``min_reliability_db`` (default 4 dB: σ ≤ 0.63
   z step) or without a significant peak are NaN in ``height_um`` (optionally filled).
   ``reliability="pertuz"``: the Pertuz et al. (2013) ratio of the earlier versions.
6. All-in-focus composite: each pixel from its sharpest slice (main window).

Examples
--------
>>> import numpy as np
>>> rng = np.random.default_rng(0)
>>> tex = rng.random((64, 64)).astype(np.float32)
>>> import cv2
>>> z = np.arange(9.0)
>>> imgs = [cv2.GaussianBlur(tex, (0, 0), 0.5 + 0.5 * abs(zk - 4.3)) for zk in z]
>>> res = height_from_focus(imgs, z_um=z)
>>> bool(abs(np.nanmedian(res.height_um) - 4.3) < 0.15)
True
>>> bool(np.nanmedian(res.height_sigma_um) < 0.15 and res.reliable.mean() > 0.9)
True
"""

from __future__ import annotations

import logging
import math
import time
from collections.abc import Callable, Sequence
from concurrent.futures import ThreadPoolExecutor
from dataclasses import dataclass, field

import numpy as np

from ..core.errors import InputError, one_line
from ..core.lazy import load
from ..io.images import convert_samples
from ..io.limits import check_memory
from ..io.stack import Stack
from .align import estimate_warps, warped_loader
from .defaults import (
    COLOURS,
    DEFAULT_COARSE_WINDOW_PX,
    DEFAULT_COLOUR,
    DEFAULT_FIT_RADIUS,
    DEFAULT_INTERPOLATION,
    DEFAULT_MIN_RELIABILITY_DB,
    DEFAULT_RELIABILITY,
    DETECTION_ALPHA,
    INTERPOLATIONS,
    PERTUZ_MIN_RELIABILITY_DB,
    RELIABILITIES,
    SIGMA_MODEL,
)
from .fill import fill_missing
from .measures import (
    DEFAULT_OPERATOR,
    DEFAULT_WINDOW,
    DEFAULT_WINDOW_PX,
    OPERATORS,
    check_window,
    focus_measures,
    noise_shape,
)
from .peaks import peak_fit
from .stream import PeakTracker
from .uncertainty import add_relief_terms, combine, fit_window

cv2 = load("cv2")

__all__ = [
    "DEFAULT_COARSE_WINDOW_PX",
    "DEFAULT_FIT_RADIUS",
    "DEFAULT_INTERPOLATION",
    "DEFAULT_MIN_RELIABILITY_DB",
    "FocusResult",
    "INTERPOLATIONS",
    "check_focus_memory",
    "height_from_focus",
    "peak_fit",
]

log = logging.getLogger(__name__)


# --------------------------------------------------------------------------------------------
# results


@dataclass
class FocusResult:
    """Result of :func:`height_from_focus`.

    Attributes
    ----------
    height_um : ndarray of float32, shape (H, W)
        Height in µm (the stack's ``z_um`` frame); NaN where unreliable unless filled.
    height_fit_um : ndarray of float32, shape (H, W)
        The fitted height everywhere (no reliability mask, no fill).
    reliability_db : ndarray of float32, shape (H, W)
        Reliability in dB (larger is more reliable). With ``reliability="sigma"`` (default)
        the precision ``−20·log10(height_sigma_um / z step)`` (20 dB: σ = 0.1 step, 6 dB:
        σ = 0.5 step), at most 0 dB where no focus peak is significant; with ``"pertuz"`` the
        ratio of Pertuz et al. (2013).
    reliable : ndarray of bool, shape (H, W)
        The pixels with a height in ``height_um``: a significant focus peak (``"sigma"``) and
        ``reliability_db >= min_reliability_db`` (all pixels when that is −inf).
    best_index : ndarray of int32, shape (H, W)
        File-order index of the sharpest slice per pixel (main window).
    focus_max : ndarray of float32, shape (H, W)
        The focus measure at the sharpest slice (main window).
    all_in_focus : ndarray of float32, shape (H, W) or (H, W, 3)
        Each pixel from its sharpest slice, in the slices' encoding, scaled to [0, 1].
    z_um : ndarray of float64, shape (N,)
        Slice heights in file order.
    params : dict
        The options used.
    timings_s : dict
        Wall times: ``read`` (waiting for decoded slices), ``focus`` (per-slice work),
        ``fit`` (peak fits, uncertainty and choice of window), ``total``.
    height_sigma_um : ndarray of float32, shape (H, W)
        One-standard-deviation uncertainty of ``height_fit_um`` in µm, NaN where no focus
        peak is significant. Calibrated on rendered stacks of known relief (steps, crater
        rims, ridges, smooth) and texture contrast and on the Cou & Guennebaud stacks:
        |error| ≤ 2σ for 96-99 % of the reliable pixels (slightly conservative;
        docs/height-from-focus.md).
    detected : ndarray of bool, shape (H, W)
        True where at least one window has a significant focus peak (a textureless pixel
        has none: it gets no height, whatever the cut).
    window_px_map : ndarray of uint8, shape (H, W)
        The focus window (px) whose height each pixel took.
    """

    height_um: np.ndarray
    height_fit_um: np.ndarray
    reliability_db: np.ndarray
    reliable: np.ndarray
    best_index: np.ndarray
    focus_max: np.ndarray
    all_in_focus: np.ndarray
    z_um: np.ndarray
    params: dict = field(default_factory=dict)
    timings_s: dict = field(default_factory=dict)
    height_sigma_um: np.ndarray | None = None
    detected: np.ndarray | None = None
    window_px_map: np.ndarray | None = None

    @property
    def unreliable_fraction(self) -> float:
        """Fraction of pixels below the reliability cut."""
        return float(1.0 - self.reliable.mean())


#: Peak memory of ``microfacet height`` ≈ base + per pixel × H × W, set just above what
#: ``/usr/bin/time -f %M`` measured on nd stacks of 16 slices (see MEMORY_NOTE in
#: docs/height-from-focus.md); slices are streamed, so their number does not count.
MEMORY_BASE_BYTES = 150 << 20
MEMORY_BYTES_PER_PIXEL = 170


def check_focus_memory(stack) -> None:
    """Refuse, before any work, a stack whose height from focus would not fit in memory."""
    h, w = stack.shape
    check_memory(MEMORY_BASE_BYTES + MEMORY_BYTES_PER_PIXEL * h * w,
                 f"{one_line(stack.path / 'stack.json')}: height from focus of {w}x{h}-pixel "
                 f"slices")


# --------------------------------------------------------------------------------------------
# streaming height from focus


def _slice_source(source, z_um):
    """Return (z_um file order, n, shape, channels, loader(file_index) -> image float32)."""
    if isinstance(source, Stack):
        if not source.has_slices:
            raise InputError(f"{source.path / 'stack.json'}: the stack has no slices (export "
                             f"only); "
                             f"height from focus needs slices")
        if z_um is not None:
            raise ValueError("z_um must not be given with a Stack (it has its own)")
        z = np.asarray(source.z_um, dtype=np.float64)

        def load(i):
            return source.read_slice(i, np.float32)

        return z, source.n_slices, source.shape, source.channels, load
    if z_um is None:
        raise ValueError("z_um is required when source is a sequence of images")
    z = np.asarray(z_um, dtype=np.float64).ravel()
    if not np.all(np.isfinite(z)):
        raise ValueError("z_um must be finite")
    if np.unique(z).size != z.size:
        raise ValueError("z_um must not hold duplicate heights")
    if len(source) != z.size:
        raise ValueError(f"z_um has {z.size} values but there are {len(source)} images")
    first = np.asarray(source[0])
    if first.ndim not in (2, 3) or (first.ndim == 3 and first.shape[2] != 3):
        raise ValueError(f"images must be (H, W) or (H, W, 3), got {first.shape}")

    def load(i):
        img = np.asarray(source[i])
        if img.shape != first.shape:
            raise ValueError(f"image {i} has shape {img.shape}, expected {first.shape}")
        if img.dtype in (np.uint8, np.uint16):
            return convert_samples(img, np.float32)
        return img.astype(np.float32, copy=False)

    return z, z.size, first.shape[:2], (3 if first.ndim == 3 else 1), load


def _windows(shape, window_px, window, fine_window_px, coarse_window_px):
    """(window_px, window, downsample) of every window, sorted by size; index of the main."""
    out = []
    if fine_window_px:
        check_window(fine_window_px, window)
        if fine_window_px < window_px:
            out.append((int(fine_window_px), window, 1))
    out.append((int(window_px), window, 1))
    main = len(out) - 1
    if coarse_window_px:
        check_window(coarse_window_px, window)
        if coarse_window_px > window_px:
            ds = 2 if coarse_window_px >= 11 and min(shape) >= 32 else 1
            out.append((int(coarse_window_px), window, ds))
    return out, main


def _check_options(operator, window_px, window, interpolation, fit_radius, reliability,
                   colour, min_reliability_db, fill):
    if operator not in OPERATORS:
        raise ValueError(f"operator must be one of {OPERATORS}, not {operator!r}")
    check_window(window_px, window)
    if interpolation not in INTERPOLATIONS:
        raise ValueError(f"interpolation must be one of {INTERPOLATIONS}, not {interpolation!r}")
    if reliability not in RELIABILITIES:
        raise ValueError(f"reliability must be one of {RELIABILITIES}, not {reliability!r}")
    if colour not in COLOURS:
        raise ValueError(f"colour must be one of {COLOURS}, not {colour!r}")
    if interpolation in ("lsq", "lorentz"):
        r = DEFAULT_FIT_RADIUS if fit_radius is None else fit_radius
        if isinstance(r, bool) or not isinstance(r, (int, np.integer)) or not 1 <= r <= 10:
            raise ValueError(f"fit_radius must be an integer in 1..10, got {fit_radius!r}")
    else:
        r = 1
    if min_reliability_db is None:
        cuts = DEFAULT_MIN_RELIABILITY_DB if reliability == "sigma" else \
            PERTUZ_MIN_RELIABILITY_DB
        min_reliability_db = cuts[operator]
    if isinstance(min_reliability_db, bool) or not isinstance(min_reliability_db, (int, float)) \
            or math.isnan(min_reliability_db):
        raise ValueError(f"min_reliability_db must be a number, got {min_reliability_db!r}")
    if fill is True:
        fill = "smooth"
    if fill not in (None, False, "smooth", "nearest"):
        raise ValueError(f"fill must be None, True, 'smooth' or 'nearest', not {fill!r}")
    return int(r), float(min_reliability_db), fill


def height_from_focus(source, *, z_um: Sequence[float] | None = None,
                      operator: str = DEFAULT_OPERATOR, window_px: int = DEFAULT_WINDOW_PX,
                      window: str = DEFAULT_WINDOW, interpolation: str = DEFAULT_INTERPOLATION,
                      fit_radius: int | None = None,
                      min_reliability_db: float | None = None,
                      fill: str | bool | None = None, align: bool | str = False,
                      reference: int | None = None, prefetch: bool = True,
                      progress: Callable[[int, int], None] | None = None,
                      colour: str = DEFAULT_COLOUR,
                      coarse_window_px: int | None = DEFAULT_COARSE_WINDOW_PX,
                      fine_window_px: int | None = None,
                      reliability: str = DEFAULT_RELIABILITY) -> FocusResult:
    """Height map and its uncertainty from a focus stack in one streaming pass.

    Parameters
    ----------
    source : Stack or sequence of ndarray
        A :class:`microfacet.io.stack.Stack`, or images (each (H, W) or (H, W, 3); uint8/uint16
        are scaled to [0, 1]) indexed in the order of ``z_um``. Slices are read one at a time
        in increasing ``z``.
    z_um : sequence of float, shape (N,), optional
        Slice heights in µm (required for an image sequence, not allowed with a Stack). Any
        order and spacing, no duplicates.
    operator : {"tenengrad", "sml", "glv"}
        Focus measure, see :func:`~microfacet.focus.measures.focus_measure`.
    window_px : int
        Odd side of the main focus window in pixels.
    window : {"gaussian", "box"}
        Window shape.
    interpolation : {"lorentz", "lsq", "gauss3", "none"}
        Sub-slice peak estimate: weighted least squares over ``±fit_radius`` slices of a
        parabola in ``F^(-1/2)`` or in ``log F``, the 3-point Gaussian, or the arg-max slice.
    fit_radius : int, optional
        Neighbours on each side used by ``"lorentz"`` and ``"lsq"`` (default 2);
        ``"gauss3"`` uses 1.
    min_reliability_db : float, optional
        Pixels with a lower reliability are NaN in ``height_um`` (``-inf`` keeps all).
        Default: 4 dB (σ ≤ 0.63 z step) for ``reliability="sigma"``,
        ``PERTUZ_MIN_RELIABILITY_DB[operator]`` for ``"pertuz"``.
    fill : {None, False, True, "smooth", "nearest"}
        Fill unreliable pixels (True means ``"smooth"``), see :func:`fill_missing`.
    align : bool or {"ecc", "phase"}
        Register every slice to a reference slice before measuring focus (two passes over the
        stack); see :mod:`microfacet.focus.align`. True means ``"ecc"``.
    reference : int, optional
        File-order index of the alignment reference (default: chosen automatically).
    prefetch : bool
        Decode the next slice in a background thread while the current one is measured.
    progress : callable(done, total), optional
        Called after each slice.
    colour : {"luma", "rgb"}
        Measure the luma of RGB slices, or sum the measures of the three channels (better
        where colour texture is more than about twice the grey one).
    coarse_window_px : int or None
        A second, larger window (evaluated on a grid downsampled by 2 when ≥ 11 px) that
        pixels take where it gives the smaller uncertainty (weak texture); None: main window
        only. Ignored unless larger than ``window_px``.
    fine_window_px : int or None
        An optional smaller window for sharp relief (ignored unless smaller than
        ``window_px``); off by default: on the Cou stacks it raises the RMSE.
    reliability : {"sigma", "pertuz"}
        What ``reliability_db`` means and what ``reliable`` requires (see FocusResult).

    Returns
    -------
    FocusResult
    """
    t_start = time.perf_counter()
    r, min_reliability_db, fill = _check_options(
        operator, window_px, window, interpolation, fit_radius, reliability, colour,
        min_reliability_db, fill)
    z, n, shape, channels, load = _slice_source(source, z_um)
    if n < 3:
        raise InputError(f"a focus stack needs at least 3 slices, got {n}")
    order = np.argsort(z, kind="stable")          # rank -> file index
    zs = z[order]                                 # sorted heights
    H, W = shape
    wins, main = _windows(shape, window_px, window, fine_window_px, coarse_window_px)

    warps = None
    if align:
        method = "ecc" if align is True else align
        warps, ref = estimate_warps(load, order, shape, method=method, reference=reference)
        load = warped_loader(load, warps, shape)

    trackers = [PeakTracker(((H + 1) // 2, (W + 1) // 2) if ds == 2 else (H, W), radius=r,
                            n_slices=n) for _, _, ds in wins]
    best_now = np.full((H, W), -np.inf, np.float32)  # undelayed max (for the composite)
    aif = np.zeros((H, W, 3) if channels == 3 else (H, W), np.float32)
    mask = np.empty((H, W), bool)

    t_read = t_focus = 0.0
    pool = ThreadPoolExecutor(max_workers=1) if prefetch else None
    try:
        fut = pool.submit(load, int(order[0])) if pool else None
        for k in range(n):
            t0 = time.perf_counter()
            img = fut.result() if pool else load(int(order[k]))
            if pool and k + 1 < n:
                fut = pool.submit(load, int(order[k + 1]))
            t1 = time.perf_counter()
            fs = focus_measures(img, wins, operator=operator, colour=colour)
            for tr, f in zip(trackers, fs):
                tr.push(f, k)
            f = fs[main]
            np.greater(f, best_now, out=mask)
            cv2.max(f, best_now, dst=best_now)
            cv2.copyTo(img, mask.view(np.uint8), aif)
            t_read += t1 - t0
            t_focus += time.perf_counter() - t1
            if progress is not None:
                progress(k + 1, n)
        t1 = time.perf_counter()
        for tr in trackers:
            tr.finish()
            tr.release_ring()
        t_focus += time.perf_counter() - t1
    finally:
        if pool:
            pool.shutdown(wait=True, cancel_futures=True)

    # ---- peak fits, uncertainty, choice of window ------------------------------------------
    t2 = time.perf_counter()
    step = float(np.median(np.diff(zs))) if n > 1 else 1.0
    fits = []
    for (px, win, ds), tr in zip(wins, trackers):
        k_noise = noise_shape(operator=operator, window_px=px, window=win, downsample=ds,
                              colour=colour, channels=channels)
        fit = fit_window(tr, zs, step, interpolation=interpolation, shape_k=k_noise,
                         alpha=DETECTION_ALPHA, prior_dof=SIGMA_MODEL["prior_dof"],
                         pertuz=(reliability == "pertuz"), window_px=px, downsample=ds)
        add_relief_terms(fit, step, SIGMA_MODEL)
        fits.append(fit.upsampled((H, W)))
    best_main = trackers[main].best
    best_rank = trackers[main].best_rank
    trackers = None
    idx, sigma, detected = combine(fits, main, step, prefer=SIGMA_MODEL["prefer"])
    pick = idx[None].astype(np.intp)
    height = np.take_along_axis(np.stack([f.height_um for f in fits]), pick, 0)[0]
    if reliability == "pertuz":
        rel = np.take_along_axis(np.stack([f.pertuz_db for f in fits]), pick, 0)[0]
        reliable = rel >= min_reliability_db
    else:
        rel = -20.0 * np.log10(np.clip(sigma, 1e-3, 1e6))
        rel = np.where(detected, rel, np.minimum(rel, 0.0))
        reliable = (detected & (rel >= min_reliability_db)) if min_reliability_db > -np.inf \
            else np.ones((H, W), bool)
    sigma_um = np.where(detected & np.isfinite(sigma), sigma * abs(step), np.nan)
    window_map = np.array([w[0] for w in wins], np.uint8)[idx]
    fits = None
    t3 = time.perf_counter()

    height = height.astype(np.float32)
    h = np.where(reliable, height, np.float32(np.nan)).astype(np.float32)
    if fill:
        h = fill_missing(h, method=fill)
    best_index = order[best_rank].astype(np.int32)
    t_end = time.perf_counter()
    params = {
        "operator": operator, "window_px": int(window_px), "window": window,
        "windows_px": [int(w[0]) for w in wins], "colour": colour,
        "interpolation": interpolation,
        "fit_radius": int(r) if interpolation in ("lsq", "lorentz") else None,
        "reliability": reliability,
        "min_reliability_db": float(min_reliability_db), "fill": fill or None,
        "align": (align if isinstance(align, str) else ("ecc" if align else None)),
        "n_slices": int(n), "shape": [int(H), int(W)], "channels": int(channels),
    }
    if warps is not None:
        params["alignment"] = {"reference": int(ref),
                               "warps": [np.asarray(w_).tolist() for w_ in warps]}
    timings = {"read": t_read, "focus": t_focus, "fit": t3 - t2, "total": t_end - t_start}
    log.info("height from focus: %d slices %dx%d, %.1f%% unreliable (%.1f%% without a focus "
             "peak), %.2f s", n, W, H, 100.0 * (1.0 - reliable.mean()),
             100.0 * (1.0 - detected.mean()), timings["total"])
    return FocusResult(height_um=h, height_fit_um=height, reliability_db=rel.astype(np.float32),
                       reliable=reliable, best_index=best_index, focus_max=best_main,
                       all_in_focus=aif, z_um=z, params=params, timings_s=timings,
                       height_sigma_um=sigma_um.astype(np.float32), detected=detected,
                       window_px_map=window_map)
