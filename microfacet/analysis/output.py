"""What a results folder holds: the maps, tables and ``summary.json`` of an analysis, written
through :mod:`microfacet.io.results` (the one module that writes and reads the folder).

The report is a separate step (:func:`microfacet.report.write_report`), which the command
line and ``batch`` run on the written folder.
"""

from __future__ import annotations

import datetime
import importlib.metadata
import math
import time
from pathlib import Path

import numpy as np

from .. import __version__
from ..colour.snapshot import stored as stored_colour_tables
from ..core.densities import cell_edges, pdf_table
from ..core.pixels import pixel_size_yx
from ..core.threads import row_chunks
from ..focus.uncertainty import (
    RELIEF_COEFFICIENT,
    height_sigma_with_bias,
    unresolved_relief_sigma_um,
)
from ..io.outdir import atomic_output_dir
from ..io.results import Results, write_results_files
from ..io.summary import (
    DeltaE,
    FacetCounts,
    Inputs,
    Iso25178Section,
    NdfSection,
    RoiCounts,
    Summary,
    ThicknessSection,
)
from .identification import (
    MEDIAN_NOISE_FLOOR_FACTOR,
    NOISE_FLOOR_FACTOR,
    mean_plane_tilt_deg,
)
from .iso25178 import REFERENCES, areal_parameters

__all__ = ["results_size_bytes", "save_results", "write_results"]

#: Bytes per pixel of the results folder (float32 maps, normals, mask, facets, PNG, the
#: float32 TIFF copies for microscopy tools and the .x3p height map) and the report's size.
_RESULT_BYTES_PER_PIXEL = 85
_REPORT_BYTES = 8 << 20
_ROI_COLUMNS = ["row0", "col0", "size", "thickness_nm", "mean_delta_e", "n_pixels", "width",
                "runner_up_thickness_nm", "runner_up_delta_e", "ambiguity_delta_e",
                "ambiguous", "pixel_mean_nm", "pixel_sd_nm", "disagrees_with_pixels"]
_ROI_FMT = ["%d", "%d", "%d", "%.3f", "%.4f", "%d", "%d", "%.3f", "%.4f", "%.4f", "%d", "%.3f",
            "%.3f", "%d"]
_FACET_COLUMNS = ["facet", "n_pixels", "tilt_deg", "tilt_sigma_deg", "height_plane",
                  "slope_sigma", "thickness_nm", "thickness_sigma_nm", "delta_e",
                  "other_order_delta_e", "other_order_thickness_nm", "censored_fraction"]
_FACET_FMT = ["%d", "%d", "%.4f", "%.4f", "%d", "%.5f", "%.3f", "%.3f", "%.4f", "%.4f", "%.1f",
              "%.4f"]


def results_size_bytes(shape, *, report: bool = True) -> int:
    """Expected size of the results folder of an analysis of ``shape`` = (H, W) images."""
    return _RESULT_BYTES_PER_PIXEL * int(shape[0]) * int(shape[1]) + (_REPORT_BYTES if report
                                                                       else 0)


def _versions():
    out = {"microfacet": __version__}
    for name in ("numpy", "scipy", "colour-science", "scikit-image", "scikit-learn",
                 "opencv-contrib-python-headless"):
        try:
            out[name] = importlib.metadata.version(name)
        except importlib.metadata.PackageNotFoundError:
            pass
    tables = stored_colour_tables()
    if tables is not None:     # the CIE tables and weights the analysis read (colour.snapshot)
        out["colour-science tables"] = tables.colour_version
    return out


def _thickness_pdf(r):
    th = r.pixels.thickness_nm[np.isfinite(r.pixels.thickness_nm)]
    if not th.size or r.thickness_fit is None:
        return np.empty((0, 3))
    lo, hi = math.floor(th.min()) - 10, math.ceil(th.max()) + 10
    grid = np.arange(max(lo, 0), hi + 1e-9, 0.5)
    return pdf_table(th, r.thickness_fit.mixture, grid=grid)


