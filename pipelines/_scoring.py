"""Scores of an analysis against synthetic truth: the fair scores of ``accuracy-sweep``
(and ``accuracy-ndf-limits``) and the per-preset scores of ``accuracy-presets``
(:func:`preset_scores`).

Every function but :func:`preset_scores` takes plain arrays (or the dicts of
``truth/params.json`` and ``summary.json``), so it can be checked alone:
``python -m doctest pipelines/_scoring.py``.

What the sweep scores, and why it is fair to the analysis:

* **Thickness per true region**: the median of the per-pixel estimate over the region's
  interior (pixels at least ``erode_px`` from any other region, so mixed boundary pixels do
  not count) against the region's true mean thickness; MAE and median absolute error over
  the regions of a scene. A region with fewer than ``min_pixels`` estimated interior pixels
  is not scored.
* **Map read an order off**: the share of all mapped pixels, boundaries included, farther
  than ``ORDER_OFF_NM`` from their true region's mean: what the per-region median hides.
* **Populations**: the fitted mixture's component count against the populations present,
  i.e. the truth's mixture components with at least one region covering, together, at least
  ``min_area_fraction`` of the field (a population on a few pixels at the border cannot be
  seen by anyone).
* **NDF**: Wasserstein-1 between the fitted lobes' tilt density and the true per-pixel tilt
  distribution, both truncated to the visibility limit asin(NA)/2 and renormalised (nothing
  beyond the limit is observable).
* **Texture**: a scene is *textured* when the median 5×5 local SD of the grey level of its
  noise-free truth image is at least ``TEXTURE_MIN_CODES`` 8-bit code values (grooves give
  3-10; planar facets without grooves 0.1-0.7): enough focus texture to measure a height.
* **Colour**: the analysis's mean ΔE00 against the scene's colour noise floor, the mean
  CIEDE2000 between the analysed all-in-focus image and the noise-free truth image over
  the unmasked pixels.
"""

from __future__ import annotations

import math

import cv2
import numpy as np
from scipy import ndimage

from microfacet.colour import delta_e_2000, srgb_to_lab
from microfacet.core.distributions import NDFMixture
from pipelines._shared import row_number, truthy

#: Fewest used pixels of a ROI for its thickness to be scored (the analysis' ``roi.min_pixels``).
ROI_MIN_PIXELS = 20

#: Median local SD (8-bit code values) of the truth image above which a scene is textured.
TEXTURE_MIN_CODES = 2.0


def interior(labels, erode_px=3):
    """Pixels whose (2·erode_px+1)² neighbourhood holds only their own label.

    >>> lab = np.zeros((7, 7), int); lab[:, 4:] = 1
    >>> interior(lab, 1).astype(int)[3].tolist()
    [1, 1, 1, 0, 0, 1, 1]
    """
    size = 2 * erode_px + 1
    lo = ndimage.minimum_filter(labels, size=size, mode="nearest")
    hi = ndimage.maximum_filter(labels, size=size, mode="nearest")
    return (lo == labels) & (hi == labels)


def region_thickness_errors(est_nm, region_id, true_mean_nm, *, erode_px=3, min_pixels=50):
    """Per true region: median estimate over its interior minus its true mean thickness.

    Parameters
    ----------
    est_nm : ndarray (H, W)
        Estimated thickness per pixel (NaN where not estimated).
    region_id : ndarray of int (H, W)
    true_mean_nm : sequence
        True mean thickness of each region id.

    Returns
    -------
    dict
        ``errors_nm`` (signed, per scored region), ``ids``, ``mae_nm``, ``median_ae_nm``
        (NaN when no region is scored), ``n_scored``, ``n_regions``.

    Examples
    --------
    >>> rid = np.zeros((20, 20), int); rid[:, 10:] = 1
    >>> est = np.where(rid == 0, 100.0, 131.0); est[:, 9:11] = 500.0   # a bad boundary
    >>> r = region_thickness_errors(est, rid, [100.5, 130.0], erode_px=2, min_pixels=10)
    >>> r["errors_nm"].tolist(), r["mae_nm"], r["n_scored"]
    ([-0.5, 1.0], 0.75, 2)
    """
    inner = interior(region_id, erode_px) & np.isfinite(est_nm)
    ids, errs = [], []
    lab = region_id[inner]
    vals = est_nm[inner]
    order = np.argsort(lab, kind="stable")
    lab, vals = lab[order], vals[order]
    uniq, start = np.unique(lab, return_index=True)
    for k, r in enumerate(uniq):
        v = vals[start[k]:(start[k + 1] if k + 1 < uniq.size else vals.size)]
        if v.size >= min_pixels:
            ids.append(int(r))
            errs.append(float(np.median(v)) - float(true_mean_nm[r]))
    errs = np.array(errs)
    return {"ids": ids, "errors_nm": errs, "n_scored": len(ids),
            "n_regions": len(true_mean_nm),
            "mae_nm": float(np.mean(np.abs(errs))) if errs.size else math.nan,
            "median_ae_nm": float(np.median(np.abs(errs))) if errs.size else math.nan}


