"""Oxide thickness per region of interest, and the global exposure (seed §3.3.3 step 2).

For each region of interest (ROI; the seed used 255 px squares) and each candidate
thickness d on a global grid, every unmasked pixel's colour is modelled from its tilt
(from the height map) as the thin-film colour at incidence = tilt, and compared with the
image by CIEDE2000; the ROI's thickness is the d of least mean ΔE, refined below the grid
step. Interference colours repeat with order, so the search is global and the result
reports the gap to the best *other* local minimum (``ambiguity_delta_e``): a small gap
means the order is uncertain.

Interference order
------------------
ROIs that span several thickness regions fit no single thickness well, and a free exposure
makes the orders nearly equally good. The order is therefore chosen first, for all ROIs
together and independently of the exposure: in CIELAB's cube-root regime an exposure
scales L*, a*, b* together, so comparing the model's Lab rescaled to each pixel's L* with
the pixel (hue and chroma only) is exposure-invariant. Each pixel may take its own
thickness inside a candidate band of ±35 nm (ROIs span several thickness regions); the band
whose mean per-pixel best invariant ΔE is least is the sample's order. Each ROI then takes
its best minimum in it unless one outside is better by more than 2 ΔE00. The exposure is
fitted the same way: each pixel at its best thickness in the band, median over pixels.

Exposure
--------
Image brightness is not calibrated: the model's XYZ are scaled by one global exposure
``e`` before the comparison. When it is not given, ``e`` is chosen to minimise the mean
over ROIs of the best *median* ΔE (a log-spaced scan over 0.25-4, then a bounded
refinement), on a random sample of pixels per ROI, before the per-ROI fits. The median
keeps partly shadowed pixels (facet boundaries, grooves: right hue, too dark) from pulling
the exposure down.

That reading assumes one order band holds every population. Where populations lie in
different orders (38 and 150 nm on one ROI), the far one is forced into the band and the
exposure follows it (0.31 for a true 0.99 on the generalization sweep). The joint mode
therefore takes a second reading that frees the order (:func:`block_exposure_reading`):
the image cut into blocks of ``exposure_block_px`` (4 px), each block's mean colour at its
best thickness over the whole range, the median over :data:`EXPOSURE_BLOCKS` random blocks
minimised the same way. A block's mean has a quarter of a pixel's noise, so it cannot chase
noise into another order as single pixels do; but with an unbalanced camera a thin film can
fit another order at another exposure, which the band's hue and chroma reject. Neither
reading is right everywhere, so where they differ by more than 5 % both are carried to the
facets, and the one whose facets fit best is kept (:mod:`.joint`).

References
----------
.. [1] N. Nagata, M. Kamei, K. Takahashi, K. Tobitani, T. Akagi, S. Yamamura, "Simulation
   Technology for Titanium Oxide Layer Interference Color", Technical Report (the seed paper),
   §3.3.3 (2) (thickness per ROI of least mean ΔE).
.. [2] G. Sharma, W. Wu, E. N. Dalal, "The CIEDE2000 color-difference formula: implementation
   notes, supplementary test data, and mathematical observations", Color Res. Appl. 30 (2005)
   21-30, doi:10.1002/col.20070.
"""

from __future__ import annotations

import logging
import math
from dataclasses import dataclass, field

import numpy as np

from ..core.lazy import load
from ..core.threads import BLOCK_VALUES, chunks, thread_map
from .options import RoiOptions
from .search import local_minima, parabola

ndimage = load("scipy.ndimage")
optimize = load("scipy.optimize")

__all__ = ["RoiFit", "block_exposure_reading", "fit_roi_thickness", "roi_grid",
           "thickness_per_roi"]

log = logging.getLogger(__name__)

