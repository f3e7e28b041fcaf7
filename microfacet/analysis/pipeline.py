"""The whole analysis of one stack (seed §3.3.3): focus stack → the two distributions.

:func:`analyze_stack` is a sequence of stages, each a function of its stage's module, tested
alone, and timed by one :class:`~microfacet.core.timing.StageTimer`:

=====================  ==============================================  ===================
timing key             stage                                            module
=====================  ==============================================  ===================
``height_from_focus``  height map (from focus, or the export's own)     :mod:`.surface`
``normals``            normals and tilt of the height map               :mod:`.surface`
``colour_and_mask``    CIELAB, mask of colourless pixels, colour noise  :mod:`.colour_image`
``colour_table``       model colour on a (tilt × thickness) grid        :mod:`..colour.table`
``thickness_roi``      thickness per ROI, interference order, exposure  :mod:`.roi`
``segmentation``,      joint mode: facets, plane fits, per-facet        :mod:`.segmentation`,
``facet_fits``         thickness                                        :mod:`.facets`
``tilt_per_pixel``     per-pixel tilt (seed: least ΔE00; joint: MAP     :mod:`.tilt`, :mod:`.joint`
                       with the facet-plane prior)
``mixtures``           thickness mixture and NDF lobes, and whether     :mod:`.identification`
                       the data determine them
=====================  ==============================================  ===================

Two modes: ``"joint"`` (default) takes each facet's tilt from a plane fit of the height map
and its thickness from colour at that tilt; ``"seed"`` is the paper's per-pixel inversion.
Accuracy of both: docs/accuracy.md. Results are written by :mod:`.output`.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from ..colour.table import build_colour_table
from ..core.errors import InputError, one_line
from ..core.timing import StageTimer
from ..io.limits import check_memory
from ..io.stack import Stack, read_stack
from .colour_image import measure_colour, no_colour_message
from .identification import (
    analysis_warnings,
    fit_joint_distributions,
    fit_seed_distributions,
    mean_plane_tilt_deg,
)
from .joint import joint_tilts
from .options import AnalysisOptions, scene_optics
from .roi import thickness_per_roi
from .surface import measure_height, surface_normals
from .tilt import seed_tilts, tilt_grid

__all__ = ["AnalysisResult", "MEMORY_BASE_BYTES", "MEMORY_BYTES_PER_PIXEL", "analyze_stack",
           "check_analysis_memory"]

#: Peak memory of :func:`analyze_stack` ≈ base + per pixel × H × W, set just above what
#: ``/usr/bin/time -f %M microfacet analyze`` measured on nd stacks of 16 slices: 597, 926 and
#: 1,832 MB at 0.26, 1.05 and 4.2 MP (≈ 620 MB + 290 B/px; slices are streamed, so their
#: number does not count).
MEMORY_BASE_BYTES = 650 << 20
MEMORY_BYTES_PER_PIXEL = 300


def check_analysis_memory(stack) -> None:
    """Refuse, before any work, a stack whose analysis would need more memory than is free.

    Raises
    ------
    InputError
        Naming the stack and the estimate (:data:`MEMORY_BYTES_PER_PIXEL`).
    """
    h, w = stack.shape
    need = MEMORY_BASE_BYTES + MEMORY_BYTES_PER_PIXEL * h * w
    check_memory(need, f"{one_line(stack.path / 'stack.json')}: analysing {w}x{h}-pixel images")


@dataclass
class AnalysisResult:
    """Everything an analysis found (maps are H×W float32 unless noted).

    Written by :func:`microfacet.analysis.output.write_results`; the fields are those of the
    stages (``focus`` from :mod:`.surface`, ``mask`` a
    :class:`~microfacet.analysis.mask.ColourMask`, ``roi`` a
    :class:`~microfacet.analysis.roi.RoiFit`, the fits
    :class:`~microfacet.analysis.mixtures.MixtureFit`).
    """

    stack: object
    options: AnalysisOptions
    focus: object
    normals: np.ndarray
    tilt_height_deg: np.ndarray
    lab: np.ndarray
    mask: object
    roi: object
    thickness_nm: np.ndarray
    tilt_deg: np.ndarray
    tilt_sigma_deg: np.ndarray
    delta_e: np.ndarray
    colour_weight: np.ndarray
    facets: np.ndarray | None
    joint: object
    thickness_fit: object
    ndf_fit: object
    exposure: float
    exposure_source: str
    noise_de: float
    max_tilt_deg: float
    table: object
    optics: dict
    timings_s: dict = field(default_factory=dict)

    @property
    def warnings(self) -> list[str]:
        """What a user must know before trusting the distributions (one line each;
        :func:`~microfacet.analysis.identification.analysis_warnings`)."""
        return analysis_warnings(thickness_fit=self.thickness_fit, ndf_fit=self.ndf_fit,
                                 roi=self.roi, delta_e_median=self.delta_e_stats["median"],
                                 noise_de=self.noise_de,
                                 mean_plane_tilt_deg=mean_plane_tilt_deg(self.joint))

    @property
    def delta_e_stats(self) -> dict:
        """Mean, median and 95th percentile of the per-pixel ΔE00 (None without pixels)."""
        v = self.delta_e[np.isfinite(self.delta_e)]
        if v.size == 0:
            return {"mean": None, "median": None, "p95": None}
        return {"mean": float(v.mean()), "median": float(np.median(v)),
                "p95": float(np.percentile(v, 95))}


def _check_colour_images(st) -> None:
    if st.channels != 3:
        key = "tiff" if st.tiff_path is not None else "slices" if st.has_slices else "image"
        raise InputError(f"{st.path / 'stack.json'}: key {key!r}: grey images; the colour "
                         f"analysis needs RGB images (height from focus alone works on grey: "
                         f"microfacet height)")


def analyze_stack(stack, options: AnalysisOptions | None = None, *, progress=None
                  ) -> AnalysisResult:
    """Run the whole analysis on one stack.

    Parameters
    ----------
    stack : path-like or microfacet.io.stack.Stack
        A stack folder (validated before any work).
    options : AnalysisOptions, optional
    progress : callable, optional
        ``progress(stage_name)`` at the start of each stage.

    Returns
    -------
    AnalysisResult

    Raises
    ------
    InputError
        A stack that breaks the format, grey images, fewer than 3 slices, too little memory,
        or no colour information: every pixel masked (grey, dark or clipped images) or too
        few unmasked pixels in every ROI. The message names stack.json, the key and the
        masked fraction per reason. Bad options name the option.

    Notes
    -----
    Hard cases with a result rather than an error: slices without focus information
    (identical or featureless) give a height map that is NaN everywhere
    (``summary.json`` ``height.unreliable_fraction`` = 1, a logged warning); the surface is
    then taken as flat, so the tilts come from colour alone. A ROI larger than the image is
    one ROI of the image's size.

    Examples
    --------
    >>> from microfacet.analysis import analyze_stack
    >>> r = analyze_stack("fixtures/stacks/nd-fixture")  # doctest: +SKIP
    >>> r.thickness_fit.mixture.means_nm  # doctest: +SKIP
    """
    opt = options or AnalysisOptions()
    opt.validate()
    st = stack if isinstance(stack, Stack) else read_stack(stack)
    _check_colour_images(st)
    check_analysis_memory(st)
    optics = scene_optics(st, opt)
    timer = StageTimer(progress)

    timer.start("height from focus")
    focus = measure_height(st, operator=opt.operator, window_px=opt.window_px, align=opt.align)
    timer.lap("height_from_focus")
    surface = surface_normals(focus, pixel_size_um=st.pixel_size_yx_um, where=str(st.path))
    timer.lap("normals")

    timer.start("colour")
    colour = measure_colour(focus.all_in_focus, color_space=st.color_space,
                            bit_depth=16 if st.dtype == np.uint16 else 8,
                            illuminant=optics.illuminant, saturation_min=opt.saturation_min,
                            value_min=opt.value_min, delta_e_method=opt.delta_e_method)
    timer.lap("colour_and_mask")
    masks = dict(saturation_min=opt.saturation_min, value_min=opt.value_min)
    if colour.mask.mask.all():
        raise InputError(no_colour_message(st, colour.mask, "every pixel is masked", **masks))

    timer.start("colour table")
    table = build_colour_table(thickness_range_nm=tuple(opt.thickness_range_nm),
                               theta_range_deg=(0.0, optics.max_tilt_deg + 0.5),
                               film=optics.film, substrate=optics.substrate,
                               illuminant=optics.illuminant)
    timer.lap("colour_table")

    timer.start("thickness per ROI")
    given = opt.exposure if opt.exposure is not None else st.exposure
    source = ("option" if opt.exposure is not None else
              "stack.json" if st.exposure is not None else "estimated")
    roi = thickness_per_roi(colour, surface.tilt_deg, table, size_px=opt.roi_size_px,
                            stride_px=opt.roi_stride_px, exposure=given, seed=opt.seed,
                            delta_e_method=opt.delta_e_method)
    if not np.isfinite(roi.thickness_nm).any():
        raise InputError(no_colour_message(
            st, colour.mask, f"only {int((~colour.mask.mask).sum())} unmasked pixels, too few "
                             f"in every region of interest", **masks))
    timer.lap("thickness_roi")

    timer.start("tilt per pixel")
    grid = tilt_grid(optics.max_tilt_deg, opt.tilt_step_deg)
    joint = None
    if opt.mode == "seed":
        exposure = roi.exposure
        pixels = seed_tilts(colour, roi, table, theta_grid_deg=grid, exposure=exposure,
                            delta_e_method=opt.delta_e_method)
    else:
        joint = joint_tilts(
            colour, surface, roi, table, theta_grid_deg=grid, max_tilt_deg=optics.max_tilt_deg,
            exposure=roi.exposure, estimate_exposure=source == "estimated",
            facet_size_um=opt.facet_size_um, pixel_size_um=st.pixel_size_yx_um,
            from_focus=st.has_slices, seed=opt.seed, timer=timer,
            delta_e_method=opt.delta_e_method)
        pixels, exposure = joint.pixels, joint.exposure
    timer.lap("tilt_per_pixel")

    timer.start("distributions")
    if joint is None:
        tfit, nfit = fit_seed_distributions(pixels, roi=roi, table=table, exposure=exposure,
                                            noise_de=colour.noise_de,
                                            max_components=opt.max_components)
    else:
        tfit, nfit = fit_joint_distributions(joint, roi=roi, table=table,
                                             max_tilt_deg=optics.max_tilt_deg,
                                             max_components=opt.max_components)
    timer.lap("mixtures")
    timer.total()
    return AnalysisResult(
        stack=st, options=opt, focus=focus, normals=surface.normals,
        tilt_height_deg=surface.tilt_deg, lab=colour.lab, mask=colour.mask, roi=roi,
        thickness_nm=pixels.thickness_nm, tilt_deg=pixels.tilt_deg,
        tilt_sigma_deg=pixels.tilt_sigma_deg, delta_e=pixels.delta_e,
        colour_weight=pixels.colour_weight, facets=None if joint is None else joint.facets,
        joint=joint, thickness_fit=tfit, ndf_fit=nfit,
        exposure=float(exposure), exposure_source=source, noise_de=colour.noise_de,
        max_tilt_deg=optics.max_tilt_deg, table=table, optics=optics.to_json(),
        timings_s=dict(timer.timings))
