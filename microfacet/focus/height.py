"""Height from focus: streaming peak search over one or more focus windows, sub-slice peak
fit, per-pixel height uncertainty, reliability and the all-in-focus composite.

The stack is read **once**, slice by slice in increasing ``z``; per pixel and window only a
fixed number of image-sized buffers is kept (:class:`~microfacet.focus.stream.PeakTracker`),
so peak memory is ``O(H·W)`` whatever the number of slices.

The options are one :class:`~microfacet.focus.options.FocusOptions` (their defaults, valid
values and the measurements behind them are declared there). Method (defaults chosen from the
measurements of ``docs/height-from-focus.md``: the RMSE on the Cou & Guennebaud (2023)
ground-truth stacks and the coverage on rendered stacks of known relief and texture contrast,
``python -m pipelines run accuracy-focus-coverage``):

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

References
----------
.. [1] N. Nagata, M. Kamei, K. Takahashi, K. Tobitani, T. Akagi, S. Yamamura, "Simulation
   Technology for Titanium Oxide Layer Interference Color", Technical Report (the seed paper),
   §3.3.2 (the height map from the focus position of each pixel, Fig. 16).
.. [2] S. K. Nayar, Y. Nakagawa, "Shape from focus", IEEE Trans. Pattern Anal. Mach. Intell.
   16(8) (1994) 824-831, doi:10.1109/34.308479.
.. [3] S. Pertuz, D. Puig, M. A. Garcia, "Analysis of focus measure operators for
   shape-from-focus", Pattern Recognit. 46 (2013), doi:10.1016/j.patcog.2012.11.011.

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
import time
from collections.abc import Callable, Sequence
from concurrent.futures import ThreadPoolExecutor
from contextlib import contextmanager
from dataclasses import dataclass, field

import numpy as np

from ..core.errors import InputError, one_line
from ..core.lazy import load
from ..core.threads import row_chunks
from ..io.limits import check_memory
from .align import estimate_warps, warped_loader
from .fill import fill_missing
from .measures import focus_measures, noise_shape
from .options import FocusOptions
from .peaks import peak_fit
from .slices import SliceSource, slice_source
from .stream import PeakTracker
from .uncertainty import SIGMA_MODEL, WindowFit, add_relief_terms, combine, fit_window

cv2 = load("cv2")

__all__ = ["FocusResult", "check_focus_memory", "height_from_focus", "peak_fit"]

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
        |error| ≤ 2σ for 96-99 % of the reliable pixels there (docs/height-from-focus.md).
        It does not hold off that calibration set: on the randomized synthetic sweep of
        docs/accuracy.md 2σ covers 43-95 % (median 80 %); heights borrowed from texture
        a window away carry a bias σ does not hold, and so does relief smaller than the
        window (the analysis' ``height_sigma_um.npy`` adds
        :func:`~microfacet.focus.uncertainty.height_sigma_with_bias` and
        :func:`~microfacet.focus.uncertainty.unresolved_relief_sigma_um`).
    detected : ndarray of bool, shape (H, W)
        True where at least one window has a significant focus peak (a textureless pixel
        has none: it gets no height, whatever the cut).
    window_px_map : ndarray of uint8, shape (H, W)
        The focus window (px) whose height each pixel took.
    evidence_height_um, evidence_sigma_um : ndarray of float32, shape (H, W), or None
        Height and 1-σ error (µm) of the evidence window (``options.evidence_window_px``),
        NaN where its focus peak is not significant or is below the reliability cut: a
        height from the focus evidence at the pixel itself, for the facet planes. None with
        the window off.
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
    evidence_height_um: np.ndarray | None = None
    evidence_sigma_um: np.ndarray | None = None

    @property
    def unreliable_fraction(self) -> float:
        """Fraction of pixels below the reliability cut."""
        return float(1.0 - self.reliable.mean())


#: Peak memory of ``microfacet height`` ≈ base + per pixel × H × W, set just above what
#: ``/usr/bin/time -f %M`` measured on nd stacks of 16 slices with the 7, 15 and 3 px
#: (evidence) windows: 185 and 368 MiB at 0.26 and 1.05 MP (≈ 124 MiB + 243 B/px); slices
#: are streamed, so their number does not count.
MEMORY_BASE_BYTES = 150 << 20
MEMORY_BYTES_PER_PIXEL = 260


def check_focus_memory(stack) -> None:
    """Refuse, before any work, a stack whose height from focus would not fit in memory."""
    h, w = stack.shape
    check_memory(MEMORY_BASE_BYTES + MEMORY_BYTES_PER_PIXEL * h * w,
                 f"{one_line(stack.path / 'stack.json')}: height from focus of {w}x{h}-pixel "
                 f"slices")


# --------------------------------------------------------------------------------------------
# streaming height from focus


def height_from_focus(source, options: FocusOptions | None = None, *,
                      z_um: Sequence[float] | None = None,
                      progress: Callable[[int, int], None] | None = None,
                      prefetch: bool = True) -> FocusResult:
    """Height map and its uncertainty from a focus stack in one streaming pass.

    Parameters
    ----------
    source : Stack or sequence of ndarray
        A :class:`microfacet.io.stack.Stack`, or images (each (H, W) or (H, W, 3); uint8/uint16
        are scaled to [0, 1]) indexed in the order of ``z_um``. Slices are read one at a time
        in increasing ``z``.
    options : FocusOptions, optional
        Focus measure, windows, peak fit, reliability, fill and alignment
        (:class:`~microfacet.focus.options.FocusOptions`, validated when constructed);
        default ``FocusOptions()``.
    z_um : sequence of float, shape (N,), optional
        Slice heights in µm (required for an image sequence, not allowed with a Stack). Any
        order and spacing, no duplicates.
    progress : callable(done, total), optional
        Called after each slice.
    prefetch : bool
        Decode the next slice in a background thread while the current one is measured.

    Returns
    -------
    FocusResult

    Raises
    ------
    InputError
        A stack without slices or with fewer than 3.
    ValueError
        Images and ``z_um`` that do not fit together.
    """
    t_start = time.perf_counter()
    plan = _plan(slice_source(source, z_um), _checked(options))
    load, alignment = _aligned_loader(plan)
    scan = _scan(plan, load, prefetch=prefetch, progress=progress)
    t2 = time.perf_counter()
    step = float(np.median(np.diff(plan.zs)))
    fits = _fit_windows(plan, scan.trackers, step)
    best_main = scan.trackers[plan.main].best
    best_rank = scan.trackers[plan.main].best_rank
    scan.trackers = None                      # free the streaming buffers before the choice
    evidence = _evidence(plan, fits, step)
    choice = _choose(plan, fits, step)
    fits = None
    t3 = time.perf_counter()

    height = choice.height.astype(np.float32)
    h = np.where(choice.reliable, height, np.float32(np.nan)).astype(np.float32)
    if plan.options.fill:
        h = fill_missing(h, method=plan.options.fill)
    t_end = time.perf_counter()
    timings = {"read": scan.t_read, "focus": scan.t_focus, "fit": t3 - t2,
               "total": t_end - t_start}
    log.info("height from focus: %d slices %dx%d, %.1f%% unreliable (%.1f%% without a focus "
             "peak), %.2f s", plan.slices.n, plan.slices.shape[1], plan.slices.shape[0],
             100.0 * (1.0 - choice.reliable.mean()), 100.0 * (1.0 - choice.detected.mean()),
             timings["total"])
    return FocusResult(height_um=h, height_fit_um=height,
                       reliability_db=choice.reliability_db.astype(np.float32),
                       reliable=choice.reliable,
                       best_index=plan.order[best_rank].astype(np.int32), focus_max=best_main,
                       all_in_focus=scan.all_in_focus, z_um=plan.slices.z_um,
                       params=_params(plan, alignment), timings_s=timings,
                       height_sigma_um=choice.sigma_um.astype(np.float32),
                       detected=choice.detected, window_px_map=choice.window_px_map,
                       evidence_height_um=evidence[0], evidence_sigma_um=evidence[1])


def _precision_db(sigma):
    """``reliability_db`` of a σ in z steps: −20·log10(σ), σ clipped to 1e-3…1e6."""
    return -20.0 * np.log10(np.clip(sigma, 1e-3, 1e6))


def _evidence(plan: _Plan, fits: list[WindowFit], step):
    """Height and σ (µm, float32) of the evidence window where its peak is significant and
    passes the reliability cut (NaN elsewhere); (None, None) without the window."""
    if plan.evidence is None:
        return None, None
    f = fits[plan.evidence]
    sigma = f.sigma.astype(np.float64)
    ok = f.detected & np.isfinite(sigma)
    if plan.options.reliability == "sigma":
        ok &= _precision_db(sigma) >= plan.options.reliability_cut_db
    nan = np.float32(np.nan)
    return (np.where(ok, f.height_um, nan).astype(np.float32),
            np.where(ok, sigma * abs(step), nan).astype(np.float32))


def _checked(options) -> FocusOptions:
    if options is None:
        return FocusOptions()
    if not isinstance(options, FocusOptions):
        raise TypeError(f"options must be a FocusOptions, not {type(options).__name__} "
                        f"(FocusOptions(**...) validates a dict of them)")
    return options


@dataclass(frozen=True)
class _Plan:
    """What one run measures: the slices, their z order, the windows and the options."""

    slices: SliceSource
    order: np.ndarray           # z rank -> file index
    windows: list               # (window_px, window, downsample): the combined ones sorted
    main: int                   # by size, then the evidence window (if any); index of the main
    evidence: int | None        # index of the evidence window (not combined), or None
    options: FocusOptions

    @property
    def zs(self) -> np.ndarray:
        """Slice heights sorted by z."""
        return self.slices.z_um[self.order]


def _plan(slices: SliceSource, options: FocusOptions) -> _Plan:
    if slices.n < 3:
        raise InputError(f"a focus stack needs at least 3 slices, got {slices.n}")
    order = np.argsort(slices.z_um, kind="stable")
    windows, main = _windows(slices.shape, options)
    evidence = None
    if options.evidence_window_px:
        evidence = len(windows)
        windows.append((int(options.evidence_window_px), options.window, 1))
    return _Plan(slices, order, windows, main, evidence, options)


def _windows(shape, o: FocusOptions):
    """(window_px, window, downsample) of every window, sorted by size; index of the main."""
    out = []
    if o.fine_window_px and o.fine_window_px < o.window_px:
        out.append((int(o.fine_window_px), o.window, 1))
    out.append((int(o.window_px), o.window, 1))
    main = len(out) - 1
    if o.coarse_window_px and o.coarse_window_px > o.window_px:
        ds = 2 if o.coarse_window_px >= 11 and min(shape) >= 32 else 1
        out.append((int(o.coarse_window_px), o.window, ds))
    return out, main


def _aligned_loader(plan: _Plan):
    """The slice loader, registered to a reference slice when ``options.align`` asks for it,
    and the alignment's record (None without)."""
    o, src = plan.options, plan.slices
    if o.align is None:
        return src.load, None
    warps, ref = estimate_warps(src.load, plan.order, src.shape, method=o.align,
                                reference=o.reference)
    return warped_loader(src.load, warps, src.shape), {
        "reference": int(ref), "warps": [np.asarray(w).tolist() for w in warps]}