def _ndf_pdf(r):
    tl = r.pixels.tilt_deg[np.isfinite(r.pixels.tilt_deg)]
    if not tl.size or r.ndf_fit is None:
        return np.empty((0, 3))
    # Equal cells of <= 0.5° exactly covering [0, max_tilt] (tilts lie there), at least two
    # (pdf_table's minimum) even for a tiny numerical aperture.
    max_tilt = r.scene.max_tilt_deg
    n_cells = max(2, math.ceil(max_tilt / 0.5 - 1e-9))
    grid = (np.arange(n_cells) + 0.5) * (max_tilt / n_cells)
    # Tilts at 0 or max_tilt may fall a rounding error outside the outer cell edges (float32
    # map, edges from the grid): clip them onto those edges.
    _, edges = cell_edges(grid)
    tl = np.clip(tl.astype(np.float64), edges[0], edges[-1])
    return pdf_table(tl, r.ndf_fit.mixture, grid=grid)


def _facet_rows(joint):
    th, pl, area = joint.thickness, joint.planes, joint.area_px
    cens = np.bincount(joint.facets.ravel(), weights=joint.censored.ravel(),
                       minlength=area.size) / np.maximum(area, 1)
    return np.column_stack([np.arange(area.size), area, pl.tilt_deg, pl.tilt_sigma_deg,
                            pl.fitted.astype(int), pl.slope_sigma, th.thickness_nm, th.sigma_nm,
                            th.delta_e, th.delta_e_other_order, th.thickness_other_order_nm,
                            cens])


def _tables(r) -> dict:
    roi = r.roi
    pix_mean, pix_sd = roi.pixel_stats(r.pixels.thickness_nm)
    roi_rows = np.column_stack([roi.row0, roi.col0, np.full(roi.row0.size, roi.height_px),
                                roi.thickness_nm, roi.mean_delta_e, roi.n_pixels,
                                np.full(roi.row0.size, roi.width_px),
                                roi.runner_up_thickness_nm, roi.runner_up_delta_e,
                                roi.ambiguity_delta_e, r.distributions.roi_ambiguous.astype(int),
                                pix_mean, pix_sd, r.roi_check[1].astype(int)])
    tables = {"thickness_roi": (roi_rows, _ROI_COLUMNS, _ROI_FMT)}
    if r.joint is not None:
        tables["facets"] = (_facet_rows(r.joint), _FACET_COLUMNS, _FACET_FMT)
    tables["thickness_pdf"] = (_thickness_pdf(r), ["thickness_nm", "density",
                                                   "mixture_density"], "%.6g")
    tables["ndf_pdf"] = (_ndf_pdf(r), ["tilt_deg", "density", "mixture_density"], "%.6g")
    return tables


def save_results(result, folder) -> dict:
    """Write the results of ``result`` into the existing folder ``folder`` (normally the
    temporary folder of an :class:`~microfacet.io.outdir.OutputFolder`); returns the maps
    written that ``result`` holds, as their files hold them (for
    ``write_report(folder, maps=...)``: :func:`~microfacet.io.results.write_results_files`)."""
    r = result
    t0 = time.perf_counter()
    rel = np.isfinite(r.focus.height_um)
    px = r.pixels
    maps = {
        "height_um": r.focus.height_um,
        # made by the job that writes each (12 and 4 bytes a pixel), not all before the files
        "normals": lambda: np.where(rel[..., None], r.surface.normals, np.nan),
        "reliability_db": r.focus.reliability_db,
        "height_sigma_um": lambda: height_sigma_um(r),
        "tilt_height_deg": r.surface.tilt_deg,
        "thickness_nm": px.thickness_nm, "tilt_deg": px.tilt_deg,
        "tilt_sigma_deg": px.tilt_sigma_deg, "delta_e": px.delta_e,
        "colour_weight": px.colour_weight, "mask": r.colour.mask.mask,
        "facets": None if r.joint is None else r.joint.facets,
    }
    summary = build_summary(r)
    stored = write_results_files(
        folder, summary=summary.to_json(), maps=maps,
        images={"all_in_focus": (r.focus.all_in_focus,
                                 16 if r.stack.dtype == np.uint16 else 8)},
        tables=_tables(r))
    # the summary is written last of the files; its write time, files included, after them
    Results(folder).record("timings_s", "write", round(time.perf_counter() - t0, 4))
    return stored


