"""Facets: a plane per facet from the height map, a thickness per facet from its colour.

Colour moves about 2 ΔE00 per nm of thickness but only 0.03-0.3 per degree of tilt: to
first order a tilt θ acts like a thickness change d·(1 − cos θ₁), so a 1 nm thickness
change inside a region masquerades as a 10-20° tilt in the seed's per-pixel inversion.
Thickness and tilt cannot both be read from one pixel's colour. The joint mode
(:mod:`.joint`) uses what each source is good at, facet by facet (facets from
:func:`microfacet.analysis.segmentation.segment_facets`):

* **Tilt from reliable heights** (:func:`fit_facet_planes`): a least-squares plane through the
  facet's *reliable* heights only, each weighted by 1/σ_h² (its error from the focus stage).
  Its covariance, inflated by the reduced χ² of the fit when the plane fits worse than the
  height errors allow, is the slope noise the NDF fit deconvolves. A facet with fewer than
  ``min_pixels`` reliable heights, or whose reliable pixels do not span a plane, gets no tilt
  (``fitted`` False, tilt NaN): it is not guessed.
* **Thickness from colour at that tilt** (:func:`facet_thickness`): the d of least ΔE00
  between the facet's mean interior Lab and the model, searched over the facet's interference
  order (±0.45 of the colour period λ/(2n) around its ROI's thickness: the colours of the
  neighbouring orders, ~λ/(2n) away, stay out), with a 1-σ error from the curvature of
  ΔE² and the tilt's own error.
"""

from __future__ import annotations

import logging
import math
from dataclasses import dataclass

import numpy as np

from ..colour.colorimetry import xyz_to_lab
from ..colour.difference import delta_e
from ..core.lazy import load
from ..optics.constants import optical_constants
from .search import coarse_to_fine
from .segmentation import plane_from_moments, plane_moments

ndimage = load("scipy.ndimage")
optimize = load("scipy.optimize")

__all__ = ["ORDER_SWITCH_DE", "ORDER_SWITCH_RATIO", "FacetFit", "FacetThickness",
           "facet_edge_distance", "facet_thickness", "film_index", "fit_facet_planes",
           "order_half_width_nm", "refine_exposure_on_facets"]

log = logging.getLogger(__name__)

#: Wavelength at which the film's index sets the colour period and the refraction angle.
_LAMBDA_C_NM = 560.0


@dataclass
class FacetFit:
    """Plane fits per facet (arrays of length S; NaN where not ``fitted``).

    Attributes
    ----------
    slope_x, slope_y : ndarray
        dh/dx and dh/dy (x = image columns, y = image rows, both in µm).
    slope_cov : ndarray, shape (S, 2, 2)
        Covariance of (slope_x, slope_y), inflated by ``max(1, chi2_dof)`` and by the
        correlation of the height errors.
    slope_sigma : ndarray
        Isotropic slope noise per axis, √(trace(cov) / 2): a measured slope vector is the
        true one plus N(0, slope_sigma² I) (the NDF fit's noise model).
    tilt_deg, tilt_sigma_deg : ndarray
        Tilt of the plane and its 1-σ uncertainty (along the gradient).
    n_pixels : ndarray of int
        Reliable pixels the plane was fitted to.
    chi2_dof : ndarray
        Weighted residual per degree of freedom (≈ 1 when the heights' σ is right and the
        facet is one plane).
    fitted : ndarray of bool
        The facet has a height tilt.
    """

    slope_x: np.ndarray
    slope_y: np.ndarray
    slope_cov: np.ndarray
    slope_sigma: np.ndarray
    tilt_deg: np.ndarray
    tilt_sigma_deg: np.ndarray
    n_pixels: np.ndarray
    chi2_dof: np.ndarray
    fitted: np.ndarray