#: A mapped thickness this far from its true region's mean is read in another interference
#: order (the orders lie ~110 nm apart; the populations of a scene at least 12 nm).
ORDER_OFF_NM = 50.0


def order_off_fraction(est_nm, region_id, true_mean_nm, *, off_nm=ORDER_OFF_NM) -> float:
    """Share of the mapped pixels (finite ``est_nm``) whose thickness lies more than
    ``off_nm`` from their true region's mean: the map read in another interference order.
    :func:`region_thickness_errors` scores each region by its median, blind to a minority of
    its pixels read an order off; this counts them.

    >>> rid = np.zeros((4, 4), int); rid[:, 2:] = 1
    >>> est = np.where(rid == 0, 101.0, 222.0); est[0, 0] = 214.0; est[3, 3] = np.nan
    >>> round(order_off_fraction(est, rid, [101.0, 222.0]), 4)     # 1 of 15 mapped pixels
    0.0667
    """
    est = np.asarray(est_nm, dtype=np.float64)
    truth = np.asarray(true_mean_nm, dtype=np.float64)[np.asarray(region_id)]
    mapped = np.isfinite(est)
    if not mapped.any():
        return math.nan
    return float(np.mean(np.abs(est[mapped] - truth[mapped]) > off_nm))


def present_means_nm(populations, *, min_area_fraction=0.02) -> list:
    """The means of the true thickness populations present (``populations`` of
    params.json: at least ``min_area_fraction`` of the area).

    >>> present_means_nm([{"mean_nm": 120.0, "area_fraction": 0.7},
    ...                   {"mean_nm": 250.0, "area_fraction": 0.01}])
    [120.0]
    """
    return [q["mean_nm"] for q in populations if q["area_fraction"] >= min_area_fraction]


def true_population_count(populations, *, min_area_fraction=0.02):
    """Number of true thickness populations present (``populations`` of params.json).

    >>> true_population_count([{"mean_nm": 1.0, "area_fraction": 0.7},
    ...                        {"mean_nm": 2.0, "area_fraction": 0.29},
    ...                        {"mean_nm": 3.0, "area_fraction": 0.01}])
    2
    """
    return len(present_means_nm(populations, min_area_fraction=min_area_fraction))


def mean_coverage(components, uncertainty, populations, *, gate_nm=15.0, min_area_fraction=0.02):
    """How the thickness components' means and their reported 1σ (summary.json
    ``thickness.mixture.components`` and ``mean_uncertainty``) cover the true populations'
    means: components and true populations (at least ``min_area_fraction`` of the area)
    paired one to one, closest first, within ``gate_nm``; per pair the error and the σ.

    Returns ``{"pairs": n, "within_2sigma": k, "errors_nm": [...], "sigmas_nm": [...]}``
    (pairs whose σ is unknown count as not within).

    >>> comps = [{"mean_nm": 100.4}, {"mean_nm": 131.0}, {"mean_nm": 300.0}]
    >>> unc = [{"sigma_nm": 0.5}, {"sigma_nm": 0.2}, {"sigma_nm": 1.0}]
    >>> pops = [{"mean_nm": 100.0, "area_fraction": 0.5}, {"mean_nm": 130.0,
    ...          "area_fraction": 0.5}]
    >>> c = mean_coverage(comps, unc, pops)
    >>> c["pairs"], c["within_2sigma"], c["errors_nm"]
    (2, 1, [0.4, 1.0])
    """
    mu = [c["mean_nm"] for c in components]
    sig = [u.get("sigma_nm") for u in (uncertainty or [{}] * len(mu))]
    true = present_means_nm(populations, min_area_fraction=min_area_fraction)
    cand = sorted((abs(m - t), i, j) for i, m in enumerate(mu) for j, t in enumerate(true)
                  if abs(m - t) <= gate_nm)
    used_c, used_t, errs, sigs = set(), set(), [], []
    for d, i, j in cand:
        if i in used_c or j in used_t:
            continue
        used_c.add(i)
        used_t.add(j)
        errs.append(round(mu[i] - true[j], 4))
        sigs.append(sig[i])
    within = sum(1 for e, s in zip(errs, sigs) if s is not None and abs(e) <= 2.0 * s)
    return {"pairs": len(errs), "within_2sigma": within, "errors_nm": errs, "sigmas_nm": sigs}


