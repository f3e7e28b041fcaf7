"""The joint mode: facets, their planes and thickness (:func:`facets_at_exposure_readings`),
then the tilt per pixel (:func:`joint_pixel_tilts`).

1. Facets from colour and height edges (:func:`~.segmentation.segment_facets`).
2. A plane per facet through its reliable heights only (:func:`~.planes.fit_facet_planes`);
   a facet without enough of them has no height tilt (it is marked, not guessed). Two sets
   from focus: through the combined height (dense, smoothed by its 7-15 px windows: the
   colour's tilt prior, where a flattened tilt moves the colour by little) and through the
   evidence window's heights (each from the focus evidence at the pixel itself: the NDF's
   samples, which the windows' smoothing would flatten).
3. The exposure refined on facets with a height tilt, then each facet's thickness from its
   colour at its tilt, within its interference order
   (:func:`~.facet_thickness.facet_thickness`). Where the ROI stage has two exposure
   readings (:mod:`.roi`), both are carried through this step and the one of least median
   facet ΔE00 wins (:func:`facets_at_exposure_readings`); within ``ambiguous_de`` of each
   other they leave the order undecided (:class:`ExposureReadings`). Facets without a
   height tilt use the area-weighted median tilt of those with one as a stand-in, with their
   spread as its error.
4. The tilt per pixel: the MAP of the colour likelihood and the facet's plane as prior
   (:func:`~.tilt.invert_tilt`). The colour term is calibrated: its error per Lab component
   is the facet's own scatter about the model (noise, thickness variation inside the facet,
   model error; at least the image noise) plus the colour change of the facet thickness's
   1-σ error. Facets without a height tilt have the stand-in as a wide prior.

References
----------
.. [1] N. Nagata et al., the seed, §3.3.2-3.3.3 (facets as planes; thickness per region,
   tilt per pixel).
"""

from __future__ import annotations

import dataclasses
import logging
import math
from dataclasses import dataclass

import numpy as np

from ..core.pixels import pixel_area_side
from ..core.threads import chunk_starts, thread_map
from ..focus.measures import measure_spread_px
from .facet_thickness import (
    FacetColours,
    FacetImage,
    FacetThickness,
    facet_thickness,
    refine_exposure_on_facets,
)
from .options import JointOptions, TiltOptions
from .planes import (
    FacetFit,
    at_least_px,
    dome_mean_square_slope,
    facet_edge_distance,
    fit_facet_planes,
    fit_unmixed_planes,
)
from .roi import EXPOSURE_DISTINCT
from .sampling import weighted_median
from .segmentation import segment_facets
from .tilt import PixelEstimates, TiltRows, invert_tilt_into, model_lab_rows
from .white_balance import rebalanced_lab

__all__ = ["ExposureReadings", "FacetGeometry", "JointResult", "Segmented", "bootstrap_labels",
           "delta_e_rebalanced", "evidence_planes", "facet_geometry", "facet_image", "facet_labels",
           "facets_at_exposure_readings", "facets_in_order", "facets_in_other_order",
           "gain_thickness_shifts", "joint_pixel_tilts"]

log = logging.getLogger(__name__)

#: Pixels in flight in the per-facet colour misfit (split over the threads).
_CHUNK_PX = 262144


@dataclass
class HeightInputs:
    """The heights the joint mode may use: height, its 1-σ error, which pixels may be used,
    and the correlation area of the errors (pixels).

    The height and its error are held as the focus stage gave them (float32: 8 bytes a pixel
    less for each while the facet stages run, docs/benchmarks.md) and read as the float64
    the plane fits work in (:attr:`height_um`, :attr:`sigma_um`: the same numbers).
    """

    stored_height_um: np.ndarray
    stored_sigma_um: np.ndarray
    reliable: np.ndarray
    correlation_px: float
    #: σ (px) of the support each height is the texture-weighted mean over
    #: (:func:`~microfacet.focus.measures.measure_spread_px`; 0: a height at its pixel)
    mixing_px: float = 0.0

    @property
    def height_um(self) -> np.ndarray:
        """Height (µm), float64, NaN where absent."""
        return np.asarray(self.stored_height_um, dtype=np.float64)

    @property
    def sigma_um(self) -> np.ndarray:
        """1-σ error of the height (µm), float64."""
        return np.asarray(self.stored_sigma_um, dtype=np.float64)

    def crop(self, crop) -> HeightInputs:
        """The inputs of ``crop`` (a pair of slices)."""
        return HeightInputs(self.stored_height_um[crop], self.stored_sigma_um[crop],
                            self.reliable[crop], self.correlation_px, self.mixing_px)