#: The exposure scan: log-spaced over this range, then a bounded refinement to this
#: tolerance in log exposure.
EXPOSURE_SCAN = (0.25, 4.0, 25)
EXPOSURE_XATOL = 0.003
#: The scan's local minima refined (the lowest first).
EXPOSURE_STARTS = 4
#: Blocks of the second exposure reading (a random sample of the usable ones).
EXPOSURE_BLOCKS = 256
#: Exposure readings closer than this relative difference are one reading.
EXPOSURE_DISTINCT = 0.05


def _starts(n, size, stride):
    if n <= size:
        return [0], n
    if stride == size:  # equal, non-overlapping tiles of about `size` covering the axis
        count = max(1, int(round(n / size)))
        s = n // count
        return [i * s for i in range(count - 1)] + [n - s], s
    starts = list(range(0, n - size + 1, stride))
    if starts[-1] + size < n:
        starts.append(n - size)
    return starts, size


def roi_grid(shape, *, size_px, stride_px=None):
    """Square regions of interest tiling an image.

    Parameters
    ----------
    shape : (int, int)
        Image height and width.
    size_px : int
        ROI side (the seed's 255 px: :class:`~.options.RoiOptions`). An image smaller
        than that gives one ROI of the image's size along that axis.
    stride_px : int, optional
        Step between ROI origins. By default (``size_px``) the axis is cut into
        ``round(n / size_px)`` equal tiles (the last absorbs the remainder's rounding), so
        ROIs do not overlap and stay within a factor 1.5 of ``size_px``. With a smaller
        stride the last ROI on each axis is shifted to end at the image edge.

    Returns
    -------
    rows, cols : list of int
        ROI origins along each axis (the ROIs are their product).
    size : (int, int)
        ROI height and width.

    Examples
    --------
    >>> roi_grid((600, 300), size_px=255)
    ([0, 300], [0], (300, 300))
    >>> roi_grid((600, 300), size_px=255, stride_px=200)
    ([0, 200, 345], [0, 45], (255, 255))
    """
    h, w = (int(v) for v in shape)
    size_px = int(size_px)
    if size_px < 8:
        raise ValueError(f"size_px: must be >= 8, got {size_px}")
    stride_px = size_px if stride_px is None else int(stride_px)
    if not 1 <= stride_px <= size_px:
        raise ValueError(f"stride_px: must be in [1, size_px], got {stride_px}")
    rows, sh = _starts(h, size_px, stride_px)
    cols, sw = _starts(w, size_px, stride_px)
    return rows, cols, (sh, sw)


def nearest_roi_index(shape, rows, cols, size):
    """For every pixel, the (row, col) index of the ROI whose centre is nearest.

    Returns
    -------
    ri, ci : ndarray of int, shape (H,) and (W,)
        ROI row index per image row and ROI column index per image column (the grid is a
        product, so nearest centres separate by axis).
    """
    def axis(n, starts, s):
        centres = np.asarray(starts, dtype=np.float64) + (s - 1) / 2.0
        x = np.arange(n, dtype=np.float64)
        return np.abs(x[:, None] - centres[None, :]).argmin(axis=1)

    return axis(shape[0], rows, size[0]), axis(shape[1], cols, size[1])


