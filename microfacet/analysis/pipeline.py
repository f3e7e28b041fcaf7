"""The whole analysis of one stack (seed §3.3.3): focus stack → the two distributions.

:func:`analyse_stack` runs the stages of :class:`~.stages.Stage` in order, each a function of
its stage's module taking only its section of :class:`~.options.AnalysisOptions`, tested alone
and timed by one :class:`~microfacet.core.timing.StageTimer` (docs/architecture.md has the
table). Two modes: ``"joint"`` (default) takes each facet's tilt from a plane fit of the
height map and its thickness from colour at that tilt; ``"seed"`` is the paper's per-pixel
inversion. Accuracy of both: docs/accuracy.md. Results are written by :mod:`.output`.

References
----------
.. [1] N. Nagata, M. Kamei, K. Takahashi, K. Tobitani, T. Akagi, S. Yamamura, "Simulation
   Technology for Titanium Oxide Layer Interference Color", Technical Report (the seed paper),
   §3.3.3.
"""

from __future__ import annotations

import dataclasses
import functools
import logging
import math
from dataclasses import dataclass, field

import numpy as np

from ..colour.model import FilmColourModel
from ..colour.table import build_colour_table
from ..core.errors import InputError, one_line
from ..core.threads import Background, return_free_memory
from ..core.timing import StageTimer
from ..io.limits import check_memory
from ..io.stack import Stack, read_stack
from .colour_image import measure_colour, no_colour_message
from .consistency import ALIAS_SD, MapCheck, mixture_map_check, roi_pixel_check
from .distributions import (
    Distributions,
    PooledOrders,
    calibrate_dome_share,
    correct_ndf_width,
    fit_joint_distributions,
    fit_seed_distributions,
    pool_interference_orders,
)
from .flat_field import (
    MAX_ROUNDS,
    ROUND_TOLERANCE,
    FlatField,
    estimate_flat_field,
    flat_fielded,
    reference_flat_field,
)
from .identification import (
    analysis_warnings,
    gains_unconstrained,
    map_check_judgement,
    mask_warning,
    mean_plane_tilt_deg,
    order_check,
    self_check_judgement,
)
from .iso25178 import areal_parameters
from .joint import (
    bootstrap_labels,
    delta_e_rebalanced,
    facet_geometry,
    facet_image,
    facet_labels,
    facets_at_exposure_readings,
    facets_in_order,
    facets_in_other_order,
    gain_thickness_shifts,
    joint_pixel_tilts,
)
from .options import AnalysisOptions, Scene, scene_of
from .order_cut import order_cut
from .roi import block_exposure_reading, thickness_per_roi
from .segmentation import neighbour_pairs
from .self_check import Conditions, SelfCheck, measured_rms_slope, self_check_ndf, slice_noise_sd
from .stages import Stage
from .surface import measure_height, surface_normals
from .tilt import seed_tilts, tilt_grid
from .white_balance import WhiteBalance, balanced_lab, choose_white_balance

log = logging.getLogger(__name__)

__all__ = ["AnalysisResult", "analyse_stack", "check_stack_for_analysis", "run_stages"]

#: Peak memory of :func:`analyse_stack` ≈ base + per pixel × H × W, set above what
#: ``microfacet analyze`` (report included) measured on nd stacks of 40 slices, 2026-11-28
#: (``python -m pipelines run speed-analyze``): 386, 968 and 2,701 MB at 1.0, 4.0 and
#: 12.1 MP (≈ 180 MB + 210 B/px; slices are streamed, so their number does not count), with
#: a margin of a fifth (12 MP) to a third (1 MP).
MEMORY_BASE_BYTES = 250 << 20
MEMORY_BYTES_PER_PIXEL = 250