@dataclass
class JointResult:
    """What the joint stage found.

    Attributes
    ----------
    pixels : PixelEstimates or None
        Per-pixel thickness and tilt (:func:`joint_pixel_tilts`).
    facets : ndarray of int32 (H, W)
        Facet labels 0..S-1.
    planes : FacetFit
        Through the segmentation's heights (dense, smoothed): the colour's tilt prior and
        the facets' thickness.
    evidence_planes : FacetFit or None
        Through the evidence window's heights (each from the focus evidence at the pixel
        itself, unbiased but sparser): the NDF's samples (:attr:`slope_planes`). None where
        the heights are not from focus.
    dome_ms_slope : (float, float) or None
        Mean square of the slope inside the facets that the planes miss (a dome term per
        facet, :func:`~.planes.dome_mean_square_slope`) and its standard error, from the
        same heights as :attr:`slope_planes`.
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
    prior_deg, prior_sigma_deg : ndarray, shape (S,)
        Each facet's tilt prior: its plane's tilt and error, or the stand-in.
    usable : ndarray of bool (H, W)
        Pixels with a colour and a ROI thickness.
    """

    pixels: PixelEstimates | None
    facets: np.ndarray
    planes: FacetFit
    thickness: FacetThickness
    area_px: np.ndarray
    censored: np.ndarray
    colour_sigma_de: np.ndarray
    exposure: float
    prior_deg: np.ndarray
    prior_sigma_deg: np.ndarray
    usable: np.ndarray
    evidence_planes: FacetFit | None = None
    dome_ms_slope: tuple | None = None

    @property
    def slope_planes(self) -> FacetFit:
        """The planes the NDF is made of: ``evidence_planes``, else ``planes``."""
        return self.planes if self.evidence_planes is None else self.evidence_planes


def height_inputs(surface, options: JointOptions, *, from_focus, evidence=True
                  ) -> HeightInputs:
    """The heights the planes may use.

    From focus (:func:`focus_heights`): the evidence window's heights and errors, or the
    focus stage's reliable pixels and its per-pixel error (``height_sigma_um``; a quarter of
    the slice spacing where the focus stage gives none), correlated over about the window
    (``options.focus_error_correlation`` × window², measured). From an export: every
    finite height, with an error left to the plane fits' residuals
    (``options.export_sigma_um``).
    """
    foc = surface.focus
    h = np.asarray(foc.height_fit_um)
    if surface.no_focus:
        return HeightInputs(h, np.full(h.shape, np.nan), np.zeros(h.shape, bool), 1.0)
    if not from_focus:
        return HeightInputs(h, np.full(h.shape, options.export_sigma_um), np.isfinite(h), 1.0)
    return focus_heights(foc, options, evidence=evidence)