def write_results(result, out, *, overwrite=False) -> Path:
    """Write the results folder (``docs/results-format.md``) of ``result`` atomically.

    Parameters
    ----------
    result : AnalysisResult
    out : path-like
        The results folder: new, empty, or (with ``overwrite``) an earlier results folder;
        never the stack or a folder that holds it (:mod:`microfacet.io.outdir`).
    overwrite : bool
        Replace an existing results folder.

    Returns
    -------
    pathlib.Path

    Raises
    ------
    InputError
        ``out`` breaks the rules of :mod:`microfacet.io.outdir`, another run is writing it, or
        the disk is read-only or too full (checked before anything is written).

    Notes
    -----
    The report is a separate step: ``microfacet.report.write_report(out)``.
    """
    with atomic_output_dir(out, kind="results", overwrite=overwrite,
                           inputs=[result.stack.path],
                           expected_bytes=results_size_bytes(result.stack.shape, report=False)
                           ) as tmp:
        save_results(result, tmp)
    return Path(out)


def _inputs(r) -> Inputs:
    st = r.stack
    jpeg = None if st.jpeg is None else {"quality": st.jpeg.quality,
                                          "dc_steps": list(st.jpeg.dc_steps),
                                          "chroma_block_px": st.jpeg.chroma_block_px}
    return Inputs(stack=str(st.path), shape=list(st.shape), n_slices=st.n_slices, jpeg=jpeg,
                  pixel_size_um=st.pixel_size_um,
                  z_um_range=([float(np.min(st.z_um)), float(np.max(st.z_um))]
                              if st.n_slices else None),
                  height_source="focus stack" if st.n_slices else "microscope export",
                  **r.scene.optics_json())


def _thickness_section(r) -> ThicknessSection:
    roi, dist = r.roi, r.distributions
    ok = np.isfinite(roi.thickness_nm)
    mix = dist.thickness.to_json() if dist.thickness is not None else {"components": [],
                                                                       "bic": None}
    mix.update(dist.thickness_judgement.to_json())
    check = r.map_check
    mix["map_check"] = None if check is None else check.to_json()
    return ThicknessSection(mix, RoiCounts(
        count=int(roi.thickness_nm.size), fitted=int(ok.sum()),
        thickness_nm_mean=float(np.mean(roi.thickness_nm[ok])) if ok.any() else None,
        ambiguous_count=int(dist.roi_ambiguous.sum()),
        ambiguous_delta_e=r.options.fits.ambiguous_order_de,
        pixel_disagree_count=int(r.roi_check[1].sum()),
        ambiguous=[{"roi": int(i), "thickness_nm": float(roi.thickness_nm[i]),
                    "delta_e": float(roi.mean_delta_e[i]),
                    "runner_up_thickness_nm": float(roi.runner_up_thickness_nm[i]),
                    "runner_up_delta_e": float(roi.runner_up_delta_e[i])}
                   for i in np.flatnonzero(dist.roi_ambiguous)]),
        order=r.order)


def _ndf_section(r) -> NdfSection:
    dist = r.distributions
    mix = dist.ndf.to_json() if dist.ndf is not None else {"components": [], "bic": None}
    return NdfSection(**dist.ndf_judgement.to_json(), mixture=mix,
                      max_tilt_deg=r.scene.max_tilt_deg,
                      mean_plane_tilt_deg=mean_plane_tilt_deg(r.joint),
                      histogram="per-pixel tilt of unmasked pixels (projected-area density)",
                      self_check=None if r.self_check is None else r.self_check.to_json())


