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
docs/conditioning.md (``python pipelines/conditioning.py``).
Colour is a weak function of tilt (0.03-0.3 ΔE00 per degree), so the 1-σ uncertainty is
reported per pixel: with image colour noise σ_n (ΔE00 per Lab component) and the local
sensitivity J = |dLab/dθ| (ΔE00 per degree, from the model at the solution),
σ_θ = σ_n / J, capped at the search range. With a prior N(θ_p, σ_p²) (the joint mode uses
the tilt of the facet's plane fitted on the height map), the objective is
ΔE²/σ_n² + (θ − θ_p)²/σ_p², σ_θ = (J²/σ_n² + 1/σ_p²)^(-1/2), and the colour's share of the
information ``J²/σ_n² / (J²/σ_n² + 1/σ_p²)`` says which information dominated.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from ..colour.colorimetry import xyz_to_lab
from ..colour.difference import delta_e
from .search import coarse_to_fine

__all__ = ["PixelEstimates", "TiltInversion", "invert_tilt", "model_lab_rows", "seed_tilts",
           "tilt_grid"]


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
    def empty(cls, shape) -> "PixelEstimates":
        nan = [np.full(shape, np.nan, np.float32) for _ in range(5)]
        return cls(*nan, np.zeros(shape, np.int32))

    def fill(self, yy, xx, inversion: "TiltInversion") -> None:
        """Store a :class:`TiltInversion` of the pixels ``(yy, xx)`` (or, with ``xx`` None,
        of the flat pixel indices ``yy``)."""
        for name in ("tilt_deg", "tilt_sigma_deg", "delta_e", "colour_weight"):
            target = getattr(self, name)
            if xx is None:
                target.reshape(-1)[yy] = getattr(inversion, name)
            else:
                target[yy, xx] = getattr(inversion, name)


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


def seed_tilts(colour, roi, table, *, theta_grid_deg, exposure, delta_e_method="CIEDE2000"
               ) -> PixelEstimates:
    """The seed's step 3 (§3.3.3): each ROI's thickness for its pixels, and per pixel the
    tilt of least ΔE00 at that thickness (:func:`invert_tilt`, no prior).

    Parameters
    ----------
    colour : ColourImage
    roi : RoiFit
    table : ColourTable
    theta_grid_deg : ndarray
        From :func:`tilt_grid`.
    exposure : float
    """
    shape = colour.lab.shape[:2]
    roi_index = roi.index_map(shape)
    out = PixelEstimates.empty(shape)
    out.thickness_group = roi_index
    usable = ~colour.mask.mask & np.isfinite(roi.thickness_nm[roi_index])
    yy, xx = np.nonzero(usable)
    rows_d = np.where(np.isfinite(roi.thickness_nm), roi.thickness_nm, table.thickness_nm[0])
    rows_lab = model_lab_rows(table, rows_d, theta_grid_deg, exposure=exposure)
    rix = roi_index[yy, xx]
    inv = invert_tilt(colour.lab[yy, xx], rows_lab, rix, theta_grid_deg, table=table,
                      thickness_px=rows_d[rix], exposure=exposure, noise_de=colour.noise_de,
                      delta_e_method=delta_e_method)
    out.thickness_nm[yy, xx] = rows_d[rix]
    out.fill(yy, xx, inv)
    return out


def model_lab_rows(table, thickness_nm, theta_grid_deg, *, exposure):
    """Model Lab for each thickness (rows) over a θ grid: shape (R, K, 3), float32."""
    d = np.asarray(thickness_nm, dtype=np.float64)
    th = np.asarray(theta_grid_deg)[None, :]
    white = table.white_xyz.astype(np.float32)
    out = np.empty((d.size, th.size, 3), np.float32)
    step = max(1, (1 << 16) // max(1, th.size))   # rows per chunk: bounded temporaries
    for a in range(0, d.size, step):
        xyz = table.xyz_at(th, d[a:a + step, None]) * exposure
        out[a:a + step] = xyz_to_lab(xyz.astype(np.float32), white=white)
    return out


def invert_tilt(lab_px, rows_lab, row_index, theta_grid_deg, *, table, thickness_px,
                exposure, noise_de, prior_deg=None, prior_sigma_deg=None,
                chunk=65536, delta_e_method="CIEDE2000", coarse_stride=4,
                by_row=False) -> TiltInversion:
    """Tilt of least ΔE00 (or MAP with a prior) for each pixel.

    Parameters
    ----------
    lab_px : ndarray, shape (n, 3)
        The pixels' Lab.
    rows_lab : ndarray, shape (R, K, 3)
        Model Lab of each row (ROI or facet thickness) on ``theta_grid_deg``
        (:func:`model_lab_rows`).
    row_index : ndarray of int, shape (n,)
        The row of each pixel.
    theta_grid_deg : ndarray, shape (K,)
        Uniform tilt grid from 0 to θ_max.
    table : ColourTable
        For the exact ΔE at the solution.
    thickness_px : ndarray, shape (n,)
        Thickness used for each pixel (its row's).
    exposure : float
    noise_de : float or ndarray, shape (n,)
        Colour error per Lab component, ΔE00 units: the image noise, or per pixel the
        calibrated error of the colour term (noise, thickness uncertainty, misfit).
    prior_deg, prior_sigma_deg : ndarray, shape (n,), optional
        Gaussian prior on the tilt (joint mode).
    delta_e_method : str
        Colour-difference formula of the search, the sensitivity and the reported ΔE
        (:func:`microfacet.colour.difference.delta_e`; default CIEDE2000).
    by_row : bool
        ``thickness_px``, ``noise_de``, ``prior_deg`` and ``prior_sigma_deg`` are given per
        row (shape (R,)) and gathered through ``row_index`` chunk by chunk: no per-pixel
        copies of values that pixels of one row share.
    coarse_stride : int
        Coarse-to-fine search: the objective on every ``coarse_stride``-th grid node, then on
        every node within ±``coarse_stride`` of the coarse minimum (≈ 2.2× fewer ΔE00 at 4;
        1 = every node). The colour changes by 0.03-0.3 ΔE00 per degree, so the objective's
        basins are many degrees wide and the coarse grid (2° at the default step) finds the
        basin of the minimum.

    Returns
    -------
    TiltInversion
    """
    def de_fn(a, b):
        return delta_e(a, b, method=delta_e_method)

    lab_px = np.asarray(lab_px, dtype=np.float32)
    th = np.asarray(theta_grid_deg, dtype=np.float64)
    step = th[1] - th[0]
    n, K = lab_px.shape[0], th.size
    out_t = np.empty(n, np.float32)
    out_s = np.empty(n, np.float32)
    out_w = np.empty(n, np.float32)
    out_j = np.empty(n, np.float32)
    out_e = np.empty(n, np.float32)
    white32 = table.white_xyz.astype(np.float32)
    size = rows_lab.shape[0] if by_row else n

    def per(v):  # per pixel of the chunk a:b, from per-pixel or per-row values
        return (lambda a, b: v[row_index[a:b]]) if by_row else (lambda a, b: v[a:b])

    noise_all = np.broadcast_to(np.asarray(noise_de, dtype=np.float64), (size,))
    noise_all = np.where(np.isfinite(noise_all), np.maximum(noise_all, 1e-3), 1.0)
    noise_of = per(noise_all)
    thickness_of = per(np.broadcast_to(np.asarray(thickness_px, dtype=np.float64), (size,)))
    if prior_deg is not None:
        prior_of, prior_sd_of = per(np.asarray(prior_deg)), per(np.asarray(prior_sigma_deg))
    stride = max(1, min(int(coarse_stride), (K - 1) // 2))
    # Sensitivity per row and grid node (central differences; one-sided at the ends).
    rl = rows_lab.astype(np.float32)
    sens_rows = np.empty(rl.shape[:2], np.float32)  # ΔE00 per degree
    sens_rows[:, 1:-1] = de_fn(rl[:, 2:], rl[:, :-2]) / (2 * step)
    sens_rows[:, 0] = de_fn(rl[:, 1], rl[:, 0]) / step
    sens_rows[:, -1] = de_fn(rl[:, -1], rl[:, -2]) / step
    for a in range(0, n, chunk):
        b = min(n, a + chunk)
        ri = row_index[a:b]
        noise = noise_of(a, b)
        if prior_deg is not None:
            p_deg, p_sd = prior_of(a, b), prior_sd_of(a, b)

        def objective(nodes):  # q on grid nodes (m, w) of each pixel
            de = de_fn(rows_lab[ri[:, None], nodes], lab_px[a:b, None, :])
            q = (de.astype(np.float64) / noise[:, None]) ** 2
            if prior_deg is not None:
                q += ((th[nodes] - p_deg[:, None]) / p_sd[:, None]) ** 2
            return q

        rr = np.arange(b - a)
        if stride > 1:
            nodes, qw, kw = coarse_to_fine(objective, K, b - a, stride=stride)
            k = nodes[rr, kw]
            y0, y1, y2 = qw[rr, kw - 1], qw[rr, kw], qw[rr, kw + 1]
            km = np.where((k > 0) & (k < K - 1), k, -1)  # a parabola only inside the grid
        else:
            q = objective(np.broadcast_to(np.arange(K), (b - a, K)))
            k = np.argmin(q, axis=1)
            km = np.clip(k, 1, K - 2)
            y0, y1, y2 = q[rr, km - 1], q[rr, km], q[rr, km + 1]
        den = y0 - 2 * y1 + y2
        with np.errstate(divide="ignore", invalid="ignore"):
            off = np.where(den > 0, 0.5 * (y0 - y2) / den, 0.0)
        off = np.where(k == km, np.clip(off, -1, 1), 0.0)  # no extrapolation at the ends
        t = th[k] + off * step
        j = sens_rows[ri, k]
        info_c = (j / noise) ** 2
        if prior_deg is not None:
            info_p = 1.0 / p_sd ** 2
            sig = 1.0 / np.sqrt(info_c + info_p)
            w = info_c / (info_c + info_p)
        else:
            with np.errstate(divide="ignore"):
                sig = np.where(j > 0, noise / j, np.inf)
            w = np.ones_like(sig)
        out_t[a:b] = t
        out_s[a:b] = np.minimum(sig, th[-1] - th[0])
        out_w[a:b] = w
        out_j[a:b] = j
        # the exact ΔE at the solution (table interpolation at the off-grid tilt), per chunk
        out_e[a:b] = de_fn(xyz_to_lab((table.xyz_at(out_t[a:b], thickness_of(a, b))
                                       * exposure).astype(np.float32), white=white32),
                           lab_px[a:b])
    return TiltInversion(out_t, out_s, out_e, out_w, out_j)