def focus_heights(foc, options: JointOptions, *, evidence=True) -> HeightInputs:
    """The heights a :class:`~microfacet.focus.height.FocusResult` gives the joint mode:
    with ``evidence`` (the planes) its evidence window's, each from the focus evidence at the
    pixel itself, where the focus stage measured them; else (the segmentation: denser,
    smoother) its combined height; errors correlated over about that window."""
    if evidence and foc.evidence_height_um is not None:
        h, sig = np.asarray(foc.evidence_height_um), np.asarray(foc.evidence_sigma_um)
        ok = np.isfinite(h) & np.isfinite(sig) & (sig > 0)
        win = int(foc.params.get("evidence_window_px", 1))
        spread = measure_spread_px(operator=foc.params.get("operator", "tenengrad"),
                                   window_px=win, window=foc.params.get("window", "gaussian"))
        return HeightInputs(h, sig, ok, options.focus_error_correlation * win ** 2, spread)
    h = np.asarray(foc.height_fit_um)
    rel = np.asarray(foc.reliable, bool) & np.isfinite(h)
    sig = getattr(foc, "height_sigma_um", None)
    if sig is None:
        z = np.sort(np.asarray(foc.z_um, dtype=np.float64))
        step = float(np.median(np.diff(z))) if z.size > 1 else 1.0
        sig = np.full(h.shape, 0.25 * step)
    sig = np.asarray(sig)
    corr = options.focus_error_correlation * float(foc.params.get("window_px", 1)) ** 2
    return HeightInputs(h, sig, rel & np.isfinite(sig) & (sig > 0), corr)


def evidence_planes(labels, h: HeightInputs, *, reliable, pixel_size_um,
                    options: JointOptions, surround_um=None) -> tuple[FacetFit, np.ndarray]:
    """The NDF's planes: :func:`~.planes.fit_unmixed_planes` through ``h``'s heights on
    ``reliable`` (the segments' interiors) with its mixing undone (``h.mixing_px``,
    ``options.unmix_heights``), and the unmixed heights (float64, (H, W)). The analysis and
    its self-check fit them alike."""
    return fit_unmixed_planes(labels, h.height_um,
                              mixing_px=h.mixing_px if options.unmix_heights else 0.0,
                              surround_um=surround_um,
                              height_sigma_um=h.sigma_um, reliable=h.reliable & reliable,
                              pixel_size_um=pixel_size_um,
                              min_pixels=options.min_plane_pixels,
                              correlation_px=h.correlation_px)


def _stand_in_tilt(planes, area):
    """Area-weighted median and spread of the fitted facets' tilts (0, 10° without any)."""
    ok = planes.fitted & np.isfinite(planes.tilt_deg)
    if ok.sum() < 3:
        return 0.0, 10.0
    t, a = planes.tilt_deg[ok], area[ok].astype(np.float64)
    med = weighted_median(t, a)
    spread = math.sqrt(float(np.average((t - med) ** 2, weights=a)))
    return med, max(spread, 1.0)


def _colour_sigma(image: FacetImage, ft: FacetThickness, tilt_f, model, noise_de):
    """Per facet: √(max(noise², mean ΔE²/3) + (∂ΔE/∂d · σ_d)²), ΔE of its pixels to its model."""
    d_f = ft.thickness_nm
    S = d_f.size
    good = np.isfinite(d_f) & np.isfinite(tilt_f)
    flat = np.flatnonzero(image.usable & good[image.labels])
    fid = image.labels.reshape(-1)[flat]
    lab_flat = image.lab.reshape(-1, 3)
    t_lo, t_hi = model.theta_range_deg
    th = np.clip(tilt_f, t_lo, t_hi)
    # one model colour per facet (its thickness at its tilt), compared with its pixels
    model_f = np.full((S, 3), np.nan, np.float32)
    model_f[good] = model.lab(th[good], d_f[good])
    de = np.empty(fid.size, np.float32)

    def chunk(ab):
        de[ab[0]:ab[1]] = model.difference(model_f[fid[ab[0]:ab[1]]], lab_flat[flat[ab[0]:ab[1]]])

    thread_map(chunk, chunk_starts(fid.size, _CHUNK_PX))
    cnt = np.bincount(fid, minlength=S)
    ms = np.bincount(fid, weights=de.astype(np.float64) ** 2, minlength=S) / np.maximum(cnt, 1)
    d_lo, d_hi = model.thickness_range_nm
    lo = np.where(good, np.clip(d_f - 0.5, d_lo, d_hi), 0)
    hi = np.where(good, np.clip(d_f + 0.5, d_lo, d_hi), 0)
    th0 = np.where(good, th, 0.0)
    with np.errstate(invalid="ignore", divide="ignore"):
        j_d = model.difference(model.lab(th0, hi), model.lab(th0, lo)) / np.maximum(hi - lo, 1e-9)
    var = np.maximum(noise_de ** 2, ms / 3.0) + (j_d * np.nan_to_num(ft.sigma_nm, nan=0.0)) ** 2
    return np.where(good, np.sqrt(var), np.nan)


