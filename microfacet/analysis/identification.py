"""Whether the data determine the distributions, and what a user must know: structured
reasons and warnings.

A :class:`Reason` is a code (stable, for programs), the option a user can act on (a dotted
path of :class:`~.options.AnalysisOptions`, or None) and one sentence whose option names are
written in backticks: ``summary.json`` shows them as option paths, the command line as its
flags (:func:`microfacet.core.errors.render_params`). Library code never names a flag.

The NDF is identified when at least ``fits.min_ndf_facets`` facets have a height tilt, the
width of a single lobe fitted to them is known to ±``fits.max_width_error``
(:func:`~.ndf_fit.width_relative_error`: few facets, or slope noise comparable to the lobes,
fail), and at most ``fits.max_censored_fraction`` of the area is censored. Colour could stand
in for height only where a tilt changes the colour in a way no thickness change can mimic, by
more than the colour error: :func:`colour_tilt_contrast` measures that
(docs/conditioning.md); the reason says which. The seed mode's colour-only NDF is identified
only where that contrast is above ``fits.colour_contrast_factor`` × the pixel noise. The
thickness mixture is not identified when the interference order is uncertain on most of the
area (ROIs, or facets, whose runner-up order fits within ``fits.ambiguous_order_de``:
:func:`ambiguous_order`), or most facets' best thickness lies at the edge of their order's
window.

References
----------
.. [1] N. Nagata et al., the seed, §3.3.3 (the two distributions).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from ..core.errors import plain_params, render_params
from .options import FitOptions
from .white_balance import LOG_RANGE

__all__ = ["Judgement", "Reason", "analysis_warnings", "colour_tilt_contrast",
           "gains_off_one", "gains_unconstrained", "mask_warning", "mean_plane_tilt_deg",
           "ndf_judgement", "order_check",
           "seed_ndf_judgement", "self_check_judgement", "self_check_passes",
           "thickness_judgement"]

#: Mean ΔE00 of pure noise of σ per Lab component, E|N(0, σ²I₃)| = 2·sqrt(2/π)·σ: the
#: image's noise floor of the mean ΔE00 is this × ``noise_de``.
NOISE_FLOOR_FACTOR = 2.0 * math.sqrt(2.0 / math.pi)
#: Median ΔE00 of the same noise: sqrt of the median of χ²₃ (2.366) × σ.
MEDIAN_NOISE_FLOOR_FACTOR = 1.5382


@dataclass(frozen=True)
class Reason:
    """Why a distribution is not identified, or a warning.

    Attributes
    ----------
    code : str
        Stable identifier (``"order_ambiguous"``, ``"few_planes"``, ...).
    text : str
        One sentence; option names in backticks (dotted paths).
    parameter : str or None
        The option a user can change to act on it.
    """

    code: str
    text: str
    parameter: str | None = None

    def plain(self) -> str:
        """The sentence with option paths (for Python users and summary.json)."""
        return plain_params(self.text)

    def render(self, flags=None) -> str:
        """The sentence with the options as command-line flags (``flags``: path → flag)."""
        return render_params(self.text, flags)

    def to_json(self) -> dict:
        return {"code": self.code, "text": self.plain(), "parameter": self.parameter}


@dataclass(frozen=True)
class Judgement:
    """Whether a distribution is identified, and the reason when not."""

    identified: bool
    reason: Reason | None = None

    def to_json(self) -> dict:
        """``identified``, ``reason`` (the sentence, "" when identified), ``reason_code``
        and ``reason_parameter``."""
        r = self.reason
        return {"identified": bool(self.identified), "reason": "" if r is None else r.plain(),
                "reason_code": None if r is None else r.code,
                "reason_parameter": None if r is None else r.parameter}


def ambiguous_order(gap_de, threshold_de) -> np.ndarray:
    """Where the runner-up interference order fits within ``threshold_de`` of the best (the one
    rule for ROIs and facets; NaN gaps are not ambiguous).

    >>> ambiguous_order(np.array([0.2, 5.0, np.nan]), 1.0).tolist()
    [True, False, False]
    """
    return np.nan_to_num(np.asarray(gap_de, dtype=np.float64), nan=np.inf) < threshold_de


def colour_tilt_contrast(model, thickness_nm, *, tilt_deg=10.0) -> float:
    """ΔE by which a tilt changes the colour beyond what a thickness change can mimic.

    The colour at ``(tilt_deg, d)`` against the nearest colour at tilt 0 over thicknesses
    within ±10 % of ``d`` (by the model's colour difference): the part of the tilt's colour
    change that colour could attribute to tilt when the facet's thickness is unknown.

    Examples
    --------
    >>> from microfacet.colour.model import FilmColourModel
    >>> from microfacet.colour.table import build_colour_table
    >>> t = build_colour_table(thickness_range_nm=(30, 80), theta_range_deg=(0, 20))
    >>> colour_tilt_contrast(FilmColourModel(t), 51.0) < 0.5
    True
    """
    d = float(thickness_nm)
    lo, hi = model.thickness_range_nm
    grid = np.linspace(max(lo, 0.9 * d), min(hi, 1.1 * d), 801)
    ref = model.lab(min(tilt_deg, model.theta_range_deg[1]), d)
    cand = model.lab(0.0, grid)
    return float(np.min(model.difference(cand, ref[None, :])))


def unexplained_facets(delta_e, mads) -> np.ndarray:
    """Facets whose best ΔE is a robust outlier among the facets' (median + ``mads`` ×
    1.4826 MAD): the film model does not explain their colour.

    >>> unexplained_facets(np.array([1.0, 1.2, 0.9, 1.1, 1.3, 9.0, np.nan]), 5.0).tolist()
    [False, False, False, False, False, True, False]
    """
    de = np.asarray(delta_e, dtype=np.float64)
    ok = np.isfinite(de)
    if ok.sum() < 5:
        return np.zeros(de.shape, bool)
    med = float(np.median(de[ok]))
    mad = 1.4826 * float(np.median(np.abs(de[ok] - med)))
    return ok & (de > med + mads * max(mad, 0.1))


_RANGE = "optics.thickness_range_nm"
_EDGE = Reason("order_window_edge", "{pct:.0f} % of the area fits best at the edge of its "
               "interference order: check the film (`optics.film`) and the thickness range",
               "optics.film")


def thickness_judgement(roi, options: FitOptions, *, edge_fraction=0.0,
                        other_order_fraction=None) -> Judgement:
    """Whether the thickness mixture is identified.

    With facets (joint mode) the order is uncertain when on more than half the area a
    neighbouring order fits within ``options.ambiguous_order_de`` (``other_order_fraction``);
    without, when more than half the ROIs are ambiguous.
    """
    if other_order_fraction is not None and other_order_fraction > 0.5:
        return Judgement(False, Reason(
            "order_ambiguous", f"interference order uncertain on "
            f"{100 * other_order_fraction:.0f} % of the area (a neighbouring order fits "
            f"within {options.ambiguous_order_de:g} ΔE00): narrow `{_RANGE}` to the expected "
            f"order", _RANGE))
    if other_order_fraction is None:
        fit = np.isfinite(roi.thickness_nm)
        amb = fit & ambiguous_order(roi.ambiguity_delta_e, options.ambiguous_order_de)
        if fit.sum() and amb.sum() > 0.5 * fit.sum():
            i = int(np.nanargmin(np.where(fit, roi.ambiguity_delta_e, np.inf)))
            return Judgement(False, Reason(
                "order_ambiguous", f"interference order uncertain in {int(amb.sum())} of "
                f"{int(fit.sum())} regions (e.g. {roi.thickness_nm[i]:.0f} nm and "
                f"{roi.runner_up_thickness_nm[i]:.0f} nm fit alike): narrow `{_RANGE}` to the "
                f"expected order", _RANGE))
    if edge_fraction > 0.5:
        return Judgement(False, Reason(_EDGE.code, _EDGE.text.format(pct=100 * edge_fraction),
                                       _EDGE.parameter))
    return Judgement(True)


def map_check_judgement(judgement: Judgement, check) -> Judgement:
    """The thickness mixture's judgement after the check against the per-pixel map it
    summarizes (:func:`~.consistency.mixture_map_check`): a mixture whose area fractions or
    means differ from the map's, or that leaves much of the map far from every component,
    does not describe the film (on the sweeps of docs/accuracy.md, 15 of the 25 scenes where
    it failed had the wrong number of populations and 17 a region error above 5 nm, regions
    read in another order) and is not identified.

    >>> from microfacet.analysis.consistency import MapCheck
    >>> bad = MapCheck([1.0], [207.6], 0.43, 0.0, 0.2, False)
    >>> j = map_check_judgement(Judgement(True), bad)
    >>> j.identified, j.reason.code
    (False, 'mixture_map_mismatch')
    """
    if not judgement.identified or check is None or check.consistent:
        return judgement
    return Judgement(False, Reason(
        "mixture_map_mismatch", "the mixture does not summarize the per-pixel thickness map: "
        + _map_mismatch_text(check), "fits.max_components"))


def _map_mismatch_text(check) -> str:
    """How a mixture differs from its map (:class:`~.consistency.MapCheck`)."""
    return (f"area fractions differ by up to {check.max_fraction_difference:.2f}, means by up "
            f"to {check.max_mean_difference_nm:.1f} nm, and "
            f"{100 * check.unexplained_fraction:.0f} % of the map is far from every component "
            f"(thickness_nm.npy is the finer answer)")


@dataclass
class NdfEvidence:
    """What the NDF's identification weighs (joint mode)."""

    n_fit: int
    n_total: int
    plane_area_fraction: float
    width_relative_error: float
    censored_fraction: float
    colour_contrast_de: float
    colour_error_de: float
    thickness_nm: float