def fit_facet_planes(labels, height_um, *, height_sigma_um, reliable, pixel_size_um,
                     min_pixels=8, correlation_px=1.0) -> FacetFit:
    """Weighted least-squares plane per facet through its reliable heights only.

    Parameters
    ----------
    labels : ndarray of int, shape (H, W)
        Facets 0..S-1.
    height_um : ndarray, shape (H, W)
        Height map (NaN ignored).
    height_sigma_um : ndarray or float
        1-σ height error per pixel (µm): weights 1/σ².
    reliable : ndarray of bool, shape (H, W)
        Pixels whose height may be used (the others, however plausible, are not).
    pixel_size_um : float or (float, float)
        Lateral pixel size in µm, ``(y, x)`` for non-square pixels.
    min_pixels : int
        Fewest reliable pixels for a plane (3 determine it; the default leaves 5 degrees of
        freedom for the residual that scales its covariance).
    correlation_px : float
        Correlation area A of the height errors in pixels. Heights from focus share their
        errors over the focus window (measured: 27-41 px² for a 7 px window), which the
        residual about the plane cannot show: the slope covariance of independent errors is
        multiplied by ``n A / (n + 5 A)`` — A for facets much larger than the correlation
        area, less for smaller ones (a smooth error tilts a small facet less than it would
        n independent errors), fitted within ±30 % to simulations of smoothed white noise
        for facets of 0.3-36 correlation areas (tests/analysis/test_facets.py).

    Returns
    -------
    FacetFit

    Examples
    --------
    >>> yy, xx = np.mgrid[0:10, 0:20]
    >>> labels = (xx >= 10).astype(np.int32)
    >>> h = np.where(labels == 0, 0.1, -0.2) * xx * 0.5     # slopes 0.1 and -0.2
    >>> rel = np.ones(h.shape, bool); rel[:, 10:] = False   # facet 1: no reliable height
    >>> ff = fit_facet_planes(labels, h, height_sigma_um=0.01, reliable=rel, pixel_size_um=0.5)
    >>> ff.fitted.tolist(), round(float(ff.slope_x[0]), 6), bool(np.isnan(ff.tilt_deg[1]))
    ([True, False], 0.1, True)
    """
    S = int(labels.max()) + 1
    sig = np.broadcast_to(np.asarray(height_sigma_um, dtype=np.float64), labels.shape)
    z = np.asarray(height_um, dtype=np.float64)
    use = np.asarray(reliable, bool) & np.isfinite(z) & np.isfinite(sig) & (sig > 0)
    with np.errstate(divide="ignore", invalid="ignore"):
        wt = np.where(use, 1.0 / sig ** 2, 0.0)
    m = plane_moments(labels, np.where(use, z, np.nan), wt, pixel_size_um=pixel_size_um,
                      n_labels=S)
    n = np.bincount(labels.ravel(), weights=use.ravel(), minlength=S).astype(np.int64)
    a, b, rss, cov = plane_from_moments(m)
    fitted = (n >= max(int(min_pixels), 4)) & np.isfinite(a) & np.isfinite(b)
    with np.errstate(invalid="ignore", divide="ignore"):
        chi2 = np.where(fitted, rss / np.maximum(n - 3, 1), np.nan)
    A = max(float(correlation_px), 1.0)
    corr = n * A / (n + 5.0 * A) if A > 1.0 else np.ones(n.shape)
    infl = np.where(fitted, np.maximum(chi2, 1.0) * np.maximum(corr, 1.0), np.nan)
    cov = np.where(fitted[:, None, None], cov * infl[:, None, None], np.nan)
    g = np.hypot(a, b)
    with np.errstate(invalid="ignore", divide="ignore"):
        ux = np.where(g > 0, a / g, 1 / np.sqrt(2))
        uy = np.where(g > 0, b / g, 1 / np.sqrt(2))
        var_g = (cov[:, 0, 0] * ux * ux + 2 * cov[:, 0, 1] * ux * uy + cov[:, 1, 1] * uy * uy)
    tilt = np.where(fitted, np.degrees(np.arctan(g)), np.nan)
    tsig = np.where(fitted, np.degrees(np.sqrt(np.maximum(var_g, 0.0)) / (1.0 + g * g)),
                    np.nan)
    ssig = np.where(fitted, np.sqrt(np.maximum(cov[:, 0, 0] + cov[:, 1, 1], 0.0) / 2.0),
                    np.nan)
    nan = np.where(fitted, 0.0, np.nan)
    return FacetFit(a + nan, b + nan, cov, ssig, tilt, tsig, n, chi2, fitted)


def film_index(table) -> float:
    """Real refractive index of the table's film at 560 nm (sets the colour period)."""
    n = optical_constants(table.film, np.array([_LAMBDA_C_NM]))
    return float(np.real(np.ravel(n)[0]))