@dataclass
class Segmented:
    """Facet labels, the heights they were drawn with (the focus stage's combined height,
    dense and smooth: the planes that are the colour's tilt prior) and the evidence window's
    heights (each from the focus evidence at the pixel itself: the planes of the NDF)."""

    labels: np.ndarray
    heights: HeightInputs
    evidence: HeightInputs | None = None


def facet_labels(colour, surface, scene, options: JointOptions) -> Segmented:
    """Step 1: facets from colour and height edges (:func:`~.segmentation.segment_facets`),
    the facet size in pixels from ``options.facet_size_um`` and the pixel size."""
    hi = height_inputs(surface, options, from_focus=scene.from_focus, evidence=False)
    labels = _segment(colour.lab, hi, colour.noise_de, scene, options)
    has_evidence = (scene.from_focus and not surface.no_focus
                    and surface.focus.evidence_height_um is not None)
    return Segmented(labels, hi, focus_heights(surface.focus, options) if has_evidence
                     else None)


def bootstrap_labels(colour, seg: Segmented, scene, options: JointOptions, *, rng, crop):
    """Facets of the ``crop`` (a pair of slices) segmented as :func:`facet_labels` did
    ``seg`` (with its heights), after fresh noise of the image's own measured level is added
    to its Lab values: a second segmentation as likely as the first (a parametric
    bootstrap), which differs from it wherever the image does not fix the facets' edges."""
    lab = colour.lab[crop]
    lab = lab + rng.normal(0.0, colour.noise_de, lab.shape).astype(np.float32)
    return _segment(lab, seg.heights.crop(crop), colour.noise_de, scene, options)


def _segment(lab, hi: HeightInputs, noise_de, scene, options: JointOptions):
    facet_px = options.facet_size_um / pixel_area_side(scene.pixel_size_um)
    return segment_facets(lab, facet_px=facet_px, noise_de=noise_de,
                          height_um=np.where(hi.reliable, hi.height_um, np.nan),
                          height_sigma_um=hi.sigma_um, pixel_size_um=scene.pixel_size_um,
                          options=options)


@dataclass
class FacetGeometry:
    """What the joint stage finds without the colours (:func:`facet_geometry`): the facet
    labels, their planes (both sets), their tilts (or the stand-in) and tilt errors, areas,
    edge distances and the dome term. Shared by every exposure reading and every flat-field
    round (:func:`facets_at_exposure_readings`)."""

    labels: np.ndarray
    planes: FacetFit
    evidence_planes: FacetFit | None
    area: np.ndarray
    edge_distance: np.ndarray
    tilt_deg: np.ndarray
    tilt_sigma_deg: np.ndarray
    dome: tuple | None

    def censored(self, steep) -> np.ndarray:
        """Pixels (H, W) of the facets tilted past the acceptance: more than half their
        pixels far darker than the film (``steep``, the colour mask's)."""
        dark = np.bincount(self.labels.ravel(), weights=np.asarray(steep).ravel(),
                           minlength=self.area.size)
        return (dark > 0.5 * self.area)[self.labels]


