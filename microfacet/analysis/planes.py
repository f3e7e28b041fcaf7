"""Facet planes: a least-squares plane per facet through its reliable heights only.

Colour moves about 2 ΔE00 per nm of thickness but only 0.03-0.3 per degree of tilt
(docs/conditioning.md), so the joint mode (:mod:`.joint`) takes each facet's tilt from the
height map: a plane through the facet's *reliable* heights, each weighted by 1/σ_h² (its
error from the focus stage). Its covariance, inflated by the reduced χ² of the fit when the
plane fits worse than the height errors allow and by the correlation of the height errors,
is the slope noise the NDF fit deconvolves. A facet with too few reliable heights, or whose
reliable pixels do not span a plane, gets no tilt (``fitted`` False, tilt NaN): it is not
guessed.

References
----------
.. [1] N. Nagata et al., the seed, §3.3.2 (facets as planes of the height map, Fig. 17).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from ..core.lazy import load
from ..core.pixels import pixel_size_yx
from ..core.threads import BLOCK_VALUES, thread_map
from .segmentation import label_groups, plane_from_moments, plane_moments

cv2 = load("cv2")

__all__ = ["FacetFit", "fit_facet_planes"]

#: Rounds of robust refitting of the plane fits: ``HALF_ROUNDS`` concentration steps on the
#: better half (a quarter of a facet 1 µm down in a pit: 6° off after one, 0.03° after four,
#: tests/analysis/test_planes.py), a biweight round, the inliers; the Tukey constant in
#: robust SDs (4.685 keeps 95 % efficiency on Gaussian errors).
ROBUST_ROUNDS = 6
HALF_ROUNDS = 4
TUKEY_C = 4.685
#: Planes whose slope noise (per axis) exceeds this carry no slope information (slivers along
#: an edge); the RMS slope of the planes (:func:`deconvolved_rms_slope`) leaves them out, as
#: their weight in the NDF's deconvolving fit is nil.
MAX_SLOPE_SIGMA = 0.3


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
                     min_pixels, correlation_px=1.0, robust_rounds=ROBUST_ROUNDS) -> FacetFit:
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
        Fewest reliable pixels for a plane (:attr:`~.options.JointOptions.min_plane_pixels`).
    robust_rounds : int
        Rounds of robust refitting (:func:`_robust_weights`): :data:`HALF_ROUNDS` refits to the
        half of the heights nearest the last plane, then Tukey biweights, the last a plain
        weighted fit to the heights within :data:`TUKEY_C` robust SDs: heights of a pit
        floor, a scratch or a neighbour's edge inside the facet stop pulling its plane (and
        its χ²). 0: plain weighted least squares through every reliable height.
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
    >>> ff = fit_facet_planes(labels, h, height_sigma_um=0.01, reliable=rel, pixel_size_um=0.5,
    ...                       min_pixels=8)
    >>> ff.fitted.tolist(), round(float(ff.slope_x[0]), 6), bool(np.isnan(ff.tilt_deg[1]))
    ([True, False], 0.1, True)
    """
    S = int(labels.max()) + 1
    sig = np.broadcast_to(np.asarray(height_sigma_um, dtype=np.float64), labels.shape)
    z = np.asarray(height_um, dtype=np.float64)
    use = np.asarray(reliable, bool) & np.isfinite(z) & np.isfinite(sig) & (sig > 0)
    with np.errstate(divide="ignore", invalid="ignore"):
        wt = np.where(use, 1.0 / sig ** 2, 0.0)
    zu = np.where(use, z, np.nan)
    if robust_rounds > 0:
        wt = _robust_weights(labels, zu, wt, pixel_size_um, S, robust_rounds)
    m = plane_moments(labels, zu, wt, pixel_size_um=pixel_size_um, n_labels=S)
    use = use & (wt > 0)
    n = np.bincount(labels.ravel(), weights=use.ravel(), minlength=S).astype(np.int64)
    a, b, rss, cov = plane_from_moments(m)
    fitted = (n >= max(int(min_pixels), 4)) & np.isfinite(a) & np.isfinite(b)
    with np.errstate(invalid="ignore", divide="ignore"):
        chi2 = np.where(fitted, rss / np.maximum(n - 3, 1), np.nan)
    infl = np.where(fitted, np.maximum(chi2, 1.0) * _correlation_factor(n, correlation_px),
                    np.nan)
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