def _tilt_information(px) -> dict:
    cwt = px.colour_weight[np.isfinite(px.colour_weight)]
    return {"colour_weight_mean": float(cwt.mean()) if cwt.size else None,
            "colour_dominated_fraction": float(np.mean(cwt > 0.5)) if cwt.size else None,
            "tilt_sigma_deg_median": float(np.nanmedian(px.tilt_sigma_deg))
            if np.isfinite(px.tilt_sigma_deg).any() else None}


def build_summary(r) -> Summary:
    """The :class:`~microfacet.io.summary.Summary` of an
    :class:`~microfacet.analysis.pipeline.AnalysisResult` (docs/results-format.md)."""
    table, noise = r.model.table, r.colour.noise_de
    return Summary(
        created=datetime.datetime.now(datetime.timezone.utc).isoformat(timespec="seconds"),
        mode=r.options.mode, inputs=_inputs(r), parameters=r.options.to_dict(),
        versions=_versions(), thickness=_thickness_section(r), ndf=_ndf_section(r),
        facets=_facet_summary(r.joint), exposure=r.exposure,
        exposure_source=r.scene.exposure_source,
        exposure_readings=(None if r.distributions.exposure_readings is None
                           else r.distributions.exposure_readings.to_json()),
        white_balance=r.white_balance.to_dict(),
        flat_field=None if r.flat_field is None else r.flat_field.to_json(r.colour.lab.shape[:2]),
        delta_e=DeltaE(**r.delta_e_stats, noise_floor_mean=NOISE_FLOOR_FACTOR * noise,
                       noise_floor_median=MEDIAN_NOISE_FLOOR_FACTOR * noise),
        masked_fraction=r.colour.mask.fraction, mask=r.colour.mask.fractions(),
        colour_noise_de=noise, colour_block_noise_de=r.colour.block_noise_de,
        tilt_information=_tilt_information(r.pixels),
        height=_height_section(r), iso25178=_iso25178_section(r),
        colour_table={"spectral_step_nm": table.spectral_step_nm,
                      "spectral_error_de00": table.spectral_error_de00,
                      "interp_error_de00": table.interp_error_de00,
                      "theta_step_deg": table.theta_step_deg,
                      "thickness_step_nm": table.thickness_step_nm},
        warnings=[w.plain() for w in r.warnings], timings_s=dict(r.timings_s))


def sigma_scale(r) -> float | None:
    """The factor the self-check measured for the focus stage's height σ (None without)."""
    c = r.self_check
    return None if c is None or not np.isfinite(c.height_sigma_scale) \
        else float(c.height_sigma_scale)


def height_sigma_um(r) -> np.ndarray | None:
    """``height_sigma_um.npy``: the focus stage's 1-σ height error where the height is
    reliable, with its bias terms and the relief its window averages away in quadrature
    (:func:`height_sigma_terms`); None for an export."""
    terms = height_sigma_terms(r)
    if terms is None:
        return None
    sig, relief = terms
    h = r.focus.height_um
    out = np.empty(h.shape, np.float32)
    # a block of rows at a time: the temporaries are a block's (were 33 bytes a pixel)
    for a, b in row_chunks(h.shape):
        s, e = sig[a:b], relief[a:b]
        out[a:b] = np.where(np.isfinite(h[a:b]), np.sqrt(s * s + e * e), np.float32(np.nan))
    return out