def facet_geometry(seg: Segmented, scene, options: JointOptions) -> FacetGeometry:
    """Step 2 of the module notes: the facets' planes through their reliable heights, their
    tilts (facets without a plane take the stand-in) and the dome term; nothing here depends
    on the colours."""
    facets, hi = seg.labels, seg.heights
    S = int(facets.max()) + 1
    area = np.bincount(facets.ravel(), minlength=S)
    dist = facet_edge_distance(facets)
    inside = at_least_px(dist, options.plane_edge_px)

    def planes_through(h: HeightInputs) -> FacetFit:
        return fit_facet_planes(facets, h.height_um, height_sigma_um=h.sigma_um,
                                reliable=h.reliable & inside, pixel_size_um=scene.pixel_size_um,
                                min_pixels=options.min_plane_pixels,
                                correlation_px=h.correlation_px)

    planes = planes_through(hi)
    ev_planes, h = None, hi
    if seg.evidence is not None:
        ev_planes, unmixed = evidence_planes(facets, seg.evidence, reliable=inside,
                                             pixel_size_um=scene.pixel_size_um,
                                             options=options, surround_um=hi.height_um)
        h = dataclasses.replace(seg.evidence, stored_height_um=unmixed)
    fitted = planes.fitted
    t_in, s_in = _stand_in_tilt(planes, area)
    log.info("facets: %d, %d with a height tilt (%.0f%% of the area); stand-in tilt %.1f ± "
             "%.1f deg", S, int(fitted.sum()), 100.0 * area[fitted].sum() / max(area.sum(), 1),
             t_in, s_in)
    tilt_f = np.where(fitted, np.clip(planes.tilt_deg, 0, scene.max_tilt_deg), t_in)
    tsig_f = np.where(fitted, planes.tilt_sigma_deg, s_in)
    dome = dome_mean_square_slope(facets, h.height_um, height_sigma_um=h.sigma_um,
                                  reliable=h.reliable & inside,
                                  pixel_size_um=scene.pixel_size_um,
                                  correlation_px=h.correlation_px)
    return FacetGeometry(facets, planes, ev_planes, area, dist, tilt_f, tsig_f, dome)


def facet_image(g: FacetGeometry, colour, roi, options: JointOptions) -> FacetImage:
    """The colour image as ``g``'s facets, with ``roi``'s thickness per pixel."""
    thick_roi_px = roi.thickness_nm[roi.index_map(colour.lab.shape[:2])]
    usable = ~colour.mask.mask & np.isfinite(thick_roi_px)
    return FacetImage(g.labels, colour.lab, usable,
                      at_least_px(g.edge_distance, options.interior_px), thick_roi_px)


def _facets_in_colour(g: FacetGeometry, colour, roi, model, scene, options: JointOptions
                      ) -> JointResult:
    """The exposure refined on the facets, their thickness and colour error, at one
    exposure reading (``roi``'s, ``model``'s)."""
    image = facet_image(g, colour, roi, options)
    usable, fitted = image.usable, g.planes.fitted
    if scene.estimate_exposure:
        model = model.with_exposure(refine_exposure_on_facets(
            image, np.where(fitted, g.tilt_deg, np.nan), model, options, seed=scene.seed))
        log.info("exposure refined on facets: %.4f", model.exposure)
    ft = facet_thickness(image.colours(), g.tilt_deg, model, options,
                         tilt_sigma_deg=g.tilt_sigma_deg, noise_de=colour.noise_de,
                         block_noise=(colour.block_noise_de, colour.block_px))
    c_sig = _colour_sigma(image, ft, g.tilt_deg, model, colour.noise_de)
    return JointResult(None, g.labels, g.planes, ft, g.area, g.censored(colour.mask.steep),
                       c_sig,
                       float(model.exposure), g.tilt_deg, g.tilt_sigma_deg, usable,
                       g.evidence_planes, g.dome)


def facets_in_other_order(joint: JointResult, image: FacetImage, colour, model,
                          options: JointOptions, *, moved, centre_nm,
                          colours: FacetColours | None = None) -> JointResult:
    """``joint`` with the facets ``moved`` (bool, shape (S,)) solved again in the
    interference order about ``centre_nm`` (per facet) instead of their ROI's, the others
    kept, each at its tilt (``joint.prior_deg``); their colour errors follow
    (:func:`~.consistency.order_move` says which facets). ``image``: :func:`facet_image` of
    ``joint``'s facets, ``colour`` (its noise) and ROIs; ``colours``: ``image.colours()``,
    where the caller has them (each round of order moves would average the image again).
    ``model`` is at ``joint``'s exposure; a facet whose old order still fits better by more
    than ``options.order_switch_de`` keeps it (:func:`~.facet_thickness.facet_thickness`)."""
    moved = np.asarray(moved, bool)
    cols = dataclasses.replace(image.colours() if colours is None else colours,
                               roi_thickness_nm=np.where(
                                   moved, np.asarray(centre_nm, dtype=np.float64), np.nan))
    new = facet_thickness(cols, joint.prior_deg, model, options,
                          tilt_sigma_deg=joint.prior_sigma_deg, noise_de=colour.noise_de,
                          block_noise=(colour.block_noise_de, colour.block_px))
    return _with_facets(joint, image, colour, model, new, moved)