def _correlation_factor(n, correlation_px):
    """How much more a fit to ``n`` heights whose errors are correlated over
    ``correlation_px`` (A) varies than one to independent errors: ``n A / (n + 5 A)``, at
    least 1 (:func:`fit_facet_planes`)."""
    n = np.asarray(n, dtype=np.float64)
    A = max(float(correlation_px), 1.0)
    return np.maximum(n * A / (n + 5.0 * A), 1.0) if A > 1.0 else np.ones(n.shape)


def _robust_weights(labels, z, wt, pixel_size_um, S, rounds):
    """The weights ``wt`` after the robust rounds: first :data:`HALF_ROUNDS` concentration
    steps on the better half of each plane's heights (a start that a cluster of outliers,
    such as a pit floor, cannot drag: least trimmed squares), then Tukey biweights
    (c = :data:`TUKEY_C` robust SDs, the SD at least the heights' own σ); the last round keeps
    the biweight's inliers at their full weight. Worked on the used pixels only, a group of
    whole facets at a time on :func:`~microfacet.core.threads.thread_map`'s threads (each
    facet's sums run over its pixels in the same order as over the whole image). The
    medians of :func:`_robust_scale` sort one float key scaled by the largest |r| of the
    facets sorted together, now a group's, not the image's: with a residual some 10⁹ σ away
    (a wild height) the key's rounding can swap |r| values of the facets grouped with it,
    and their weights then depend on the grouping (a known limitation, an xfail test;
    an exact two-key sort moved one plane of the x3p fixture)."""
    h, w = labels.shape
    flat = labels.ravel()
    idx = np.flatnonzero(wt.ravel() > 0)
    py, px = pixel_size_yx(pixel_size_um)
    out = np.zeros(labels.size)

    def group(g):
        lo, hi, a, b = g
        part = idx[a:b]
        sel = part[(flat[part] >= lo) & (flat[part] < hi)]
        out[sel] = _robust_group(flat[sel] - lo, hi - lo, z.ravel()[sel], wt.ravel()[sel],
                                 (sel % w - (w - 1) / 2.0) * px,
                                 (sel // w - (h - 1) / 2.0) * py, rounds)

    thread_map(group, label_groups(labels, idx, S, BLOCK_VALUES))
    return out.reshape(labels.shape)


def _robust_group(lab, S, zz, w0, x, y, rounds):
    """:func:`_robust_weights`' rounds for the pixels of labels ``0..S-1``."""
    sig = 1.0 / np.sqrt(w0)
    wr = w0
    for k in range(rounds):
        # plane_moments' ten sums, over the used pixels only, one weighted term at a time
        terms = (lambda: wr, lambda: wr * x, lambda: wr * y, lambda: wr * zz,
                 lambda: wr * x * x, lambda: wr * x * y, lambda: wr * y * y,
                 lambda: wr * x * zz, lambda: wr * y * zz, lambda: wr * zz * zz)
        m = np.stack([np.bincount(lab, t(), S) for t in terms], axis=1)
        a, b, _, _ = plane_from_moments(m)
        with np.errstate(invalid="ignore", divide="ignore"):
            c0 = (m[:, 3] - a * m[:, 1] - b * m[:, 2]) / m[:, 0]
            r = (zz - (a[lab] * x + b[lab] * y + c0[lab])) / sig
        scale = np.nan_to_num(_robust_scale(lab, r, S), nan=1.0)
        if k < HALF_ROUNDS:
            t = (np.abs(r) <= scale[lab] / 1.4826).astype(np.float64)
        else:
            u = r / (TUKEY_C * np.maximum(scale, 1.0)[lab])
            t = np.where(np.abs(u) < 1.0, (1.0 - u * u) ** 2, 0.0)
        t = np.where(np.isfinite(a)[lab], t, 1.0)       # no plane yet: nothing to judge
        wr = w0 * (t if HALF_ROUNDS <= k < rounds - 1 else (t > 0))
    return wr


def _robust_scale(lab, r, S):
    """Per label: 1.4826 × the median |r| (NaN without any finite one)."""
    ok = np.isfinite(r)
    lab, a = lab[ok], np.abs(r[ok])
    # one sort of label + |r| scaled into [0, 1): the labels' runs, each in |r| order (to
    # the key's rounding: |r| closer than ~label·2⁻⁵² of the largest |r| may swap)
    order = np.argsort(lab + a / (float(a.max(initial=0.0)) * 1.0001 + 1e-300))
    lab, a = lab[order], a[order]
    cnt = np.bincount(lab, minlength=S)
    start = np.concatenate([[0], np.cumsum(cnt)[:-1]])
    med = np.full(S, np.nan)
    has = cnt > 0
    med[has] = a[start[has] + cnt[has] // 2]
    return 1.4826 * med


def at_least_px(distance, threshold_px) -> np.ndarray:
    """``distance >= threshold_px`` for a :func:`facet_edge_distance` map, decided as on the
    exact distances (√ of whole numbers n, as scipy's float64 transform gives them): the
    threshold becomes the float32 √m of the least whole m with √m ≥ ``threshold_px``, so
    that the float32 map is compared with a value it holds (exact for n below 4·10⁶, a
    distance of 2000 px).

    >>> d = facet_edge_distance(np.repeat(np.arange(2), 8)[None].repeat(9, 0))
    >>> int(at_least_px(d, 2.0).sum()), int(at_least_px(d, 2.5).sum())
    (117, 99)
    """
    t = float(threshold_px)
    if not math.isfinite(t) or t <= 0.0:
        return np.asarray(distance) >= t
    m = math.ceil(t * t)
    while m > 0 and math.sqrt(m - 1) >= t:
        m -= 1
    while math.sqrt(m) < t:
        m += 1
    return np.asarray(distance) >= np.float32(math.sqrt(m))


def facet_edge_distance(labels) -> np.ndarray:
    """Distance in pixels of every pixel from the nearest facet boundary (0 on it; +inf
    everywhere for a single facet, which has no boundary): float32, OpenCV's exact Euclidean
    transform (``DIST_MASK_PRECISE``): scipy's ``distance_transform_edt`` distances, √ of
    whole numbers, exactly where they are whole and within one float32 rounding elsewhere
    (tested); scipy's float64 transform is 18× slower at 12 MP."""
    edge = np.zeros(labels.shape, bool)
    edge[:, 1:] |= labels[:, 1:] != labels[:, :-1]
    edge[1:, :] |= labels[1:, :] != labels[:-1, :]
    if not edge.any():
        return np.full(labels.shape, np.inf, np.float32)
    return cv2.distanceTransform((~edge).view(np.uint8), cv2.DIST_L2, cv2.DIST_MASK_PRECISE)


def deconvolved_rms_slope(planes: FacetFit, ok, weights) -> float:
    """Weighted RMS |∇h| of ``planes[ok]`` (``weights`` per selected plane) with their slope
    noise (2 ``slope_sigma``² per facet) removed in quadrature: the facets' own RMS slope.
    Slivers (slope noise above :data:`MAX_SLOPE_SIGMA`) are left out: they carry no slope,
    and a few of them would swamp the noise-removed mean square (0 with none left)."""
    sig = planes.slope_sigma[ok]
    keep = sig < MAX_SLOPE_SIGMA
    w = np.asarray(weights, dtype=np.float64)[keep]
    g2 = np.tan(np.radians(planes.tilt_deg[ok][keep])) ** 2
    noise2 = 2.0 * sig[keep] ** 2
    return math.sqrt(max(float(np.sum(w * (g2 - noise2)) / max(float(np.sum(w)), 1e-300)),
                         0.0))


def dome_mean_square_slope(labels, height_um, *, height_sigma_um, reliable, pixel_size_um,
                           correlation_px=1.0, min_pixels=12) -> tuple[float, float] | None:
    """How curved the facets are: the area-weighted mean square of the slope that a dome
    term adds inside a facet, from a weighted fit of ``z = a x + b y + c + d r²`` per facet
    (r from the centroid of its heights), the noise of ``d`` removed (µm/µm squared), and its
    standard error.

    Planes read a rounded facet (a grain top, a dome) as its mean slope: the NDF of the
    planes then lacks the slopes inside the facets. This measures them; None with fewer than
    3 facets of ``min_pixels`` heights. The noise of ``d`` is inflated by the reduced χ² and
    by the correlation of the height errors (``correlation_px``) as in
    :func:`fit_facet_planes`.

    Examples
    --------
    >>> yy, xx = np.mgrid[0:40, 0:40] * 0.5
    >>> labels = (xx >= 10).astype(np.int32) + 2 * (yy >= 10)
    >>> cy, cx = np.where(yy >= 10, 14.75, 4.75), np.where(xx >= 10, 14.75, 4.75)
    >>> h = -0.05 * ((xx - cx) ** 2 + (yy - cy) ** 2)          # domes: slope 0.1 × r
    >>> ms, se = dome_mean_square_slope(labels, h, height_sigma_um=0.001,
    ...                             reliable=np.ones(h.shape, bool), pixel_size_um=0.5)
    >>> round(ms / float(np.mean(0.01 * ((xx - cx) ** 2 + (yy - cy) ** 2))), 3)
    1.0
    """
    c = dome_coefficients(labels, height_um, height_sigma_um=height_sigma_um,
                          reliable=reliable, pixel_size_um=pixel_size_um,
                          correlation_px=correlation_px, min_pixels=min_pixels)
    if c.ok.sum() < 3:
        return None
    d, var_d, r2, area = c.d[c.ok], c.var_d[c.ok], c.r2[c.ok], c.area[c.ok]
    # the dome's slope 2 d r, its mean square over the facet's pixels (all of them)
    ms = float(np.sum(area * 4.0 * (d * d - var_d) * r2) / np.sum(area))
    # Var(d̂²) = 4 d² v + 2 v² for d̂ ~ N(d, v), with d² estimated by max(d̂² − v, 0)
    var_t = (4.0 * r2) ** 2 * (4.0 * np.maximum(d * d - var_d, 0.0) * var_d + 2.0 * var_d ** 2)
    return ms, float(np.sqrt(np.sum(area ** 2 * var_t)) / np.sum(area))


@dataclass
class DomeCoefficients:
    """Per facet (arrays of length S): the dome coefficient ``d`` (µm⁻¹) of
    ``z = a x + b y + c + d r²``, its noise variance ``var_d``, whether it was measured
    (``ok``), the mean r² over the facet's pixels ``r2`` (µm²) and its pixels ``area``."""

    d: np.ndarray
    var_d: np.ndarray
    ok: np.ndarray
    r2: np.ndarray
    area: np.ndarray


def dome_coefficients(labels, height_um, *, height_sigma_um, reliable, pixel_size_um,
                      correlation_px=1.0, min_pixels=12) -> DomeCoefficients:
    """Each facet's dome term: the weighted fit of ``z = a x + b y + c + d r²`` (r from the
    centroid of its weighted heights) of :func:`dome_mean_square_slope`, per facet.

    >>> yy, xx = np.mgrid[0:20, 0:20] * 0.5
    >>> h = -0.05 * ((xx - 4.75) ** 2 + (yy - 4.75) ** 2) + 0.1 * xx
    >>> c = dome_coefficients(np.zeros((20, 20), np.int32), h, height_sigma_um=0.001,
    ...                       reliable=np.ones(h.shape, bool), pixel_size_um=0.5)
    >>> bool(c.ok[0]), round(float(c.d[0]), 4)
    (True, -0.05)
    """
    S = int(labels.max()) + 1
    sums = _dome_sums(labels, np.asarray(height_um), height_sigma_um, reliable,
                      pixel_size_um, S)
    A, rhs, n, szz, r2sum, area = (sums[k] for k in ("A", "rhs", "n", "szz", "r2", "area"))
    ok = n >= max(min_pixels, 5)
    ok[ok] &= np.abs(np.linalg.det(A[ok])) > 1e-12 * np.prod(np.diagonal(A[ok], axis1=1,
                                                                         axis2=2), axis=1)
    d, var_d = np.full(S, np.nan), np.full(S, np.nan)
    if ok.any():
        inv = np.linalg.inv(A[ok])
        coef = np.einsum("sij,sj->si", inv, rhs[ok])
        rss = szz[ok] - np.einsum("si,si->s", coef, rhs[ok])
        chi2 = np.maximum(rss / np.maximum(n[ok] - 4, 1), 1.0)
        d[ok] = coef[:, 3]
        var_d[ok] = inv[:, 3, 3] * chi2 * _correlation_factor(n[ok], correlation_px)
    r2 = np.where(area > 0, r2sum / np.maximum(area, 1), 0.0)
    return DomeCoefficients(d, var_d, ok, r2, area)


def _dome_sums(labels, height_um, height_sigma_um, reliable, pixel_size_um, S):
    """:func:`dome_mean_square_slope`'s sums per facet (arrays of length S): the normal
    equations ``A`` (S, 4, 4) and ``rhs`` (S, 4) of the basis x, y, 1, r² about the centroid
    of the facet's weighted heights, the heights used ``n``, Σ w z² ``szz``, Σ r² over all
    its pixels ``r2`` and its pixels ``area``. A group of whole facets at a time on
    :func:`~microfacet.core.threads.thread_map`'s threads, each facet's sums over its pixels
    in image order."""
    h, wd = labels.shape
    flat = labels.ravel()
    py, px = pixel_size_yx(pixel_size_um)
    sig_map = np.broadcast_to(np.asarray(height_sigma_um), labels.shape)
    rel = np.asarray(reliable, bool)
    out = {"A": np.zeros((S, 4, 4)), "rhs": np.zeros((S, 4)), "n": np.zeros(S),
           "szz": np.zeros(S), "r2": np.zeros(S), "area": np.zeros(S)}

    def group(g):
        lo, hi, a, b = g
        part = np.arange(a, b)
        sel = part[(flat[a:b] >= lo) & (flat[a:b] < hi)]
        lab, k = flat[sel] - lo, hi - lo
        rows, cols = np.divmod(sel, wd)
        z = height_um[rows, cols].astype(np.float64)
        sig = sig_map[rows, cols].astype(np.float64)
        use = rel[rows, cols] & np.isfinite(z) & np.isfinite(sig) & (sig > 0)
        w = np.where(use, 1.0 / np.where(use, sig, 1.0) ** 2, 0.0)
        zz = np.where(use, z, 0.0)
        x, y = cols * px, rows * py
        sw = np.bincount(lab, w, k)
        with np.errstate(invalid="ignore", divide="ignore"):
            cx, cy = np.bincount(lab, w * x, k) / sw, np.bincount(lab, w * y, k) / sw
        x, y = x - np.nan_to_num(cx)[lab], y - np.nan_to_num(cy)[lab]
        basis = (x, y, np.ones_like(x), x * x + y * y)
        A, rhs = out["A"][lo:hi], out["rhs"][lo:hi]
        for i in range(4):
            rhs[:, i] = np.bincount(lab, w * basis[i] * zz, k)
            for j in range(i, 4):
                A[:, i, j] = A[:, j, i] = np.bincount(lab, w * basis[i] * basis[j], k)
        out["n"][lo:hi] = np.bincount(lab, use, k)
        out["szz"][lo:hi] = np.bincount(lab, w * zz * zz, k)
        out["r2"][lo:hi] = np.bincount(lab, basis[3], k)
        out["area"][lo:hi] = np.bincount(lab, minlength=k)

    thread_map(group, label_groups(labels, None, S, BLOCK_VALUES))
    return out