def height_sigma_terms(r, *, coefficient=RELIEF_COEFFICIENT
                       ) -> tuple[np.ndarray, np.ndarray] | None:
    """The two parts of :func:`height_sigma_um` (µm): the focus stage's σ with the variance of
    its unexplained disagreement with the evidence window
    (:func:`~microfacet.focus.uncertainty.height_sigma_with_bias`) times the self-check's
    :func:`sigma_scale`, and the unresolved relief at ``coefficient``
    (:func:`~microfacet.focus.uncertainty.unresolved_relief_sigma_um` of the map's
    :func:`height_rms_gradient`; 0 without a window map); None for an export."""
    if r.focus.height_sigma_um is None or not r.scene.from_focus:
        return None
    sig = height_sigma_with_bias(r.focus) * np.float32(sigma_scale(r) or 1.0)
    relief = (np.zeros_like(sig) if r.focus.window_px_map is None else
              unresolved_relief_sigma_um(height_rms_gradient(r), r.focus.window_px_map,
                                         r.scene.pixel_size_um, coefficient=coefficient))
    return sig, relief


def height_rms_gradient(r) -> float | None:
    """The height map's RMS gradient Sdq (ISO 25178-2, about its least-squares plane, on its
    reliable pixels; None with fewer than 3)."""
    return None if r.height_areal is None else r.height_areal.Sdq


def _height_section(r) -> dict:
    """Unreliable fraction; the σ (µm, ``[y, x]``) by which the slopes were smoothed before
    the normals (0 for an instrument's height map); the self-check's scale of the height σ
    and the 2σ coverage of its heights before it; the unresolved-relief term's coefficient
    and the map's RMS gradient it multiplies (null for an export)."""
    sigma_px = r.options.focus.slope_sigma_px if r.scene.from_focus else 0.0
    c = r.self_check
    cov = None if c is None else c.height_coverage
    relief = r.scene.from_focus and r.focus.window_px_map is not None
    return {"unreliable_fraction": float(np.mean(~np.isfinite(r.focus.height_um))),
            "normals_slope_sigma_um": [sigma_px * p for p in pixel_size_yx(
                r.scene.pixel_size_um)],
            "sigma_scale": sigma_scale(r),
            "self_check_coverage": float(cov) if cov is not None and np.isfinite(cov)
            else None,
            "relief_coefficient": RELIEF_COEFFICIENT if relief else None,
            "relief_rms_gradient": height_rms_gradient(r) if relief else None}


def _iso25178_section(r) -> Iso25178Section | None:
    """``summary.json`` ``iso25178``: the height map's ISO 25178-2 parameters on its reliable
    pixels (finite ``height_um``) about the least-squares plane, SurfaceTopography's RMS
    height and gradient of the map as measured, and the RMS slope of the analysis' own
    normals on the same pixels (None with fewer than 3 reliable heights, or all on a line)."""
    h = np.asarray(r.focus.height_um)
    px = r.scene.pixel_size_um
    iso = r.height_areal
    if iso is None:
        return None
    raw = areal_parameters(h, pixel_size_um=px, reference="mean")
    tan = np.asarray(r.surface.tilt_deg)[np.isfinite(h)].astype(np.float64)
    np.tan(np.radians(tan, out=tan), out=tan)
    tan = tan[np.isfinite(tan)]
    gy, gx = iso.plane_slope_yx
    return Iso25178Section(
        reference=REFERENCES["plane"], differences="forward", n_points=iso.n_points,
        Sq_um=iso.Sq_um, Sa_um=iso.Sa_um, Sdq=iso.Sdq, Sdr_percent=iso.Sdr_percent,
        plane_tilt_deg=math.degrees(math.atan(math.hypot(gy, gx))),
        rms_height_um=raw.Sq_um, rms_gradient=raw.Sdq,
        rms_slope_normals=float(np.sqrt(np.mean(tan ** 2))) if tan.size else None)


def _facet_summary(joint) -> FacetCounts | None:
    """``summary.json`` ``facets`` (joint mode; None in seed mode)."""
    if joint is None:
        return None
    pl, area = joint.planes, joint.area_px.astype(np.float64)
    tot = max(float(area.sum()), 1.0)
    return FacetCounts(count=int(area.size), median_area_px=float(np.median(area)),
                       with_height_plane=int(pl.fitted.sum()),
                       height_plane_area_fraction=float(area[pl.fitted].sum() / tot),
                       censored_area_fraction=float(joint.censored.sum() / tot))