def facets_in_order(joint: JointResult, image: FacetImage, colour, model,
                    options: JointOptions, *, moved, centre_nm,
                    colours: FacetColours | None = None) -> JointResult:
    """``joint`` with the facets ``moved`` (bool, shape (S,)) solved in the interference
    order about ``centre_nm`` (per facet), all of them, whatever another order's fit (no
    scan of the other orders): :func:`~.order_cut.order_cut` decided it. Their runner-up
    order is the one they left (``delta_e_other_order`` and ``thickness_other_order_nm``
    their old ΔE and thickness); at ``options.thickness_step_nm``; the rest (``colours``
    too) as :func:`facets_in_other_order`."""
    moved = np.asarray(moved, bool)
    cols = dataclasses.replace(image.colours() if colours is None else colours,
                               roi_thickness_nm=np.where(
                                   moved, np.asarray(centre_nm, dtype=np.float64), np.nan))
    new = facet_thickness(cols, joint.prior_deg, model,
                          options.replace(exposure_thickness_step_nm=options.thickness_step_nm),
                          tilt_sigma_deg=joint.prior_sigma_deg, noise_de=colour.noise_de,
                          block_noise=(colour.block_noise_de, colour.block_px), thorough=False)
    old = joint.thickness
    new = dataclasses.replace(new, delta_e_other_order=old.delta_e,
                              thickness_other_order_nm=old.thickness_nm)
    return _with_facets(joint, image, colour, model, new, moved)


def _with_facets(joint, image, colour, model, new: FacetThickness, moved) -> JointResult:
    """``joint`` with the facets ``moved`` of ``new``, the others its own; the colour
    errors of them all."""
    old = joint.thickness
    ft = FacetThickness(*(np.where(moved, getattr(new, f.name), getattr(old, f.name))
                          for f in dataclasses.fields(FacetThickness)))
    return dataclasses.replace(joint, thickness=ft, colour_sigma_de=_colour_sigma(
        image, ft, joint.prior_deg, model, colour.noise_de))


#: Half-width (nm) of the window :func:`gain_thickness_shifts` solves a facet in again: a
#: gain's 1σ moves a facet by tenths of a nm (99.9 % of the facets of a 1 MP nd synth by
#: less than 2.5 nm at the gains' 2 and 4 %); a wider window only costs time.
SHIFT_WINDOW_NM = 10.0


def gain_thickness_shifts(colours: FacetColours, thickness_nm, tilt_deg, model,
                          options: JointOptions, *, log_gain_rb, illuminant) -> np.ndarray:
    """Per facet, how far its thickness moves (nm) when its colours are balanced with the R
    gain, then the B gain, larger by ``exp(log_gain_rb)``
    (:func:`~.white_balance.rebalanced_lab`).

    Each facet is solved again within :data:`SHIFT_WINDOW_NM` of ``thickness_nm`` (in its
    own order) at ``tilt_deg``, as is and moved, both at
    ``options.exposure_thickness_step_nm``, so that the difference carries no search step.

    Parameters
    ----------
    colours : FacetColours
        The facets' mean Lab (:meth:`~.facet_thickness.FacetImage.colours` of
        :func:`facet_image`).
    thickness_nm, tilt_deg : ndarray, shape (S,)
        Each facet's thickness (NaN: none) and the tilt it was solved at.
    model : FilmColourModel
        At the facets' exposure.
    options : JointOptions
    log_gain_rb : (float, float)
        The R and B moves of the log gains.
    illuminant : str

    Returns
    -------
    ndarray, shape (2, S)
        The R and B moves (nm); NaN where a facet has no thickness.
    """
    solve = _near_solver(colours, thickness_nm, tilt_deg, model, options)
    base = solve(colours.mean_lab).thickness_nm
    out = np.full((2, base.size), np.nan)
    for c in (0, 1):
        step = np.zeros(2)
        step[c] = log_gain_rb[c]
        out[c] = solve(rebalanced_lab(colours.mean_lab, step,
                                      illuminant=illuminant)).thickness_nm - base
    return out