def _within(value, se, options: FitOptions) -> bool:
    """``value`` in ``fits.self_check_range`` by at least ``fits.self_check_sigmas`` of its
    standard error ``se`` on either side (False for NaN)."""
    low, high = options.self_check_range
    margin = options.self_check_sigmas * se
    return bool(low + margin <= value <= high - margin)


def self_check_passes(check, options: FitOptions) -> bool:
    """Whether the self-check (:class:`~.self_check.SelfCheck`, or None) says the stack
    resolves the facets' slopes: its slope gain (``transfer``) and its width transfer both
    in ``fits.self_check_range`` by ``fits.self_check_sigmas`` of their standard errors, and
    the gain's half-range over the injected widths (``spread``) at most
    ``fits.self_check_max_spread`` (False where any was not measured)."""
    if check is None:
        return False
    return (_within(check.transfer, check.transfer_se, options)
            and _within(check.width_transfer, check.width_transfer_se, options)
            and check.spread <= options.self_check_max_spread)


def self_check_judgement(judgement: Judgement, check, options: FitOptions) -> Judgement:
    """The NDF's judgement after its self-check (:mod:`.self_check`): an NDF the stack
    cannot resolve — the recovered/injected slope gain (``transfer``) or the width the NDF
    would see over the true width (``width_transfer``) outside ``fits.self_check_range`` or
    within ``fits.self_check_sigmas`` of their standard errors of its edge, a
    gain that changes with the injected width by more than ``fits.self_check_max_spread``, or
    not measurable — is not identified, whatever its other evidence says."""
    if not judgement.identified or check is None or self_check_passes(check, options):
        return judgement
    low, high = options.self_check_range
    t, wt = check.transfer, check.width_transfer
    if not math.isfinite(t) and check.facets == 0:
        said = "had fewer than 3 facet planes with measurable slopes to inject on"
    elif not math.isfinite(t):
        said = "could not recover injected slopes"
    elif (low <= t <= high and low <= wt <= high
          and not (_within(t, check.transfer_se, options)
                   and _within(wt, check.width_transfer_se, options))):
        k = options.self_check_sigmas
        return Judgement(False, Reason(
            "self_check", f"the self-check on this stack recovers the injected slopes at "
            f"{t:.2f} ± {check.transfer_se:.2f}× and the width at {wt:.2f} ± "
            f"{check.width_transfer_se:.2f}× (standard errors over its facets): within "
            f"{k:g} standard error of the edge of {low:g}-{high:g} "
            f"(`fits.self_check_sigmas`, `fits.self_check_range`), its own measurement does "
            f"not establish that the heights resolve the facets' slopes "
            f"(ndf.self_check in summary.json)", "fits.self_check_sigmas"))
    elif low <= t <= high and low <= wt <= high:
        return Judgement(False, Reason(
            "self_check", f"the self-check on this stack recovers the injected slopes at "
            f"{min(check.ratio):.2f}-{max(check.ratio):.2f}× depending on their width (a "
            f"half-range of {check.spread:.2f}; identified only up to "
            f"{options.self_check_max_spread:g}, `fits.self_check_max_spread`): the stack's "
            f"slope transfer is not one number to correct by (ndf.self_check in summary.json)",
            "fits.self_check_max_spread"))
    elif low <= t <= high:
        said = (f"recovers the injected slopes ({t:.2f}×) but the NDF would see "
                f"{wt:.2f}× their RMS once their noise is removed")
    else:
        said = f"recovers {t:.2f}× the injected RMS slope"
    return Judgement(False, Reason(
        "self_check", f"the self-check on this stack {said} (identified only within "
        f"{low:g}-{high:g}, `fits.self_check_range`): its heights do not resolve the facets' "
        f"slopes (ndf.self_check in summary.json)", "fits.self_check_range"))