def order_half_width_nm(table) -> float:
    """Half-width of one interference order's thickness window: 0.45 λ/(2n) at 560 nm.

    The colour of a film repeats (paler) about every λ/(2n) of thickness (~110 nm for TiO2):
    a search of ±0.45 of that around a thickness in the right order cannot reach the
    neighbouring orders' look-alike colours.
    """
    return 0.45 * _LAMBDA_C_NM / (2.0 * film_index(table))


@dataclass
class FacetThickness:
    """Thickness per facet (arrays of length S; NaN where a facet has no usable pixel).

    Attributes
    ----------
    thickness_nm, sigma_nm : ndarray
        Thickness and its 1-σ error (colour noise and misfit through the curvature of ΔE²,
        plus the thickness equivalent of the tilt's error).
    delta_e : ndarray
        ΔE00 between the facet's mean colour and the model at the solution.
    at_window_edge : ndarray of bool
        The minimum lies at the edge of the interference-order window (the colour fits a
        thickness outside the order better: ambiguous).
    n_pixels : ndarray of int
        Pixels whose mean colour was used.
    delta_e_other_order : ndarray
        The least ΔE00 in the neighbouring orders' windows (one colour period above and
        below; NaN where both lie outside the table): close to ``delta_e``, the order is
        uncertain.
    """

    thickness_nm: np.ndarray
    sigma_nm: np.ndarray
    delta_e: np.ndarray
    at_window_edge: np.ndarray
    n_pixels: np.ndarray
    delta_e_other_order: np.ndarray


def _facet_means(labels, lab, usable, interior, values):
    S = int(labels.max()) + 1
    lab_flat = np.asarray(lab, dtype=np.float64).reshape(-1, 3)
    u = np.asarray(usable, bool).ravel()
    lb = labels.ravel()
    if interior is not None:
        ui = u & np.asarray(interior, bool).ravel()
        has_interior = np.bincount(lb[ui], minlength=S) > 0
        u = np.where(has_interior[lb], ui, u)
    cnt = np.bincount(lb[u], minlength=S).astype(np.float64)
    mean_lab = np.stack([np.bincount(lb[u], weights=lab_flat[u, c], minlength=S)
                         for c in range(3)], axis=-1) / np.maximum(cnt, 1)[:, None]
    v = np.asarray(values, dtype=np.float64).ravel()[u]
    ok = np.isfinite(v)
    mv = (np.bincount(lb[u][ok], weights=v[ok], minlength=S)
          / np.maximum(np.bincount(lb[u][ok], minlength=S), 1))
    return mean_lab, cnt, mv


def _scan(table, centre, tilt, mean_lab, offsets, exposure, white, method):
    """ΔE of each facet's mean Lab at ``centre + offsets`` (offsets (k,) or per facet
    (S, k)), clipped to the table; returns the thicknesses and the ΔE, both (S, k)."""
    lo, hi = float(table.thickness_nm[0]), float(table.thickness_nm[-1])
    off = np.asarray(offsets, dtype=np.float64)
    grid = np.clip(centre[:, None] + (off if off.ndim == 2 else off[None, :]), lo, hi)
    xyz = table.xyz_at(tilt[:, None], grid) * exposure
    model = xyz_to_lab(xyz.astype(np.float32), white=white)
    de = delta_e(model, mean_lab[:, None, :].astype(np.float32), method=method)
    return grid, de.astype(np.float64)


def _fine_scan(table, centre, tilt, mean_lab, fine, exposure, white, method, stride=5):
    """The fine scan ``centre + fine`` (uniform offsets) coarse-to-fine
    (:func:`~microfacet.analysis.search.coarse_to_fine`; ΔE is unimodal over ±1 nm).

    Returns the scanned thicknesses and ΔE (S, m), and two column indices into them: the
    least ΔE, and the node about which a full scan fits its parabola (its
    ``clip(k, 1, n − 2)``; different from the first exactly when the minimum is at an end of
    ``fine``).
    """
    n = fine.size
    r = np.arange(centre.size)
    if n < 4 * stride:
        grid, de = _scan(table, centre, tilt, mean_lab, fine, exposure, white, method)
        k = np.argmin(de, axis=1)
        return grid, de, k, np.clip(k, 1, n - 2)
    idx, de, kw = coarse_to_fine(
        lambda nodes: _scan(table, centre, tilt, mean_lab, fine[nodes], exposure, white,
                            method)[1], n, centre.size, stride=stride)
    lo, hi = float(table.thickness_nm[0]), float(table.thickness_nm[-1])
    grid = np.clip(centre[:, None] + fine[idx], lo, hi)
    # the node a full scan would fit its parabola about, clip(k, 1, n − 2), found in this
    # scan (it is kw itself unless the minimum is at an end of ``fine``)
    target = np.clip(idx[r, kw], 1, n - 2)
    km = np.argmax(idx == target[:, None], axis=1)
    return grid, de, kw, km