def check_stack_for_analysis(stack) -> None:
    """Refuse, before any work, a stack the analysis cannot use: grey images, or one whose
    analysis would need more memory than is free (:data:`MEMORY_BYTES_PER_PIXEL`).

    Raises
    ------
    InputError
        Naming stack.json, the key and the reason.
    """
    if stack.channels != 3:
        key = "tiff" if stack.tiff_path is not None else "slices" if stack.has_slices else "image"
        raise InputError(f"{stack.path / 'stack.json'}: key {key!r}: grey images; the colour "
                         f"analysis needs RGB images (height from focus alone works on grey: "
                         f"microfacet height)")
    h, w = stack.shape
    check_memory(MEMORY_BASE_BYTES + MEMORY_BYTES_PER_PIXEL * h * w,
                 f"{one_line(stack.path / 'stack.json')}: analysing {w}x{h}-pixel images")


@dataclass
class AnalysisResult:
    """Everything an analysis found: the stages' results (maps are H×W float32 unless noted).

    Written by :func:`microfacet.analysis.output.write_results`.

    Attributes
    ----------
    stack : Stack
    options : AnalysisOptions
    scene : Scene
    focus : FocusResult
    surface : Surface
    colour : ColourImage
    model : FilmColourModel
        The film colour at the final exposure.
    roi : RoiFit
    pixels : PixelEstimates
    joint : JointResult or None
        The facets (joint mode).
    distributions : Distributions
    timings_s : dict
    self_check : SelfCheck or None
    white_balance : WhiteBalance
        The camera gains the colours were corrected for, and the scene's estimate.
    flat_field : FlatField or None
        The flat field (vignetting) the colours were divided by, or why none: a reference's
        (both modes) or the joint mode's estimate; None in seed mode without a reference.
    map_check : MapCheck or None
        The thickness mixture against the per-pixel thickness map
        (:func:`~.consistency.mixture_map_check`; None without either): a mixture that
        fails it is not identified (:func:`~.identification.map_check_judgement`).
    """

    stack: Stack
    options: AnalysisOptions
    scene: Scene
    focus: object
    surface: object
    colour: object
    model: FilmColourModel
    roi: object
    pixels: object
    joint: object
    distributions: Distributions
    timings_s: dict = field(default_factory=dict)
    self_check: SelfCheck | None = None
    white_balance: WhiteBalance = field(default_factory=WhiteBalance)
    flat_field: FlatField | None = None
    map_check: MapCheck | None = None

    @functools.cached_property
    def height_areal(self):
        """ISO 25178-2 parameters of the height map about its least-squares plane, on its
        reliable pixels (:func:`~.iso25178.areal_parameters`; None with fewer than 3, or all
        on a line): computed once for the summary and the height σ."""
        try:
            return areal_parameters(self.focus.height_um, pixel_size_um=self.scene.pixel_size_um,
                                    reference="plane")
        except InputError:
            return None

    @functools.cached_property
    def roi_check(self):
        """Per ROI the median of its pixels' thicknesses and whether its single fit disagrees
        with it (:func:`~.consistency.roi_pixel_check`)."""
        return roi_pixel_check(self.roi, self.pixels.thickness_nm)

    @property
    def thickness_fit(self):
        """The thickness mixture (:class:`~.mixtures.MixtureFit`, or None)."""
        return self.distributions.thickness

    @property
    def ndf_fit(self):
        """The NDF lobes (:class:`~.mixtures.MixtureFit`, or None)."""
        return self.distributions.ndf

    @property
    def exposure(self) -> float:
        return float(self.model.exposure)

    @property
    def warnings(self) -> list:
        """What a user must know before trusting the distributions
        (:class:`~.identification.Reason` each;
        :func:`~microfacet.analysis.identification.analysis_warnings`)."""
        out = analysis_warnings(self.distributions, delta_e_median=self.delta_e_stats["median"],
                                noise_de=self.colour.noise_de,
                                mean_plane_tilt=mean_plane_tilt_deg(self.joint),
                                options=self.options.fits, white_balance=self.white_balance,
                                map_check=self.map_check, roi_check=self.roi_check)
        masked = mask_warning(self.colour.mask.fractions())     # the colours', not the fits'
        return out if masked is None else [masked, *out]

    @functools.cached_property
    def order(self) -> dict:
        """Whether the thicknesses' interference order is established, and if not why
        (:func:`~.identification.order_check`; summary.json ``thickness.order``). It does not
        depend on which gains are called determined, only on the estimate and its spread."""
        return order_check(self.distributions, delta_e_median=self.delta_e_stats["median"],
                           noise_de=self.colour.noise_de, options=self.options.fits,
                           white_balance=self.white_balance)

    @property
    def delta_e_stats(self) -> dict:
        """Mean, median and 95th percentile of the per-pixel ΔE (None without pixels)."""
        v = self.pixels.delta_e[np.isfinite(self.pixels.delta_e)]
        if v.size == 0:
            return {"mean": None, "median": None, "p95": None}
        return {"mean": float(v.mean()), "median": float(np.median(v)),
                "p95": float(np.percentile(v, 95))}