def dome_judgement(judgement: Judgement, dome_share, options: FitOptions) -> Judgement:
    """An NDF of facet planes is a sample of the normals only where the facets are planar:
    where the mean square slope inside them may exceed ``fits.max_dome_share`` of the planes'
    own (``dome_share``: the upper end, +2 standard errors, of
    :func:`~.planes.dome_mean_square_slope` over the planes' deconvolved mean square), the
    planes' NDF may be too narrow and is not identified (rounded grains, or facets too small
    for their heights to show whether they are). NaN: not measured (fewer than 3 facets with
    enough heights for a dome term, or planes whose slope is all noise), so not shown planar
    either: not identified; infinite: heights that show none of an injected dome
    (:func:`~.distributions.calibrate_dome_share`), likewise. None (no planes): unchanged."""
    if not judgement.identified or dome_share is None or dome_share <= options.max_dome_share:
        return judgement
    if not math.isfinite(dome_share):
        why = ("the self-check's heights show none of the domes it injected "
               "(ndf.self_check.dome_transfer)" if math.isinf(dome_share) else
               "fewer than 3 facets have enough heights inside their edges for a dome term (or "
               "their planes' slope is all noise)")
        return Judgement(False, Reason(
            "curved_facets", f"whether the facets are planar is not measured: {why}, so an "
            f"NDF of the planes may be too narrow; larger facets in pixels (a higher "
            f"magnification) would show it", "fits.max_dome_share"))
    return Judgement(False, Reason(
        "curved_facets", f"the facets may not be planar: the slopes inside them may add up to "
        f"{100 * dome_share:.0f} % to the mean square slope of their planes (identified up "
        f"to {100 * options.max_dome_share:.0f} %, `fits.max_dome_share`), so an NDF of the "
        f"planes may be too narrow", "fits.max_dome_share"))


