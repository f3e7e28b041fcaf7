"""Comparing a predicted angular map with a measured one (seed §2.5 Table 2, §3.5 Fig. 20),
and fitting a global exposure and eq. 6's cosine-lobe exponent to it.

:func:`delta_e_map` gives the CIEDE2000 difference per cell; :func:`mean_delta_e` the mean
over all cells and the mean outside the **specular region**
``|θ_view − θ_light| ≤ specular_halfwidth_deg`` (default 10°, a band about the mirror
direction; the half-vector tilt is then ≤ 5°). The seed's half-vector evaluation excluded
that region; its microfacet evaluation used all cells. Cells where either map is NaN (masked
measurements) are left out of both means and counted.

References
----------
.. [1] N. Nagata, M. Kamei, K. Takahashi, K. Tobitani, T. Akagi, S. Yamamura, "Simulation
   Technology for Titanium Oxide Layer Interference Color", Technical Report (the seed paper),
   §2.5 Table 2 and §3.5 Fig. 20 (mean ΔE against measured maps).
.. [2] G. Sharma, W. Wu, E. N. Dalal, "The CIEDE2000 color-difference formula: implementation
   notes, supplementary test data, and mathematical observations", Color Res. Appl. 30 (2005)
   21-30, doi:10.1002/col.20070.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from ..colour.colorimetry import spectral_weights, xyz_to_lab
from ..colour.difference import delta_e_2000
from ..core.angular import AngularMap
from ..core.lazy import load
from ..optics.constants import DEFAULT_FILM, DEFAULT_SUBSTRATE
from .angular import positive
from .eq6 import Eq6Kernel

optimize = load("scipy.optimize")

__all__ = ["Eq6Fit", "delta_e_map", "fit_eq6", "fit_exposure", "mean_delta_e"]


def specular_mask(theta_light_deg, theta_view_deg, *, halfwidth_deg=10.0):
    """Cells of the specular region ``|θ_view − θ_light| ≤ halfwidth_deg``, shape (L, V).

    Examples
    --------
    >>> specular_mask([0, 40], [0, 45, 60], halfwidth_deg=10).tolist()
    [[True, False, False], [False, True, False]]
    """
    h = float(halfwidth_deg)
    if not (math.isfinite(h) and h >= 0):
        raise ValueError(f"halfwidth_deg: must be finite and >= 0, got {halfwidth_deg!r}")
    tl = np.asarray(theta_light_deg, dtype=np.float64).ravel()
    tv = np.asarray(theta_view_deg, dtype=np.float64).ravel()
    return np.abs(tv[None, :] - tl[:, None]) <= h + 1e-9


def _same_grid(a: AngularMap, b: AngularMap):
    for name in ("theta_light_deg", "theta_view_deg"):
        x, y = getattr(a, name), getattr(b, name)
        if x.shape != y.shape or not np.allclose(x, y, atol=1e-6):
            raise ValueError(f"{name}: the two maps are on different angle grids")


def delta_e_map(predicted: AngularMap, measured: AngularMap):
    """CIEDE2000 difference per cell between two maps on the same angle grid.

    Returns
    -------
    ndarray (L, V) float64
        NaN where either map is NaN.

    Examples
    --------
    >>> m = AngularMap(np.array([0.0]), np.array([0.0, 10.0]), np.full((1, 2, 3), 50.0))
    >>> delta_e_map(m, m).tolist()
    [[0.0, 0.0]]
    """
    _same_grid(predicted, measured)
    return delta_e_2000(np.asarray(predicted.lab, np.float64),
                              np.asarray(measured.lab, np.float64))


def mean_delta_e(delta_e, theta_light_deg, theta_view_deg, *, specular_halfwidth_deg=10.0):
    """The seed's two evaluations: mean ΔE over all cells and outside the specular region.

    Parameters
    ----------
    delta_e : array_like (L, V)
        From :func:`delta_e_map`; NaN cells are left out.
    specular_halfwidth_deg : float
        Specular region ``|θ_view − θ_light| ≤`` this.

    Returns
    -------
    dict
        ``mean`` (all cells), ``mean_excluding_specular``, ``median``, ``max``,
        ``n_cells``, ``n_cells_excluding_specular``, ``specular_halfwidth_deg``
        (means are NaN when no cell is left).
    """
    de = np.asarray(delta_e, dtype=np.float64)
    spec = specular_mask(theta_light_deg, theta_view_deg, halfwidth_deg=specular_halfwidth_deg)
    if de.shape != spec.shape:
        raise ValueError(f"delta_e: shape {de.shape} does not match the angle grids "
                         f"{spec.shape}")
    ok = np.isfinite(de)
    diff = ok & ~spec

    def _mean(mask):
        return float(np.mean(de[mask])) if np.any(mask) else float("nan")

    return {"mean": _mean(ok), "mean_excluding_specular": _mean(diff),
            "median": float(np.median(de[ok])) if np.any(ok) else float("nan"),
            "max": float(np.max(de[ok])) if np.any(ok) else float("nan"),
            "n_cells": int(ok.sum()), "n_cells_excluding_specular": int(diff.sum()),
            "specular_halfwidth_deg": float(specular_halfwidth_deg)}


def _mean_de(xyz, white, ref_lab, mask):
    lab = xyz_to_lab(xyz[mask], white=white)
    return float(np.mean(delta_e_2000(lab, ref_lab)))


def fit_exposure(xyz, measured_lab, *, white, mask=None, bounds=(1e-3, 1e3)):
    """Global exposure minimising the mean CIEDE2000 difference to a measured map.

    Parameters
    ----------
    xyz : array_like (..., 3)
        Model XYZ at exposure 1 (scale of ``white``).
    measured_lab : array_like (..., 3)
        Same shape; NaN cells are ignored.
    white : array_like (3,)
        Perfect reflector XYZ the Lab values are relative to.
    mask : array_like of bool (...,), optional
        Cells to use (default all finite).
    bounds : (float, float)
        Search range of the exposure (log-uniform coarse scan, then Brent refinement).

    Returns
    -------
    exposure : float
    mean_delta_e : float
    """
    xyz = np.asarray(xyz, dtype=np.float64)
    ref = np.asarray(measured_lab, dtype=np.float64)
    if xyz.shape != ref.shape:
        raise ValueError(f"measured_lab: shape {ref.shape} does not match xyz {xyz.shape}")
    ok = np.all(np.isfinite(ref), axis=-1) & np.all(np.isfinite(xyz), axis=-1)
    if mask is not None:
        ok &= np.asarray(mask, dtype=bool)
    if not np.any(ok):
        raise ValueError("measured_lab: no finite cells to fit")
    lo, hi = (math.log(positive(b, "bounds")) for b in bounds)
    if not lo < hi:
        raise ValueError("bounds: need low < high")
    white = np.asarray(white, dtype=np.float64)
    x, r = xyz[ok], ref[ok]

    def cost(le):
        return _mean_de(math.exp(le) * x, white, r, slice(None))

    grid = np.linspace(lo, hi, 33)
    costs = [cost(g) for g in grid]
    k = int(np.argmin(costs))
    a, b = grid[max(k - 1, 0)], grid[min(k + 1, grid.size - 1)]
    res = optimize.minimize_scalar(cost, bounds=(a, b), method="bounded", options={"xatol": 1e-5})
    best = (res.x, res.fun) if res.fun <= costs[k] else (grid[k], costs[k])
    return math.exp(best[0]), float(best[1])


@dataclass
class Eq6Fit:
    """Result of :func:`fit_eq6`: exponent, exposure, the mean ΔE reached, the scan."""

    n: float
    exposure: float
    mean_delta_e: float
    scan: list


def fit_eq6(measured: AngularMap, *, thickness, ndf, fit_exposure_too=True, exposure=1.0,
            n_bounds=(0.5, 5000.0), region="all", specular_halfwidth_deg=10.0,
            wavelength_nm=None, film=DEFAULT_FILM, substrate=DEFAULT_SUBSTRATE,
            n_ambient=1.0, theta_m_step_deg=0.5) -> Eq6Fit:
    """Fit eq. 6's cosine-lobe exponent n (and a global exposure) by least mean ΔE00.

    The eq. 6 kernel (:class:`microfacet.forward.brdf.Eq6Kernel`) is built once on the measured
    grid; each trial n is one sparse weighted sum onto the film table's XYZ. n is scanned
    on a log grid over ``n_bounds`` (with the best exposure per n when
    ``fit_exposure_too``), then refined by Brent's method between the scan neighbours.

    Parameters
    ----------
    measured : AngularMap
        The measured map (its Lab; NaN cells ignored). Its illuminant and observer are
        used for the model colours.
    thickness, ndf
        As :func:`simulate_map`.
    fit_exposure_too : bool
        Also fit a global exposure; otherwise ``exposure`` is fixed.
    region : {"all", "diffuse"}
        Fit on all cells or outside the specular region.

    Returns
    -------
    Eq6Fit

    Seed
    ----
    §3.4: n is "a parameter of the cosine lobe model"; §3.5 compares by mean ΔE.
    """
    if region not in ("all", "diffuse"):
        raise ValueError(f"region: expected 'all' or 'diffuse', got {region!r}")
    lo, hi = (math.log(positive(b, "n_bounds")) for b in n_bounds)
    if not lo < hi:
        raise ValueError("n_bounds: need low < high")
    exposure = positive(exposure, "exposure")
    tl, tv = measured.theta_light_deg, measured.theta_view_deg
    kern = Eq6Kernel.build(tl[:, None], tv[None, :], thickness=thickness, ndf=ndf,
                                wavelength_nm=wavelength_nm, film=film, substrate=substrate,
                                n_ambient=n_ambient, theta_m_step_deg=theta_m_step_deg)
    tx = kern.film.xyz(illuminant=measured.illuminant, observer=measured.observer)
    white = spectral_weights(kern.film.wavelength_nm, illuminant=measured.illuminant,
                                   observer=measured.observer).sum(axis=0)
    ref = np.asarray(measured.lab, np.float64)
    mask = np.all(np.isfinite(ref), axis=-1)
    if region == "diffuse":
        mask &= ~specular_mask(tl, tv, halfwidth_deg=specular_halfwidth_deg)
    if not np.any(mask):
        raise ValueError("measured: no finite cells in the fitted region")
    scan = []

    def evaluate(ln):
        xyz = kern.xyz(math.exp(ln), table_xyz=tx)
        if fit_exposure_too:
            e, c = fit_exposure(xyz, ref, white=white, mask=mask)
        else:
            e, c = exposure, _mean_de(exposure * xyz[mask], white, ref[mask], slice(None))
        scan.append((math.exp(ln), e, c))
        return c, e

    grid = np.linspace(lo, hi, 25)
    res = [evaluate(g) for g in grid]
    k = int(np.argmin([r[0] for r in res]))
    a, b = grid[max(k - 1, 0)], grid[min(k + 1, grid.size - 1)]
    opt = optimize.minimize_scalar(lambda ln: evaluate(ln)[0], bounds=(a, b), method="bounded",
                          options={"xatol": 1e-3})
    best_c, best_e = evaluate(opt.x)
    best_ln = opt.x
    if res[k][0] < best_c:
        best_c, best_e, best_ln = res[k][0], res[k][1], grid[k]
    return Eq6Fit(math.exp(best_ln), float(best_e), float(best_c), scan)