def truncated_w1(grid, pdf, samples, limit):
    """W1 between a density on ``grid`` and a sample, both truncated to [grid[0], limit].

    The density's CDF is its cumulative trapezoid integral over the grid up to ``limit``,
    renormalised; the sample's is its empirical CDF on the same grid.

    >>> g = np.linspace(0, 10, 2001)
    >>> pdf = np.ones_like(g)                       # uniform on [0, 10]
    >>> round(truncated_w1(g, pdf, np.linspace(0, 10, 100001), 10.0), 3)
    0.0
    >>> round(truncated_w1(g, pdf, np.full(10, 5.0), 10.0), 3)    # all mass at 5
    2.5
    """
    g = np.asarray(grid, float)
    keep = g <= limit
    g, p = g[keep], np.asarray(pdf, float)[keep]
    s = np.sort(np.asarray(samples, float))
    s = s[np.isfinite(s) & (s <= limit) & (s >= g[0])]
    if s.size == 0 or g.size < 2:
        return math.nan
    c = np.concatenate([[0.0], np.cumsum(0.5 * (p[1:] + p[:-1]) * np.diff(g))])
    if c[-1] <= 0:
        return math.nan
    f_fit = c / c[-1]
    f_true = np.searchsorted(s, g, side="right") / s.size
    d = np.abs(f_fit - f_true)
    return float(np.sum(0.5 * (d[1:] + d[:-1]) * np.diff(g)))


def ndf_w1_deg(lobes, true_tilt_deg, limit_deg, *, step_deg=0.02):
    """W1 (degrees) between fitted NDF lobes and the true per-pixel tilts, truncated to
    ``limit_deg``. ``lobes``: ``[(weight, sd_deg), ...]``; NaN without lobes.

    >>> rng = np.random.default_rng(0)
    >>> s = np.tan(np.deg2rad(6.0))
    >>> tilt = np.rad2deg(np.arctan(np.hypot(*rng.normal(0, s, (2, 200000)))))
    >>> [round(ndf_w1_deg([(1.0, sd)], tilt, 26.57), 1) for sd in (6.0, 8.0)]
    [0.0, 2.4]
    """
    if not lobes:
        return math.nan
    grid = np.arange(0.0, limit_deg + step_deg / 2, step_deg)
    pdf = NDFMixture(lobes).tilt_pdf(grid)
    return truncated_w1(grid, pdf, np.ravel(true_tilt_deg), limit_deg)


def lobe_rms_ratio(lobes, true_tilt_deg, limit_deg, *, n_grid=2001):
    """RMS slope (E[tan² θ]^½) of the fitted lobes' tilt density truncated at ``limit_deg``
    over that of the true tilts below it; NaN without lobes or truth.

    >>> rng = np.random.default_rng(0)
    >>> s = np.tan(np.deg2rad(6.0))
    >>> tilt = np.rad2deg(np.arctan(np.hypot(*rng.normal(0, s, (2, 200000)))))
    >>> [round(lobe_rms_ratio([(1.0, sd)], tilt, 26.57), 2) for sd in (6.0, 4.8)]
    [1.0, 0.8]
    """
    t = np.ravel(true_tilt_deg)
    t = t[np.isfinite(t) & (t < limit_deg)]
    if not lobes or t.size == 0:
        return math.nan
    grid = np.linspace(0.0, limit_deg, n_grid)
    pdf = NDFMixture(lobes).tilt_pdf(grid)
    tan2 = np.tan(np.radians(grid)) ** 2
    fit = float(np.trapezoid(pdf * tan2, grid) / np.trapezoid(pdf, grid))
    true = float(np.mean(np.tan(np.radians(t)) ** 2))
    return math.sqrt(fit / true) if true > 0 else math.nan