def ndf_judgement(e: NdfEvidence, options: FitOptions) -> Judgement:
    """Whether the joint mode's NDF (facet planes) is identified, and if not why and what
    would identify it."""
    if (e.n_fit >= options.min_ndf_facets and e.width_relative_error <= options.max_width_error
            and e.censored_fraction <= options.max_censored_fraction):
        return Judgement(True)
    if e.censored_fraction > options.max_censored_fraction:
        code, parts = "censored", [f"{100 * e.censored_fraction:.0f} % of the surface is tilted "
                                   f"past the objective's acceptance"]
    elif e.n_fit < options.min_ndf_facets:
        code, parts = "few_planes", [f"height from focus gives a plane on {e.n_fit} of "
                                     f"{e.n_total} facets ({100 * e.plane_area_fraction:.1f} % "
                                     f"of the area)"]
    else:
        code, parts = "noisy_slopes", [f"the facets' slopes are too noisy to fix the lobe width "
                                       f"(±{100 * e.width_relative_error:.0f} %)"]
    parameter = None
    if e.colour_contrast_de <= options.colour_contrast_factor * e.colour_error_de:
        parts.append(f"colour cannot carry tilt at {e.thickness_nm:.0f} nm (a 10° tilt changes "
                     f"it by {e.colour_contrast_de:.2f} ΔE00 beyond a thickness change, below "
                     f"{options.colour_contrast_factor:g}× the facet colour error "
                     f"{e.colour_error_de:.2f})")
    else:
        parameter = "mode"
        parts.append(f"colour might carry tilt at {e.thickness_nm:.0f} nm "
                     f"({e.colour_contrast_de:.2f} ΔE00 for 10°): try `mode` seed")
    return Judgement(False, Reason(code, "; ".join(parts) + "; a stack with more texture, a "
                                   "finer z step, or a microscope height export would identify "
                                   "it", parameter))


def seed_ndf_judgement(contrast_de, thickness_nm, noise_de, options: FitOptions) -> Judgement:
    """The seed mode's colour-only NDF: identified only where a 10° tilt changes the colour
    by more than ``options.colour_contrast_factor`` × the pixel noise."""
    if contrast_de > options.colour_contrast_factor * noise_de:
        return Judgement(True)
    return Judgement(False, Reason(
        "colour_only", f"tilt from colour alone (seed mode): colour cannot carry tilt at "
        f"{thickness_nm:.0f} nm (a 10° tilt changes it by {contrast_de:.2f} ΔE00 beyond a "
        f"thickness change, below the pixel noise {noise_de:.2f}); `mode` joint takes tilt "
        f"from the height map", "mode"))


#: The reason given when a distribution has no samples at all to fit.
NO_SAMPLES = {"thickness": Judgement(False, Reason("no_samples", "no thickness values to fit")),
              "ndf": Judgement(False, Reason("no_samples", "no facet tilts to fit"))}


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
    try:
        return float(ndf_fit.mixture.rms_sd_deg)
    except (AttributeError, TypeError, ValueError):
        return None


def _spike_warning(fit) -> Reason | None:
    """A thickness component whose SD sits at the floor, or that rests on one thickness
    region (``info["sd_one_region"]``, :func:`~.distributions.one_region_components`): its
    SD is not a population's spread."""
    if fit is None:
        return None
    floor = list(fit.info.get("sd_at_floor") or [])
    one = [i for i in fit.info.get("sd_one_region") or [] if i not in floor]
    spikes = sorted(floor + one)
    if not spikes:
        return None
    comps = fit.mixture.components
    what = ", ".join(f"{comps[i][1]:.1f} nm ({100 * comps[i][0]:.0f} %)" for i in spikes)
    sd = ", ".join(f"{comps[i][2]:.2f}" for i in spikes)
    why = ("the floor" if not one else "one region's own scatter" if not floor
           else "the floor or one region's own scatter")
    return Reason("thickness_sd_not_measured", f"thickness component(s) {what} rest on too "
                  f"few regions for a spread: their SD ({sd} nm) is {why}, not a "
                  f"population's; a larger field would measure it", "fits.thickness_sd_floor_nm")


#: Area fraction of the facets with a runner-up order within ``fits.ambiguous_order_de``
#: above which the interference order is not established (where it exceeds one half, the
#: thickness is not identified at all).
ORDER_AMBIGUOUS_AREA = 0.05


def gains_unconstrained(wb) -> bool:
    """Whether the scene leaves the camera's white balance free: no reference gives the
    gains, and the scene's own estimate (:func:`~.white_balance.estimate_white_balance`)
    has a spread on R or B that is unbounded or not a number (its misfit has no minimum to
    measure: e.g. one film colour, where a gain and a thickness trade off) or whose ±2σ
    interval spans the half-range of log gains it searches (:data:`~.white_balance.LOG_RANGE`:
    σ ≥ 0.1; at σ ≥ 0.2 only, a fresh install's OpenCV 5.1 moved seed-4 g014 of the sweep,
    one 85 nm population read at 326.6 nm, from an unbounded σ to 0.175 and its wrong order
    to established, docs/accuracy.md), or its best at
    the edge of that search (the misfit still falls there: the gains are not bracketed; on
    the held-out 256² draws of the sweep two one-colour scenes with R 0.82 and 0.79, at the
    edge, were read an order off unflagged, docs/accuracy.md). With
    ``white_balance = "apply"`` a gain left at 1 beside an applied one counts too. Without
    an estimate (``white_balance = "off"``, or too few tiles for one) nothing is known, and
    False is returned. ``wb``: a :class:`~.white_balance.WhiteBalance` or None.

    >>> import dataclasses
    >>> from microfacet.analysis.white_balance import WhiteBalance
    >>> free = WhiteBalance(estimate_rgb=(0.9, 1.0, 0.89), estimate_sigma=(math.inf, 0.03))
    >>> referenced = dataclasses.replace(free, source="stack.json")
    >>> gains_unconstrained(free), gains_unconstrained(referenced)
    (True, False)
    >>> wide = dataclasses.replace(free, estimate_sigma=(0.175, 0.07))    # ±2σ past 0.2
    >>> gains_unconstrained(wide), gains_unconstrained(dataclasses.replace(
    ...     wide, estimate_sigma=(0.09, 0.07)))
    (True, False)
    >>> edge = WhiteBalance(estimate_rgb=(0.818, 1.0, 0.99), estimate_sigma=(0.04, 0.02))
    >>> gains_unconstrained(edge), gains_unconstrained(dataclasses.replace(
    ...     edge, estimate_rgb=(0.95, 1.0, 0.99)))
    (True, False)
    """
    if (wb is None or wb.from_reference or wb.estimate_rgb is None
            or not wb.estimate_sigma):
        return False
    return (not all(math.isfinite(s) and 2.0 * s < LOG_RANGE for s in wb.estimate_sigma)
            or any(wb.at_search_edge()))


