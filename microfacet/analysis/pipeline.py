"""The whole pipeline on one stack (seed §3.3.3): focus stack → distributions.

Stages
------
1. **Height from focus** (:mod:`microfacet.focus.height`) → height map, reliability, all-in-focus
   composite; normals and per-pixel tilt from the (filled) height map.
2. **Colour**: the composite to CIELAB (relative to the stack's illuminant); the mask of
   pixels without colour information (:mod:`microfacet.analysis.mask`); the image colour noise.
3. **Colour table** for the scene's range: tilts 0 … asin(NA)/2, thicknesses in
   ``thickness_range_nm`` (:mod:`microfacet.colour.table`).
4. **Thickness per ROI** and the exposure (:mod:`microfacet.analysis.roi`).
5. **Per-pixel thickness and tilt**, in one of two modes:

   ``"seed"`` — the paper's method: the ROI's thickness for every pixel of the ROI, and the
   tilt of least ΔE00 per pixel at that thickness (:mod:`microfacet.analysis.tilt`).

   ``"joint"`` (default) — facets segmented by colour, tilt per facet from a plane fit to the
   height map, thickness per facet from colour at that tilt, and per-pixel tilt as the MAP
   with the facet prior (:mod:`microfacet.analysis.facets`). It is the default because it measures
   better on synthetic truth (docs/accuracy.md).
6. **Distributions**: a Gaussian mixture of thickness and a mixture of zero-mean
   Gaussian-slope lobes of tilt, components by BIC (:mod:`microfacet.analysis.mixtures`).

:func:`analyze_stack` returns an :class:`AnalysisResult`; :func:`write_results` writes the
results folder of ``docs/results-format.md`` atomically.
"""

from __future__ import annotations

import dataclasses
import datetime
import json
import logging
import math
import time
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
from ..colour.srgb import srgb_encode, srgb_to_lab

__all__ = ["AnalysisOptions", "AnalysisResult", "analyze_stack", "check_analysis_memory",
           "results_size_bytes", "write_results"]

log = logging.getLogger(__name__)

MODES = ("joint", "seed")

#: Peak memory of :func:`analyze_stack` ≈ base + per pixel × H × W, set just above what
#: ``/usr/bin/time -f %M microfacet analyze`` measured on nd stacks of 16 slices: 597, 926 and
#: 1,832 MB at 0.26, 1.05 and 4.2 MP (≈ 620 MB + 290 B/px; slices are streamed, so their
#: number does not count).
MEMORY_BASE_BYTES = 650 << 20
MEMORY_BYTES_PER_PIXEL = 300
#: Bytes per pixel of the results folder (float32 maps, normals, mask, facets, PNG) and the
#: report's size.
_RESULT_BYTES_PER_PIXEL = 64
_REPORT_BYTES = 8 << 20


def check_analysis_memory(stack) -> None:
    """Refuse, before any work, a stack whose analysis would need more memory than is free.

    Raises
    ------
    InputError
        Naming the stack and the estimate (:data:`MEMORY_BYTES_PER_PIXEL`).
    """
    from ..core.errors import one_line
    from ..io.limits import check_memory

    h, w = stack.shape
    need = MEMORY_BASE_BYTES + MEMORY_BYTES_PER_PIXEL * h * w
    check_memory(need, f"{one_line(stack.path / 'stack.json')}: analysing {w}x{h}-pixel images")


def results_size_bytes(shape, *, report: bool = True) -> int:
    """Expected size of the results folder of an analysis of ``shape`` = (H, W) images."""
    return _RESULT_BYTES_PER_PIXEL * int(shape[0]) * int(shape[1]) + (_REPORT_BYTES if report
                                                                       else 0)