def _window_minimum(table, centre, tilt, mean_lab, offsets, exposure, white, method):
    """The node of least ΔE among ``centre + offsets`` (a uniform grid): every other node,
    then the two next to the best. Returns the thickness, the node's index and its ΔE."""
    r = np.arange(centre.size)
    n = offsets.size
    idx2 = np.unique(np.r_[np.arange(0, n, 2), n - 1])
    _, de2 = _scan(table, centre, tilt, mean_lab, offsets[idx2], exposure, white, method)
    k2 = idx2[np.argmin(de2, axis=1)]
    best = de2[r, np.argmin(de2, axis=1)]
    nb = np.clip(k2[:, None] + np.array([-1, 1])[None, :], 0, n - 1)
    grid_nb, de_nb = _scan(table, centre, tilt, mean_lab, offsets[nb], exposure, white, method)
    j = np.argmin(de_nb, axis=1)
    better = de_nb[r, j] < best
    k = np.where(better, nb[r, j], k2)
    lo, hi = float(table.thickness_nm[0]), float(table.thickness_nm[-1])
    return np.clip(centre + offsets[k], lo, hi), k, np.where(better, de_nb[r, j], best)


def _order_scan(table, centre, tilt, mean_lab, hw, exposure, white, method):
    """Least ΔE inside the order window ±``hw`` about ``centre`` and the best thickness
    outside it, on the table's whole range at 1 nm: a 2 nm scan, then the 1 nm nodes next to
    each side's best (the ΔE curve's basins are several nm wide), half the evaluations of a
    1 nm scan.

    Returns
    -------
    best_in, d_out, de_out : ndarray, shape (S,)
    """
    lo, hi = float(table.thickness_nm[0]), float(table.thickness_nm[-1])
    r = np.arange(centre.size)
    coarse, de = _scan(table, np.zeros(centre.size), tilt, mean_lab,
                       np.arange(lo, hi + 1e-9, 2.0), exposure, white, method)
    inside = np.abs(coarse - centre[:, None]) <= hw
    results = []
    for want_inside in (True, False):
        sel = inside if want_inside else ~inside
        k = np.argmin(np.where(sel, de, np.inf), axis=1)
        grid, de_n = _scan(table, coarse[r, k], tilt, mean_lab, np.array([-1.0, 1.0]),
                           exposure, white, method)
        ok_n = (np.abs(grid - centre[:, None]) <= hw) == want_inside
        ok_n &= (grid > lo - 1e-9) & (grid < hi + 1e-9) & (grid != coarse[r, k][:, None])
        de_n = np.where(ok_n, de_n, np.inf)
        best = np.where(sel[r, k], de[r, k], np.inf)
        j = np.argmin(de_n, axis=1)
        better = de_n[r, j] < best
        results.append((np.where(better, grid[r, j], coarse[r, k]),
                        np.where(better, de_n[r, j], best)))
    (_, best_in), (d_out, de_out) = results
    return best_in, d_out, de_out


#: A facet leaves its ROI's interference order when a thickness outside it fits its colour
#: better by more than this (ΔE00); within it the orders are not told apart by colour.
ORDER_SWITCH_DE = 1.0
#: ... and by a factor: the other order must fit at most this fraction of the ROI order's
#: ΔE00 (a facet of two regions or of a groove fits neither well and stays; on the
#: fixture, without it 1.8 % of the pixels switched to a wrong order).
ORDER_SWITCH_RATIO = 0.5


