"""The distributions stage, and saying when the data cannot tell.

Joint mode (:func:`fit_joint_distributions`)
    * **Thickness**: one sample per facet (its thickness, its 1-σ error, its area), the
      mixture deconvolved from the errors (:func:`~.mixtures.fit_thickness_mixture`) with
      the number of independent thickness regions as ``n_eff`` (the area-weighted count
      of :func:`~.sampling.thickness_regions`). Dark (censored) facets and facets whose
      colour the model does not explain (:func:`unexplained_facets`) are left out.
    * **NDF**: one sample per facet with a height tilt (its plane's slope, the slope noise of
      the fit, its area), deconvolved; dark facet-sized areas (tilted past the acceptance)
      enter as censored samples (:func:`~.ndf_fit.fit_ndf_mixture`); ``n_eff`` = facets.

Seed mode (:func:`fit_seed_distributions`)
    The seed's per-pixel histograms: thickness per ROI, tilt per pixel from colour alone.

Identification (both)
    The NDF is identified when at least :data:`MIN_NDF_FACETS` facets have a height tilt and
    the width of a single lobe fitted to them is known to ±:data:`MAX_WIDTH_ERROR`
    (:func:`~.ndf_fit.width_relative_error`: few facets, or slope noise comparable to the
    lobes, fail), and at most half the area is censored. Colour could stand in for height
    only where a tilt changes the colour in a way no thickness change can mimic, by more
    than the colour error: :func:`colour_tilt_contrast` measures that (docs/conditioning.md);
    the reason says which. The seed mode's colour-only NDF is identified only where it is
    above 3× the pixel noise. The thickness mixture is not identified when the
    interference order is uncertain in most ROIs, or most facets' best thickness lies at
    the edge of their order's window.
"""

from __future__ import annotations

import math

import numpy as np

from ..colour.colorimetry import xyz_to_lab
from ..colour.difference import delta_e
from .mixtures import fit_thickness_mixture
from .ndf_fit import fit_ndf_mixture, width_relative_error
from .sampling import thickness_regions

__all__ = ["AMBIGUOUS_ORDER_DE", "EXCESS_DELTA_E", "MAX_WIDTH_ERROR", "MEDIAN_NOISE_FLOOR_FACTOR",
           "MIN_NDF_FACETS", "NOISE_FLOOR_FACTOR", "NO_SAMPLES", "UNEXPLAINED_MADS",
           "analysis_warnings", "colour_tilt_contrast", "fit_joint_distributions",
           "fit_seed_distributions", "identification", "thickness_reason",
           "unexplained_facets"]

#: Fewest facets with a height tilt for an identified NDF.
MIN_NDF_FACETS = 20
#: Largest relative 1-σ error of the lobe width for an identified NDF.
MAX_WIDTH_ERROR = 0.25
#: A ROI whose runner-up interference order fits within this ΔE00 of its best is ambiguous.
AMBIGUOUS_ORDER_DE = 1.0
#: Mean ΔE00 of pure noise of σ per Lab component, E|N(0, σ²I₃)| = 2·sqrt(2/π)·σ: the
#: image's noise floor of the mean ΔE00 is this × ``noise_de``.
NOISE_FLOOR_FACTOR = 2.0 * math.sqrt(2.0 / math.pi)
#: Median ΔE00 of the same noise: sqrt of the median of χ²₃ (2.366) × σ.
MEDIAN_NOISE_FLOOR_FACTOR = 1.5382
#: A median ΔE00 more than this above its noise floor is reported: the model misses
#: something everywhere, not only at the mixed pixels of edges and grooves (which raise the
#: mean; docs/accuracy.md).
EXCESS_DELTA_E = 1.0


