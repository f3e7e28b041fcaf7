"""Facet tilt per pixel from its colour at a known thickness (seed §3.3.3 step 3).

With the thickness fixed (per ROI in the seed's method, per facet in the joint mode), the
tilt of a pixel is the incidence angle θ in [0, θ_max] whose modelled Lab is nearest the
pixel's by CIEDE2000. The search runs on a θ grid for all pixels at once (each pixel
compares with the model row of its ROI or facet), is refined by a parabola through the
three grid values around the minimum, and the ΔE00 is evaluated exactly (table
interpolation, no grid) at the final θ.

Uncertainty
-----------
For which films and tilts colour carries tilt information at all, per thickness:
docs/conditioning.md (``python -m pipelines run accuracy-conditioning``).
Colour is a weak function of tilt (0.03-0.3 ΔE00 per degree), so the 1-σ uncertainty is
reported per pixel: with image colour noise σ_n (ΔE00 per Lab component) and the local
sensitivity J = |dLab/dθ| (ΔE00 per degree, from the model at the solution),
σ_θ = σ_n / J, capped at the search range. With a prior N(θ_p, σ_p²) (the joint mode uses
the tilt of the facet's plane fitted on the height map), the objective is
ΔE²/σ_n² + (θ − θ_p)²/σ_p², σ_θ = (J²/σ_n² + 1/σ_p²)^(-1/2), and the colour's share of the
information ``J²/σ_n² / (J²/σ_n² + 1/σ_p²)`` says which information dominated.

References
----------
.. [1] N. Nagata, M. Kamei, K. Takahashi, K. Tobitani, T. Akagi, S. Yamamura, "Simulation
   Technology for Titanium Oxide Layer Interference Color", Technical Report (the seed paper),
   §3.3.3 (3) (the normal of least ΔE at the ROI's thickness).
.. [2] G. Sharma, W. Wu, E. N. Dalal, "The CIEDE2000 color-difference formula: implementation
   notes, supplementary test data, and mathematical observations", Color Res. Appl. 30 (2005)
   21-30, doi:10.1002/col.20070.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from ..core.threads import chunk_starts, chunks, thread_map
from .options import TiltOptions
from .search import coarse_to_fine, refine

__all__ = ["TiltInversion", "TiltRows", "invert_tilt", "invert_tilt_into",
           "model_lab_rows", "seed_tilts"]

#: Pixels in flight in the search (bounded temporaries; split over the threads).
CHUNK_PX = 65536


@dataclass
class TiltInversion:
    """Per-pixel results (1-D, one entry per inverted pixel).

    Attributes
    ----------
    tilt_deg, tilt_sigma_deg, delta_e : ndarray of float32
        Tilt, its 1-σ uncertainty, and the exact ΔE00 at the chosen tilt.
    colour_weight : ndarray of float32
        Share of the tilt information that came from colour (1 without a prior).
    sensitivity_de_per_deg : ndarray of float32
        J, ΔE00 per degree at the solution.
    """

    tilt_deg: np.ndarray
    tilt_sigma_deg: np.ndarray
    delta_e: np.ndarray
    colour_weight: np.ndarray
    sensitivity_de_per_deg: np.ndarray


@dataclass
class PixelEstimates:
    """Per-pixel thickness and tilt (maps H×W, float32, NaN where not estimated).

    Attributes
    ----------
    thickness_nm, tilt_deg, tilt_sigma_deg, delta_e, colour_weight : ndarray
        Thickness; tilt, its 1-σ uncertainty; the ΔE00 at the solution; the share of the
        tilt information that came from colour.
    thickness_group : ndarray of int (H, W)
        Which pixels share one thickness estimate (ROIs in the seed mode, facets in the
        joint mode).
    """

    thickness_nm: np.ndarray
    tilt_deg: np.ndarray
    tilt_sigma_deg: np.ndarray
    delta_e: np.ndarray
    colour_weight: np.ndarray
    thickness_group: np.ndarray

    @classmethod
    def empty(cls, shape, *, group=None) -> "PixelEstimates":
        """NaN maps of ``shape``, and ``group`` (default zeros) as ``thickness_group``."""
        nan = [np.full(shape, np.nan, np.float32) for _ in range(5)]
        return cls(*nan, np.zeros(shape, np.int32) if group is None else group)


def tilt_grid(max_tilt_deg, step_deg) -> np.ndarray:
    """The uniform tilt grid :func:`invert_tilt` needs (its parabola refinement and
    sensitivities use one step): equal steps of at most ``step_deg`` from 0 to
    ``max_tilt_deg``, at least 3 nodes.

    >>> g = tilt_grid(26.57, 0.5)
    >>> g.size, round(float(g[1]), 4), float(g[-1])
    (55, 0.492, 26.57)
    """
    n_steps = max(2, math.ceil(max_tilt_deg / step_deg - 1e-9))
    return np.linspace(0.0, max_tilt_deg, n_steps + 1)


@dataclass
class TiltRows:
    """What the pixels of one row (a ROI in the seed mode, a facet in the joint mode) share.

    Attributes
    ----------
    lab : ndarray of float32, shape (R, K, 3)
        Model Lab of each row's thickness on the tilt grid (:func:`model_lab_rows`).
    thickness_nm : ndarray, shape (R,)
    noise_de : ndarray, shape (R,), or float
        Colour error per Lab component (ΔE units): the image noise, or per row the
        calibrated error of the colour term (noise, thickness uncertainty, misfit).
    prior_deg, prior_sigma_deg : ndarray, shape (R,), optional
        A Gaussian prior on the tilt (the joint mode's facet plane).
    """

    lab: np.ndarray
    thickness_nm: np.ndarray
    noise_de: object
    prior_deg: np.ndarray | None = None
    prior_sigma_deg: np.ndarray | None = None

    @property
    def noise(self) -> np.ndarray:
        """Per row, finite and at least 1e-3 (1 where not finite)."""
        n = np.broadcast_to(np.asarray(self.noise_de, dtype=np.float64), (self.lab.shape[0],))
        return np.where(np.isfinite(n), np.maximum(n, 1e-3), 1.0)


def model_lab_rows(model, thickness_nm, theta_grid_deg):
    """Model Lab for each thickness (rows) over a θ grid: shape (R, K, 3), float32."""
    d = np.asarray(thickness_nm, dtype=np.float64)
    th = np.asarray(theta_grid_deg)[None, :]
    out = np.empty((d.size, th.size, 3), np.float32)

    def rows(ab):   # a chunk of rows: bounded temporaries, on the threads
        out[ab[0]:ab[1]] = model.lab(th, d[ab[0]:ab[1], None])

    thread_map(rows, chunks(d.size, (1 << 16) // max(1, th.size)))
    return out


def _sensitivity(model, rows_lab, step):
    """ΔE per degree of each row at each grid node (central differences; one-sided at the
    ends)."""
    rl = rows_lab.astype(np.float32, copy=False)
    sens = np.empty(rl.shape[:2], np.float32)

    def rows(ab):   # a chunk of rows on the threads
        r, s = rl[ab[0]:ab[1]], sens[ab[0]:ab[1]]
        s[:, 1:-1] = model.difference(r[:, 2:], r[:, :-2]) / (2 * step)
        s[:, 0] = model.difference(r[:, 1], r[:, 0]) / step
        s[:, -1] = model.difference(r[:, -1], r[:, -2]) / step

    thread_map(rows, chunks(rl.shape[0], (1 << 16) // max(1, rl.shape[1])))
    return sens


def _invert_chunk(lab_px, ri, rows, sens, th, model, stride):
    """The search for one chunk of pixels: tilt, σ, colour weight, J and ΔE at the grid."""
    noise = rows.noise[ri]
    prior = rows.prior_deg is not None
    if prior:
        p_deg, p_sd = rows.prior_deg[ri], rows.prior_sigma_deg[ri]

    # the rows' model Lab as one (R·K, 3) table: a flat take of row·K + node gathers the
    # same values as lab[row, node], ~2.5× faster (a view where the rows are contiguous)
    table, first = rows.lab.reshape(-1, 3), (ri * rows.lab.shape[1])[:, None]

    def objective(nodes):  # q on grid nodes (m, w) of each pixel
        de = model.difference(np.take(table, first + nodes, axis=0), lab_px[:, None, :])
        q = (de.astype(np.float64) / noise[:, None]) ** 2
        if prior:
            q += ((th[nodes] - p_deg[:, None]) / p_sd[:, None]) ** 2
        return q

    m = refine(coarse_to_fine(objective, th.size, ri.size, stride=stride), th.size)
    t = th[m.node] + m.offset * (th[1] - th[0])
    j = sens[ri, m.node]
    info_c = (j / noise) ** 2
    if prior:
        info_p = 1.0 / p_sd ** 2
        sig, w = 1.0 / np.sqrt(info_c + info_p), info_c / (info_c + info_p)
    else:
        with np.errstate(divide="ignore"):
            sig = np.where(j > 0, noise / j, np.inf)
        w = np.ones_like(sig)
    return t, np.minimum(sig, th[-1] - th[0]), w, j


def invert_tilt(lab_px, row_index, rows: TiltRows, theta_grid_deg, model,
                options: TiltOptions) -> TiltInversion:
    """Tilt of least ΔE (or MAP with a prior) for each pixel.

    Parameters
    ----------
    lab_px : ndarray, shape (n, 3)
        The pixels' Lab.
    row_index : ndarray of int, shape (n,)
        The row of each pixel.
    rows : TiltRows
        Per row: model Lab on the grid, thickness, colour error, prior.
    theta_grid_deg : ndarray, shape (K,)
        Uniform tilt grid from 0 to θ_max (:func:`tilt_grid`).
    model : FilmColourModel
        For the exact ΔE at the solution (table interpolation at the off-grid tilt) and the
        colour difference of the search.
    options : TiltOptions
        ``coarse_stride``: the objective on every ``coarse_stride``-th grid node, then on
        every node within ±``coarse_stride`` of the coarse minimum (≈ 2.2× fewer ΔE at 4;
        1 = every node). The colour changes by 0.03-0.3 ΔE00 per degree, so the objective's
        basins are many degrees wide and the coarse grid finds the basin of the minimum.

    Returns
    -------
    TiltInversion
    """
    lab_px = np.asarray(lab_px, dtype=np.float32)
    n = lab_px.shape[0]
    out = {k: np.empty(n, np.float32) for k in ("t", "s", "w", "j", "e")}
    search = _search(rows, theta_grid_deg, model, options)

    def chunk(ab):
        a, b = ab
        out["t"][a:b], out["s"][a:b], out["w"][a:b], out["j"][a:b], out["e"][a:b] = search(
            lab_px[a:b], row_index[a:b])

    thread_map(chunk, chunk_starts(n, CHUNK_PX))
    return TiltInversion(out["t"], out["s"], out["e"], out["w"], out["j"])


def invert_tilt_into(out: PixelEstimates, flat, lab, rows: TiltRows, theta_grid_deg, model,
                     options: TiltOptions) -> None:
    """:func:`invert_tilt` of the pixels at the flat indices ``flat`` of the image ``lab``
    (H, W, 3), each in the row ``out.thickness_group`` gives it, stored into the maps of
    ``out`` with the row's thickness: the same numbers, gathered and stored chunk by chunk
    (the memory of a chunk beside the maps, not of every pixel's Lab and results: ~60 bytes
    a pixel less; docs/benchmarks.md).

    Parameters
    ----------
    out : PixelEstimates
        Maps (H, W) to fill; ``thickness_group`` holds each pixel's row.
    flat : ndarray of int, shape (n,)
        The pixels (flat indices into H × W).
    lab : ndarray, shape (H, W, 3)
    rows, theta_grid_deg, model, options
        As :func:`invert_tilt`.
    """
    lab_flat, group = lab.reshape(-1, 3), out.thickness_group.reshape(-1)
    maps = [m.reshape(-1) for m in (out.tilt_deg, out.tilt_sigma_deg, out.colour_weight)]
    de_map, d_map = out.delta_e.reshape(-1), out.thickness_nm.reshape(-1)
    d_rows = np.asarray(rows.thickness_nm).astype(np.float32)     # as the map stores it
    search = _search(rows, theta_grid_deg, model, options)

    def chunk(ab):
        px = flat[ab[0]:ab[1]]
        ri = group[px]
        t, s, w, _, e = search(np.asarray(lab_flat[px], dtype=np.float32), ri)
        for m, v in zip(maps, (t, s, w)):
            m[px] = v
        de_map[px], d_map[px] = e, d_rows[ri]

    thread_map(chunk, chunk_starts(flat.size, CHUNK_PX))


def _search(rows: TiltRows, theta_grid_deg, model, options: TiltOptions):
    """``search(lab_px, row_index) -> (tilt, σ, colour weight, J, ΔE)`` of a chunk of pixels:
    the search of :func:`invert_tilt` with what every chunk shares computed once."""
    th = np.asarray(theta_grid_deg, dtype=np.float64)
    sens = _sensitivity(model, rows.lab, th[1] - th[0])
    stride = max(1, min(int(options.coarse_stride), (th.size - 1) // 2))
    d_rows = np.asarray(rows.thickness_nm, dtype=np.float64)

    def search(lab_px, ri):
        t, s, w, j = _invert_chunk(lab_px, ri, rows, sens, th, model, stride)
        t = t.astype(np.float32)     # the tilt as stored, and the ΔE of that tilt
        # the exact ΔE at the solution (table interpolation at the off-grid tilt)
        return t, s, w, j, model.delta_e(lab_px, t, d_rows[ri])
    return search


def seed_tilts(colour, roi, model, theta_grid_deg, options: TiltOptions) -> PixelEstimates:
    """The seed's step 3 (§3.3.3): each ROI's thickness for its pixels, and per pixel the
    tilt of least ΔE at that thickness (:func:`invert_tilt`, no prior).

    Parameters
    ----------
    colour : ColourImage
    roi : RoiFit
    model : FilmColourModel
        At the scene's exposure.
    theta_grid_deg : ndarray
        From :func:`tilt_grid`.
    options : TiltOptions
    """
    shape = colour.lab.shape[:2]
    roi_index = roi.index_map(shape)
    out = PixelEstimates.empty(shape, group=roi_index)
    flat = np.flatnonzero(~colour.mask.mask & np.isfinite(roi.thickness_nm[roi_index]))
    rows_d = np.where(np.isfinite(roi.thickness_nm), roi.thickness_nm,
                      model.thickness_range_nm[0])
    rows = TiltRows(model_lab_rows(model, rows_d, theta_grid_deg), rows_d, colour.noise_de)
    invert_tilt_into(out, flat, colour.lab, rows, theta_grid_deg, model, options)
    return out