@dataclass
class RoiFit:
    """Per-ROI thickness results (arrays of length = number of ROIs, row-major).

    Attributes
    ----------
    row0, col0 : ndarray of int
    height_px, width_px : int
    thickness_nm : ndarray
        Best thickness (NaN where the ROI has too few unmasked pixels).
    mean_delta_e : ndarray
        Mean ΔE of the ROI's unmasked pixels at the best thickness.
    runner_up_thickness_nm, runner_up_delta_e : ndarray
        The best other local minimum of the mean-ΔE curve.
    n_pixels : ndarray of int
        Unmasked pixels used.
    exposure : float
    exposure_estimated : bool
    exposure_alternative : float or None
        The joint mode's second exposure reading where it differs from ``exposure`` by more
        than :data:`EXPOSURE_DISTINCT` (:func:`block_exposure_reading`); the facets decide
        between them (:func:`~.joint.facets_at_exposure_readings`).
    grid_nm : ndarray
        The global thickness grid of the scan.
    curves : ndarray, shape (n_roi, n_grid)
        Mean ΔE of the pixel sample of each ROI along the grid.
    rows, cols : list of int
        ROI origins along each axis (the ROIs are their product, row-major).
    """

    row0: np.ndarray
    col0: np.ndarray
    height_px: int
    width_px: int
    thickness_nm: np.ndarray
    mean_delta_e: np.ndarray
    runner_up_thickness_nm: np.ndarray
    runner_up_delta_e: np.ndarray
    n_pixels: np.ndarray
    exposure: float = 1.0
    exposure_estimated: bool = False
    exposure_alternative: float | None = None
    grid_nm: np.ndarray = field(default_factory=lambda: np.zeros(0))
    curves: np.ndarray = field(default_factory=lambda: np.zeros((0, 0)))
    rows: list = field(default_factory=list)
    cols: list = field(default_factory=list)

    @property
    def ambiguity_delta_e(self) -> np.ndarray:
        """``runner_up_delta_e − mean_delta_e`` (small: the interference order is uncertain)."""
        return self.runner_up_delta_e - self.mean_delta_e

    def pixel_stats(self, thickness_nm) -> tuple[np.ndarray, np.ndarray]:
        """Mean and SD (nm) of the finite per-pixel thicknesses inside each ROI's window.

        The single least-ΔE fit (:attr:`thickness_nm`) of a ROI mixing populations is no
        summary of it; these are (NaN for a ROI without pixels).

        >>> z = np.zeros(1)
        >>> r = RoiFit(np.array([0]), np.array([0]), 2, 2, z, z, z, z, np.zeros(1, int))
        >>> [round(float(v[0]), 3) for v in r.pixel_stats([[100.0, 110.0], [np.nan, 120.0]])]
        [110.0, 8.165]
        """
        mean = np.full(self.row0.size, np.nan)
        sd = np.full(self.row0.size, np.nan)
        for i, v in self.pixel_values(thickness_nm):
            mean[i], sd[i] = v.mean(), v.std()
        return mean, sd

    def pixel_values(self, thickness_nm):
        """``(index, values)`` for every ROI with finite per-pixel thicknesses in its window
        (flat float64 arrays)."""
        d = np.asarray(thickness_nm, dtype=np.float64)
        for i, (r0, c0) in enumerate(zip(self.row0, self.col0)):
            v = d[r0:r0 + self.height_px, c0:c0 + self.width_px]
            v = v[np.isfinite(v)]
            if v.size:
                yield i, v

    def index_map(self, shape) -> np.ndarray:
        """For every pixel of an image of ``shape``, the index of the ROI whose centre is
        nearest (int, H×W)."""
        ri, ci = nearest_roi_index(shape, self.rows, self.cols, (self.height_px, self.width_px))
        return ri[:, None] * len(self.cols) + ci[None, :]


@dataclass
class _Sample:
    """One ROI's pixels: the model XYZ of a random sample along the grid (exposure 1), its
    Lab, and every usable pixel's coordinates."""

    xyz: np.ndarray
    lab: np.ndarray
    yy: np.ndarray
    xx: np.ndarray


def _curve(model, xyz, lab):
    """Mean ΔE over a sample for every grid thickness: xyz (n, D, 3), lab (n, 3) → (D,)."""
    return model.difference(model.lab_from_xyz(xyz), lab[:, None, :]).mean(axis=0)


