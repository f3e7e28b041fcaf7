"""Joint per-facet estimate of thickness and tilt (beyond the seed).

Colour moves about 2 ΔE00 per nm of thickness but only 0.03-0.3 per degree of tilt: to
first order a tilt θ acts like a thickness change d·(1 − cos θ₁), so a 1 nm thickness
change inside a region masquerades as a 10-20° tilt in the seed's per-pixel inversion.
Thickness and tilt cannot both be read from one pixel's colour. The joint estimate uses
what each source is good at:

1. **Facets from colour.** The seed observed (§3.3.2, Fig. 17) that one colour in the
   microscope image is one flat facet. The all-in-focus image is segmented into facets
   (SLIC superpixels on Lab, mean size = the expected facet size).
2. **Tilt from the height map, per facet.** A weighted least-squares plane is fitted to the
   height-from-focus map over each facet (weights: focus reliability, and distance from
   the facet boundary, where the focus window mixes neighbours). Many noisy heights give
   one well-determined slope; its covariance gives the prior σ.
3. **Thickness from colour, per facet.** With the facet's tilt known, its thickness is the
   d of least ΔE00 between the mean Lab of the facet's interior and the model, searched
   within ±30 nm of its ROI's thickness (same interference order).
4. **Tilt per pixel**: the MAP with the facet-plane prior and the colour likelihood at the
   facet's thickness (:func:`microfacet.analysis.tilt.invert_tilt`), which also reports the share of
   the information that came from colour.
"""

from __future__ import annotations

import logging
import math
from dataclasses import dataclass

import numpy as np

from ..colour.colorimetry import xyz_to_lab
from ..colour.difference import delta_e
from ..core.lazy import load
from .tilt import PixelEstimates, invert_tilt, model_lab_rows

segmentation = load("skimage.segmentation")
ndimage = load("scipy.ndimage")
optimize = load("scipy.optimize")

__all__ = ["FacetFit", "facet_edge_distance", "facet_thickness", "fit_facet_planes",
           "joint_tilts", "refine_exposure_on_facets", "segment_facets", "thickness_blocks"]

log = logging.getLogger(__name__)


def segment_facets(lab, *, facet_px, compactness=2.0):
    """Superpixel segmentation of a Lab image into facets.

    Parameters
    ----------
    lab : ndarray, shape (H, W, 3)
        CIELAB image (NaN allowed; treated as mid grey for segmentation).
    facet_px : float
        Expected mean facet diameter in pixels.
    compactness : float
        SLIC compactness in Lab units (low: follow colour edges).

    Returns
    -------
    ndarray of int32, shape (H, W)
        Segment labels 0..S-1.
    """
    lab = np.asarray(lab, dtype=np.float64)
    img = np.where(np.isfinite(lab), lab, np.array([50.0, 0.0, 0.0]))
    h, w = img.shape[:2]
    n_seg = max(1, int(round(h * w / (np.pi * (max(facet_px, 2.0) / 2) ** 2))))
    labels = segmentation.slic(img, n_segments=n_seg, compactness=compactness, convert2lab=False,
                  channel_axis=-1, start_label=0, enforce_connectivity=True, sigma=0.5)
    _, inv = np.unique(labels, return_inverse=True)
    return inv.reshape(h, w).astype(np.int32)


@dataclass
class FacetFit:
    """Plane fits per facet (arrays of length S).

    Attributes
    ----------
    slope_x, slope_y : ndarray
        dh/dx and dh/dy (x = image columns, y = image rows, both in µm).
    tilt_deg, tilt_sigma_deg : ndarray
        Tilt of the plane and its 1-σ uncertainty.
    n_eff : ndarray
        Sum of the weights.
    fitted : ndarray of bool
        False where too few weighted pixels: tilt falls back to the mean of the smoothed
        height-map tilt with a wide σ.
    """

    slope_x: np.ndarray
    slope_y: np.ndarray
    tilt_deg: np.ndarray
    tilt_sigma_deg: np.ndarray
    n_eff: np.ndarray
    fitted: np.ndarray