def _colour(st, focus, options, scene):
    colour = measure_colour(focus.all_in_focus, options.mask, color_space=st.color_space,
                            bit_depth=16 if st.dtype == np.uint16 else 8,
                            illuminant=scene.illuminant,
                            delta_e_method=options.optics.delta_e_method, jpeg=st.jpeg)
    if colour.mask.mask.all():
        raise InputError(no_colour_message(st, colour.mask, "every pixel is masked",
                                           options.mask))
    return colour


def film_model(scene: Scene, options) -> FilmColourModel:
    """The film colour over the scene's range: tilts up to the acceptance (+0.5°), the
    thickness search range (``options`` is the ``optics`` section), at exposure 1."""
    table = build_colour_table(thickness_range_nm=tuple(options.thickness_range_nm),
                               theta_range_deg=(0.0, scene.max_tilt_deg + 0.5),
                               film=scene.film, substrate=scene.substrate,
                               illuminant=scene.illuminant)
    return FilmColourModel(table, delta_e_method=options.delta_e_method)


def _model_for(model, colour, exposure) -> FilmColourModel:
    """``model`` at ``exposure``, clipped as ``colour``'s analysed pixels are
    (``ColourImage.clip_rgb``)."""
    return model.with_exposure(exposure).with_clip(colour.clip_rgb)


def _roi(st, colour, surface, model, options, scene, *, exposure=None):
    """The ROI stage at the scene's exposure (None: estimated; in the joint mode with the
    blocks' second reading, :mod:`.roi`), or at ``exposure``: the second reading, still
    reported as estimated."""
    model = model.with_clip(colour.clip_rgb)
    if exposure is not None:
        return dataclasses.replace(thickness_per_roi(colour, surface.tilt_deg, model,
                                                     options.roi, exposure=exposure,
                                                     seed=scene.seed),
                                   exposure_estimated=True)
    roi = thickness_per_roi(colour, surface.tilt_deg, model, options.roi,
                            exposure=scene.exposure, seed=scene.seed)
    if not np.isfinite(roi.thickness_nm).any():
        raise InputError(no_colour_message(
            st, colour.mask, f"only {int((~colour.mask.mask).sum())} unmasked pixels, too few "
                             f"in every region of interest", options.mask))
    if roi.exposure_estimated and options.mode == "joint":
        roi = dataclasses.replace(roi, exposure_alternative=block_exposure_reading(
            colour, surface.tilt_deg, model, options.roi, exposure=roi.exposure,
            seed=scene.seed))
    return roi