@dataclass(frozen=True)
class AnalysisOptions:
    """Options of :func:`analyze_stack` (all keyword; defaults follow the seed).

    Attributes
    ----------
    mode : {"joint", "seed"}
    roi_size_px, roi_stride_px : int
        ROI side (seed: 255 px) and stride (default = size).
    saturation_min, value_min : float
        Mask thresholds on the 0-255 HSV scale (seed: saturation 15).
    thickness_range_nm : (float, float)
        Global thickness search range.
    exposure : float or None
        Overrides stack.json's ``exposure``; estimated when both are absent.
    film, substrate, illuminant : str or None
        Override the stack's (or the defaults).
    facet_size_um : float
        Expected facet diameter for the joint mode's segmentation (seed: 1-3 µm).
    tilt_step_deg : float
        Tilt grid step of the per-pixel search (refined below it). 1-2° steps measure as
        accurate at half the time (docs/speed-vs-error.md §3c); whether tilt from colour
        means anything for a film: docs/conditioning.md.
    max_components : int
        Largest number of mixture components tried by BIC.
    operator, window_px, align : focus options (None = the focus module's defaults).
    seed : int
        Random sampling in the ROI fits.
    """

    mode: str = "joint"
    roi_size_px: int = 255
    roi_stride_px: int | None = None
    saturation_min: float = 15.0
    value_min: float = 20.0
    thickness_range_nm: tuple = (0.0, 400.0)
    exposure: float | None = None
    film: str | None = None
    substrate: str | None = None
    illuminant: str | None = None
    facet_size_um: float = 2.0
    tilt_step_deg: float = 0.5
    max_components: int = 5
    operator: str | None = None
    window_px: int | None = None
    align: bool | str = False
    seed: int = 0

    def validate(self):
        if self.mode not in MODES:
            raise ValueError(f"mode: must be one of {', '.join(MODES)}, got {self.mode!r}")
        lo, hi = self.thickness_range_nm
        if not (0 <= lo < hi <= 2000):
            raise ValueError(f"thickness_range_nm: need 0 <= low < high <= 2000, got {(lo, hi)}")
        if self.exposure is not None and not (self.exposure > 0 and math.isfinite(self.exposure)):
            raise ValueError(f"exposure: must be > 0, got {self.exposure!r}")
        if not self.facet_size_um > 0:
            raise ValueError("facet_size_um: must be > 0")
        if not 0.05 <= self.tilt_step_deg <= 5:
            raise ValueError("tilt_step_deg: must be in [0.05, 5]")
        if not 1 <= self.max_components <= 10:
            raise ValueError("max_components: must be in [1, 10]")
        if not self.roi_size_px >= 8:
            raise ValueError(f"roi_size_px: must be >= 8, got {self.roi_size_px!r}")
        if self.roi_stride_px is not None and not 1 <= self.roi_stride_px <= self.roi_size_px:
            raise ValueError(f"roi_stride_px: must be in [1, roi_size_px], "
                             f"got {self.roi_stride_px!r}")


@dataclass
class AnalysisResult:
    """Everything :func:`write_results` writes (maps are H×W float32 unless noted)."""

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
    def delta_e_stats(self) -> dict:
        v = self.delta_e[np.isfinite(self.delta_e)]
        if v.size == 0:
            return {"mean": None, "median": None, "p95": None}
        return {"mean": float(v.mean()), "median": float(np.median(v)),
                "p95": float(np.percentile(v, 95))}