def fit_facet_planes(labels, height_um, weight, *, pixel_size_um, fallback_tilt_deg,
                     min_weight=6.0, fallback_sigma_deg=8.0) -> FacetFit:
    """Weighted least-squares plane per segment (vectorised with bincount sums).

    Parameters
    ----------
    labels : ndarray of int, shape (H, W)
    height_um : ndarray, shape (H, W)
        Height map (NaN ignored).
    weight : ndarray, shape (H, W)
        Non-negative weights (0 = not used).
    pixel_size_um : float
    fallback_tilt_deg : ndarray, shape (H, W)
        Per-pixel tilt used (averaged per segment) where a plane cannot be fitted.
    """
    h, w = labels.shape
    S = int(labels.max()) + 1
    yy, xx = np.mgrid[0:h, 0:w].astype(np.float64) * pixel_size_um
    z = np.asarray(height_um, dtype=np.float64)
    wt = np.where(np.isfinite(z), np.asarray(weight, dtype=np.float64), 0.0)
    z = np.where(np.isfinite(z), z, 0.0)
    lab = labels.ravel()

    def s(v):
        return np.bincount(lab, weights=(wt * v).ravel(), minlength=S)

    sw = s(1.0)
    sx, sy, sz = s(xx), s(yy), s(z)
    sxx, sxy, syy = s(xx * xx), s(xx * yy), s(yy * yy)
    sxz, syz, szz = s(xx * z), s(yy * z), s(z * z)
    with np.errstate(invalid="ignore", divide="ignore"):
        mx, my, mz = sx / sw, sy / sw, sz / sw
        cxx = sxx - sw * mx * mx
        cxy = sxy - sw * mx * my
        cyy = syy - sw * my * my
        cxz = sxz - sw * mx * mz
        cyz = syz - sw * my * mz
        czz = szz - sw * mz * mz
        det = cxx * cyy - cxy * cxy
        a = (cyy * cxz - cxy * cyz) / det  # dz/dx
        b = (cxx * cyz - cxy * cxz) / det  # dz/dy
        resid = np.maximum(czz - a * cxz - b * cyz, 0.0)
        var = resid / np.maximum(sw - 3.0, 1.0)
        # Covariance of (a, b) = var * inv(C); project on the gradient direction.
        g = np.hypot(a, b)
        ux, uy = np.where(g > 0, a / g, 1 / np.sqrt(2)), np.where(g > 0, b / g, 1 / np.sqrt(2))
        var_g = var * (cyy * ux * ux - 2 * cxy * ux * uy + cxx * uy * uy) / det
    fitted = (sw >= min_weight) & (det > 1e-12 * np.maximum(cxx * cyy, 1e-300)) & np.isfinite(a)
    tilt = np.rad2deg(np.arctan(np.where(fitted, g, 0.0)))
    sig = np.rad2deg(np.sqrt(np.maximum(var_g, 0.0)) / (1.0 + g * g))
    fb = np.asarray(fallback_tilt_deg, dtype=np.float64)
    ok = np.isfinite(fb)
    cnt = np.bincount(lab, weights=ok.ravel().astype(float), minlength=S)
    fb_sum = np.bincount(lab, weights=np.where(ok, fb, 0).ravel(), minlength=S)
    fb_mean = fb_sum / np.maximum(cnt, 1)
    tilt = np.where(fitted, tilt, fb_mean)
    sig = np.where(fitted & np.isfinite(sig), np.maximum(sig, 0.25), fallback_sigma_deg)
    return FacetFit(np.where(fitted, a, np.nan), np.where(fitted, b, np.nan), tilt, sig, sw,
                    fitted)