def run_stages(st: Stack, options: AnalysisOptions, *, progress=None) -> AnalysisResult:
    """The stages of :func:`analyse_stack` on a stack already checked
    (:func:`check_stack_for_analysis`); ``progress(stage)`` at the start of each."""
    scene = scene_of(st, options)
    timer = StageTimer(progress, between=return_free_memory)
    with timer.stage(Stage.HEIGHT):
        focus = measure_height(st, options.focus)
    with timer.stage(Stage.NORMALS):
        surface = surface_normals(
            focus, pixel_size_um=scene.pixel_size_um, where=str(st.path),
            smooth_sigma_px=options.focus.slope_sigma_px if scene.from_focus else 0.0)
    with timer.stage(Stage.COLOUR):
        colour = _colour(st, focus, options, scene)
    with timer.stage(Stage.COLOUR_TABLE):
        model = film_model(scene, options.optics)
    with timer.stage(Stage.ROI):
        wb = choose_white_balance(st, colour.encoded, surface.tilt_deg, colour.mask.coloured,
                                  model, options.optics, illuminant=scene.illuminant,
                                  seed=scene.seed)
        flat_ref = reference_flat_field(st, options.optics.flat_reference,
                                        colour.lab.shape[:2], where_given="flat_reference")
        if flat_ref is not None:     # the white balance's gains too: Lab computed once
            colour = flat_fielded(colour, flat_ref.map(colour.lab.shape[:2]),
                                  gains_rgb=wb.gains_rgb if wb.applied else (1.0, 1.0, 1.0),
                                  illuminant=scene.illuminant,
                                  mask_options=options.mask)
        elif wb.applied:
            colour = dataclasses.replace(colour, lab=balanced_lab(
                colour.encoded, wb.gains_rgb, illuminant=scene.illuminant), clip_rgb=None
                if colour.clip_rgb is None else tuple(1.0 / g for g in wb.gains_rgb))
        roi = _roi(st, colour, surface, model, options, scene)
    model = _model_for(model, colour, roi.exposure)
    grid = tilt_grid(scene.max_tilt_deg, options.tilt.step_deg)
    joint = check = None
    if options.mode == "seed":
        with timer.stage(Stage.TILT):
            pixels = seed_tilts(colour, roi, model, grid, options.tilt)
        with timer.stage(Stage.MIXTURES):
            dist = fit_seed_distributions(pixels, roi, model, colour.noise_de, options.fits,
                                          seed=scene.seed)
    else:
        with timer.stage(Stage.SEGMENTATION):
            seg = facet_labels(colour, surface, scene, options.joint)
        with timer.stage(Stage.FACET_FITS):
            geometry = facet_geometry(seg, scene, options.joint)

            def facets(c, r):
                return facets_at_exposure_readings(
                    geometry, c, r, _model_for(model, c, r.exposure), scene, options,
                    refit_roi=lambda e: _roi(st, c, surface, model, options, scene,
                                             exposure=e))
            if flat_ref is None:
                (joint, roi, readings), colour, flat = _flat_field_pass(
                    facets(colour, roi), colour,
                    lambda c: facets(c, _roi(st, c, surface, model, options, scene)),
                    model=model, options=options, scene=scene, wb=wb)
            else:
                (joint, roi, readings), flat = facets(colour, roi), flat_ref
            # the facets, their planes and the colours are final: the self-check runs on its
            # own thread while the facets' thicknesses, the per-pixel tilts and the mixtures
            # are computed (it reads none of them; docs/benchmarks.md)
            check_job = Background(functools.partial(
                _self_check, st, focus, joint, scene, options,
                cells=lambda crop, c=colour: bootstrap_labels(
                    c, seg, scene, options.joint, rng=np.random.default_rng([scene.seed, 22]),
                    crop=crop)))
            model = _model_for(model, colour, joint.exposure)
            image = facet_image(geometry, colour, roi, options.joint)   # the colours are final
            cols = image.colours()
            fits = _fit_options(options, model)
            pooled = _order_moves(joint, image, cols, colour, model, options, scene, fits)
            joint = pooled.joint
        with timer.stage(Stage.TILT):
            pixels = joint.pixels = joint_pixel_tilts(joint, colour, model, grid, options.tilt)
        with timer.stage(Stage.MIXTURES):
            dist = fit_joint_distributions(
                joint, roi, model, scene, fits, pooled=pooled,
                gain_shifts_nm=_gain_shifts(joint, cols, model, options, scene, wb),
                delta_e_at_estimate=_delta_e_at_estimate(joint, cols, model, options, scene,
                                                         wb))
            dist.exposure_readings = readings
            # read by the facet stages only: freed (and given back at the stage's end)
            # before the self-check's peak
            del facets, geometry, image, cols, pooled
        with timer.stage(Stage.SELF_CHECK):
            check = check_job.result()
            dist.ndf_judgement = self_check_judgement(dist.ndf_judgement, check, options.fits)
            dist = calibrate_dome_share(dist, check, options.fits)
            dist = correct_ndf_width(dist, joint, scene, fits, check)
            if check is not None and dist.ndf is not None:
                err = check.width_error(dist.ndf.info.get("width_relative_error"))
                dist.ndf.info["width_relative_error_total"] = (float(err) if math.isfinite(err)
                                                               else None)
    map_check = mixture_map_check(pixels.thickness_nm, dist.thickness.mixture
                                  if dist.thickness is not None else None)
    dist.thickness_judgement = map_check_judgement(dist.thickness_judgement, map_check)
    if not dist.thickness_judgement.identified:
        wb = _withdrawn(wb, "the thickness is not identified")
    timer.total()
    result = AnalysisResult(st, options, scene, focus, surface, colour, model, roi, pixels,
                            joint, dist, dict(timer.timings), check, wb,
                            flat if options.mode == "joint" else flat_ref, map_check)
    if not result.order["established"]:
        result.white_balance = _withdrawn(wb, "the interference order is not established")
    return result