def _timer(timings, name, t0):
    t = time.perf_counter()
    timings[name] = round(t - t0, 4)
    return t


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
        A stack that breaks the format (:func:`microfacet.io.stack.read_stack`), fewer than 3
        slices, or no colour information: every pixel masked (grey, dark or clipped images)
        or too few unmasked pixels in every ROI. The message names stack.json, the key and
        the masked fraction per reason.
    ValueError
        Bad options (the message names the option).

    Notes
    -----
    Hard cases with a result rather than an error: slices without focus information
    (identical or featureless) give a height map that is NaN everywhere
    (``summary.json`` ``height.unreliable_fraction`` = 1, a logged warning); the surface is
    then taken as flat (``tilt_height_deg`` = 0, no facet-plane fits), so the tilts come
    from colour alone. A ROI larger than the image is one ROI of the image's size.

    Examples
    --------
    >>> from microfacet.analysis.pipeline import analyze_stack
    >>> r = analyze_stack("fixtures/stacks/nd-fixture")  # doctest: +SKIP
    >>> r.thickness_fit.mixture.means_nm  # doctest: +SKIP
    """
    from ..colour.table import build_colour_table
    from ..core.errors import InputError
    from ..focus.height import fill_missing, height_from_focus
    from .mask import colour_mask
    from .mixtures import fit_ndf_mixture, fit_thickness_mixture
    from ..focus.normals import normals_from_height, tilt_azimuth_deg
    from ..optics.constants import DEFAULT_FILM, DEFAULT_SUBSTRATE, load_set
    from ..io.stack import Stack, read_stack
    from .roi import fit_roi_thickness, nearest_roi_index, roi_grid

    opt = options or AnalysisOptions()
    opt.validate()
    st = stack if isinstance(stack, Stack) else read_stack(stack)
    if st.channels != 3:
        key = "slices" if st.has_slices else "image"
        if st.tiff_path is not None:
            key = "tiff"
        raise InputError(f"{st.path / 'stack.json'}: key {key!r}: grey images; the colour "
                         f"analysis needs RGB images (height from focus alone works on grey: "
                         f"microfacet height)")
    check_analysis_memory(st)
    film = opt.film or st.film or DEFAULT_FILM
    substrate = opt.substrate or st.substrate or DEFAULT_SUBSTRATE
    for key, name in (("film", film), ("substrate", substrate)):
        try:
            load_set(name)
        except ValueError as exc:
            raise ValueError(f"{key}: {exc}") from None
    illuminant = opt.illuminant or st.illuminant or "D65"
    na = float(st.numerical_aperture)
    max_tilt = math.degrees(math.asin(na)) / 2.0
    step = progress or (lambda name: None)
    timings: dict = {}
    t0 = t_all = time.perf_counter()

    # 1. Height from focus.
    step("height from focus")
    kw = {}
    if opt.operator:
        kw["operator"] = opt.operator
    if opt.window_px:
        kw["window_px"] = opt.window_px
    if not st.has_slices:
        foc = _export_as_focus(st)  # the microscope's own height map and composite
    elif st.n_slices < 3:
        raise InputError(f"{st.path / 'stack.json'}: key 'slices': height from focus needs at "
                         f"least 3 slices, the stack has {st.n_slices}")
    else:
        foc = height_from_focus(st, align=opt.align, **kw)
    t0 = _timer(timings, "height_from_focus", t0)
    no_focus = not foc.reliable.any()
    if no_focus:
        # No focus information (e.g. identical or featureless slices): the fitted height is
        # rounding noise, so the surface is taken as flat and the facet planes get no
        # weight; tilts come from colour alone. summary.json: height.unreliable_fraction 1.
        log.warning("%s: no pixel has a reliable height (the slices carry no focus "
                    "information); the surface is taken as flat and facet tilts come from "
                    "colour alone", st.path)
        height_filled = np.zeros(foc.height_um.shape, np.float32)
    elif np.isnan(foc.height_um).any():
        height_filled = fill_missing(foc.height_um, method="smooth")
    else:
        height_filled = foc.height_um
    normals = normals_from_height(height_filled, pixel_size_um=st.pixel_size_um,
                                  smooth_sigma_px=1.0)
    tilt_h, _ = tilt_azimuth_deg(normals)
    t0 = _timer(timings, "normals", t0)

    # 2. Colour and mask.
    step("colour")
    aif = foc.all_in_focus
    if aif.ndim == 2:
        aif = np.repeat(aif[..., None], 3, axis=-1)
    if st.color_space == "linear-sRGB":
        enc = srgb_encode(aif, dtype=np.float32)
    else:
        enc = aif.astype(np.float32)
    bit_depth = 16 if st.dtype == np.uint16 else 8
    cm = colour_mask(enc, saturation_min=opt.saturation_min, value_min=opt.value_min,
                     bit_depth=bit_depth)
    lab = srgb_to_lab(enc, illuminant=illuminant).astype(np.float32)
    from .tilt import estimate_colour_noise, quantization_noise_de

    noise_de = estimate_colour_noise(lab, cm.mask)
    noise_floor = quantization_noise_de(enc, cm.mask, bit_depth=bit_depth,
                                        illuminant=illuminant)
    if np.isfinite(noise_floor) and not noise_de >= noise_floor:
        log.info("colour noise %.4g below the quantization floor; using %.4g ΔE00",
                 noise_de, noise_floor)
        noise_de = noise_floor
    t0 = _timer(timings, "colour_and_mask", t0)
    if cm.mask.all():
        raise InputError(_no_colour_message(st, cm, opt, "every pixel is masked"))

    # 3. Colour table for the scene.
    step("colour table")
    table = build_colour_table(thickness_range_nm=tuple(opt.thickness_range_nm),
                               theta_range_deg=(0.0, max_tilt + 0.5), film=film,
                               substrate=substrate, illuminant=illuminant)
    t0 = _timer(timings, "colour_table", t0)

    # 4. Thickness per ROI and exposure.
    step("thickness per ROI")
    exposure = opt.exposure if opt.exposure is not None else st.exposure
    exposure_source = ("option" if opt.exposure is not None else
                       "stack.json" if st.exposure is not None else "estimated")
    rois = roi_grid(lab.shape[:2], size_px=opt.roi_size_px, stride_px=opt.roi_stride_px)
    roi = fit_roi_thickness(lab, tilt_h, cm.mask, table, rois=rois, exposure=exposure,
                            seed=opt.seed)
    if not np.isfinite(roi.thickness_nm).any():
        raise InputError(_no_colour_message(
            st, cm, opt, f"only {int((~cm.mask).sum())} unmasked pixels, too few in every "
                         f"region of interest"))
    exposure = roi.exposure
    ri, ci = nearest_roi_index(lab.shape[:2], *rois)
    roi_index = ri[:, None] * len(rois[1]) + ci[None, :]
    thick_roi_px = roi.thickness_nm[roi_index]
    t0 = _timer(timings, "thickness_roi", t0)

    # 5. Per-pixel thickness and tilt.
    step("tilt per pixel")
    usable = ~cm.mask & np.isfinite(thick_roi_px)
    # invert_tilt needs a uniform grid (its parabola refinement and sensitivities use one
    # step): equal steps of at most tilt_step_deg ending at max_tilt, at least 3 nodes.
    n_steps = max(2, math.ceil(max_tilt / opt.tilt_step_deg - 1e-9))
    theta_grid = np.linspace(0.0, max_tilt, n_steps + 1)
    H, W = lab.shape[:2]
    thickness = np.full((H, W), np.nan, np.float32)
    tilt = np.full((H, W), np.nan, np.float32)
    tilt_sig = np.full((H, W), np.nan, np.float32)
    dE = np.full((H, W), np.nan, np.float32)
    cw = np.full((H, W), np.nan, np.float32)
    facets = None
    from .tilt import invert_tilt, model_lab_rows

    yy, xx = np.nonzero(usable)
    if opt.mode == "seed":
        rows_d = np.where(np.isfinite(roi.thickness_nm), roi.thickness_nm, table.thickness_nm[0])
        rows_lab = model_lab_rows(table, rows_d, theta_grid, exposure=exposure)
        rix = roi_index[yy, xx]
        inv = invert_tilt(lab[yy, xx], rows_lab, rix, theta_grid, table=table,
                          thickness_px=rows_d[rix], exposure=exposure, noise_de=noise_de)
        thickness[yy, xx] = rows_d[rix]
        group_thick = roi_index
    else:
        from .facets import facet_thickness, fit_facet_planes, segment_facets

        facets = segment_facets(lab, facet_px=opt.facet_size_um / st.pixel_size_um)
        t0 = _timer(timings, "segmentation", t0)
        if st.has_slices:
            rel = np.clip(np.nan_to_num(foc.reliability_db, nan=0.0) / 20.0, 0.0, 1.0) ** 2
        else:  # a microscope export's height is trusted where it is finite
            rel = np.isfinite(foc.height_fit_um).astype(np.float64)
        from scipy import ndimage

        edge = np.zeros((H, W), bool)
        edge[:, 1:] |= facets[:, 1:] != facets[:, :-1]
        edge[1:, :] |= facets[1:, :] != facets[:-1, :]
        dist = ndimage.distance_transform_edt(~edge)
        weight = rel * np.clip(dist / 2.0, 0.0, 1.0) if not no_focus else np.zeros((H, W))
        ff = fit_facet_planes(facets, foc.height_fit_um, weight, pixel_size_um=st.pixel_size_um,
                              fallback_tilt_deg=tilt_h)
        tilt_f = np.clip(ff.tilt_deg, 0, max_tilt)
        if exposure_source == "estimated":
            exposure = _refine_exposure_on_facets(facets, lab, usable, tilt_f, thick_roi_px,
                                                  table, exposure, interior=dist >= 1.5,
                                                  seed=opt.seed)
            log.info("exposure refined on facets: %.4f", exposure)
        d_f, _ = facet_thickness(facets, lab, usable, tilt_f, thick_roi_px, table,
                                 exposure=exposure, interior=dist >= 1.5)
        t0 = _timer(timings, "facet_fits", t0)
        fid = facets[yy, xx]
        d_rows = np.where(np.isfinite(d_f), d_f, table.thickness_nm[0])
        rows_lab = model_lab_rows(table, d_rows, theta_grid, exposure=exposure)
        prior = np.clip(ff.tilt_deg[fid], 0, max_tilt)
        inv = invert_tilt(lab[yy, xx], rows_lab, fid, theta_grid, table=table,
                          thickness_px=d_rows[fid], exposure=exposure, noise_de=noise_de,
                          prior_deg=prior, prior_sigma_deg=ff.tilt_sigma_deg[fid])
        thickness[yy, xx] = d_rows[fid]
        # Neighbouring facets share a smooth thickness field: they are not independent
        # samples for the BIC. Blocks of ~10 µm are (docs/accuracy.md).
        block = max(4, int(round(10.0 / st.pixel_size_um)))
        by, bx = np.mgrid[0:H, 0:W]
        group_thick = (by // block) * ((W + block - 1) // block) + bx // block
    tilt[yy, xx] = inv.tilt_deg
    tilt_sig[yy, xx] = inv.tilt_sigma_deg
    dE[yy, xx] = inv.delta_e
    cw[yy, xx] = inv.colour_weight
    t0 = _timer(timings, "tilt_per_pixel", t0)

    # 6. Distributions.
    step("distributions")
    ok = np.isfinite(thickness)
    if ok.sum() >= 2:
        tfit = fit_thickness_mixture(thickness[ok], max_components=opt.max_components,
                                     group=group_thick[ok])
    else:
        tfit = None
    okt = np.isfinite(tilt)
    if okt.sum() >= 2:
        nfit = fit_ndf_mixture(tilt[okt], max_components=opt.max_components,
                               group=facets[okt] if facets is not None else None)
    else:
        nfit = None
    t0 = _timer(timings, "mixtures", t0)
    timings["total"] = round(time.perf_counter() - t_all, 4)
    return AnalysisResult(
        stack=st, options=opt, focus=foc, normals=normals, tilt_height_deg=tilt_h, lab=lab,
        mask=cm, roi=roi, thickness_nm=thickness, tilt_deg=tilt, tilt_sigma_deg=tilt_sig,
        delta_e=dE, colour_weight=cw, facets=facets, thickness_fit=tfit, ndf_fit=nfit,
        exposure=float(exposure), exposure_source=exposure_source, noise_de=noise_de,
        max_tilt_deg=max_tilt, table=table,
        optics={"film": film, "substrate": substrate, "illuminant": illuminant,
                "numerical_aperture": na},
        timings_s=timings)


def _no_colour_message(st, cm, opt, what):
    """One-line InputError text for a stack without usable colour, with the mask reasons."""
    key = "tiff" if st.tiff_path is not None else "slices" if st.has_slices else "image"
    f = cm.fractions()
    reasons = ", ".join(f"{name.replace('_', ' ')} {100 * f[name]:.0f}%" for name in
                        ("low_saturation", "dark", "clipped", "invalid", "shadow"))
    return (f"{st.path / 'stack.json'}: key {key!r}: no colour information to analyse, "
            f"{what} ({reasons}; saturation_min {opt.saturation_min:g}, value_min "
            f"{opt.value_min:g} on the 0-255 scale)")


def _export_as_focus(st):
    """A :class:`~microfacet.focus.height.FocusResult` from a microscope export (``height_um`` +
    ``image`` in stack.json): the height map as given (non-finite = unreliable), the export
    image as the all-in-focus composite, no focus measure (reliability NaN)."""
    from ..focus.height import FocusResult

    t0 = time.perf_counter()
    h = st.read_export_height()
    img = st.read_export_image()
    reliable = np.isfinite(h)
    shape = h.shape
    return FocusResult(
        height_um=h, height_fit_um=h.copy(), reliability_db=np.full(shape, np.nan, np.float32),
        reliable=reliable, best_index=np.zeros(shape, np.int32),
        focus_max=np.full(shape, np.nan, np.float32), all_in_focus=img,
        z_um=np.zeros(0), params={"source": "microscope export"},
        timings_s={"total": round(time.perf_counter() - t0, 4)})


def _refine_exposure_on_facets(facets, lab, usable, tilt_f, thick_roi_px, table, exposure, *,
                               interior, seed=0, n_facets=2000):
    """Exposure of least median facet ΔE00, each facet's thickness re-solved per candidate.

    Facets are homogeneous (one tilt, one thickness), unlike ROIs that span several
    thickness regions, so they pin the exposure down better than the ROI fit did.
    """
    from scipy.optimize import minimize_scalar

    from .facets import facet_thickness

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
                                exposure=math.exp(log_e), interior=interior)
        return float(np.nanmedian(de))

    lo, hi = math.log(exposure / 1.5), math.log(exposure * 1.5)
    opt = minimize_scalar(objective, bounds=(lo, hi), method="bounded",
                          options={"xatol": 0.005})
    return float(math.exp(opt.x)) if opt.fun <= objective(math.log(exposure)) else exposure


def _versions():
    import importlib.metadata as md

    from .. import __version__

    out = {"microfacet": __version__}
    for name in ("numpy", "scipy", "colour-science", "scikit-image", "scikit-learn",
                 "opencv-contrib-python-headless"):
        try:
            out[name] = md.version(name)
        except md.PackageNotFoundError:
            pass
    return out


def _pdf_csv(path, header, table):
    np.savetxt(path, table, delimiter=",", header=header, comments="", fmt="%.6g")


def write_results(result: AnalysisResult, out, *, overwrite=False, report=True) -> Path:
    """Write the results folder (``docs/results-format.md``) atomically.

    Parameters
    ----------
    result : AnalysisResult
    out : path-like
        The results folder: new, empty, or (with ``overwrite``) an earlier results folder;
        never the stack or a folder that holds it (:mod:`microfacet.io.outdir`).
    overwrite : bool
        Replace an existing results folder.
    report : bool
        Also write ``report.pdf`` (and its PNG figures).

    Raises
    ------
    InputError
        ``out`` breaks the rules of :mod:`microfacet.io.outdir`, another run is writing it, or
        the disk is read-only or too full (checked before anything is written).
    """
    from ..io.images import write_image
    from .mixtures import _cells, pdf_table
    from ..io.outdir import atomic_output_dir

    r = result
    t0 = time.perf_counter()
    with atomic_output_dir(out, kind="results", overwrite=overwrite, inputs=[r.stack.path],
                           expected_bytes=results_size_bytes(r.stack.shape, report=report)
                           ) as tmp:
        rel = np.isfinite(r.focus.height_um)
        np.save(tmp / "height_um.npy", r.focus.height_um.astype(np.float32))
        normals = np.where(rel[..., None], r.normals, np.nan).astype(np.float32)
        np.save(tmp / "normals.npy", normals)
        np.save(tmp / "reliability_db.npy", r.focus.reliability_db.astype(np.float32))
        np.save(tmp / "tilt_height_deg.npy", r.tilt_height_deg.astype(np.float32))
        np.save(tmp / "thickness_nm.npy", r.thickness_nm)
        np.save(tmp / "tilt_deg.npy", r.tilt_deg)
        np.save(tmp / "tilt_sigma_deg.npy", r.tilt_sigma_deg)
        np.save(tmp / "delta_e.npy", r.delta_e)
        np.save(tmp / "colour_weight.npy", r.colour_weight)
        np.save(tmp / "mask.npy", r.mask.mask)
        if r.facets is not None:
            np.save(tmp / "facets.npy", r.facets)
        write_image(tmp / "all_in_focus.png", r.focus.all_in_focus,
                    bit_depth=16 if r.stack.dtype == np.uint16 else 8)

        roi = r.roi
        rows = np.column_stack([roi.row0, roi.col0, np.full(roi.row0.size, roi.height_px),
                                roi.thickness_nm, roi.mean_delta_e, roi.n_pixels,
                                np.full(roi.row0.size, roi.width_px),
                                roi.runner_up_thickness_nm, roi.runner_up_delta_e,
                                roi.ambiguity_delta_e])
        np.savetxt(tmp / "thickness_roi.csv", rows, delimiter=",", comments="",
                   header="row0,col0,size,thickness_nm,mean_delta_e,n_pixels,width,"
                          "runner_up_thickness_nm,runner_up_delta_e,ambiguity_delta_e",
                   fmt=["%d", "%d", "%d", "%.3f", "%.4f", "%d", "%d", "%.3f", "%.4f", "%.4f"])

        th = r.thickness_nm[np.isfinite(r.thickness_nm)]
        if th.size and r.thickness_fit is not None:
            lo = math.floor(th.min()) - 10
            hi = math.ceil(th.max()) + 10
            grid = np.arange(max(lo, 0), hi + 1e-9, 0.5)
            _pdf_csv(tmp / "thickness_pdf.csv", "thickness_nm,density,mixture_density",
                     pdf_table(th, r.thickness_fit.mixture, grid=grid))
        else:
            _pdf_csv(tmp / "thickness_pdf.csv", "thickness_nm,density,mixture_density",
                     np.empty((0, 3)))
        tl = r.tilt_deg[np.isfinite(r.tilt_deg)]
        if tl.size and r.ndf_fit is not None:
            # Equal cells of <= 0.5° exactly covering [0, max_tilt] (tilts lie there), at
            # least two (pdf_table's minimum) even for a tiny numerical aperture.
            n_cells = max(2, math.ceil(r.max_tilt_deg / 0.5 - 1e-9))
            grid = (np.arange(n_cells) + 0.5) * (r.max_tilt_deg / n_cells)
            # Tilts at 0 or max_tilt may fall a rounding error outside the outer cell edges
            # (float32 map, edges from the grid): clip them onto those edges.
            _, edges = _cells(grid)
            tl = np.clip(tl.astype(np.float64), edges[0], edges[-1])
            _pdf_csv(tmp / "ndf_pdf.csv", "tilt_deg,density,mixture_density",
                     pdf_table(tl, r.ndf_fit.mixture, grid=grid))
        else:
            _pdf_csv(tmp / "ndf_pdf.csv", "tilt_deg,density,mixture_density", np.empty((0, 3)))

        summary = _summary(r)
        summary["timings_s"]["write"] = round(time.perf_counter() - t0, 4)
        (tmp / "summary.json").write_text(json.dumps(summary, indent=2, allow_nan=False))
        if report:
            t1 = time.perf_counter()
            from ..report.writer import write_report

            write_report(tmp, out_pdf=tmp / "report.pdf", png_dir=tmp)
            summary["timings_s"]["report"] = round(time.perf_counter() - t1, 4)
            (tmp / "summary.json").write_text(json.dumps(summary, indent=2, allow_nan=False))
    return Path(out)


def _clean(x):
    """JSON-safe: NaN/inf → None, numpy scalars → Python."""
    if isinstance(x, dict):
        return {str(k): _clean(v) for k, v in x.items()}
    if isinstance(x, (list, tuple)):
        return [_clean(v) for v in x]
    if isinstance(x, (np.floating, float)):
        return float(x) if math.isfinite(float(x)) else None
    if isinstance(x, (np.integer,)):
        return int(x)
    if isinstance(x, np.bool_):
        return bool(x)
    if isinstance(x, np.ndarray):
        return _clean(x.tolist())
    return x


def _summary(r: AnalysisResult) -> dict:
    st = r.stack
    roi = r.roi
    cwt = r.colour_weight[np.isfinite(r.colour_weight)]
    opts = dataclasses.asdict(r.options)
    empty_mix = {"components": [], "bic": None}
    thick_mix = r.thickness_fit.to_json() if r.thickness_fit is not None else empty_mix
    ndf_mix = r.ndf_fit.to_json() if r.ndf_fit is not None else empty_mix
    ok_roi = np.isfinite(roi.thickness_nm)
    s = {
        "format": "microfacet-results/1",
        "created": datetime.datetime.now(datetime.timezone.utc).isoformat(timespec="seconds"),
        "mode": r.options.mode,
        "inputs": {"stack": str(st.path), "shape": list(st.shape), "n_slices": st.n_slices,
                   "pixel_size_um": st.pixel_size_um,
                   "z_um_range": ([float(np.min(st.z_um)), float(np.max(st.z_um))]
                                  if st.n_slices else None),
                   "height_source": "focus stack" if st.n_slices else "microscope export",
                   **r.optics},
        "parameters": opts,
        "versions": _versions(),
        "film": r.optics["film"], "substrate": r.optics["substrate"],
        "illuminant": r.optics["illuminant"],
        "thickness": {
            "mixture": thick_mix,
            "roi": {"count": int(roi.thickness_nm.size), "fitted": int(ok_roi.sum()),
                    "thickness_nm_mean": float(np.mean(roi.thickness_nm[ok_roi]))
                    if ok_roi.any() else None,
                    "ambiguous_count": int(np.sum(roi.ambiguity_delta_e[ok_roi] < 1.0))},
        },
        "ndf": {"mixture": ndf_mix, "max_tilt_deg": r.max_tilt_deg,
                "histogram": "per-pixel tilt of unmasked pixels (projected-area density)"},
        "exposure": r.exposure,
        "exposure_source": r.exposure_source,
        "delta_e": r.delta_e_stats,
        "masked_fraction": r.mask.fraction,
        "mask": r.mask.fractions(),
        "colour_noise_de": r.noise_de,
        "tilt_information": {
            "colour_weight_mean": float(cwt.mean()) if cwt.size else None,
            "colour_dominated_fraction": float(np.mean(cwt > 0.5)) if cwt.size else None,
            "tilt_sigma_deg_median": float(np.nanmedian(r.tilt_sigma_deg))
            if np.isfinite(r.tilt_sigma_deg).any() else None,
        },
        "height": {"unreliable_fraction": float(np.mean(~np.isfinite(r.focus.height_um)))},
        "colour_table": {"spectral_step_nm": r.table.spectral_step_nm,
                         "spectral_error_de00": r.table.spectral_error_de00,
                         "interp_error_de00": r.table.interp_error_de00,
                         "theta_step_deg": r.table.theta_step_deg,
                         "thickness_step_nm": r.table.thickness_step_nm},
        "timings_s": dict(r.timings_s),
    }
    return _clean(s)