def order_check(dist, *, delta_e_median, noise_de, options: FitOptions,
                white_balance=None) -> dict:
    """Whether the thicknesses' interference order is established, and if not why.

    The order is what the colours decide least firmly (orders ~110 nm apart can give close
    colours): it is not established where a ROI's runner-up order fits within
    ``options.ambiguous_order_de``, where more than :data:`ORDER_AMBIGUOUS_AREA` of the
    facets' area has such a runner-up, where the film model does not explain the colours
    (median ΔE00 more than ``options.excess_delta_e`` above its noise floor: the least-ΔE
    order of a model that does not fit is no evidence; on the generalization sweep a scene
    with unbalanced colours was read ~110 nm off so, with no ambiguity), where the scene
    leaves the white balance free and no reference gives it (``white_balance``:
    :func:`gains_unconstrained`, not checked without an estimate of the gains; the order
    then rests on the image being balanced: on an
    independent draw of the sweep a one-colour scene with R × 1.14, B × 0.91 was read
    241 nm off so, with no ambiguity), or where the scene's estimate asks for gains off 1
    and no reference gives them (:func:`gains_off_one`: on the held-out draws of 2026-12-02
    a one-population scene under R × 1.09, B × 1.04 was read 239 nm off with its estimate
    asking for R × 1.07, B × 0.95), or where the thickness is not identified. Returns
    ``{"established": bool, "reasons": [str]}`` (summary.json ``thickness.order``).
    """
    why = []
    if int(dist.roi_ambiguous.sum()):
        why.append(f"{int(dist.roi_ambiguous.sum())} ROI(s) with an ambiguous order")
    readings = dist.exposure_readings
    if readings is not None and readings.ambiguous:
        why.append("two exposures fit the facets' colours alike (" + _readings_text(readings)
                   + ")")
    frac = _order_ambiguous_fraction(dist.thickness)
    if frac > ORDER_AMBIGUOUS_AREA:
        why.append(f"{100 * frac:.0f} % of the facets' area has a runner-up order")
    floor = _unexplained_floor(delta_e_median, noise_de, options)
    if floor is not None:
        why.append(f"the film model does not explain the colours (median dE00 "
                   f"{delta_e_median:.2f}, noise floor {floor:.2f})")
    if gains_unconstrained(white_balance):
        why.append("the colours leave the white balance free and no reference gives it: the "
                   "order rests on the image being balanced")
    elif off := gains_off_one(white_balance):
        why.append("the colours ask for white-balance gains " + ", ".join(
            f"{n} x{g:.3f}" for n, g, _ in off) + " and no reference gives them: the order "
            "rests on the image being balanced")
    for a in _aliases(dist.thickness):
        why.append(f"the {a[0]:.1f} nm component may be the {a[1]:.1f} nm one read in "
                   f"another order")
    for c in _candidate_aliases(dist.thickness):
        why.append(f"the candidate at {c.mean_nm:.1f} nm may be the {c.alias_of_nm:.1f} nm "
                   f"component read in another order")
    for m in _order_moves(dist.thickness):
        why.append(f"the facets of a {m['from_nm']:.1f} nm component were read in the order "
                   f"of the {m['to_nm']:.1f} nm one (their colours fit both within "
                   f"{options.ambiguous_order_de:g} dE00 on average)")
    if not dist.thickness_judgement.identified:
        why.append("the thickness is not identified")
    return {"established": not why, "reasons": why}


def _readings_text(readings) -> str:
    """``"exposure 0.97: median dE00 2.10 (reported), exposure 0.36: 2.40"``."""
    parts = [f"exposure {e:.3g}: median dE00 {d:.2f}" + (" (reported)" if i == readings.chosen
                                                         else "")
             for i, (e, d) in enumerate(zip(readings.exposures, readings.median_delta_e))]
    return ", ".join(parts)


def _order_ambiguous_fraction(fit) -> float:
    """The facets' area share with a close runner-up order (0 without the joint fit's)."""
    return (fit.info.get("order_ambiguous_fraction") or 0.0) if fit is not None else 0.0