def facet_tilts(truth):
    """The true per-pixel tilts of the surface's facets: NaN on pits, scratches, dust and
    stains (``truth/feature.npy`` ≠ 0), which are not facets."""
    t = np.load(truth / "tilt_deg.npy").astype(np.float64)
    f = truth / "feature.npy"
    return np.where(np.load(f) == 0, t, np.nan) if f.is_file() else t


def past_limit_fraction(truth, limit_deg):
    """Share of the facet pixels truly tilted past the acceptance ``limit_deg``."""
    t = facet_tilts(truth)
    t = t[np.isfinite(t)]
    return float(np.mean(t > limit_deg)) if t.size else math.nan


def height_coverage(height_um, sigma_um, truth):
    """Share of the facet pixels with a height and a σ whose error against the true height
    is within 2σ (NaN without any)."""
    ht = np.load(truth / "height_um.npy")
    ok = np.isfinite(height_um) & np.isfinite(sigma_um) & np.isfinite(facet_tilts(truth))
    if not ok.any():
        return math.nan
    return float(np.mean(np.abs(height_um[ok] - ht[ok]) <= 2.0 * sigma_um[ok]))


def relief_coefficient_95(error_um, sigma_um, relief_unit_um, *, target=0.95):
    """The coefficient κ of the unresolved-relief term
    (:func:`microfacet.focus.uncertainty.unresolved_relief_sigma_um`, whose value at κ = 1 is
    ``relief_unit_um``) at which 2·√(σ² + (κ·unit)²) covers ``target`` of the height errors
    ``error_um`` (0 when σ alone does, inf when no κ up to 50 does, NaN without errors).

    >>> e = np.array([0.1, 0.2, 0.3, 0.4])
    >>> round(relief_coefficient_95(e, np.full(4, 0.05), np.full(4, 0.1), target=1.0), 3)
    1.936
    """
    ok = np.isfinite(error_um) & np.isfinite(sigma_um) & np.isfinite(relief_unit_um)
    if not ok.any():
        return math.nan
    e, s, u = np.abs(error_um[ok]), sigma_um[ok], relief_unit_um[ok]

    def cover(k):
        return float(np.mean(e <= 2.0 * np.sqrt(s * s + (k * u) ** 2)))

    if cover(0.0) >= target:
        return 0.0
    lo, hi = 0.0, 50.0
    if cover(hi) < target:
        return math.inf
    for _ in range(40):
        mid = 0.5 * (lo + hi)
        lo, hi = (mid, hi) if cover(mid) < target else (lo, mid)
    return hi


def texture_codes(truth_rgb8, window_px=5):
    """Median over pixels of the local SD (``window_px``², reflected borders) of the grey
    level (mean of R, G, B) of an 8-bit image, in code values.

    >>> flat = np.full((20, 20, 3), 100, np.uint8)
    >>> texture_codes(flat)
    0.0
    >>> checker = ((np.indices((20, 20)).sum(0) % 2) * 40).astype(np.uint8)
    >>> round(texture_codes(np.dstack([checker] * 3)), 1)
    20.0
    """
    g = np.asarray(truth_rgb8, np.float32).mean(axis=-1)
    m = cv2.blur(g, (window_px, window_px), borderType=cv2.BORDER_REFLECT)
    v = cv2.blur(g * g, (window_px, window_px), borderType=cv2.BORDER_REFLECT) - m * m
    return float(np.median(np.sqrt(np.maximum(v, 0.0))))


def colour_floor_de(analysed_srgb, truth_srgb, used):
    """Mean CIEDE2000 between two sRGB-encoded images (float 0-1 or uint8) over ``used``.

    >>> a = np.full((4, 4, 3), 0.5, np.float32)
    >>> colour_floor_de(a, a, np.ones((4, 4), bool))
    0.0
    >>> round(colour_floor_de(a, a * 1.02, np.ones((4, 4), bool)), 2)
    0.96
    """
    if not np.any(used):
        return math.nan
    la = srgb_to_lab(np.asarray(analysed_srgb)[used])
    lb = srgb_to_lab(np.asarray(truth_srgb)[used])
    return float(np.mean(delta_e_2000(la, lb)))