def _withdrawn(wb, why):
    """``wb`` with no gain called determined, because ``why``: the gains the film's colours
    ask for are those of the thicknesses, in the orders, they were read at
    (:meth:`~.white_balance.WhiteBalance.withdraw`)."""
    return wb.withdraw(f"{why}, and the gains the film's colours ask for are those of the "
                       f"thicknesses, in the orders, they were read at"
                       + (" (the determined gains were applied)" if wb.source == "estimated"
                          else ""))


def _gain_shifts(joint, cols, model, options, scene, wb):
    """Each facet's thickness move for a 1σ error of the R and B gains
    (:func:`~.joint.gain_thickness_shifts` at :meth:`~.white_balance.WhiteBalance.log_gain_sigma`,
    each facet at the tilt it was solved at, ``joint.prior_deg``; ``cols``: the facets'
    colours, :meth:`~.facet_thickness.FacetImage.colours`); None where the gains' error is
    not known."""
    sigma = wb.log_gain_sigma()
    if sigma is None:
        return None
    return gain_thickness_shifts(cols, joint.thickness.thickness_nm, joint.prior_deg, model,
                                 options.joint, log_gain_rb=sigma, illuminant=scene.illuminant)


def _delta_e_at_estimate(joint, cols, model, options, scene, wb):
    """``misfit()``: each facet's colour misfit at the scene's white-balance estimate
    (:func:`~.joint.delta_e_rebalanced`, at the tilt it was solved at), computed at the
    first call (only a component the colour rule would set aside asks for it: 0.1 s for the
    fixture's 936 facets, docs/accuracy.md); None where the colours were balanced already
    (a reference, or the estimate applied), nothing was estimated, or the estimate leaves
    the gains free (:func:`~.identification.gains_unconstrained`: its value then says
    nothing of the balance; on seed-31 g029 of the sweep such an estimate, R 0.92 ± 29 %,
    kept a 276 nm component of a balanced 33 / 66 nm scene)."""
    log_gain = wb.estimate_log_rb()
    if wb.applied or log_gain is None or gains_unconstrained(wb):
        return None
    return functools.cache(lambda: delta_e_rebalanced(
        cols, joint.thickness.thickness_nm, joint.prior_deg, model, options.joint,
        log_gain_rb=log_gain, illuminant=scene.illuminant))


def _order_window_nm(options, model) -> float:
    """Half-width of a facet's interference-order window (nm): ``joint.order_window_fraction``
    of the colours' period."""
    return options.joint.order_window_fraction * model.period_nm


def _fit_options(options, model):
    """``options.fits`` with the thickness components' SD ceiling where it sets none: a
    :data:`~.consistency.ALIAS_SD`-th of a facet's order window (a population does not span
    interference orders; ``fits.thickness_max_sd_nm``)."""
    fits, top = options.fits, _order_window_nm(options, model) / ALIAS_SD
    if fits.thickness_max_sd_nm is None and top > fits.thickness_sd_floor_nm:
        fits = fits.replace(thickness_max_sd_nm=top)
    return fits