def _unexplained_floor(delta_e_median, noise_de, options) -> float | None:
    """The median ΔE00's noise floor where the median lies more than
    ``options.excess_delta_e`` above it (the model does not explain the colours); else
    None."""
    floor = MEDIAN_NOISE_FLOOR_FACTOR * noise_de
    if delta_e_median is not None and delta_e_median > floor + options.excess_delta_e:
        return floor
    return None


def _aliases(fit) -> list:
    """``(mean, alias mean, ambiguous fraction, both ways)`` of each component that may be
    another read in a neighbouring order (``info["component_orders"]``,
    :func:`~.consistency.component_orders`); a pair that are each other's alias once, by
    the one with more of its area ambiguous."""
    if fit is None:
        return []
    orders = fit.info.get("component_orders") or []
    out = [(c[1], o["alias_of_nm"], o["order_ambiguous_fraction"], o.get("alias_both_ways"))
           for c, o in zip(fit.mixture.components, orders) if o.get("alias_of_nm") is not None]
    back = {a[0]: a for a in out}          # a pair: the partner's alias is this one
    return [a for a in out if not (a[1] in back and back[a[1]][1] == a[0]
                                   and (back[a[1]][2], a[0]) > (a[2], a[1]))]


def _order_moves(fit) -> list:
    """The components moved to another's interference order (``info["order_moves"]``,
    :func:`~.distributions.pool_interference_orders`)."""
    return (fit.info.get("order_moves") or []) if fit is not None else []


def _candidate_aliases(fit) -> list:
    """The candidate populations that may be a component read in another order
    (:attr:`~.mixtures.PopulationCandidate.alias_of_nm`)."""
    cands = (fit.info.get("candidates") or []) if fit is not None else []
    return [c for c in cands if getattr(c, "alias_of_nm", None) is not None]


def _candidate_warning(fit) -> Reason | None:
    """Populations the regions suggest and the field is too small to decide."""
    cands = [c for c in ((fit.info.get("candidates") or []) if fit is not None else [])
             if c.reported and c.decided_at_field_um is not None]
    if not cands:
        return None

    def one(c):
        n = f"{c.regions} region{'s' if c.regions > 1 else ''}"
        return (f"{c.mean_nm:.1f} nm ({100 * c.area_fraction:.0f} %, {n}; a field of "
                f"~{c.decided_at_field_um:.0f} um square would decide it)")

    return Reason("thickness_candidates", f"candidate thickness population(s) the field is "
                  f"too small to tell: {'; '.join(one(c) for c in cands)}; not in the "
                  f"mixture (summary.json thickness.mixture.candidates)",
                  "fits.thickness_min_component_samples")


def _misread_one(m) -> str:
    """One component set aside, with why (``why``: colour or scattered)."""
    if m.get("why") == "scattered":
        return (f"{m['mean_nm']:.1f} nm ({100 * m['weight']:.0f} %, scattered: "
                f"{m['facets_per_region']:.1f} facets per region)")
    return (f"{m['mean_nm']:.1f} nm ({100 * m['weight']:.0f} %, median dE00 "
            f"{m['delta_e']:.2f} against the populations' {m['delta_e_populations']:.2f})")


def _misread_warning(fit) -> Reason | None:
    """Minor components set aside as misread facets (``info["misread_components"]``,
    :func:`~.distributions.fit_joint_distributions`): colours the film explains much worse
    than the populations', or facets scattered in regions of a few facets."""
    gone = (fit.info.get("misread_components") or []) if fit is not None else []
    if not gone:
        return None
    return Reason("thickness_misread", f"facets misread, set aside and not counted as "
                  f"populations: {'; '.join(_misread_one(m) for m in gone)} "
                  f"(summary.json thickness.mixture.misread_components; their thicknesses stay "
                  f"in thickness_nm.npy)", "optics.film")


#: Share of the image masked above which :func:`mask_warning` says what is masked and why.
MASKED_WARN_FRACTION = 0.3

#: Per mask reason (:data:`~.mask.MASK_REASONS`): what its pixels are and what would show
#: them, and the option that sets it (None: the acquisition, not an option).
_MASK_REMEDY = {
    "clipped": ("two or more channels at the top code value (over-exposed: their colour is "
                "not the film's; one clipped channel is analysed, `mask.clipped_one_channel`, "
                "unless a flat field is divided out); slices taken with a shorter exposure "
                "would show them", None),
    "low_saturation": ("grey (HSV saturation below `mask.saturation_min`, in areas "
                       "narrower than `mask.grey_film_min_px`)", "mask.saturation_min"),
    "dark": ("too dark to read (HSV value below `mask.value_min`); a longer exposure would "
             "show them", "mask.value_min"),
    "shadow": ("darker than their neighbourhood (`mask.shadow_ratio`)", "mask.shadow_ratio"),
    "steep": ("tilted past the objective's acceptance (censored in the NDF); a higher "
              "numerical aperture would see them", None),
    "dark_feature": ("scratches, pits and rims darker than the film (`mask.dark_film_min_px`)",
                     "mask.dark_film_min_px"),
    "invalid": ("not numbers in the input", None),
}


