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
"""

from __future__ import annotations

import logging
import math
from dataclasses import dataclass, field

import numpy as np

from ..colour.colorimetry import xyz_to_lab
from ..colour.difference import delta_e
from ..core.lazy import load

ndimage = load("scipy.ndimage")
optimize = load("scipy.optimize")

__all__ = ["RoiFit", "fit_roi_thickness", "nearest_roi_index", "roi_grid", "thickness_per_roi"]

log = logging.getLogger(__name__)


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


def roi_grid(shape, *, size_px=255, stride_px=None):
    """Square regions of interest tiling an image.

    Parameters
    ----------
    shape : (int, int)
        Image height and width.
    size_px : int
        ROI side (the seed's 255 px). An image smaller than that gives one ROI of the
        image's size along that axis.
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
        Mean ΔE00 of the ROI's unmasked pixels at the best thickness.
    runner_up_thickness_nm, runner_up_delta_e : ndarray
        The best other local minimum of the mean-ΔE curve.
    ambiguity_delta_e : ndarray
        ``runner_up_delta_e − mean_delta_e`` (small: the interference order is uncertain).
    n_pixels : ndarray of int
        Unmasked pixels used.
    exposure : float
    exposure_estimated : bool
    grid_nm : ndarray
        The global thickness grid of the scan.
    curves : ndarray, shape (n_roi, n_grid)
        Mean ΔE00 of the pixel sample of each ROI along the grid.
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
    ambiguity_delta_e: np.ndarray
    n_pixels: np.ndarray
    exposure: float
    exposure_estimated: bool
    grid_nm: np.ndarray
    curves: np.ndarray
    rows: list = field(default_factory=list)
    cols: list = field(default_factory=list)

    def pixel_stats(self, thickness_nm) -> tuple[np.ndarray, np.ndarray]:
        """Mean and SD (nm) of the finite per-pixel thicknesses inside each ROI's window.

        The single least-ΔE fit (:attr:`thickness_nm`) of a ROI mixing populations is no
        summary of it; these are (NaN for a ROI without pixels).

        >>> r = RoiFit(np.array([0]), np.array([0]), 2, 2, *[np.zeros(1)] * 5,
        ...            np.zeros(1, int), 1.0, False, np.zeros(1), np.zeros((1, 1)))
        >>> [round(float(v[0]), 3) for v in r.pixel_stats([[100.0, 110.0], [np.nan, 120.0]])]
        [110.0, 8.165]
        """
        d = np.asarray(thickness_nm, dtype=np.float64)
        mean = np.full(self.row0.size, np.nan)
        sd = np.full(self.row0.size, np.nan)
        for i, (r0, c0) in enumerate(zip(self.row0, self.col0)):
            v = d[r0:r0 + self.height_px, c0:c0 + self.width_px]
            v = v[np.isfinite(v)]
            if v.size:
                mean[i], sd[i] = v.mean(), v.std()
        return mean, sd

    def index_map(self, shape) -> np.ndarray:
        """For every pixel of an image of ``shape``, the index of the ROI whose centre is
        nearest (int, H×W)."""
        ri, ci = nearest_roi_index(shape, self.rows, self.cols, (self.height_px, self.width_px))
        return ri[:, None] * len(self.cols) + ci[None, :]


def _model_lab(xyz, exposure, white):
    return xyz_to_lab((xyz * exposure).astype(np.float32),
                            white=white.astype(np.float32))


def _curve(xyz_s, lab_s, exposure, white, method):
    """Mean ΔE00 over the sample for every grid thickness: xyz_s (n, D, 3), lab_s (n, 3) → (D,)."""
    de = delta_e(_model_lab(xyz_s, exposure, white), lab_s[:, None, :], method=method)
    return de.mean(axis=0)


def _band_curve(xyz_s, lab_s, white, grid, half_width_nm, exposure=None, method="CIEDE2000"):
    """Band score: mean over pixels of each pixel's best ΔE00 within ±half_width of d.

    Each pixel may take its own thickness inside the band (ROIs span several thickness
    regions). With ``exposure=None`` the model's Lab is rescaled to each pixel's L*: in
    CIELAB's cube-root regime an exposure e scales L*, a*, b* together by e^(1/3), so this
    compares hue and chroma only, whatever the exposure.
    """
    if exposure is None:
        model = _model_lab(xyz_s, 1.0, white)
        model = model * (lab_s[:, None, 0:1] / np.maximum(model[..., 0:1], 1e-3))
    else:
        model = _model_lab(xyz_s, exposure, white)
    de = delta_e(model, lab_s[:, None, :], method=method)
    step = grid[1] - grid[0] if grid.size > 1 else 1.0
    k = max(1, int(round(half_width_nm / step)))
    return ndimage.minimum_filter1d(de, size=2 * k + 1, axis=1, mode="nearest").mean(axis=0)


def _local_minima(curve):
    c = np.where(np.isfinite(curve), curve, np.inf)
    padded = np.concatenate([[np.inf], c, [np.inf]])
    is_min = (padded[1:-1] <= padded[:-2]) & (padded[1:-1] < padded[2:])
    idx = np.flatnonzero(is_min & np.isfinite(c))
    return idx[np.argsort(c[idx])]


def _fine_minimum(curve_at, centre, half_width, lo, hi, step):
    """The node of least ``curve_at`` on a ``step`` grid within ±``half_width`` of
    ``centre`` (clipped to [lo, hi])."""
    nodes = np.arange(centre - half_width, centre + half_width + 1e-9, step)
    nodes = nodes[(nodes >= lo) & (nodes <= hi)]
    if nodes.size == 0:
        return float(np.clip(centre, lo, hi))
    return float(nodes[int(np.argmin(curve_at(nodes)))])


def _parabola(x, y, i):
    """Vertex of the parabola through (i-1, i, i+1) of a uniform grid, clamped to ±1 step."""
    if i <= 0 or i >= len(y) - 1:
        return float(x[i])
    y0, y1, y2 = y[i - 1], y[i], y[i + 1]
    den = y0 - 2 * y1 + y2
    off = 0.5 * (y0 - y2) / den if den > 0 else 0.0
    return float(x[i] + np.clip(off, -1, 1) * (x[1] - x[0]))


def fit_roi_thickness(lab, tilt_deg, mask, table, *, rois, exposure=None,
                      grid_step_nm=1.0, sample_px=256, refine_px=8000, min_pixels=20,
                      consensus_half_width_nm=35.0, order_margin_de=2.0,
                      seed=0, delta_e_method="CIEDE2000") -> RoiFit:
    """Thickness of least mean ΔE00 per ROI, and the exposure if not given.

    Parameters
    ----------
    lab : ndarray, shape (H, W, 3)
        CIELAB of the image (relative to the illuminant white).
    tilt_deg : ndarray, shape (H, W)
        Facet tilt per pixel from the height map (NaN = unknown: pixel not used).
    mask : ndarray of bool, shape (H, W)
        True where the pixel carries no colour information.
    table : microfacet.colour.table.ColourTable
        Must cover the tilts and the thickness range to search.
    rois : tuple
        ``(rows, cols, (h, w))`` from :func:`roi_grid`.
    exposure : float, optional
        Known exposure; estimated when None.
    grid_step_nm : float
        Step of the global thickness scan (the minima are ≥ 20 nm apart). The time is set
        by ``refine_px``; a coarser scan is slower, not faster (docs/speed-vs-error.md §3a).
    sample_px, refine_px : int
        Pixels per ROI used for the global scan / for the refinement. The order consensus
        uses 128 of them. More does not make the order choice robust: at 12-15 % image
        noise a different 1 of 42 synthetic stacks gets the wrong order with 128 and with
        512, always flagged (``ambiguity_delta_e`` < 1), and 512 made mixed-population ROIs
        worse (docs/accuracy.md).
    min_pixels : int
        ROIs with fewer unmasked pixels get NaN.
    consensus_half_width_nm, order_margin_de : float
        Interference-order consensus: the band of ±``consensus_half_width_nm`` (less than
        half the ~110 nm spacing of the orders) that minimises the ROIs' summed best mean ΔE
        within it is the sample's order; each ROI takes its best minimum inside the band,
        unless a minimum outside is better by more than ``order_margin_de`` (a sample that
        really spans two orders). 0 disables the consensus.
    delta_e_method : {"CIEDE2000", "CIE94", "CIE76"}
        Colour-difference formula (:func:`microfacet.colour.difference.delta_e`); the seed
        and the defaults use CIEDE2000 (docs/speed-vs-error.md compares the others).

    Returns
    -------
    RoiFit
    """
    rows, cols, (rh, rw) = rois
    lab = np.asarray(lab, dtype=np.float32)
    tilt = np.asarray(tilt_deg, dtype=np.float64)
    t_lo, t_hi = float(table.theta_deg[0]), float(table.theta_deg[-1])
    usable = ~np.asarray(mask, bool) & np.isfinite(tilt) & np.all(np.isfinite(lab), axis=-1)
    tilt = np.clip(np.where(np.isfinite(tilt), tilt, t_lo), t_lo, t_hi)
    d_lo, d_hi = float(table.thickness_nm[0]), float(table.thickness_nm[-1])
    grid = np.arange(d_lo, d_hi + 1e-9, grid_step_nm)
    white = table.white_xyz
    rng = np.random.default_rng(seed)

    samples = []  # per ROI: (xyz (n, D, 3), lab (n, 3), idx of all usable pixels)
    for r0 in rows:
        for c0 in cols:
            sub = usable[r0:r0 + rh, c0:c0 + rw]
            yy, xx = np.nonzero(sub)
            yy, xx = yy + r0, xx + c0
            if yy.size < min_pixels:
                samples.append(None)
                continue
            pick = rng.choice(yy.size, min(sample_px, yy.size), replace=False)
            ys, xs = yy[pick], xx[pick]
            xyz = table.xyz_at(tilt[ys, xs][:, None], grid[None, :]).astype(np.float32)
            samples.append((xyz, lab[ys, xs], yy, xx))

    valid = [s for s in samples if s is not None]
    band = None
    if consensus_half_width_nm > 0 and valid and grid.size > 2:
        # The interference order, from hue and chroma alone (before the exposure is known).
        score = np.mean([_band_curve(x[:128], lab_s[:128], white, grid, consensus_half_width_nm,
                                     method=delta_e_method)
                         for x, lab_s, _, _ in valid], axis=0)
        centre = float(grid[int(np.argmin(score))])
        band = (centre - consensus_half_width_nm, centre + consensus_half_width_nm)
        log.info("interference-order consensus (exposure-invariant): %.1f-%.1f nm", *band)
    estimated = exposure is None
    if estimated:
        exposure = (_estimate_exposure(valid, white, grid, band, delta_e_method) if valid
                    else 1.0)
        log.info("estimated exposure %.4f", exposure)
    elif not (np.isfinite(exposure) and exposure > 0):
        raise ValueError(f"exposure: must be > 0, got {exposure!r}")

    n = len(samples)
    out = {k: np.full(n, np.nan) for k in ("d", "de", "d2", "de2")}
    npx = np.zeros(n, dtype=np.int64)
    curves = np.full((n, grid.size), np.nan, dtype=np.float32)
    for i, s in enumerate(samples):
        if s is not None:
            curves[i] = _curve(s[0], s[1], exposure, white, delta_e_method)
    for i, s in enumerate(samples):
        if s is None:
            continue
        xyz, lab_s, yy, xx = s
        npx[i] = yy.size
        curve = curves[i]
        minima = _local_minima(curve)
        chosen_by_consensus = False
        if band is not None and minima.size:
            inside = minima[(grid[minima] >= band[0]) & (grid[minima] <= band[1])]
            if inside.size and curve[minima[0]] >= curve[inside[0]] - order_margin_de:
                minima = np.concatenate([inside[:1], minima[minima != inside[0]]])
                chosen_by_consensus = True
        # Refine the two best minima on a larger sample at 0.05 nm.
        pick = rng.choice(yy.size, min(refine_px, yy.size), replace=False)
        yr, xr = yy[pick], xx[pick]
        res = []
        t_r, lab_r = tilt[yr, xr][:, None], lab[yr, xr]

        def curve_at(d):
            xyz_f = table.xyz_at(t_r, d[None, :]).astype(np.float32)
            return _curve(xyz_f, lab_r, exposure, white, delta_e_method)

        for j in minima[:2]:
            # ±1 grid step at 0.25 nm, then ±0.25 nm at 0.05 nm about the best: the mean ΔE
            # over thousands of pixels is smooth at that scale (20 evaluations, not 41)
            mid = _fine_minimum(curve_at, float(grid[j]), grid_step_nm, d_lo, d_hi, 0.25)
            fine = np.arange(mid - 0.25, mid + 0.25 + 1e-9, 0.05)
            fine = fine[(fine >= d_lo) & (fine <= d_hi)]
            c_f = curve_at(fine)
            k = int(np.argmin(c_f))
            d_best = _parabola(fine, c_f, k)
            de_best = float(_curve(table.xyz_at(tilt[yr, xr], d_best)[:, None, :].astype(
                np.float32), lab[yr, xr], exposure, white, delta_e_method)[0])
            res.append((de_best, d_best))
        if not chosen_by_consensus:
            res.sort()
        out["de"][i], out["d"][i] = res[0]
        if len(res) > 1:
            out["de2"][i], out["d2"][i] = res[1]
    r0s = np.repeat(np.asarray(rows), len(cols))
    c0s = np.tile(np.asarray(cols), len(rows))
    return RoiFit(r0s, c0s, rh, rw, out["d"], out["de"], out["d2"], out["de2"],
                  out["de2"] - out["de"], npx, float(exposure), estimated, grid, curves,
                  list(rows), list(cols))


def thickness_per_roi(colour, tilt_deg, table, *, size_px=255, stride_px=None, exposure=None,
                      seed=0, delta_e_method="CIEDE2000") -> RoiFit:
    """The ROI stage: a grid of ROIs over the image and :func:`fit_roi_thickness` on it.

    Parameters
    ----------
    colour : ColourImage
        Lab and mask of the image (:func:`~microfacet.analysis.colour_image.measure_colour`).
    tilt_deg : ndarray (H, W)
        Tilt per pixel from the height map.
    table : ColourTable
    size_px, stride_px, exposure, seed
        See :func:`roi_grid` and :func:`fit_roi_thickness`.
    """
    rois = roi_grid(colour.lab.shape[:2], size_px=size_px, stride_px=stride_px)
    return fit_roi_thickness(colour.lab, tilt_deg, colour.mask.mask, table, rois=rois,
                             exposure=exposure, seed=seed, delta_e_method=delta_e_method)


def _estimate_exposure(samples, white, grid, band, method):
    """Exposure minimising the ROIs' mean best median ΔE (within the order band, if any)."""
    sub = [(xyz[:128], lab_s[:128]) for xyz, lab_s, _, _ in samples]
    inside = (np.ones(grid.size, bool) if band is None
              else (grid >= band[0]) & (grid <= band[1]))

    def objective(log_e):
        # Each pixel at its best thickness in the band; the median over pixels (robust to
        # partly shadowed pixels), averaged over ROIs.
        e = math.exp(log_e)
        vals = []
        for x, lab_s in sub:
            de = delta_e(_model_lab(x[:, inside], e, white), lab_s[:, None, :], method=method)
            vals.append(np.median(de.min(axis=1)))
        return float(np.mean(vals))

    log_grid = np.linspace(math.log(0.25), math.log(4.0), 25)
    vals = np.array([objective(g) for g in log_grid])
    i = int(np.argmin(vals))
    lo, hi = log_grid[max(i - 1, 0)], log_grid[min(i + 1, log_grid.size - 1)]
    opt = optimize.minimize_scalar(objective, bounds=(lo, hi), method="bounded",
                          options={"xatol": 0.003})
    best = opt.x if opt.fun <= vals[i] else log_grid[i]
    return float(math.exp(best))