def _order_moves(joint, image, cols, colour, model, options, scene, fits):
    """The facets of a component that is another read in a neighbouring interference order,
    in that order (:func:`~.distributions.pool_interference_orders`, ``fits.order_moves``),
    then every facet's order decided with its neighbours' (:func:`_order_cut`); ``image``
    and ``cols``: the facets' image and colours (:func:`~.joint.facet_image`), shared by
    every round; ``fits``: the mixtures' options (:func:`_fit_options`)."""
    pooled = PooledOrders(joint) if fits.order_moves == "off" else pool_interference_orders(
        joint, lambda j, moved, centre: facets_in_other_order(
            j, image, colour, model, options.joint, moved=moved, centre_nm=centre,
            colours=cols),
        period_nm=model.period_nm, window_nm=_order_window_nm(options, model), options=fits,
        seed=scene.seed)
    return _order_cut(pooled, image, cols, colour, model, options.joint)


def _order_cut(pooled, image, cols, colour, model, options):
    """``pooled`` with the facets :func:`~.order_cut.order_cut` reads in their runner-up
    order solved in it (``options``: the joint options); its record in ``pooled.cut``."""
    if options.order_cut_strength <= 0:
        return pooled
    joint = pooled.joint
    th = joint.thickness
    pairs = neighbour_pairs(joint.facets)
    moved = order_cut(th, cols.mean_lab, pairs, period_nm=model.period_nm, options=options)
    a = joint.area_px.astype(np.float64)
    cut = {"facets": int(moved.sum()), "area_fraction": float(a[moved].sum() / max(a.sum(), 1))}
    if not moved.any():
        return dataclasses.replace(pooled, cut=cut, pairs=pairs)
    after = facets_in_order(joint, image, colour, model, options, moved=moved,
                            centre_nm=th.thickness_other_order_nm, colours=cols)
    return PooledOrders(after, pooled.moves, cut=cut, pairs=pairs)


def _flat_field_pass(first, colour, facets_in, *, model, options, scene, wb):
    """The joint mode's flat field estimated from the facets (:mod:`.flat_field`).

    Parameters
    ----------
    first : tuple
        ``(JointResult, RoiFit, ExposureReadings or None)`` of the colours as measured.
    colour : ColourImage
    facets_in : callable
        ``facets_in(colour)``: the ROI and facet stages again on other colours, as ``first``.
    model : FilmColourModel
    options : AnalysisOptions
    scene : Scene
    wb : WhiteBalance
        The gains applied to the colours (kept when they are divided by the field).

    Returns
    -------
    (tuple, ColourImage, FlatField)
        The facets and the colours, flat-fielded where the facets' brightness asks for a
        field and the facets refitted under it fit their colours better (median ΔE00), and
        the :class:`FlatField`. The facets' thicknesses absorb part of an uncorrected field,
        so it is estimated again on the refitted facets and added, up to
        :data:`~.flat_field.MAX_ROUNDS` times.
    """
    if options.joint.flat_field == "off":
        return first, colour, FlatField(reason="joint.flat_field is off")
    shape = colour.lab.shape[:2]
    best, best_colour, total = first, colour, None
    same = _unclipped_facets(first[0], colour.mask)
    de0 = float(np.nanmedian(first[0].thickness.delta_e[same]))
    for k in range(MAX_ROUNDS):
        joint = best[0]
        ff = estimate_flat_field(joint, best_colour.lab,
                                 _model_for(model, best_colour, joint.exposure),
                                 unexplained_mads=options.fits.unexplained_mads)
        if ff.reason:
            break
        trial = ff if total is None else total.plus(ff).checked(shape)
        if trial.reason:
            ff = trial
            break
        flat = flat_fielded(colour, trial.map(shape),
                            gains_rgb=wb.gains_rgb if wb.applied else (1.0, 1.0, 1.0),
                            illuminant=scene.illuminant, mask_options=options.mask)
        second = facets_in(flat)
        de = tuple(float(np.nanmedian(j.thickness.delta_e[same])) for j in (joint, second[0]))
        log.info("flat field, round %d: corner loss %.3f; median facet dE00 %.3f -> %.3f",
                 k + 1, trial.corner_loss(shape), *de)
        if not de[1] < de[0]:
            break
        best, best_colour, total = second, flat, dataclasses.replace(trial, rounds=k + 1)
        if abs(ff.corner_loss(shape)) < ROUND_TOLERANCE:
            break
    if total is None:
        return first, colour, (ff if ff.reason else dataclasses.replace(
            ff, median_delta_e=de, reason="the facets fit their colours no better with it"))
    de1 = float(np.nanmedian(best[0].thickness.delta_e))
    return best, best_colour, dataclasses.replace(total, applied=True,
                                                  median_delta_e=(de0, de1))