def facet_thickness(labels, lab, usable, facet_tilt_deg, roi_thickness_px, table, *,
                    exposure, tilt_sigma_deg=None, noise_de=1.0, half_width_nm=None,
                    step_nm=0.05, interior=None, delta_e_method="CIEDE2000",
                    order_switch_de=ORDER_SWITCH_DE, other_orders=True) -> FacetThickness:
    """Thickness per facet from its mean Lab at its tilt, within its interference order.

    The order is the ROI's (the window ±``half_width_nm`` about the ROI thickness) unless a
    scan of the table's whole thickness range finds, outside that window, a thickness whose
    colour fits the facet better by more than ``order_switch_de`` and with at most
    :data:`ORDER_SWITCH_RATIO` of the ROI order's ΔE00: a facet of another
    population than its ROI's majority, in another order, takes its own. Within ΔE00
    ``order_switch_de`` the orders are not told apart by colour and the ROI's is kept.

    Parameters
    ----------
    labels : ndarray of int, shape (H, W)
    lab : ndarray, shape (H, W, 3)
    usable : ndarray of bool, shape (H, W)
        Unmasked pixels.
    facet_tilt_deg : ndarray, shape (S,)
        Tilt per facet (its plane's, or a stand-in where it has none).
    roi_thickness_px : ndarray, shape (H, W)
        The ROI stage's thickness per pixel: the facet's window is centred on its mean.
    table : ColourTable
    exposure : float
    tilt_sigma_deg : ndarray, shape (S,), optional
        Error of ``facet_tilt_deg`` (adds d·tan θ₁·cos θ/(n cos θ₁)·σ_θ to the error).
    noise_de : float
        Colour noise per Lab component of one pixel.
    half_width_nm : float, optional
        Half-width of the search window (default :func:`order_half_width_nm`).
    step_nm : float
        Final resolution (a 1 nm scan, then ±1 nm at this step, then a parabola).
    interior : ndarray of bool, optional
        Pixels away from the facet's boundary (partly shadowed): the mean colour uses them
        where a facet has any.
    delta_e_method : str
        ``"CIEDE2000"``, ``"CIE94"`` or ``"CIE76"``.
    order_switch_de : float or None
        None: stay in the ROI's order (no whole-range scan).
    other_orders : bool
        Scan the neighbouring orders for ``delta_e_other_order`` (NaN without the scan).

    Returns
    -------
    FacetThickness
    """
    S = int(labels.max()) + 1
    mean_lab, cnt, centre = _facet_means(labels, lab, usable, interior, roi_thickness_px)
    tilt = np.asarray(facet_tilt_deg, dtype=np.float64)
    has = (cnt > 0) & np.isfinite(centre) & np.isfinite(tilt)
    hw = order_half_width_nm(table) if half_width_nm is None else float(half_width_nm)
    n_film = film_index(table)
    white = table.white_xyz.astype(np.float32)
    t_lo, t_hi = float(table.theta_deg[0]), float(table.theta_deg[-1])
    out = {k: np.full(S, np.nan) for k in ("d", "s", "de", "alt")}
    d_lo, d_hi = float(table.thickness_nm[0]), float(table.thickness_nm[-1])
    period = hw / 0.45
    edge = np.zeros(S, bool)
    coarse = np.arange(-hw, hw + 1e-9, 1.0)
    fine = np.arange(-1.0, 1.0 + 1e-9, step_nm)
    idx = np.flatnonzero(has)
    for a in range(0, idx.size, 2048):
        ii = idx[a:a + 2048]
        r = np.arange(ii.size)
        th = np.clip(tilt[ii], t_lo, t_hi)
        if order_switch_de is not None:
            cen = centre[ii]
            best_in, full_out, de_out = _order_scan(table, cen, th, mean_lab[ii], hw,
                                                    exposure, white, delta_e_method)
            switch = (de_out < best_in - order_switch_de) & (de_out < ORDER_SWITCH_RATIO
                                                             * best_in)
            centre[ii] = np.where(switch, full_out, cen)
        d_k, k, _ = _window_minimum(table, centre[ii], th, mean_lab[ii], coarse, exposure,
                                    white, delta_e_method)
        edge[ii] = (k == 0) | (k == coarse.size - 1)
        grid, de, k, km = _fine_scan(table, d_k, th, mean_lab[ii], fine, exposure, white,
                                     delta_e_method)
        y0, y1, y2 = de[r, km - 1] ** 2, de[r, km] ** 2, de[r, km + 1] ** 2
        den = y0 - 2 * y1 + y2
        with np.errstate(divide="ignore", invalid="ignore"):
            o = np.where((den > 0) & (k == km), np.clip(0.5 * (y0 - y2) / den, -1, 1), 0.0)
            curv = np.where(den > 0, den / step_nm ** 2, np.nan)   # d²(ΔE²)/dd²
        d_best = grid[r, k] + o * step_nm
        de_best = np.sqrt(np.maximum(y1 - 0.25 * (y0 - y2) * o, 0.0))
        # colour error of the facet's mean per Lab component: noise over its pixels, or
        # the misfit itself when larger (model error, thickness variation in the facet)
        sc = np.maximum(noise_de / np.sqrt(cnt[ii]), de_best / math.sqrt(3.0))
        with np.errstate(divide="ignore", invalid="ignore"):
            s_col = sc * np.sqrt(2.0 / curv)
        s2 = s_col ** 2
        if tilt_sigma_deg is not None:
            sin1 = np.sin(np.radians(th)) / n_film
            cos1 = np.sqrt(1.0 - sin1 ** 2)
            dd_dth = d_best * (sin1 / cos1) * np.cos(np.radians(th)) / (n_film * cos1)
            ts = np.asarray(tilt_sigma_deg, dtype=np.float64)[ii]
            s2 = s2 + (dd_dth * np.radians(np.nan_to_num(ts, nan=0.0))) ** 2
        # at most the SD of a uniform spread over the window (a flat ΔE curve)
        s_tot = np.minimum(np.sqrt(s2), hw / math.sqrt(3.0))
        out["d"][ii], out["de"][ii], out["s"][ii] = d_best, de_best, np.where(
            np.isfinite(s_tot), s_tot, hw / math.sqrt(3.0))
        alt = np.full(ii.size, np.inf)
        for shift in (-period, period) if other_orders else ():
            c2 = d_best + shift
            inside = (c2 + hw >= d_lo) & (c2 - hw <= d_hi)
            if inside.any():
                *_, de2 = _window_minimum(table, c2[inside], th[inside], mean_lab[ii[inside]],
                                          coarse, exposure, white, delta_e_method)
                alt[inside] = np.minimum(alt[inside], de2)
        out["alt"][ii] = np.where(np.isfinite(alt), alt, np.nan)
    return FacetThickness(out["d"], out["s"], out["de"], edge, cnt.astype(np.int64),
                          out["alt"])