def mask_warning(fractions: dict) -> Reason | None:
    """A warning where more than :data:`MASKED_WARN_FRACTION` of the image is masked
    (``fractions``: :meth:`~.mask.ColourMask.fractions`): the distributions are of the rest
    only, so a population under the mask is not in them; it names the largest reason and
    what would show those pixels.

    >>> mask_warning({"clipped": 0.62, "low_saturation": 0.01, "any": 0.63}).code
    'masked'
    >>> mask_warning({"clipped": 0.02, "any": 0.04}) is None
    True
    """
    share = float(fractions.get("any", 0.0))
    reasons = {k: float(fractions.get(k, 0.0)) for k in _MASK_REMEDY}
    if share <= MASKED_WARN_FRACTION or max(reasons.values()) <= 0:
        return None
    top = max(reasons, key=reasons.get)
    what, parameter = _MASK_REMEDY[top]
    return Reason("masked", f"{100 * share:.0f} % of the image is masked, "
                  f"{100 * reasons[top]:.0f} % of it {what}: the distributions are of the other "
                  f"{100 * (1 - share):.0f} % only, and a population that lies under the mask "
                  f"is not in them (summary.json mask)", parameter)


#: A gain the scene's own white-balance estimate asks for is "off 1" beyond this many of its
#: SDs (:func:`gains_off_one`) ...
GAIN_OFF_SIGMAS = 3.0
#: ... and beyond this relative size (the estimate's bias on balanced scenes: the film model
#: does not hold every scene effect, docs/accuracy.md "White balance").
GAIN_OFF_MIN = 0.03


def gains_off_one(wb) -> list:
    """The gains the scene's own estimate asks for that differ from 1 by more than
    :data:`GAIN_OFF_SIGMAS` σ and :data:`GAIN_OFF_MIN` in log, where no reference gives them:
    ``[(name, gain, sigma)]`` for R and B (empty without an estimate with a spread, or with
    a reference). Either the image is not balanced for the illuminant, or the film model does
    not fit it; the scene cannot tell which.

    >>> from microfacet.analysis.white_balance import WhiteBalance
    >>> gains_off_one(WhiteBalance(estimate_rgb=(1.101, 1.0, 0.98), estimate_sigma=(0.008, 0.01)))
    [('R', 1.101, 0.008)]
    """
    if wb is None or wb.estimate_rgb is None or wb.source != "none" or not wb.estimate_sigma:
        return []
    return [(name, g, s) for name, g, log_g, s in zip(
                ("R", "B"), (wb.estimate_rgb[0], wb.estimate_rgb[2]), wb.estimate_log_rb(),
                wb.estimate_sigma)
            if abs(log_g) > max(GAIN_OFF_SIGMAS * s, GAIN_OFF_MIN)]


def _white_balance_warning(wb) -> Reason | None:
    """The colours leave the gains free (:func:`gains_unconstrained`), or look unbalanced:
    an estimate, no reference, a gain off 1 by > 3σ, > 3 %."""
    if gains_unconstrained(wb):
        return Reason("white_balance_free", f"the film's colours do not fix the white balance "
                      f"(e.g. one film colour: a gain and a thickness trade off; they ask for R "
                      f"x{wb.estimate_rgb[0]:.3f}, B x{wb.estimate_rgb[2]:.3f} with a spread "
                      f"as wide as the search, or at its edge) and no reference gives it, so "
                      f"the thickness "
                      f"and its interference order rest on the image being balanced for the "
                      f"illuminant; a white or bare-substrate reference "
                      f"(`optics.white_reference`, `optics.substrate_reference`) settles it",
                      "optics.white_reference")
    off = gains_off_one(wb)
    if not off:
        return None
    gains = ", ".join(f"{n} x{g:.3f} (+-{100 * s:.1f} %)" for n, g, s in off)
    return Reason("white_balance_suspect", f"the film's colours ask for white-balance gains "
                  f"{gains}: the image may not be balanced for the illuminant, or the film "
                  f"model does not fit it; a white or bare-substrate reference settles it",
                  "optics.white_reference")