def colour_tilt_contrast(table, thickness_nm, *, exposure, tilt_deg=10.0,
                         delta_e_method="CIEDE2000") -> float:
    """ΔE00 by which a tilt changes the colour beyond what a thickness change can mimic.

    The colour at ``(tilt_deg, d)`` against the nearest colour at tilt 0 over thicknesses
    within ±10 % of ``d``: the part of the tilt's colour change that colour could
    attribute to tilt when the facet's thickness is unknown.

    Examples
    --------
    >>> from microfacet.colour.table import build_colour_table
    >>> t = build_colour_table(thickness_range_nm=(30, 80), theta_range_deg=(0, 20))
    >>> colour_tilt_contrast(t, 51.0, exposure=1.0) < 0.5
    True
    """
    d = float(thickness_nm)
    lo = max(float(table.thickness_nm[0]), 0.9 * d)
    hi = min(float(table.thickness_nm[-1]), 1.1 * d)
    grid = np.linspace(lo, hi, 801)
    white = table.white_xyz.astype(np.float32)
    ref = xyz_to_lab((table.xyz_at(min(tilt_deg, table.theta_deg[-1]), d) * exposure)
                     .astype(np.float32), white=white)
    cand = xyz_to_lab((table.xyz_at(0.0, grid) * exposure).astype(np.float32), white=white)
    return float(np.min(delta_e(cand, ref[None, :], method=delta_e_method)))


#: Robust outlier rule for facet ΔE00: above median + this × 1.4826·MAD.
UNEXPLAINED_MADS = 5.0


def unexplained_facets(delta_e) -> np.ndarray:
    """Facets whose best ΔE00 is a robust outlier among the facets' (median +
    :data:`UNEXPLAINED_MADS` × 1.4826 MAD): the film model does not explain their colour.

    >>> unexplained_facets(np.array([1.0, 1.2, 0.9, 1.1, 1.3, 9.0, np.nan])).tolist()
    [False, False, False, False, False, True, False]
    """
    de = np.asarray(delta_e, dtype=np.float64)
    ok = np.isfinite(de)
    if ok.sum() < 5:
        return np.zeros(de.shape, bool)
    med = float(np.median(de[ok]))
    mad = 1.4826 * float(np.median(np.abs(de[ok] - med)))
    return ok & (de > med + UNEXPLAINED_MADS * max(mad, 0.1))


def thickness_reason(roi, *, edge_fraction=0.0, other_order_fraction=None) -> str:
    """Why the thickness mixture is not identified ("" when it is).

    With facets (joint mode) the order is uncertain when on more than half the area a
    neighbouring order fits within :data:`AMBIGUOUS_ORDER_DE` (``other_order_fraction``);
    without, when more than half the ROIs are ambiguous.
    """
    if other_order_fraction is not None:
        if other_order_fraction > 0.5:
            return (f"interference order uncertain on {100 * other_order_fraction:.0f} % of "
                    f"the area (a neighbouring order fits within {AMBIGUOUS_ORDER_DE:g} "
                    f"ΔE00): narrow --thickness-range to the expected order")
        if edge_fraction > 0.5:
            return (f"{100 * edge_fraction:.0f} % of the area fits best at the edge of its "
                    f"interference order: check the film (--film) and the thickness range")
        return ""
    amb = np.asarray(roi.ambiguity_delta_e, dtype=np.float64)
    fit = np.isfinite(roi.thickness_nm)
    n_amb = int(np.sum(fit & (amb < AMBIGUOUS_ORDER_DE)))
    if fit.sum() and n_amb > 0.5 * fit.sum():
        i = int(np.nanargmin(np.where(fit, amb, np.inf)))
        return (f"interference order uncertain in {n_amb} of {int(fit.sum())} regions "
                f"(e.g. {roi.thickness_nm[i]:.0f} nm and {roi.runner_up_thickness_nm[i]:.0f} "
                f"nm fit alike): narrow --thickness-range to the expected order")
    if edge_fraction > 0.5:
        return (f"{100 * edge_fraction:.0f} % of the area fits best at the edge of its "
                f"interference order: check the film (--film) and the thickness range")
    return ""