def facet_thickness(labels, lab, usable, facet_tilt_deg, roi_thickness_px, table, *,
                    exposure, half_range_nm=30.0, step_nm=0.1, interior=None,
                    delta_e_method="CIEDE2000"):
    """Thickness per facet from its mean Lab at its plane tilt, near its ROI's thickness.

    The search covers ±``half_range_nm`` around the facet's ROI thickness: wide enough for
    the spread of thickness inside a ROI, well inside one interference order (~110 nm).
    ``interior`` (bool H×W) restricts the facet's mean colour to pixels away from its
    boundary (partly shadowed by the step to the neighbour) where a facet has any.
    ``delta_e_method`` is the colour-difference formula (``"CIEDE2000"``, ``"CIE94"``,
    ``"CIE76"``; :func:`microfacet.colour.difference.delta_e`).

    Returns
    -------
    thickness_nm, delta_e : ndarray, shape (S,)
        NaN for facets with no usable pixel.
    """
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
    d_roi = np.bincount(lb[u], weights=np.asarray(roi_thickness_px).ravel()[u],
                        minlength=S) / np.maximum(cnt, 1)
    has = (cnt > 0) & np.isfinite(d_roi)
    idx = np.flatnonzero(has)
    off = np.arange(-half_range_nm, half_range_nm + 1e-9, step_nm)
    lo, hi = float(table.thickness_nm[0]), float(table.thickness_nm[-1])
    th_out = np.full(S, np.nan)
    de_out = np.full(S, np.nan)
    t_lo, t_hi = float(table.theta_deg[0]), float(table.theta_deg[-1])
    for a in range(0, idx.size, 4096):
        ii = idx[a:a + 4096]
        grid = np.clip(d_roi[ii, None] + off[None, :], lo, hi)
        th = np.clip(facet_tilt_deg[ii], t_lo, t_hi)[:, None]
        xyz = table.xyz_at(th, grid) * exposure
        model = xyz_to_lab(xyz.astype(np.float32), white=table.white_xyz.astype(np.float32))
        de = delta_e(model, mean_lab[ii, None, :].astype(np.float32),
                     method=delta_e_method).astype(np.float64)
        k = np.argmin(de, axis=1)
        km = np.clip(k, 1, off.size - 2)
        r = np.arange(ii.size)
        y0, y1, y2 = de[r, km - 1] ** 2, de[r, km] ** 2, de[r, km + 1] ** 2
        den = y0 - 2 * y1 + y2
        with np.errstate(divide="ignore", invalid="ignore"):
            o = np.where((den > 0) & (k == km), np.clip(0.5 * (y0 - y2) / den, -1, 1), 0.0)
        th_out[ii] = grid[r, k] + o * step_nm
        de_out[ii] = de[r, k]
    return th_out, de_out


def refine_exposure_on_facets(facets, lab, usable, tilt_f, thick_roi_px, table, exposure, *,
                               interior, seed=0, n_facets=2000, delta_e_method="CIEDE2000"):
    """Exposure of least median facet ΔE00, each facet's thickness re-solved per candidate.

    Facets are homogeneous (one tilt, one thickness), unlike ROIs that span several
    thickness regions, so they pin the exposure down better than the ROI fit did.
    """
    S = int(facets.max()) + 1
    rng = np.random.default_rng(seed)
    cnt = np.bincount(facets[usable & interior], minlength=S)
    cand = np.flatnonzero(cnt >= 4)
    if cand.size < 10:
        return exposure
    pick = np.zeros(S, bool)
    pick[rng.choice(cand, min(n_facets, cand.size), replace=False)] = True
    sel = usable & pick[facets]

    def objective(log_e):
        _, de = facet_thickness(facets, lab, sel, tilt_f, thick_roi_px, table,
                                exposure=math.exp(log_e), interior=interior,
                                delta_e_method=delta_e_method)
        return float(np.nanmedian(de))

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