#: Log-exposure step of :func:`delta_e_rebalanced`'s refit of the exposure (±4 steps, then
#: halved twice about the best): gains of 0.85-1.15 moved the fitted exposure of a
#: one-population nd synth by 5 %.
REBALANCE_EXPOSURE_STEP = 0.03


def delta_e_rebalanced(colours: FacetColours, thickness_nm, tilt_deg, model,
                       options: JointOptions, *, log_gain_rb, illuminant) -> np.ndarray:
    """Per facet, its colour misfit (ΔE00) once its colours are balanced with R and B gains
    larger by ``exp(log_gain_rb)`` (the scene's white-balance estimate, not applied) and it
    is solved again within :data:`SHIFT_WINDOW_NM` of ``thickness_nm``, in its own order, at
    ``tilt_deg`` and at the exposure (refitted about ``model``'s) where the facets' median
    misfit is least; NaN where a facet has no thickness. A white-balance error fits the film
    worse at some thicknesses than at others: a population misfit at the image's balance but
    not at the estimate's is the camera's, not misread facets
    (:func:`~.distributions.fit_joint_distributions`).

    Parameters as :func:`gain_thickness_shifts`.
    """
    lab = rebalanced_lab(colours.mean_lab, log_gain_rb, illuminant=illuminant)
    has = np.isfinite(np.asarray(thickness_nm, np.float64))

    def misfit(log_exposure):
        m = model.with_exposure(model.exposure * math.exp(log_exposure))
        de = _near_solver(colours, thickness_nm, tilt_deg, m, options)(lab).delta_e
        de = np.where(has, de, np.nan)
        return (float(np.nanmedian(de)) if np.isfinite(de).any() else math.inf), de

    # the exposure was fitted to the colours as they were: refitted to them rebalanced
    # (coarse steps, then half steps about the best twice)
    step = REBALANCE_EXPOSURE_STEP
    tried = {round(x, 6): misfit(x) for x in step * np.arange(-4, 5)}
    for _ in range(2):
        best = min(tried, key=lambda x: tried[x][0])
        step /= 2.0
        for x in (best - step, best + step):
            tried.setdefault(round(x, 6), misfit(x))
    return tried[min(tried, key=lambda x: tried[x][0])][1]


def _near_solver(colours: FacetColours, thickness_nm, tilt_deg, model, options: JointOptions):
    """``solve(lab)``: the facets' :func:`~.facet_thickness.facet_thickness` for the mean Lab
    ``lab``, each within :data:`SHIFT_WINDOW_NM` of ``thickness_nm`` (in its own order) at
    ``tilt_deg``, at ``options.exposure_thickness_step_nm``."""
    cols = dataclasses.replace(colours, roi_thickness_nm=np.asarray(thickness_nm, np.float64))
    near = dataclasses.replace(options, order_window_fraction=float(np.clip(
        SHIFT_WINDOW_NM / model.period_nm, 0.05, options.order_window_fraction)))

    def solve(lab):
        return facet_thickness(dataclasses.replace(cols, mean_lab=lab), tilt_deg, model,
                               near, thorough=False)
    return solve