@dataclass
class _Scan:
    """The streaming pass: a tracker per window, the all-in-focus composite, wall times."""

    trackers: list | None
    all_in_focus: np.ndarray
    t_read: float
    t_focus: float


def _scan(plan: _Plan, load, *, prefetch: bool, progress) -> _Scan:
    """Read the slices once in increasing z: focus measures, running peaks, composite."""
    o, (H, W), n = plan.options, plan.slices.shape, plan.slices.n
    trackers = []
    for _, _, ds in plan.windows:       # one set of work planes per grid (pushed in turn)
        trackers.append(PeakTracker(((H + 1) // 2, (W + 1) // 2) if ds == 2 else (H, W),
                                    radius=o.fit_radius_used, n_slices=n,
                                    work_from=trackers[0] if trackers else None))
    composite = _Composite((H, W), plan.slices.channels)
    t_read = t_focus = 0.0
    with _slices_in_z_order(load, plan.order, prefetch) as slices:
        for k, img, t_wait in slices:
            t1 = time.perf_counter()
            # each window's measure computed into its tracker's ring: no copy, no extra map
            fs = focus_measures(img, plan.windows, operator=o.operator, colour=o.colour,
                                out=[tr.next_slot(k) for tr in trackers])
            for tr, f in zip(trackers, fs):
                tr.push(f, k)
            composite.add(fs[plan.main], img)
            t_read += t_wait
            t_focus += time.perf_counter() - t1
            if progress is not None:
                progress(k + 1, n)
    for tr in trackers:
        tr.release_ring()
    return _Scan(trackers, composite.image, t_read, t_focus)


@contextmanager
def _slices_in_z_order(load, order, prefetch: bool):
    """``(rank, slice, seconds waited for it)`` in increasing z; with ``prefetch`` the next
    slice is decoded in a background thread, which is shut down on leaving."""
    pool = ThreadPoolExecutor(max_workers=1) if prefetch else None
    try:
        yield _read_ahead(load, order, pool)
    finally:
        if pool:
            pool.shutdown(wait=True, cancel_futures=True)


def _read_ahead(load, order, pool):
    n = len(order)
    fut = pool.submit(load, int(order[0])) if pool else None
    for k in range(n):
        t0 = time.perf_counter()
        img = fut.result() if pool else load(int(order[k]))
        if pool and k + 1 < n:
            fut = pool.submit(load, int(order[k + 1]))
        yield k, img, time.perf_counter() - t0


class _Composite:
    """All-in-focus image: each pixel from the slice where the main window's focus measure is
    largest so far (undelayed running arg-max)."""

    def __init__(self, shape, channels):
        self.best = np.full(shape, -np.inf, np.float32)
        self.image = np.zeros(tuple(shape) + (3,) if channels == 3 else tuple(shape),
                              np.float32)
        self._mask = np.empty(shape, bool)

    def add(self, f, img):
        np.greater(f, self.best, out=self._mask)
        cv2.max(f, self.best, dst=self.best)
        cv2.copyTo(img, self._mask.view(np.uint8), self.image)


def _fit_windows(plan: _Plan, trackers, step) -> list[WindowFit]:
    """Peak fit, significance and uncertainty of every window, on the full grid."""
    o, zs = plan.options, plan.zs
    fits = []
    for (px, win, ds), tr in zip(plan.windows, trackers):
        k_noise = noise_shape(operator=o.operator, window_px=px, window=win, downsample=ds,
                              colour=o.colour, channels=plan.slices.channels)
        fit = fit_window(tr, zs, step, interpolation=o.interpolation, shape_k=k_noise,
                         pertuz=(o.reliability == "pertuz"), window_px=px, downsample=ds)
        tr.release_curves()          # the next window's fit runs without this one's curves
        add_relief_terms(fit, step, SIGMA_MODEL)
        fits.append(fit.upsampled(plan.slices.shape))
    return fits


@dataclass
class _Choice:
    """Per pixel: the chosen window's height, its reliability and σ."""

    height: np.ndarray
    reliability_db: np.ndarray
    reliable: np.ndarray
    sigma_um: np.ndarray
    detected: np.ndarray
    window_px_map: np.ndarray


def _choose(plan: _Plan, fits: list[WindowFit], step) -> _Choice:
    """Each pixel takes the window with the smallest σ among those with a significant peak;
    its reliability and whether it passes the cut."""
    o = plan.options
    cut = o.reliability_cut_db
    if plan.evidence is not None:
        fits = fits[:plan.evidence]
    idx, sigma, detected = combine(fits, plan.main, step, prefer=SIGMA_MODEL["prefer"])
    # the chosen window's numbers a block of rows at a time (no stack of every window's map)
    height = np.empty(idx.shape, np.result_type(*[f.height_um for f in fits]))
    pertuz = o.reliability == "pertuz"
    rel = np.empty(idx.shape, np.result_type(*[f.pertuz_db for f in fits])) if pertuz \
        else None
    for a, b in row_chunks(idx.shape):
        pick = idx[None, a:b].astype(np.intp)
        height[a:b] = np.take_along_axis(np.stack([f.height_um[a:b] for f in fits]), pick,
                                         0)[0]
        if pertuz:
            rel[a:b] = np.take_along_axis(np.stack([f.pertuz_db[a:b] for f in fits]), pick,
                                          0)[0]
    if pertuz:
        reliable = rel >= cut
    else:
        rel = _precision_db(sigma)
        rel = np.where(detected, rel, np.minimum(rel, 0.0))
        reliable = (detected & (rel >= cut)) if cut > -np.inf \
            else np.ones(plan.slices.shape, bool)
    sigma_um = np.where(detected & np.isfinite(sigma), sigma * abs(step), np.nan)
    window_map = np.array([w[0] for w in plan.windows], np.uint8)[idx]
    return _Choice(height, rel, reliable, sigma_um, detected, window_map)


def _params(plan: _Plan, alignment: dict | None) -> dict:
    """``FocusResult.params``: the options used, the windows and the stack's size."""
    o, src = plan.options, plan.slices
    H, W = src.shape
    params = {
        "operator": o.operator, "window_px": int(o.window_px), "window": o.window,
        "windows_px": [int(w[0]) for w in plan.windows[:plan.evidence]],
        "evidence_window_px": int(o.evidence_window_px), "colour": o.colour,
        "interpolation": o.interpolation,
        "fit_radius": o.fit_radius_used if o.interpolation in ("lsq", "lorentz") else None,
        "reliability": o.reliability, "min_reliability_db": o.reliability_cut_db,
        "fill": o.fill, "align": o.align,
        "n_slices": int(src.n), "shape": [int(H), int(W)], "channels": int(src.channels),
    }
    if alignment is not None:
        params["alignment"] = alignment
    return params