def analysis_warnings(dist, *, delta_e_median, noise_de, mean_plane_tilt,
                      options: FitOptions, white_balance=None, map_check=None,
                      roi_check=None) -> list[Reason]:
    """One :class:`Reason` per thing a user must know before trusting the distributions.

    An unidentified (or missing) thickness mixture or NDF, ambiguous interference orders
    (ROIs whose runner-up order fits within ``options.ambiguous_order_de``), a median ΔE more
    than ``options.excess_delta_e`` above its noise floor (:data:`MEDIAN_NOISE_FLOOR_FACTOR`
    × ``noise_de``), and a sample whose mean plane is tilted by more than
    ``options.sample_tilt_warn_fraction`` of the NDF's rms lobe width; with a white-balance
    estimate and no reference, gains that the colours leave free (:func:`gains_unconstrained`,
    ``white_balance_free``) or else that differ from 1 by more than 3σ and 3 %.

    Parameters
    ----------
    dist : Distributions
        The fits, their judgements and the ROIs' ambiguity (:mod:`.distributions`).
    white_balance : WhiteBalance, optional
        The applied gains and the scene's estimate (:mod:`.white_balance`).
    map_check : MapCheck, optional
        The thickness mixture against the per-pixel map (:mod:`.consistency`): a warning
        when they disagree.
    roi_check : tuple, optional
        ``(pixel_median_nm, disagrees)`` per ROI (:func:`~.consistency.roi_pixel_check`):
        a warning naming the ROIs whose single fit disagrees with their pixels.
    """
    out = [r for r in (_spike_warning(dist.thickness), _candidate_warning(dist.thickness),
                       _misread_warning(dist.thickness)) if r is not None]
    judged = dist.thickness_judgement.reason
    if (map_check is not None and not map_check.consistent
            and (judged is None or judged.code != "mixture_map_mismatch")):
        out.append(Reason("mixture_map_mismatch", "the thickness mixture does not summarize "
                          "the per-pixel map: " + _map_mismatch_text(map_check),
                          "fits.max_components"))
    if roi_check is not None and np.any(roi_check[1]):
        med, bad = roi_check
        i = int(np.flatnonzero(bad)[0])
        out.append(Reason("roi_pixel_mismatch", f"{int(bad.sum())} ROI(s) have a single "
                          f"thickness far from their own pixels' (ROI {i}: median of its "
                          f"pixels {med[i]:.1f} nm): a ROI spanning several populations or "
                          f"orders; thickness_roi.csv flags them", "roi.size_px"))
    wb = _white_balance_warning(white_balance)
    if wb is not None:
        out.append(wb)
    for what, fit, j in (("thickness distribution", dist.thickness, dist.thickness_judgement),
                         ("NDF", dist.ndf, dist.ndf_judgement)):
        if not j.identified:
            how = "" if fit is None else " (the fit is written for inspection only)"
            out.append(Reason(f"not_identified_{'ndf' if what == 'NDF' else 'thickness'}",
                              f"{what} not identified{how}: {j.reason.text}",
                              j.reason.parameter))
    frac = _order_ambiguous_fraction(dist.thickness)
    if ORDER_AMBIGUOUS_AREA < frac and dist.thickness_judgement.identified:
        out.append(Reason("order_ambiguous_facets", f"{100 * frac:.0f} % of the facets' area "
                          f"has a runner-up interference order within "
                          f"{options.ambiguous_order_de:g} dE00: the order is not established "
                          f"there (facets.csv other_order_delta_e)", _RANGE))
    for mean, other, frac, both in _aliases(dist.thickness):
        out.append(Reason("order_alias", f"the {mean:.1f} nm thickness component may be the "
                          f"{other:.1f} nm population read in another interference order: "
                          f"{100 * frac:.0f} % of its area fits that order within "
                          f"{options.ambiguous_order_de:g} dE00"
                          + (", and that component's runner-up order lies on this one"
                             if both else "") + " (facets.csv other_order_thickness_nm)",
                          _RANGE))
    for m in _order_moves(dist.thickness):
        out.append(Reason("order_pooled", f"{100 * m['area_share']:.0f} % of a "
                          f"{m['from_nm']:.1f} nm thickness component was read in the "
                          f"interference order of the {m['to_nm']:.1f} nm population: its "
                          f"colours fit that order within {m['mean_gap_de']:.2f} dE00 of their "
                          f"own on average, so it is that population, not another an order "
                          f"away (fits.order_moves)", "fits.order_moves"))
    for c in _candidate_aliases(dist.thickness):
        out.append(Reason("order_alias", f"the candidate population at {c.mean_nm:.1f} nm "
                          f"({100 * c.area_fraction:.0f} % of the area) may be the "
                          f"{c.alias_of_nm:.1f} nm component read in another interference "
                          f"order, or that component this one: its facets fit that order "
                          f"within {c.order_gap_de:.2f} dE00 of their own, inside the "
                          f"populations' misfit (summary.json thickness.mixture.candidates)",
                          _RANGE))
    readings = dist.exposure_readings
    if readings is not None and readings.ambiguous:
        out.append(Reason("exposure_ambiguous", f"two exposures fit the facets' colours "
                          f"within {options.ambiguous_order_de:g} dE00 ("
                          f"{_readings_text(readings)}), each with its own interference "
                          f"orders: the reported one fits best, but the order is not "
                          f"established; give the exposure (--exposure, stack.json) or a "
                          f"white reference to decide", "optics.exposure"))
    amb = int(dist.roi_ambiguous.sum())
    if amb:
        out.append(Reason("ambiguous_rois", f"{amb} of {int(dist.roi_fitted.sum())} ROIs have "
                          f"an ambiguous interference order (runner-up within "
                          f"{options.ambiguous_order_de:g} dE00)", _RANGE))
    floor = _unexplained_floor(delta_e_median, noise_de, options)
    if floor is not None:
        out.append(Reason("colours_unexplained", f"median dE00 {delta_e_median:.2f} is "
                          f"{delta_e_median - floor:.2f} above the image's noise floor "
                          f"{floor:.2f}: the model does not explain the colours (wrong film, "
                          f"illuminant, exposure or white balance?), so the thicknesses' "
                          f"interference order is not established", "optics.film"))
    width = _ndf_width_deg(dist.ndf)
    if mean_plane_tilt is not None and width is not None \
            and mean_plane_tilt > options.sample_tilt_warn_fraction * width:
        out.append(Reason("sample_tilted", f"the sample's mean plane is tilted by "
                          f"{mean_plane_tilt:.2f} deg against the optical axis: the NDF is of "
                          f"facet tilts against the axis, not the surface; level the sample on "
                          f"the stage for an NDF of the surface"))
    return out
