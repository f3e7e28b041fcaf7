"""The joint mode's per-pixel stage: facets, their planes, their thickness, the tilt per pixel.

1. Facets from colour and height edges (:func:`~.segmentation.segment_facets`).
2. A plane per facet through its reliable heights only (:func:`~.facets.fit_facet_planes`);
   a facet without enough of them has no height tilt (it is marked, not guessed).
3. The exposure refined on facets with a height tilt, then each facet's thickness from its
   colour at its tilt, within its interference order (:func:`~.facets.facet_thickness`).
   Facets without a height tilt use the area-weighted median tilt of those with one as a
   stand-in, with their spread as its error.
4. The tilt per pixel: the MAP of the colour likelihood and the facet's plane as prior
   (:func:`~.tilt.invert_tilt`). The colour term is calibrated: its error per Lab component
   is the facet's own scatter about the model (noise, thickness variation inside the facet,
   model error; at least the image noise) plus the colour change of the facet thickness's
   1-σ error. Facets without a height tilt have the stand-in as a wide prior.
"""

from __future__ import annotations

import logging
import math
from dataclasses import dataclass

import numpy as np

from ..colour.colorimetry import xyz_to_lab
from ..colour.difference import delta_e
from ..core.pixels import pixel_area_side
from .facets import (
    FacetFit,
    FacetThickness,
    facet_edge_distance,
    facet_thickness,
    fit_facet_planes,
    refine_exposure_on_facets,
)
from .segmentation import segment_facets
from .tilt import PixelEstimates, invert_tilt, model_lab_rows

__all__ = ["JointResult", "height_inputs", "joint_tilts"]

log = logging.getLogger(__name__)

#: Correlation area of the focus stage's height errors per window area (window_px²):
#: measured 27-41 px² for the 7 px window on synthetic nd stacks (errors against truth).
_FOCUS_ERROR_CORRELATION = 0.7

#: Height error assumed for an export whose error is not given: tiny, so that the plane
#: fits' covariance comes from their own residuals (the reduced-χ² inflation).
_EXPORT_SIGMA_UM = 1e-4


@dataclass
class JointResult:
    """What the joint stage found.

    Attributes
    ----------
    pixels : PixelEstimates
    facets : ndarray of int32 (H, W)
        Facet labels 0..S-1.
    planes : FacetFit
    thickness : FacetThickness
    area_px : ndarray of int, shape (S,)
        Pixels per facet.
    censored : ndarray of bool (H, W)
        Facets more than half of whose pixels are far darker than the film
        (:func:`~microfacet.analysis.mask.steep_facet_mask`): tilted past the objective's
        acceptance.
    colour_sigma_de : ndarray, shape (S,)
        Calibrated colour error per Lab component of one pixel, per facet.
    exposure : float
    """

    pixels: PixelEstimates
    facets: np.ndarray
    planes: FacetFit
    thickness: FacetThickness
    area_px: np.ndarray
    censored: np.ndarray
    colour_sigma_de: np.ndarray
    exposure: float


def height_inputs(surface, *, from_focus):
    """Height, its 1-σ error, the pixels whose height may be used, and the correlation area
    of the errors (pixels).

    From focus: the focus stage's reliable pixels and its per-pixel error
    (``height_sigma_um``; a quarter of the slice spacing where the focus stage gives none),
    correlated over about the focus window (area 0.7 window², measured). From an export:
    every finite height, with an error left to the plane fits' residuals.
    """
    foc = surface.focus
    h = np.asarray(foc.height_fit_um, dtype=np.float64)
    if surface.no_focus:
        return h, np.full(h.shape, np.nan), np.zeros(h.shape, bool), 1.0
    if not from_focus:
        return h, np.full(h.shape, _EXPORT_SIGMA_UM), np.isfinite(h), 1.0
    rel = np.asarray(foc.reliable, bool) & np.isfinite(h)
    sig = getattr(foc, "height_sigma_um", None)
    if sig is None:
        z = np.sort(np.asarray(foc.z_um, dtype=np.float64))
        step = float(np.median(np.diff(z))) if z.size > 1 else 1.0
        sig = np.full(h.shape, 0.25 * step)
    sig = np.asarray(sig, dtype=np.float64)
    corr = _FOCUS_ERROR_CORRELATION * float(foc.params.get("window_px", 1)) ** 2
    return h, sig, rel & np.isfinite(sig) & (sig > 0), corr