def refine_exposure_on_facets(facets, lab, usable, tilt_f, thick_roi_px, table, exposure, *,
                               interior, seed=0, n_facets=2000, delta_e_method="CIEDE2000"):
    """Exposure of least median facet ΔE00, each facet's thickness re-solved per candidate.

    Facets are homogeneous (one tilt, one thickness), unlike ROIs that span several
    thickness regions, so they pin the exposure down better than the ROI fit did. Facets
    without a tilt (NaN in ``tilt_f``) are not used.
    """
    S = int(facets.max()) + 1
    rng = np.random.default_rng(seed)
    cnt = np.bincount(facets[usable & interior], minlength=S)
    cand = np.flatnonzero((cnt >= 4) & np.isfinite(tilt_f))
    if cand.size < 10:
        return exposure
    pick = np.zeros(S, bool)
    pick[rng.choice(cand, min(n_facets, cand.size), replace=False)] = True
    sel = usable & pick[facets]
    tilt = np.where(pick, tilt_f, np.nan)

    def objective(log_e):
        ft = facet_thickness(facets, lab, sel, tilt, thick_roi_px, table,
                             exposure=math.exp(log_e), interior=interior, step_nm=0.1,
                             delta_e_method=delta_e_method, order_switch_de=None,
                             other_orders=False)
        return float(np.nanmedian(ft.delta_e))

    lo, hi = math.log(exposure / 1.5), math.log(exposure * 1.5)
    opt = optimize.minimize_scalar(objective, bounds=(lo, hi), method="bounded",
                                   options={"xatol": 0.005})
    return float(math.exp(opt.x)) if opt.fun <= objective(math.log(exposure)) else exposure


def facet_edge_distance(labels) -> np.ndarray:
    """Distance in pixels of every pixel from the nearest facet boundary (0 on it; +inf
    everywhere for a single facet, which has no boundary)."""
    edge = np.zeros(labels.shape, bool)
    edge[:, 1:] |= labels[:, 1:] != labels[:, :-1]
    edge[1:, :] |= labels[1:, :] != labels[:-1, :]
    if not edge.any():
        return np.full(labels.shape, np.inf)
    return ndimage.distance_transform_edt(~edge)