def _band_curve(model, xyz, lab, grid, half_width_nm, *, invariant):
    """Band score: mean over pixels of each pixel's best ΔE within ±half_width of d.

    Each pixel may take its own thickness inside the band (ROIs span several thickness
    regions). ``invariant``: the model's Lab is rescaled to each pixel's L* (at exposure 1):
    in CIELAB's cube-root regime an exposure e scales L*, a*, b* together by e^(1/3), so this
    compares hue and chroma only, whatever the exposure.
    """
    if invariant:
        m = model.with_exposure(1.0).lab_from_xyz(xyz)
        m = m * (lab[:, None, 0:1] / np.maximum(m[..., 0:1], 1e-3))
    else:
        m = model.lab_from_xyz(xyz)
    de = model.difference(m, lab[:, None, :])
    step = grid[1] - grid[0] if grid.size > 1 else 1.0
    k = max(1, int(round(half_width_nm / step)))
    return ndimage.minimum_filter1d(de, size=2 * k + 1, axis=1, mode="nearest").mean(axis=0)


def _samples(lab, tilt, usable, rois, model, grid, options, rng):
    """Per ROI (row-major) a :class:`_Sample`, or None with fewer than ``min_pixels``."""
    rows, cols, (rh, rw) = rois
    drawn = []                  # the random samples in ROI order, then the model on threads
    for r0 in rows:
        for c0 in cols:
            yy, xx = np.nonzero(usable[r0:r0 + rh, c0:c0 + rw])
            yy, xx = yy + r0, xx + c0
            drawn.append(None if yy.size < options.min_pixels else (yy, xx, rng.choice(
                yy.size, min(options.sample_px, yy.size), replace=False)))

    def sample(d):
        if d is None:
            return None
        yy, xx, pick = d
        ys, xs = yy[pick], xx[pick]
        xyz = model.xyz(tilt[ys, xs][:, None], grid[None, :]).astype(np.float32)
        return _Sample(xyz, lab[ys, xs], yy, xx)

    return thread_map(sample, drawn)


def _order_band(valid, model, grid, options):
    """The interference order, from hue and chroma alone (before the exposure is known): the
    band of ±``consensus_half_width_nm`` whose ROIs' mean best in-band ΔE is least."""
    hw = options.consensus_half_width_nm
    if hw <= 0 or not valid or grid.size <= 2:
        return None
    n = options.consensus_px
    score = np.mean(thread_map(lambda s: _band_curve(model, s.xyz[:n], s.lab[:n], grid, hw,
                                                     invariant=True), valid), axis=0)
    centre = float(grid[int(np.argmin(score))])
    log.info("interference-order consensus (exposure-invariant): %.1f-%.1f nm",
             centre - hw, centre + hw)
    return centre - hw, centre + hw