def _weighted_median(x, w):
    o = np.argsort(x)
    c = np.cumsum(w[o])
    return float(x[o][np.searchsorted(c, 0.5 * c[-1])])


def _stand_in_tilt(planes, area):
    """Area-weighted median and spread of the fitted facets' tilts (0, 10° without any)."""
    ok = planes.fitted & np.isfinite(planes.tilt_deg)
    if ok.sum() < 3:
        return 0.0, 10.0
    t, a = planes.tilt_deg[ok], area[ok].astype(np.float64)
    med = _weighted_median(t, a)
    spread = math.sqrt(float(np.average((t - med) ** 2, weights=a)))
    return med, max(spread, 1.0)


def _colour_sigma(labels, lab, usable, table, d_f, t_f, exposure, noise_de, s_d,
                  delta_e_method):
    """Per facet: √(max(noise², mean ΔE²/3) + (∂ΔE/∂d · σ_d)²), ΔE of its pixels to its model."""
    S = d_f.size
    good_f = np.isfinite(d_f) & np.isfinite(t_f)
    flat = np.flatnonzero(usable & good_f[labels])
    fid = labels.reshape(-1)[flat]
    lab_flat = lab.reshape(-1, 3)
    white = table.white_xyz.astype(np.float32)
    th = np.clip(t_f, table.theta_deg[0], table.theta_deg[-1])
    # one model colour per facet (its thickness at its tilt), compared with its pixels
    model_f = np.full((S, 3), np.nan, np.float32)
    model_f[good_f] = xyz_to_lab((table.xyz_at(th[good_f], d_f[good_f]) * exposure).astype(
        np.float32), white=white)
    de = np.empty(fid.size, np.float32)
    for a in range(0, fid.size, 262144):
        f = fid[a:a + 262144]
        de[a:a + 262144] = delta_e(model_f[f], lab_flat[flat[a:a + 262144]],
                                   method=delta_e_method)
    cnt = np.bincount(fid, minlength=S)
    ms = np.bincount(fid, weights=de.astype(np.float64) ** 2, minlength=S) / np.maximum(cnt, 1)
    good = np.isfinite(d_f) & np.isfinite(t_f)
    lo = np.where(good, np.clip(d_f - 0.5, table.thickness_nm[0], table.thickness_nm[-1]), 0)
    hi = np.where(good, np.clip(d_f + 0.5, table.thickness_nm[0], table.thickness_nm[-1]), 0)
    th0 = np.where(good, th, 0.0)
    lab_lo = xyz_to_lab((table.xyz_at(th0, lo) * exposure).astype(np.float32), white=white)
    lab_hi = xyz_to_lab((table.xyz_at(th0, hi) * exposure).astype(np.float32), white=white)
    with np.errstate(invalid="ignore", divide="ignore"):
        j_d = delta_e(lab_hi, lab_lo, method=delta_e_method) / np.maximum(hi - lo, 1e-9)
    var = np.maximum(noise_de ** 2, ms / 3.0) + (j_d * np.nan_to_num(s_d, nan=0.0)) ** 2
    return np.where(good, np.sqrt(var), np.nan)