def _ndf_reason(n_fit, n_total, area_frac, rel_err, censored_fraction, colour_contrast,
                colour_error, thickness_nm):
    if n_fit >= MIN_NDF_FACETS and rel_err <= MAX_WIDTH_ERROR and censored_fraction <= 0.5:
        return ""
    parts = []
    if censored_fraction > 0.5:
        parts.append(f"{100 * censored_fraction:.0f} % of the surface is tilted past the "
                     f"objective's acceptance")
    elif n_fit < MIN_NDF_FACETS:
        parts.append(f"height from focus gives a plane on {n_fit} of {n_total} facets "
                     f"({100 * area_frac:.1f} % of the area)")
    else:
        parts.append(f"the facets' slopes are too noisy to fix the lobe width (±"
                     f"{100 * rel_err:.0f} %)")
    if colour_contrast <= 3.0 * colour_error:
        parts.append(f"colour cannot carry tilt at {thickness_nm:.0f} nm (a 10° tilt changes "
                     f"it by {colour_contrast:.2f} ΔE00 beyond a thickness change, below 3× "
                     f"the facet colour error {colour_error:.2f})")
    else:
        parts.append(f"colour might carry tilt at {thickness_nm:.0f} nm ({colour_contrast:.2f} "
                     f"ΔE00 for 10°): try --mode seed")
    return "; ".join(parts) + ("; a stack with more texture, a finer z step, or a "
                               "microscope height export would identify it")


def fit_joint_distributions(joint, *, roi, table, max_tilt_deg, max_components=5):
    """Thickness mixture and NDF of a :class:`~.joint.JointResult`, with identification.

    Returns
    -------
    thickness_fit, ndf_fit : MixtureFit or None
        None without samples (fewer than two facets with a value).
    """
    th = joint.thickness
    area = joint.area_px.astype(np.float64)
    cens_px = np.bincount(joint.facets.ravel(), weights=joint.censored.ravel(),
                          minlength=area.size)
    cens_frac = cens_px / np.maximum(area, 1)
    # Facets whose colour the film model does not explain (dust, pit floors, mixed or dark
    # facets: ΔE00 a robust outlier among the facets') and censored (dark) facets carry no
    # thickness: they are left out of the mixture, and counted.
    unexplained = unexplained_facets(th.delta_e)
    ok_t = np.isfinite(th.thickness_nm) & (area > 0) & (cens_frac < 0.5) & ~unexplained
    tfit = None
    if ok_t.sum() >= 2:
        regions = thickness_regions(joint.facets, np.where(ok_t, th.thickness_nm, np.nan),
                                    th.sigma_nm)
        n_eff = max(1.0, regions.effective_count)
        tfit = fit_thickness_mixture(th.thickness_nm[ok_t], sigma_nm=th.sigma_nm[ok_t],
                                     weights=area[ok_t], n_effective=n_eff,
                                     max_components=max_components, background=True)
        a_t = area[ok_t].sum()
        edge = float(area[ok_t & th.at_window_edge].sum() / a_t)
        amb = ok_t & (th.delta_e_other_order < th.delta_e + AMBIGUOUS_ORDER_DE)
        other = float(area[amb].sum() / a_t)
        tfit.reason = thickness_reason(roi, edge_fraction=edge, other_order_fraction=other)
        tfit.identified = not tfit.reason
        tfit.info.update({"facets": int(ok_t.sum()),
                          "unexplained_area_fraction": float(area[unexplained].sum()
                                                             / max(area.sum(), 1.0)),
                          "thickness_regions": regions.count, "order_edge_fraction": edge,
                          "order_ambiguous_fraction": other})

    pl = joint.planes
    fit_ok = pl.fitted & np.isfinite(pl.tilt_deg) & (cens_frac < 0.5)
    # A plane steeper than the acceptance (a wall seen through the blur) is not an exact
    # sample of a censored distribution: it counts as censored, with the dark facets.
    beyond = fit_ok & (pl.tilt_deg > max_tilt_deg)
    use = fit_ok & ~beyond
    C = float(joint.censored.sum()) + float(area[beyond].sum())
    mean_area = float(area[use].mean()) if use.any() else float(area.mean())
    n_eff = float(use.sum()) + C / max(mean_area, 1.0)
    nfit = None
    d_med = float(np.nanmedian(th.thickness_nm)) if np.isfinite(th.thickness_nm).any() else 0.0
    contrast = colour_tilt_contrast(table, d_med, exposure=joint.exposure) if d_med > 0 else 0.0
    c_err = float(np.nanmedian(joint.colour_sigma_de / np.sqrt(np.maximum(area, 1))))
    if use.sum() >= 2:
        nfit = fit_ndf_mixture(pl.tilt_deg[use], slope_sigma=pl.slope_sigma[use],
                               weights=area[use], censored_weight=C,
                               censor_tilt_deg=max_tilt_deg if C > 0 else None,
                               n_effective=max(n_eff, 1.0), max_components=max_components)
        rel = width_relative_error(pl.tilt_deg[use], pl.slope_sigma[use], area[use],
                                   float(use.sum()))
    else:
        rel = math.inf
        # No facet planes: for inspection only (never identified), the per-pixel tilts,
        # one independent sample per facet.
        okp = np.isfinite(joint.pixels.tilt_deg)
        if okp.sum() >= 2:
            nfit = fit_ndf_mixture(joint.pixels.tilt_deg[okp], group=joint.facets[okp],
                                   max_components=max_components)
            nfit.info["samples"] = "per-pixel tilt (no facet has a height plane)"
    # the censored share of the measured surface (of the whole, when no facet has a tilt)
    seen = float(area[use].sum()) + C if use.any() else float(area.sum())
    reason = _ndf_reason(int(use.sum()), int(area.size),
                         float(area[pl.fitted].sum() / max(area.sum(), 1)), rel,
                         C / max(seen, 1.0), contrast, c_err, d_med)
    if nfit is not None:
        nfit.identified, nfit.reason = not reason, reason
        nfit.info.setdefault("samples", "facet plane tilts (height from focus)")
        nfit.info.update({"facets": int(use.sum()), "facets_total": int(area.size),
                          "width_relative_error": float(rel) if math.isfinite(rel) else None,
                          "colour_tilt_contrast_de": contrast})
    return tfit, nfit