def ndf_identified(summary):
    """``summary.json`` ``ndf.identified``; a missing key counts as identified.

    >>> ndf_identified({"ndf": {}}), ndf_identified({"ndf": {"identified": False}})
    (True, False)
    """
    v = (summary.get("ndf") or {}).get("identified", True)
    return bool(v) if v is not None else True


def fraction(flags):
    """Fraction of True among the non-None ``flags`` (NaN if none).

    >>> fraction([True, False, None, True])
    0.6666666666666666
    """
    v = [bool(f) for f in flags if f is not None]
    return sum(v) / len(v) if v else math.nan


def finite_median(values):
    """Median of the finite values (NaN if none).

    >>> finite_median([1.0, float("nan"), 3.0, None])
    2.0
    """
    v = [float(x) for x in values if x is not None and np.isfinite(x)]
    return float(np.median(v)) if v else math.nan


#: The issue's targets: (row label, score key, target text, passes(value)).
TARGETS = (
    ("region thickness MAE, median over scenes (nm)", "region_mae_median_nm", "≤ 0.5",
     lambda v: v <= 0.5),
    ("scenes with the true number of thickness populations", "populations_ok", "≥ 90 %",
     lambda v: v >= 0.9),
    ("… counting a component the analysis calls another's order alias as that one",
     "populations_ok_distinct", "–", None),
    ("… and counting the reported candidate populations (field too small) too",
     "populations_ok_candidates", "–", None),
    ("scenes with a reported candidate where the count was already right (spurious)",
     "candidates_spurious", "–", None),
    ("true population means within 2σ of their component's (pairs within 15 nm)",
     "mean_within_2sigma", "–", None),
    ("… the components' mean 1σ, median over scenes (nm)", "mean_sigma_median_nm", "–", None),
    ("scenes where the analysis says the interference order is not established",
     "order_not_established", "–", None),
    ("scenes read in a wrong interference order (region median error > 20 nm)",
     "order_wrong_count", "–", None),
    ("… of those with the order said established (summary.json thickness.order)",
     "order_wrong_unflagged", "0", lambda v: v == 0),
    ("estimated exposure within 5 % of the truth", "exposure_ok", "–", None),
    ("… scenes where two exposures fit alike (order said not established)",
     "exposure_ambiguous", "–", None),
    ("scenes with the true number of NDF lobes", "lobes_ok", "–", None),
    ("NDF identified, all scenes", "identified_all", "–", None),
    ("identified NDFs with an RMS slope off by > 25 % (scenes)", "identified_wrong", "0",
     lambda v: v == 0),
    ("NDF identified, textured scenes", "identified_textured", "≥ 50 %", lambda v: v >= 0.5),
    ("NDF W1, identified textured scenes, median (°)", "w1_identified_textured_deg", "≤ 1.5",
     lambda v: v <= 1.5),
    ("identified NDFs with the RMS slope within ±15 %", "rms_ok_identified", "100 %",
     lambda v: v >= 1.0),
    ("censored − truly past the limit, median absolute difference", "censored_error_median",
     "≤ 0.03",
     lambda v: v <= 0.03),
    ("height 2σ coverage, median over scenes", "height_coverage_median", "≥ 90 %",
     lambda v: v >= 0.9),
    ("NDF W1, all scenes, median (°)", "w1_all_deg", "–", None),
    ("mean ΔE00 − noise floor, median over scenes", "de_excess_median", "≤ 1.0",
     lambda v: v <= 1.0),
    ("scenes with mean ΔE00 − floor ≤ 1.0", "de_excess_ok", "–", None),
    ("white-balance gains determined (R and B, of all)", "wb_determined_all", "–", None),
    ("determined gains within 2 % of the truth", "wb_within_2pct", "100 %",
     lambda v: v >= 1.0),
)


def _int(v, default):
    """An integer from a row (a CSV text, or missing: ``default``)."""
    x = row_number(v)
    if math.isfinite(x):
        return int(x)
    return default if default is None else int(row_number(default))