def joint_tilts(colour, surface, roi, table, *, theta_grid_deg, max_tilt_deg, exposure,
                estimate_exposure, facet_size_um, pixel_size_um, from_focus=True, seed=0,
                timer=None, delta_e_method="CIEDE2000") -> JointResult:
    """Run the joint stage (see the module notes).

    Parameters
    ----------
    colour : ColourImage
    surface : Surface
    roi : RoiFit
    table : ColourTable
    theta_grid_deg : ndarray
        From :func:`~microfacet.analysis.tilt.tilt_grid`.
    max_tilt_deg : float
        The acceptance limit asin(NA)/2.
    exposure : float
        From the ROI stage.
    estimate_exposure : bool
        Refine the exposure on facets.
    facet_size_um : float
    pixel_size_um : float or (float, float)
        ``(y, x)`` for non-square pixels (facet sizes in pixels use the geometric mean).
    from_focus : bool
        The height comes from focus (its reliable pixels) rather than an export.
    timer : StageTimer, optional
        Records ``segmentation`` and ``facet_fits``.
    delta_e_method : str

    Returns
    -------
    JointResult
    """
    lab = colour.lab
    shape = lab.shape[:2]
    thick_roi_px = roi.thickness_nm[roi.index_map(shape)]
    usable = ~colour.mask.mask & np.isfinite(thick_roi_px)
    h, h_sig, rel, corr_px = height_inputs(surface, from_focus=from_focus)
    facet_px = facet_size_um / pixel_area_side(pixel_size_um)
    facets = segment_facets(lab, facet_px=facet_px, noise_de=colour.noise_de,
                            height_um=np.where(rel, h, np.nan), height_sigma_um=h_sig,
                            pixel_size_um=pixel_size_um)
    if timer is not None:
        timer.lap("segmentation")
    S = int(facets.max()) + 1
    area = np.bincount(facets.ravel(), minlength=S)
    dist = facet_edge_distance(facets)
    interior = dist >= 1.5
    planes = fit_facet_planes(facets, h, height_sigma_um=h_sig, reliable=rel & (dist >= 1.0),
                              pixel_size_um=pixel_size_um, correlation_px=corr_px)
    fitted = planes.fitted
    t_in, s_in = _stand_in_tilt(planes, area)
    log.info("facets: %d, %d with a height tilt (%.0f%% of the area); stand-in tilt %.1f ± "
             "%.1f deg", S, int(fitted.sum()), 100.0 * area[fitted].sum() / max(area.sum(), 1),
             t_in, s_in)
    tilt_f = np.where(fitted, np.clip(planes.tilt_deg, 0, max_tilt_deg), t_in)
    tsig_f = np.where(fitted, planes.tilt_sigma_deg, s_in)
    if estimate_exposure:
        exposure = refine_exposure_on_facets(facets, lab, usable,
                                             np.where(fitted, tilt_f, np.nan), thick_roi_px,
                                             table, exposure, interior=interior, seed=seed,
                                             delta_e_method=delta_e_method)
        log.info("exposure refined on facets: %.4f", exposure)
    ft = facet_thickness(facets, lab, usable, tilt_f, thick_roi_px, table, exposure=exposure,
                         tilt_sigma_deg=tsig_f, noise_de=colour.noise_de, interior=interior,
                         delta_e_method=delta_e_method)
    if timer is not None:
        timer.lap("facet_fits")
    d_f = ft.thickness_nm
    c_sig = _colour_sigma(facets, lab, usable, table, d_f, tilt_f, exposure, colour.noise_de,
                          ft.sigma_nm, delta_e_method)
    flat = np.flatnonzero(usable & np.isfinite(d_f)[facets])   # flat indices: 8 B/px
    fid = facets.reshape(-1)[flat]
    rows_lab = model_lab_rows(table, np.where(np.isfinite(d_f), d_f, table.thickness_nm[0]),
                              theta_grid_deg, exposure=exposure)
    # thickness, noise and prior are the facet's: given per row, gathered chunk by chunk
    inv = invert_tilt(lab.reshape(-1, 3)[flat], rows_lab, fid, theta_grid_deg, table=table,
                      thickness_px=d_f, exposure=exposure, noise_de=c_sig,
                      prior_deg=tilt_f, prior_sigma_deg=tsig_f, by_row=True,
                      delta_e_method=delta_e_method)
    out = PixelEstimates.empty(shape)
    out.thickness_nm.reshape(-1)[flat] = d_f[fid]
    out.fill(flat, None, inv)
    del inv, flat, fid
    out.thickness_group = facets
    # facets tilted past the acceptance: more than half their pixels far darker than film
    dark = np.bincount(facets.ravel(), weights=colour.mask.steep.ravel(), minlength=S)
    censored = (dark > 0.5 * area)[facets]
    return JointResult(out, facets, planes, ft, area, censored, c_sig, float(exposure))
