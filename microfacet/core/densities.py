"""Densities on grids: histograms, mixture densities per cell, the NDF per steradian, and
Wasserstein distances. Shared by the analysis (the pdf CSVs), the report and the sweeps.

Histograms of per-pixel tilts count projected area (one pixel = one unit of projected area),
so their density already *is* the tilt density ``p(θ)`` that
:meth:`~microfacet.core.distributions.NDFMixture.tilt_pdf` models — the ``sin θ`` of the
solid-angle element is inside ``p(θ)``; do not divide the histogram by ``sin θ`` to compare it
with the fit. Dividing by ``2π sin θ cos θ`` (:func:`ndf_D_from_tilt_histogram`) gives the
NDF D per steradian.

Distances: the 1-D earth mover's distance, between samples (:func:`wasserstein1`) or between
densities on a grid (:func:`wasserstein1_pdf`).
"""

from __future__ import annotations

import math

import numpy as np

from .distributions import NDFMixture, ThicknessMixture
from .lazy import load

special = load("scipy.special")
stats = load("scipy.stats")
integrate = load("scipy.integrate")

__all__ = ["cell_edges", "histogram_density", "ndf_D_from_tilt_histogram", "pdf_table",
           "wasserstein1"]

_DEG = math.pi / 180.0

def histogram_density(values, *, bins, range=None):
    """Histogram density of the finite ``values``, normalised over ``range``.

    Parameters
    ----------
    values : array_like, any shape
        Samples (e.g. thickness in nm, tilt in degrees); NaN is ignored.
    bins : int or array_like (B + 1,)
        Number of equal bins over ``range`` or the bin edges (as :func:`numpy.histogram`).
    range : (float, float), optional
        ``(low, high)``; values outside are left out and the density integrates to 1 over
        the bins (``Σ density · width = 1``).

    Returns
    -------
    centres : ndarray (B,)
        Bin centres.
    density : ndarray (B,)
        Density per unit of ``values``. For per-pixel tilts this is the projected-area tilt
        density ``p(θ)`` per degree that :meth:`NDFMixture.tilt_pdf` models (do not divide
        by sin θ to compare; see :func:`ndf_D_from_tilt_histogram` for D).

    Raises
    ------
    ValueError
        No finite values inside the range.

    Examples
    --------
    >>> c, d = histogram_density([0.5, 1.5, 1.6, 2.5], bins=3, range=(0, 3))
    >>> c.tolist(), d.tolist()
    ([0.5, 1.5, 2.5], [0.25, 0.5, 0.25])
    """
    v = np.asarray(values, dtype=np.float64).ravel()
    v = v[np.isfinite(v)]
    counts, edges = np.histogram(v, bins=bins, range=range)
    total = counts.sum()
    if total == 0:
        raise ValueError("values: no finite values inside the histogram range")
    width = np.diff(edges)
    return 0.5 * (edges[:-1] + edges[1:]), counts / (total * width)


def cell_edges(grid):
    """``(grid, edges)``: cell edges half-way between the centres ``grid`` (the outer cells
    symmetric about the first and last point).

    >>> cell_edges([1.0, 2.0, 4.0])[1].tolist()
    [0.5, 1.5, 3.0, 5.0]
    """
    g = np.asarray(grid, dtype=np.float64)
    if g.ndim != 1 or g.size < 2 or not np.all(np.isfinite(g)) or np.any(np.diff(g) <= 0):
        raise ValueError("grid: expected a strictly increasing 1-D array of >= 2 finite values")
    mid = 0.5 * (g[1:] + g[:-1])
    edges = np.concatenate([[g[0] - (mid[0] - g[0])], mid, [g[-1] + (g[-1] - mid[-1])]])
    return g, edges


def mixture_cdf(mixture, x):
    """CDF of a :class:`ThicknessMixture` (x in nm) or :class:`NDFMixture` (tilt x in degrees)."""
    x = np.asarray(x, dtype=np.float64)
    if isinstance(mixture, ThicknessMixture):
        z = (x[:, None] - mixture.means_nm) / mixture.sds_nm
        return np.sum(mixture.weights * special.ndtr(z), axis=1)
    if isinstance(mixture, NDFMixture):
        t = np.tan(np.clip(x, 0.0, 90.0) * _DEG)
        with np.errstate(over="ignore"):
            c = 1.0 - np.exp(-0.5 * (t * t)[:, None] / mixture.slope_sd ** 2)
        c = np.where(x[:, None] >= 90.0, 1.0, c)
        return np.sum(mixture.weights * c, axis=1)
    raise ValueError(f"mixture: expected a ThicknessMixture or NDFMixture, got "
                     f"{type(mixture).__name__}")