def _unclipped_facets(joint, mask) -> np.ndarray:
    """Per facet of ``joint``, whether none of its pixels is analysed with a clipped channel:
    the colours with and without a flat field are compared on these alone (divided by a
    field, every clipped pixel is masked, and facets that lose their clipped pixels would not
    compare)."""
    n = joint.area_px.size
    if not mask.clip_analysed:
        return np.ones(n, bool)
    return np.bincount(joint.facets.ravel(), weights=mask.clipped_one.ravel(),
                       minlength=n) == 0


def _self_check(st, focus, joint, scene, options, *, cells) -> SelfCheck | None:
    """The NDF's injection-recovery (:mod:`.self_check`) where the heights come from focus;
    None when switched off or for heights not from focus. With fewer than 3 facet planes
    whose slopes it could measure, nothing was measured (:meth:`SelfCheck.unmeasured`): the
    stack's transfer is unknown, so its NDF is not identified. ``cells(crop)`` gives the
    facets the injection follows on the self-check's crop (a second segmentation of the
    re-noised image, :func:`~.joint.bootstrap_labels`)."""
    if not (options.fits.self_check and scene.from_focus and st.has_slices):
        return None
    rms = measured_rms_slope(joint, scene.max_tilt_deg)
    if rms is None:
        return SelfCheck.unmeasured()
    cond = Conditions(np.asarray(st.z_um, np.float64), scene.pixel_size_um,
                      scene.numerical_aperture, slice_noise_sd(st, focus), scene.seed)
    return self_check_ndf(focus, joint.facets, cells=cells, conditions=cond, rms_slope=rms,
                          focus_options=options.focus, joint=options.joint)


def analyse_stack(stack, options: AnalysisOptions | None = None, *, progress=None
                  ) -> AnalysisResult:
    """Run the whole analysis on one stack.

    Parameters
    ----------
    stack : path-like or microfacet.io.stack.Stack
        A stack folder (validated before any work).
    options : AnalysisOptions, optional
        Validated when constructed.
    progress : callable, optional
        ``progress(stage)`` (a :class:`~.stages.Stage`) at the start of each stage.

    Returns
    -------
    AnalysisResult

    Raises
    ------
    InputError
        A stack that breaks the format, grey images, fewer than 3 slices, too little memory,
        or no colour information: every pixel masked (grey, dark or clipped images) or too
        few unmasked pixels in every ROI. The message names stack.json, the key and the
        masked fraction per reason.

    Notes
    -----
    Hard cases with a result rather than an error: slices without focus information
    (identical or featureless) give a height map that is NaN everywhere
    (``summary.json`` ``height.unreliable_fraction`` = 1, a logged warning); the surface is
    then taken as flat, so the tilts come from colour alone. A ROI larger than the image is
    one ROI of the image's size.

    Examples
    --------
    >>> from microfacet.analysis import analyse_stack
    >>> r = analyse_stack("fixtures/stacks/nd-fixture")  # doctest: +SKIP
    >>> r.thickness_fit.mixture.means_nm  # doctest: +SKIP
    """
    options = AnalysisOptions() if options is None else options
    st = stack if isinstance(stack, Stack) else read_stack(stack)
    check_stack_for_analysis(st)
    return run_stages(st, options, progress=progress)