def _coverage(rows) -> float:
    """The share of the true population means within 2σ of their component's, over rows
    whose analysis reported a σ (NaN: none did, e.g. the seed mode)."""
    pairs = float(np.nansum([row_number(r.get("mean_pairs")) for r in rows] or [0.0]))
    within = float(np.nansum([row_number(r.get("mean_within_2sigma")) for r in rows] or [0.0]))
    return within / pairs if pairs else math.nan


def summarize(rows):
    """The summary scores of one mode's per-scene rows (keys of :data:`TARGETS`).

    >>> rows = [dict(status="done", region_mae_nm=0.3, pops_found=2, pops_true=2,
    ...              lobes_found=1, lobes_true=1, identified=True, textured=True,
    ...              ndf_w1_deg=1.0, de_excess=0.5)]
    >>> s = summarize(rows)
    >>> s["region_mae_median_nm"], s["populations_ok"], s["w1_identified_textured_deg"]
    (0.3, 1.0, 1.0)
    """
    ok = [r for r in rows if r.get("status") == "done"]
    tex = [r for r in ok if r.get("textured")]
    good = [r for r in tex if r.get("identified")]
    return {
        "scenes": len(rows), "failed": len(rows) - len(ok), "textured": len(tex),
        "region_mae_median_nm": finite_median(r.get("region_mae_nm") for r in ok),
        "populations_ok": fraction(r["pops_found"] == r["pops_true"] if r.get("pops_found")
                                   is not None else False for r in ok),
        "populations_ok_distinct": fraction(
            _int(r.get("pops_distinct"), r.get("pops_found")) == r["pops_true"]
            if r.get("pops_found") is not None else False for r in ok),
        "populations_ok_candidates": fraction(
            _int(r.get("pops_distinct"), r.get("pops_found")) + int(r.get("pops_candidates")
                                                                    or 0) == r["pops_true"]
            if r.get("pops_found") is not None else False for r in ok),
        "mean_within_2sigma": _coverage([r for r in ok
                                         if np.isfinite(row_number(r.get("mean_sigma_nm")))]),
        "mean_sigma_median_nm": finite_median(r.get("mean_sigma_nm") for r in ok),
        "candidates_spurious": sum(1 for r in ok if int(r.get("pops_candidates") or 0) > 0
                                   and r.get("pops_found") == r.get("pops_true")),
        "order_not_established": sum(1 for r in ok if truthy(r.get("order_flagged"))),
        "order_wrong_count": sum(1 for r in ok if truthy(r.get("order_wrong"))),
        "order_wrong_unflagged": sum(1 for r in ok if truthy(r.get("order_wrong"))
                                     and not truthy(r.get("order_flagged"))),
        "exposure_ok": fraction(abs(row_number(r.get("exposure_error"))) <= 0.05 for r in ok
                                if np.isfinite(row_number(r.get("exposure_error")))),
        "exposure_ambiguous": sum(1 for r in ok if truthy(r.get("exposure_ambiguous"))),
        "lobes_ok": fraction(r["lobes_found"] == r["lobes_true"] if r.get("lobes_found")
                             is not None else False for r in ok),
        "identified_all": fraction(r.get("identified") for r in ok),
        "identified_textured": fraction(r.get("identified") for r in tex),
        "w1_identified_textured_deg": finite_median(r.get("ndf_w1_deg") for r in good),
        "identified_wrong": sum(1 for r in ok if r.get("identified") and not (
            abs(r.get("lobe_rms_ratio", math.nan) - 1.0) <= 0.25)),
        "rms_ok_identified": fraction(abs(r.get("lobe_rms_ratio", math.nan) - 1.0) <= 0.15
                                      for r in ok if r.get("identified")),
        "censored_error_median": finite_median(
            abs(r["censored_fraction"] - r["past_limit_fraction"]) for r in ok
            if r.get("censored_fraction") is not None
            and r.get("past_limit_fraction") is not None),
        "height_coverage_median": finite_median(r.get("height_coverage") for r in ok),
        "w1_all_deg": finite_median(r.get("ndf_w1_deg") for r in ok),
        "de_excess_median": finite_median(r.get("de_excess") for r in ok),
        "de_excess_ok": fraction(r["de_excess"] <= 1.0 if r.get("de_excess") is not None
                                 and np.isfinite(r["de_excess"]) else False for r in ok),
        "wb_determined_all": fraction(r.get(k) is not None and np.isfinite(r[k]) for r in ok
                                  for k in ("wb_err_r", "wb_err_b")),
        "wb_within_2pct": fraction(abs(r[k]) <= 0.02 for r in ok for k in ("wb_err_r",
                                                                          "wb_err_b")
                                   if r.get(k) is not None and np.isfinite(r[k])),
    }