def pdf_table(values, mixture, *, grid):
    """Histogram density and mixture density on one grid, for the pdf CSVs.

    The columns are those of ``thickness_nm,density,mixture_density`` (thickness) and
    ``tilt_deg,density,mixture_density`` (tilt). The grid points are cell centres; cell
    edges lie half-way between neighbours (the outer cells are symmetric about the first
    and last point). Both densities integrate to 1 over the cells,
    ``Σ density_i · width_i = 1``: the histogram counts only the values inside the cells,
    and the mixture column is the mixture's probability in each cell divided by the cell
    width (the cell average, computed exactly from the mixture CDF), **renormalised over
    the grid range** (the mixture's mass outside the grid is dropped). For tilts, the
    histogram of per-pixel tilts is compared with :meth:`NDFMixture.tilt_pdf` directly —
    both are projected-area tilt densities; no sin θ division.

    Parameters
    ----------
    values : array_like, any shape
        Samples (thickness in nm or tilt in degrees); NaN is ignored.
    mixture : ThicknessMixture or NDFMixture
        The fitted mixture (e.g. ``MixtureFit.mixture``).
    grid : array_like (N,)
        Strictly increasing cell centres (nm or degrees).

    Returns
    -------
    ndarray (N, 3)
        Columns: grid, histogram density, mixture density (per nm or per degree).

    Raises
    ------
    ValueError
        Bad grid, no values inside the grid, or no mixture mass inside it.

    Examples
    --------
    >>> g = ThicknessMixture([(1.0, 130.0, 3.0)])
    >>> rng = np.random.default_rng(0)
    >>> grid = np.arange(110.0, 150.0, 0.5) + 0.25
    >>> t = pdf_table(rng.normal(130, 3, 5000), g, grid=grid)
    >>> t.shape, round(float(np.sum(t[:, 2]) * 0.5), 6)
    ((80, 3), 1.0)
    """
    g, edges = cell_edges(grid)
    _, hist = histogram_density(values, bins=edges)
    cdf = mixture_cdf(mixture, edges)
    mass = np.diff(cdf)
    total = float(cdf[-1] - cdf[0])
    if not total > 0:
        raise ValueError("grid: the mixture has no probability inside the grid range")
    mix = mass / (total * np.diff(edges))
    return np.column_stack([g, hist, mix])


def ndf_D_from_tilt_histogram(centres_deg, density):
    """The NDF D per steradian from a tilt density per degree (projected-area normalised).

    ``D(θ) = p(θ) / (2π sin θ cos θ) · (180/π)``, so that ``∫ D cos θ dω = 1`` if
    ``∫ p dθ = 1``. For Gaussian-slope lobes this is :meth:`NDFMixture.D`.

    Parameters
    ----------
    centres_deg : array_like (N,)
        Tilt of the histogram bin centres, degrees.
    density : array_like (N,)
        Tilt density per degree (e.g. from :func:`histogram_density`).

    Returns
    -------
    ndarray (N,)
        D per steradian; NaN where θ ≤ 0 or θ ≥ 90 (the Jacobian vanishes).

    Examples
    --------
    >>> f = NDFMixture([(1.0, 5.0)])
    >>> th = np.array([0.0, 2.0, 6.0])
    >>> D = ndf_D_from_tilt_histogram(th, f.tilt_pdf(th))
    >>> bool(np.isnan(D[0])), bool(np.allclose(D[1:], f.D(th[1:])))
    (True, True)
    """
    th = np.asarray(centres_deg, dtype=np.float64)
    p = np.asarray(density, dtype=np.float64)
    if th.shape != p.shape:
        raise ValueError(f"density: shape {p.shape} does not match centres_deg {th.shape}")
    r = th * _DEG
    jac = 2.0 * math.pi * np.sin(r) * np.cos(r)
    ok = (th > 0) & (th < 90)
    with np.errstate(divide="ignore", invalid="ignore"):
        d = p / np.where(ok, jac, 1.0) / _DEG
    return np.where(ok, d, np.nan)


# ------------------------------------------------------------------------- distances


def _finite_1d(x, name):
    v = np.asarray(x, dtype=np.float64).ravel()
    v = v[~np.isnan(v)]
    if v.size == 0:
        raise ValueError(f"{name}: no finite values")
    if np.isinf(v).any():
        raise ValueError(f"{name}: contains infinite values")
    return v


def wasserstein1(samples_a, samples_b):
    """1-D Wasserstein-1 (earth mover's) distance between two samples (NaN ignored).

    Parameters
    ----------
    samples_a, samples_b : array_like, any shape
        Samples in the same unit; the result is in that unit.

    Returns
    -------
    float

    Examples
    --------
    >>> wasserstein1([1.0, 2.0, 3.0], [3.0, 4.0, 5.0])
    2.0
    """
    return float(stats.wasserstein_distance(_finite_1d(samples_a, "samples_a"),
                                      _finite_1d(samples_b, "samples_b")))


def wasserstein1_pdf(grid, pdf_a, pdf_b):
    """Wasserstein-1 distance ``∫ |F_a − F_b| dx`` between two densities on one grid.

    Each density is renormalised to unit mass over the grid (trapezoid rule) and its CDF
    is the cumulative trapezoid integral; the distance is then integrated by the
    trapezoid rule. Accurate to O(Δx²) for smooth densities.

    Parameters
    ----------
    grid : array_like (N,)
        Strictly increasing grid (e.g. nm or degrees).
    pdf_a, pdf_b : array_like (N,)
        Non-negative densities on ``grid`` (any normalisation).

    Returns
    -------
    float
        In the unit of ``grid``.

    Examples
    --------
    >>> x = np.linspace(0, 100, 2001)
    >>> a = ThicknessMixture([(1, 40, 3)]).pdf(x)
    >>> b = ThicknessMixture([(1, 45, 3)]).pdf(x)
    >>> round(wasserstein1_pdf(x, a, b), 3)
    5.0
    """
    g, _ = cell_edges(grid)
    out = []
    for name, p in (("pdf_a", pdf_a), ("pdf_b", pdf_b)):
        p = np.asarray(p, dtype=np.float64)
        if p.shape != g.shape:
            raise ValueError(f"{name}: shape {p.shape} does not match grid {g.shape}")
        if not np.all(np.isfinite(p)) or np.any(p < 0):
            raise ValueError(f"{name}: must be finite and >= 0")
        F = integrate.cumulative_trapezoid(p, g, initial=0.0)
        if not F[-1] > 0:
            raise ValueError(f"{name}: has no mass on the grid")
        out.append(F / F[-1])
    return float(np.trapezoid(np.abs(out[0] - out[1]), g))