def fit_seed_distributions(pixels, *, roi, table, exposure, noise_de, max_components=5):
    """The seed's fits on per-pixel estimates (thickness per ROI, tilt from colour alone).

    The NDF is identified only if colour carries tilt at the median thickness
    (:func:`colour_tilt_contrast` above 3× the pixel noise).
    """
    ok = np.isfinite(pixels.thickness_nm)
    tfit = (fit_thickness_mixture(pixels.thickness_nm[ok], max_components=max_components,
                                  group=pixels.thickness_group[ok]) if ok.sum() >= 2 else None)
    if tfit is not None:
        tfit.reason = thickness_reason(roi)
        tfit.identified = not tfit.reason
    okt = np.isfinite(pixels.tilt_deg)
    nfit = None
    if okt.sum() >= 2:
        nfit = fit_ndf_mixture(pixels.tilt_deg[okt], max_components=max_components,
                               group=pixels.thickness_group[okt])
        d_med = float(np.nanmedian(pixels.thickness_nm))
        contrast = colour_tilt_contrast(table, d_med, exposure=exposure)
        if contrast <= 3.0 * noise_de:
            nfit.identified = False
            nfit.reason = (f"tilt from colour alone (seed mode): colour cannot carry tilt at "
                           f"{d_med:.0f} nm (a 10° tilt changes it by {contrast:.2f} ΔE00 "
                           f"beyond a thickness change, below the pixel noise "
                           f"{noise_de:.2f}); the joint mode takes tilt from the height map")
        nfit.info["colour_tilt_contrast_de"] = contrast
    return tfit, nfit


#: The reason given when a distribution has no samples at all to fit.
NO_SAMPLES = {"thickness": "no thickness values to fit", "ndf": "no facet tilts to fit"}


def identification(fit, what) -> tuple[bool, str]:
    """``(identified, reason)`` of a fit of ``what`` (``"thickness"`` or ``"ndf"``); a
    missing fit (None: no samples) is not identified, with :data:`NO_SAMPLES`' reason.

    >>> identification(None, "ndf")
    (False, 'no facet tilts to fit')
    """
    if fit is None:
        return False, NO_SAMPLES[what]
    return bool(fit.identified), fit.reason


#: A sample is reported as tilted when its mean plane's tilt exceeds this fraction of the NDF's
#: rms lobe width: the zero-mean lobes are tilts against the optical axis, and a
#: tilted mounting m widens a lobe σ to about √(σ² + m²) (+12 % at m = σ/2).
SAMPLE_TILT_WARN_FRACTION = 0.5