@dataclass(frozen=True)
class ExposureReadings:
    """The exposure readings the facets decided between (summary.json ``exposure_readings``).

    Attributes
    ----------
    exposures : tuple of float
        Each reading's exposure, refined on the facets: the ROI stage's order band's first,
        then its blocks' (:mod:`.roi`).
    median_delta_e : tuple of float
        The median ΔE00 of each reading's facet thicknesses.
    chosen : int
        The reading of least median ΔE00, the one reported.
    ambiguous : bool
        The two differ by more than :data:`~.roi.EXPOSURE_DISTINCT` and fit within
        ``ambiguous_de``: the colours do not tell the exposures, nor so the interference
        orders, apart.
    """

    exposures: tuple
    median_delta_e: tuple
    chosen: int
    ambiguous: bool

    def to_json(self) -> dict:
        return {"exposures": list(self.exposures), "median_delta_e": list(self.median_delta_e),
                "chosen": self.chosen, "ambiguous": self.ambiguous}


def facets_at_exposure_readings(geometry: FacetGeometry, colour, roi, model, scene, options,
                                *, refit_roi):
    """Step 3 of the module notes: the exposure refined on the facets, their thickness and
    calibrated colour error and the censored facets (the per-pixel tilt is
    :func:`joint_pixel_tilts`), at the ROI stage's exposure and, where it has a second
    reading (``roi.exposure_alternative``), at that one too; the reading of least median
    facet ΔE00 wins.

    Parameters
    ----------
    geometry : FacetGeometry
        From :func:`facet_geometry` (the planes do not depend on the colours: computed once
        for every reading and flat-field round).
    colour : ColourImage
    roi : RoiFit
    model : FilmColourModel
        At the ROI stage's exposure.
    scene : Scene
        Pixel size, the acceptance limit, whether the exposure is to be estimated, the seed.
    options : AnalysisOptions
        ``joint``, and ``fits.ambiguous_order_de`` (two readings that fit within it are
        ambiguous).
    refit_roi : callable
        ``refit_roi(exposure)``: the ROI stage at the second reading.

    Returns
    -------
    (JointResult, RoiFit, ExposureReadings or None)
        The chosen reading's facets (without ``pixels``) and ROIs; None with one reading.
    """
    first = _facets_in_colour(geometry, colour, roi, model, scene, options.joint)
    if roi.exposure_alternative is None:
        return first, roi, None
    roi_b = refit_roi(roi.exposure_alternative)
    second = _facets_in_colour(geometry, colour, roi_b, model.with_exposure(roi_b.exposure),
                               scene, options.joint)
    runs = ((first, roi), (second, roi_b))
    de = tuple(float(np.nanmedian(j.thickness.delta_e)) for j, _ in runs)
    k = int(np.nanargmin(de)) if np.isfinite(de).any() else 0
    e = tuple(j.exposure for j, _ in runs)
    ambiguous = bool(abs(e[1] / e[0] - 1.0) > EXPOSURE_DISTINCT
                     and abs(de[1] - de[0]) <= options.fits.ambiguous_order_de)
    log.info("exposure readings %.4f (median facet dE00 %.2f) and %.4f (%.2f): the %s%s",
             e[0], de[0], e[1], de[1], ("first", "second")[k], ", ambiguous" * ambiguous)
    return (*runs[k], ExposureReadings(e, de, k, ambiguous))


def joint_pixel_tilts(joint: JointResult, colour, model, theta_grid_deg,
                      options: TiltOptions) -> PixelEstimates:
    """Step 4: the tilt of every usable pixel of a facet with a thickness, the MAP of its
    colour (at the facet's thickness, with the facet's calibrated error) and the facet's
    prior. ``model`` is at the joint stage's exposure."""
    d_f = joint.thickness.thickness_nm
    flat = np.flatnonzero(joint.usable & np.isfinite(d_f)[joint.facets])  # 8 B/px
    d_rows = np.where(np.isfinite(d_f), d_f, model.thickness_range_nm[0])
    # thickness, noise and prior are the facet's: given per row, gathered chunk by chunk
    rows = TiltRows(model_lab_rows(model, d_rows, theta_grid_deg), d_f, joint.colour_sigma_de,
                    joint.prior_deg, joint.prior_sigma_deg)
    out = PixelEstimates.empty(joint.facets.shape, group=joint.facets)
    invert_tilt_into(out, flat, colour.lab, rows, theta_grid_deg, model, options)
    return out