def thickness_blocks(shape, *, pixel_size_um, block_um=10.0) -> np.ndarray:
    """Block id per pixel of square blocks of ``block_um`` (at least 4 px).

    Neighbouring facets share a smooth thickness field: they are not independent samples for
    the mixture's model choice. Blocks of ~10 µm are (docs/accuracy.md).
    """
    h, w = shape
    block = max(4, int(round(block_um / pixel_size_um)))
    by, bx = np.mgrid[0:h, 0:w]
    return (by // block) * ((w + block - 1) // block) + bx // block


def joint_tilts(colour, surface, roi, table, *, theta_grid_deg, max_tilt_deg, exposure,
                estimate_exposure, facet_size_um, pixel_size_um, from_focus=True, seed=0,
                timer=None, delta_e_method="CIEDE2000"):
    """The joint mode's per-pixel stage: facets, their planes, their thickness, and the tilt
    per pixel as the MAP with the facet-plane prior (see the module notes).

    Parameters
    ----------
    colour : ColourImage
    surface : Surface
    roi : RoiFit
    table : ColourTable
    theta_grid_deg : ndarray
        From :func:`~microfacet.analysis.tilt.tilt_grid`.
    max_tilt_deg : float
    exposure : float
        From the ROI stage.
    estimate_exposure : bool
        Refine the exposure on facets (:func:`refine_exposure_on_facets`).
    facet_size_um, pixel_size_um : float
    from_focus : bool
        The height comes from focus (weights from its reliability) rather than an export
        (trusted where finite).
    timer : StageTimer, optional
        Records ``segmentation`` and ``facet_fits``.
    delta_e_method : str
        Colour-difference formula (:func:`microfacet.colour.difference.delta_e`).

    Returns
    -------
    estimates : PixelEstimates
    facets : ndarray of int32 (H, W)
    exposure : float
    """
    lab = colour.lab
    shape = lab.shape[:2]
    foc = surface.focus
    thick_roi_px = roi.thickness_nm[roi.index_map(shape)]
    usable = ~colour.mask.mask & np.isfinite(thick_roi_px)
    facets = segment_facets(lab, facet_px=facet_size_um / pixel_size_um)
    if timer is not None:
        timer.lap("segmentation")
    if from_focus:
        rel = np.clip(np.nan_to_num(foc.reliability_db, nan=0.0) / 20.0, 0.0, 1.0) ** 2
    else:  # a microscope export's height is trusted where it is finite
        rel = np.isfinite(foc.height_fit_um).astype(np.float64)
    dist = facet_edge_distance(facets)
    weight = rel * np.clip(dist / 2.0, 0.0, 1.0) if not surface.no_focus else np.zeros(shape)
    ff = fit_facet_planes(facets, foc.height_fit_um, weight, pixel_size_um=pixel_size_um,
                          fallback_tilt_deg=surface.tilt_deg)
    tilt_f = np.clip(ff.tilt_deg, 0, max_tilt_deg)
    if estimate_exposure:
        exposure = refine_exposure_on_facets(facets, lab, usable, tilt_f, thick_roi_px, table,
                                             exposure, interior=dist >= 1.5, seed=seed,
                                             delta_e_method=delta_e_method)
        log.info("exposure refined on facets: %.4f", exposure)
    d_f, _ = facet_thickness(facets, lab, usable, tilt_f, thick_roi_px, table,
                             exposure=exposure, interior=dist >= 1.5,
                             delta_e_method=delta_e_method)
    if timer is not None:
        timer.lap("facet_fits")
    yy, xx = np.nonzero(usable)
    fid = facets[yy, xx]
    d_rows = np.where(np.isfinite(d_f), d_f, table.thickness_nm[0])
    rows_lab = model_lab_rows(table, d_rows, theta_grid_deg, exposure=exposure)
    prior = np.clip(ff.tilt_deg[fid], 0, max_tilt_deg)
    inv = invert_tilt(lab[yy, xx], rows_lab, fid, theta_grid_deg, table=table,
                      thickness_px=d_rows[fid], exposure=exposure, noise_de=colour.noise_de,
                      prior_deg=prior, prior_sigma_deg=ff.tilt_sigma_deg[fid],
                      delta_e_method=delta_e_method)
    out = PixelEstimates.empty(shape)
    out.thickness_nm[yy, xx] = d_rows[fid]
    out.fill(yy, xx, inv)
    out.thickness_group = thickness_blocks(shape, pixel_size_um=pixel_size_um)
    return out, facets, float(exposure)