def mean_plane_tilt_deg(joint) -> float | None:
    """Tilt of the sample's mean plane against the optical axis, degrees: the area-weighted
    mean facet slope (None without fitted facet planes).

    >>> from types import SimpleNamespace as NS
    >>> planes = NS(fitted=np.array([True, True, False]), slope_x=np.array([0.1, 0.3, 9.0]),
    ...             slope_y=np.array([0.0, 0.0, 9.0]))
    >>> round(mean_plane_tilt_deg(NS(planes=planes, area_px=np.array([1, 1, 5]))), 3)
    11.31
    """
    if joint is None:
        return None
    f = np.asarray(joint.planes.fitted, bool)
    w = np.asarray(joint.area_px, np.float64) * f
    if not f.any() or w.sum() <= 0:
        return None
    a = float(np.sum(w * np.where(f, joint.planes.slope_x, 0.0)) / w.sum())
    b = float(np.sum(w * np.where(f, joint.planes.slope_y, 0.0)) / w.sum())
    return float(np.degrees(np.arctan(np.hypot(a, b))))


def _ndf_width_deg(ndf_fit):
    mix = getattr(ndf_fit, "mixture", ndf_fit)
    try:
        return float(mix.rms_sd_deg)
    except (AttributeError, TypeError, ValueError):
        return None


def analysis_warnings(*, thickness_fit, ndf_fit, roi, delta_e_median, noise_de,
                      mean_plane_tilt_deg=None) -> list[str]:
    """One line per thing a user must know before trusting the distributions.

    An unidentified (or missing) thickness mixture or NDF, ambiguous interference orders
    (ROIs whose runner-up order fits within :data:`AMBIGUOUS_ORDER_DE`), and a median ΔE00
    more than :data:`EXCESS_DELTA_E` above its noise floor
    (:data:`MEDIAN_NOISE_FLOOR_FACTOR` × ``noise_de``), and a sample whose mean plane is
    tilted by more than :data:`SAMPLE_TILT_WARN_FRACTION` of the NDF's rms lobe width.

    Examples
    --------
    >>> from types import SimpleNamespace as NS
    >>> roi = NS(thickness_nm=np.array([130.0, 131.0]), ambiguity_delta_e=np.array([0.2, 5.0]))
    >>> for w in analysis_warnings(thickness_fit=None, ndf_fit=None, roi=roi,
    ...                            delta_e_median=4.0, noise_de=1.0):
    ...     print(w[:40])
    thickness distribution not identified: n
    NDF not identified: no facet tilts to fi
    1 of 2 ROIs have an ambiguous interferen
    median dE00 4.00 is 2.46 above the image
    """
    out = []
    for what, fit, key in (("thickness distribution", thickness_fit, "thickness"),
                           ("NDF", ndf_fit, "ndf")):
        ok, reason = identification(fit, key)
        if fit is None:
            out.append(f"{what} not identified: {reason}")
        elif not ok:
            out.append(f"{what} not identified (the fit is written for inspection only): "
                       f"{reason}")
    fit = np.isfinite(roi.thickness_nm)
    amb = int(np.sum(fit & (np.nan_to_num(roi.ambiguity_delta_e, nan=np.inf)
                            < AMBIGUOUS_ORDER_DE)))
    if amb:
        out.append(f"{amb} of {int(fit.sum())} ROIs have an ambiguous interference order "
                   f"(runner-up within {AMBIGUOUS_ORDER_DE:g} dE00)")
    floor = MEDIAN_NOISE_FLOOR_FACTOR * noise_de
    if delta_e_median is not None and delta_e_median > floor + EXCESS_DELTA_E:
        out.append(f"median dE00 {delta_e_median:.2f} is {delta_e_median - floor:.2f} above the "
                   f"image's noise floor {floor:.2f}: the model does not explain the colours "
                   f"(wrong film, illuminant or exposure?)")
    width = _ndf_width_deg(ndf_fit)
    if mean_plane_tilt_deg is not None and width is not None \
            and mean_plane_tilt_deg > SAMPLE_TILT_WARN_FRACTION * width:
        out.append(f"the sample's mean plane is tilted by {mean_plane_tilt_deg:.2f} deg against "
                   f"the optical axis: the NDF is of facet tilts against the axis, not the "
                   f"surface; level the sample on the stage for an NDF of the surface")
    return out