def preset_scores(results, truth_dir, params) -> dict:
    """Scores of one results folder against its synthetic truth (``accuracy-presets``).

    * ``thickness_mae_nm``: mean |estimated − true| per-pixel thickness (unmasked, finite);
    * ``roi_mae_nm``: the same for ROI means (the analysis' ROI grid; a seed-mode pixel has
      its ROI's thickness, so this is the ROI estimate's error), ROIs with ≥ 20 such pixels;
    * ``tilt_median_err_deg``, ``ndf_w1_deg``: median |error| of the per-pixel tilt and the W1
      distance of the estimated tilts to the true ones (visible, finite);
    * ``ndf_rms_err_deg``: fitted NDF rms slope angle − true (signed);
    * ``components_found`` / ``components_true`` and ``worst_mean_err_nm`` (largest distance
      from a true thickness-component mean to the nearest fitted mean);
    * ``delta_e_mean`` / ``delta_e_median``, ``masked_fraction``, ``exposure``,
      ``colour_noise_de`` from the summary.

    ``results``: a results folder; ``truth_dir``: the stack's ``truth/``; ``params``: its
    :class:`~microfacet.forward.synth.SynthParams`.
    """
    from pathlib import Path

    from microfacet.analysis.roi import nearest_roi_index, roi_grid
    from microfacet.io.results import Results
    from pipelines._shared import tilt_scores, worst_mean_error

    truth_dir = Path(truth_dir)
    res = Results(results)
    d_true = np.load(truth_dir / "thickness_nm.npy")
    t_true = np.load(truth_dir / "tilt_deg.npy")
    vis = np.load(truth_dir / "visible.npy")
    d_est = res.map("thickness_nm")
    t_est = res.map("tilt_deg")
    mask = res.map("mask")
    used = ~mask & np.isfinite(d_est)
    out = {"thickness_mae_nm": float(np.mean(np.abs(d_est[used] - d_true[used])))
           if used.any() else math.nan}
    rows, cols, size = roi_grid(d_true.shape, size_px=res.parameter("roi.size_px"),
                                stride_px=res.parameter("roi.stride_px"))
    ri, ci = nearest_roi_index(d_true.shape, rows, cols, size)
    idx = (ri[:, None] * len(cols) + ci[None, :])[used]
    n = np.bincount(idx, minlength=len(rows) * len(cols))
    ok = n >= ROI_MIN_PIXELS
    est = np.bincount(idx, d_est[used], minlength=n.size)[ok] / n[ok]
    tru = np.bincount(idx, d_true[used], minlength=n.size)[ok] / n[ok]
    out["roi_mae_nm"] = float(np.mean(np.abs(est - tru))) if ok.any() else math.nan
    out["tilt_median_err_deg"], out["ndf_w1_deg"] = tilt_scores(t_est, t_true, vis)
    ndf = res.ndf_mixture()
    true_ndf = NDFMixture([(lb.weight, lb.sd_deg) for lb in params.tilt_lobes])
    out["ndf_rms_err_deg"] = (ndf.rms_sd_deg - true_ndf.rms_sd_deg if ndf is not None
                              else math.nan)
    thick = res.thickness_mixture()
    fit_means = list(thick.means_nm) if thick is not None else []
    out["components_true"] = len(params.thickness)
    out["components_found"] = len(fit_means)
    out["worst_mean_err_nm"] = worst_mean_error([c.mean_nm for c in params.thickness],
                                                fit_means)
    for key, path in (("delta_e_mean", ("delta_e", "mean")),
                      ("delta_e_median", ("delta_e", "median")),
                      ("masked_fraction", ("masked_fraction",)), ("exposure", ("exposure",)),
                      ("colour_noise_de", ("colour_noise_de",))):
        v = res.get(*path)
        out[key] = math.nan if v is None else float(v)
    return out