def _estimate_exposure(valid, model, grid, band, options):
    """Exposure minimising the ROIs' mean best median ΔE (within the order band, if any)."""
    n = options.consensus_px
    sub = [(s.xyz[:n], s.lab[:n]) for s in valid]
    inside = (np.ones(grid.size, bool) if band is None
              else (grid >= band[0]) & (grid <= band[1]))
    # the ROIs in groups of about BLOCK_VALUES colour pairs, a group per ΔE call, on the
    # threads (the values, medians and their mean are those of one ROI at a time)
    per_roi = max(1, n * int(inside.sum()))
    groups = [sub[a:b] for a, b in chunks(len(sub), BLOCK_VALUES // per_roi)]

    def medians(group, m):
        x = np.concatenate([x[:, inside] for x, _ in group])
        lab_s = np.concatenate([lab_s for _, lab_s in group])
        best = model.difference(m.lab_from_xyz(x), lab_s[:, None, :]).min(axis=1)
        return [np.median(b) for b in np.split(best, np.cumsum([len(v) for v, _ in group])[:-1])]

    def objective(log_e):
        # Each pixel at its best thickness in the band; the median over pixels (robust to
        # partly shadowed pixels), averaged over ROIs.
        m = model.with_exposure(math.exp(log_e))
        return float(np.mean([v for part in thread_map(lambda g: medians(g, m), groups)
                              for v in part]))

    return _scan_exposure(objective)


def _inputs(lab, tilt_deg, mask, model, options: RoiOptions):
    """Lab (float32), the tilt clipped to the table's range, the usable pixels (unmasked,
    with a tilt and a colour) and the global thickness grid."""
    lab = np.asarray(lab, dtype=np.float32)
    tilt = np.asarray(tilt_deg, dtype=np.float64)
    t_lo, t_hi = model.theta_range_deg
    usable = ~np.asarray(mask, bool) & np.isfinite(tilt) & np.all(np.isfinite(lab), axis=-1)
    tilt = np.clip(np.where(np.isfinite(tilt), tilt, t_lo), t_lo, t_hi)
    d_lo, d_hi = model.thickness_range_nm
    return lab, tilt, usable, np.arange(d_lo, d_hi + 1e-9, options.grid_step_nm)


def block_exposure_reading(colour, tilt_deg, model, options: RoiOptions, *, exposure,
                           seed=0) -> float | None:
    """The second exposure reading of the module notes, where it differs from the first.

    Parameters
    ----------
    colour : ColourImage
        Lab and mask of the image.
    tilt_deg : ndarray (H, W)
        Tilt per pixel from the height map.
    model : FilmColourModel
    options : RoiOptions
        ``exposure_block_px`` and the thickness grid.
    exposure : float
        The first reading (the order band's, :func:`fit_roi_thickness`).
    seed : int
        The blocks' random sample.

    Returns
    -------
    float or None
        None where it is within :data:`EXPOSURE_DISTINCT` of ``exposure`` or the image has
        fewer than 16 usable blocks.
    """
    lab, tilt, usable, grid = _inputs(colour.lab, tilt_deg, colour.mask.mask, model, options)
    other = _block_exposure(_Image(lab, tilt, grid, None), usable, model, options,
                            np.random.default_rng([seed, 1]))
    if other is None or abs(other / exposure - 1.0) <= EXPOSURE_DISTINCT:
        return None
    log.info("second exposure reading (blocks, each at its own order) %.4f", other)
    return other


def _scan_exposure(objective) -> float:
    """The exposure minimising ``objective(log e)``: a log-spaced scan over
    :data:`EXPOSURE_SCAN`, then a bounded refinement about each of its
    :data:`EXPOSURE_STARTS` lowest local minima, the least refined one kept.

    One start at the best node is not enough: a film's ΔE rises by ~1 ΔE00 per 6 % of
    exposure, so a basin narrower than the scan's 12 % step can lie between two nodes that
    both read higher than another basin's node (a one-colour scene of the generalization
    sweep: its true exposure, 0.94 at 86 nm with median ΔE00 0.61, between two nodes that
    read 1.27 and 1.55 ΔE00, lost to 1.59 at 394 nm, 0.85). NaN values of the scan are
    ignored (the least node of a scan with none finite is returned)."""
    lo, hi, count = EXPOSURE_SCAN
    log_grid = np.linspace(math.log(lo), math.log(hi), count)
    vals = np.array([objective(g) for g in log_grid])
    starts = local_minima(vals)
    if starts.size == 0:
        return float(math.exp(log_grid[int(np.argmin(vals))]))
    best_x, best_f = log_grid[starts[0]], float(vals[starts[0]])
    for i in starts[:EXPOSURE_STARTS]:
        a, b = log_grid[max(i - 1, 0)], log_grid[min(i + 1, log_grid.size - 1)]
        opt = optimize.minimize_scalar(objective, bounds=(a, b), method="bounded",
                                       options={"xatol": EXPOSURE_XATOL})
        if opt.fun < best_f:
            best_x, best_f = float(opt.x), float(opt.fun)
    return float(math.exp(best_x))


def _block_exposure(img: "_Image", usable, model, options, rng) -> float | None:
    """The second exposure reading: the exposure minimising the median over blocks of
    ``exposure_block_px`` of each block's best ΔE over the whole thickness range (its mean
    Lab at its mean tilt; blocks with at least 3/4 of their pixels usable, at most
    :data:`EXPOSURE_BLOCKS` of them). None with fewer than 16 such blocks."""
    b = options.exposure_block_px
    hb, wb = usable.shape[0] // b, usable.shape[1] // b

    def block_sum(a):
        a = a[:hb * b, :wb * b]
        return a.reshape(hb, b, wb, b, *a.shape[2:]).sum(axis=(1, 3)).reshape(hb * wb, -1)

    n = block_sum(usable.astype(np.float32))[:, 0]
    ok = np.flatnonzero(n >= 0.75 * b * b)
    if ok.size < 16:
        return None
    pick = rng.choice(ok, min(EXPOSURE_BLOCKS, ok.size), replace=False)
    lab = (block_sum(np.where(usable[..., None], img.lab, np.float32(0)))[pick]
           / n[pick, None]).astype(np.float32)
    tilt = block_sum(np.where(usable, img.tilt, 0.0))[pick, 0] / n[pick]
    xyz = model.xyz(tilt[:, None], img.grid[None, :]).astype(np.float32)

    def objective(log_e):
        m = model.with_exposure(math.exp(log_e))
        return float(np.median(model.difference(m.lab_from_xyz(xyz), lab[:, None, :])
                               .min(axis=1)))

    return _scan_exposure(objective)


def _candidate_minima(curve, grid, band, margin_de):
    """The curve's local minima, best first; inside the order band first unless one outside
    is better by more than ``margin_de``. Returns the minima and whether the band chose."""
    minima = local_minima(curve)
    if band is None or not minima.size:
        return minima, False
    inside = minima[(grid[minima] >= band[0]) & (grid[minima] <= band[1])]
    if inside.size and curve[minima[0]] >= curve[inside[0]] - margin_de:
        return np.concatenate([inside[:1], minima[minima != inside[0]]]), True
    return minima, False


def _refine_minimum(curve_at, centre, step_nm, limits):
    """A minimum of the mean-ΔE curve below the grid step: ±1 grid step at 0.25 nm, then
    ±0.25 nm at 0.05 nm about the best (the mean ΔE over thousands of pixels is smooth at
    that scale: 20 evaluations, not 41), then a parabola. Returns the thickness."""
    lo, hi = limits
    nodes = np.arange(centre - step_nm, centre + step_nm + 1e-9, 0.25)
    nodes = nodes[(nodes >= lo) & (nodes <= hi)]
    mid = float(np.clip(centre, lo, hi)) if nodes.size == 0 else float(
        nodes[int(np.argmin(curve_at(nodes)))])
    fine = np.arange(mid - 0.25, mid + 0.25 + 1e-9, 0.05)
    fine = fine[(fine >= lo) & (fine <= hi)]
    c = curve_at(fine)
    k = int(np.argmin(c))
    if 0 < k < len(c) - 1:
        off, _, _ = parabola(c[k - 1], c[k], c[k + 1])
        return float(fine[k] + float(off) * (fine[1] - fine[0]))
    return float(fine[k])


@dataclass
class _Image:
    """What every ROI's refinement reads: the image's Lab and tilt, the global thickness
    grid and the interference-order band (None: no consensus)."""

    lab: np.ndarray
    tilt: np.ndarray
    grid: np.ndarray
    band: tuple | None


def _fit_one(s, curve, img: _Image, model, options, pick):
    """The two best minima of one ROI refined on a larger sample (its pixels ``pick``):
    ((ΔE, d), (ΔE, d))."""
    minima, by_band = _candidate_minima(curve, img.grid, img.band, options.order_margin_de)
    yr, xr = s.yy[pick], s.xx[pick]
    t_r, lab_r = img.tilt[yr, xr], img.lab[yr, xr]

    def curve_at(d):
        return _curve(model, model.xyz(t_r[:, None], d[None, :]).astype(np.float32), lab_r)

    res = []
    for j in minima[:2]:
        d = _refine_minimum(curve_at, float(img.grid[j]), options.grid_step_nm,
                            model.thickness_range_nm)
        de = float(_curve(model, model.xyz(t_r, d)[:, None, :].astype(np.float32), lab_r)[0])
        res.append((de, d))
    if not by_band:
        res.sort()
    return res + [(np.nan, np.nan)] * (2 - len(res))


def fit_roi_thickness(lab, tilt_deg, mask, model, options: RoiOptions, *, rois, exposure=None,
                      seed=0) -> RoiFit:
    """Thickness of least mean ΔE per ROI, and the exposure if not given.

    Parameters
    ----------
    lab : ndarray, shape (H, W, 3)
        CIELAB of the image (relative to the illuminant white).
    tilt_deg : ndarray, shape (H, W)
        Facet tilt per pixel from the height map (NaN = unknown: pixel not used).
    mask : ndarray of bool, shape (H, W)
        True where the pixel carries no colour information.
    model : FilmColourModel
        The film colour (its table must cover the tilts and the thickness range to search);
        its exposure is not used.
    options : RoiOptions
        The grid step, pixel samples and the interference-order consensus (see the module
        notes and the fields' help).
    rois : tuple
        ``(rows, cols, (h, w))`` from :func:`roi_grid`.
    exposure : float, optional
        Known exposure; estimated when None.
    seed : int
        Random pixel samples.

    Returns
    -------
    RoiFit
    """
    lab, tilt, usable, grid = _inputs(lab, tilt_deg, mask, model, options)
    rng = np.random.default_rng(seed)
    samples = _samples(lab, tilt, usable, rois, model, grid, options, rng)
    valid = [s for s in samples if s is not None]
    band = _order_band(valid, model, grid, options)
    estimated = exposure is None
    if estimated:
        exposure = _estimate_exposure(valid, model, grid, band, options) if valid else 1.0
        log.info("estimated exposure %.4f", exposure)
    model = model.with_exposure(exposure)
    n = len(samples)
    curves = np.full((n, grid.size), np.nan, dtype=np.float32)
    best = np.full((n, 2, 2), np.nan)
    npx = np.zeros(n, dtype=np.int64)
    img = _Image(lab, tilt, grid, band)
    # the refinement's pixel samples drawn in ROI order, then the ROIs on the threads
    picks = [None if s is None else rng.choice(s.yy.size, min(options.refine_px, s.yy.size),
                                               replace=False) for s in samples]

    def fit(i):
        s = samples[i]
        if s is not None:
            curves[i] = _curve(model, s.xyz, s.lab)
            npx[i] = s.yy.size
            best[i] = _fit_one(s, curves[i], img, model, options, picks[i])

    thread_map(fit, range(n))
    rows, cols, (rh, rw) = rois
    return RoiFit(row0=np.repeat(np.asarray(rows), len(cols)),
                  col0=np.tile(np.asarray(cols), len(rows)), height_px=rh, width_px=rw,
                  thickness_nm=best[:, 0, 1], mean_delta_e=best[:, 0, 0],
                  runner_up_thickness_nm=best[:, 1, 1], runner_up_delta_e=best[:, 1, 0],
                  n_pixels=npx, exposure=float(exposure), exposure_estimated=estimated,
                  grid_nm=grid, curves=curves, rows=list(rows), cols=list(cols))


def thickness_per_roi(colour, tilt_deg, model, options: RoiOptions, *, exposure=None,
                      seed=0) -> RoiFit:
    """The ROI stage: a grid of ROIs over the image and :func:`fit_roi_thickness` on it.

    Parameters
    ----------
    colour : ColourImage
        Lab and mask of the image (:func:`~microfacet.analysis.colour_image.measure_colour`).
    tilt_deg : ndarray (H, W)
        Tilt per pixel from the height map.
    model : FilmColourModel
    options : RoiOptions
    exposure, seed
        See :func:`fit_roi_thickness`.
    """
    rois = roi_grid(colour.lab.shape[:2], size_px=options.size_px, stride_px=options.stride_px)
    return fit_roi_thickness(colour.lab, tilt_deg, colour.mask.mask, model, options, rois=rois,
                             exposure=exposure, seed=seed)
