"""Oxide thickness from a measured spectral reflectance (seed §2.5, Table 1 method).

The thickness d minimises the mean squared difference between the measured spectrum and
the thin-film model R(λ; θ, d). Interference colours repeat with order, so the residual
has several local minima: a local optimiser alone lands in whichever is nearest its
start. We therefore scan a global thickness grid fine enough to resolve every minimum
(the minima are about λ/(4n) ≈ 40 nm apart at the shortest wavelengths; a 1 nm grid
samples each several dozen times), then refine the best few minima with a bounded scalar
search, and report the best and the runner-up (the best *other* local minimum), so a
user sees how ambiguous the answer is.

The absolute level of a measured spectrum is rarely right to better than 10-20 % (the
reference mirror's own reflectance, lamp drift between reference and sample, the
collection of a microscope objective on a tilted or rough facet), while the thickness is
carried by where the fringes are. So one multiplicative scale is fitted by default
(``fit_scale=True``: a spectrum measured at 0.8 of its true level still returns its
thickness); with ``fit_scale=False`` the level is trusted, and a warning is logged when a
free scale would have fitted far better (the data look scaled).

References
----------
.. [1] N. Nagata, M. Kamei, K. Takahashi, K. Tobitani, T. Akagi, S. Yamamura, "Simulation
   Technology for Titanium Oxide Layer Interference Color", Technical Report (the seed paper),
   §2.5 (the thickness of a sample from its spectrum, Table 1).
.. [2] M. Born, E. Wolf, *Principles of Optics*, 7th ed., Cambridge University Press (1999),
   doi:10.1017/CBO9781139644181.
"""

from __future__ import annotations

import logging
from dataclasses import dataclass

import numpy as np

from ..core.errors import InputError
from ..core.lazy import load
from .constants import DEFAULT_FILM, DEFAULT_SUBSTRATE, resolve_index
from .thinfilm import reflectance

optimize = load("scipy.optimize")

#: Thickest film searched (anodic films are < 1 µm; beyond ~10 µm a spectrometer no longer
#: resolves the fringes and the coherent model does not apply).
MAX_THICKNESS_NM = 10_000.0
#: Fewest distinct wavelengths a fit accepts.
MIN_WAVELENGTHS = 3
_SCAN_ELEMENTS = 1 << 21   # thickness x wavelength evaluations per block of the scan
#: A fitted scale outside this range is warned about (the level is off by more than a
#: reference or alignment error explains).
PLAUSIBLE_SCALE = (0.5, 2.0)
#: With the scale fixed, a free scale that lowers the RMS residual by at least this factor
#: and moves the scale by more than :data:`SCALED_BY` means the data are scaled (warned).
SCALED_RESIDUAL_RATIO = 0.5
SCALED_BY = 0.05

log = logging.getLogger(__name__)

__all__ = ["SpectrumFit", "fit_thickness"]


@dataclass
class SpectrumFit:
    """Result of :func:`fit_thickness`.

    Attributes
    ----------
    thickness_nm : float
        Best thickness.
    residual_rms : float
        RMS of (model − measured) reflectance at the best thickness (reflectance units).
    runner_up_thickness_nm : float
        The best other local minimum (NaN if the grid has only one).
    runner_up_residual_rms : float
    scale : float
        Multiplier applied to the model (fitted unless ``fit_scale=False``, then 1).
    angle_deg : float
    grid_thickness_nm, grid_residual_rms : ndarray
        The global scan.
    """

    thickness_nm: float
    residual_rms: float
    runner_up_thickness_nm: float
    runner_up_residual_rms: float
    scale: float
    angle_deg: float
    grid_thickness_nm: np.ndarray
    grid_residual_rms: np.ndarray
    scale_fitted: bool = True


def _model(wl, angle, d, n1, n2):
    return reflectance(wl, angle, np.asarray(d, dtype=np.float64)[..., None], n1, n2)


def _residual(model, meas, fit_scale):
    if fit_scale:
        # Least-squares scale per thickness: s = <m, y> / <m, m>.
        s = np.sum(model * meas, axis=-1) / np.maximum(np.sum(model * model, axis=-1), 1e-300)
        model = model * s[..., None]
    else:
        s = np.ones(model.shape[:-1])
    return np.sqrt(np.mean((model - meas) ** 2, axis=-1)), s


def fit_thickness(wavelength_nm, reflectance, *, angle_deg=0.0, film=DEFAULT_FILM,
                  substrate=DEFAULT_SUBSTRATE, thickness_range_nm=(0.0, 1000.0),
                  grid_step_nm=1.0, fit_scale=True) -> SpectrumFit:
    """Film thickness whose modelled spectrum best matches a measured one.

    Parameters
    ----------
    wavelength_nm : array_like (N,)
        Wavelengths in nm, inside the range of both optical-constant sets.
    reflectance : array_like (N,)
        Measured reflectance (fraction, 0-1) at those wavelengths; NaN samples are ignored.
    angle_deg : float
        Angle of incidence (θ_d for a gonio measurement under the half-vector model).
    film, substrate : str
        Optical-constant set names.
    thickness_range_nm : (float, float)
        Global search range.
    grid_step_nm : float
        Step of the global scan (default 1 nm; must stay well below λ/(4n) ≈ 40 nm).
    fit_scale : bool
        Fit one multiplicative scale of the model (default; a measured level is rarely
        better than 10-20 %). ``False`` trusts the absolute level, and logs a warning when
        a free scale fits far better.

    Returns
    -------
    SpectrumFit

    Examples
    --------
    >>> import numpy as np
    >>> from microfacet.optics.thinfilm import reflectance
    >>> wl = np.arange(400.0, 751.0, 10.0)
    >>> R = reflectance(wl, 0.0, 121.4, "TiO2_Jolivet2023_amorphous", "Ti_JohnsonChristy1974")
    >>> round(fit_thickness(wl, R).thickness_nm, 2)
    121.4
    >>> fit = fit_thickness(wl, 0.8 * R)      # a measured level 20 % low
    >>> round(fit.thickness_nm, 2), round(fit.scale, 3)
    (121.4, 0.8)
    """
    wl = np.asarray(wavelength_nm, dtype=np.float64)
    y = np.asarray(reflectance, dtype=np.float64)
    if wl.ndim != 1 or y.shape != wl.shape:
        raise InputError("must be 1-D and the same length as `wavelength_nm`",
                         param="reflectance")
    keep = np.isfinite(wl) & np.isfinite(y)
    if keep.sum() < 3:
        raise InputError("need at least 3 finite samples", param="reflectance")
    wl, y = wl[keep], y[keep]
    if np.unique(wl).size < MIN_WAVELENGTHS:
        raise InputError(f"the spectrum has {np.unique(wl).size} distinct wavelength(s); a "
                         f"thickness fit needs at least {MIN_WAVELENGTHS}", param="wavelength_nm")
    lo, hi = (float(v) for v in thickness_range_nm)
    if not (0 <= lo < hi <= MAX_THICKNESS_NM):
        raise InputError(f"need 0 <= low < high <= {MAX_THICKNESS_NM:g} nm, got {lo:g}:{hi:g}",
                         param="thickness_range_nm")
    if not (0 < grid_step_nm <= 10):
        raise InputError("must be in (0, 10] nm so no minimum is skipped", param="grid_step_nm")
    if not (0 <= angle_deg < 90):
        raise InputError(f"must satisfy 0 <= angle < 90 degrees, got {angle_deg:g}",
                         param="angle_deg")
    n1 = resolve_index(film, wl)
    n2 = resolve_index(substrate, wl)
    fit = _fit(wl, y, angle_deg, n1, n2, lo, hi, grid_step_nm, fit_scale)
    if fit_scale and not PLAUSIBLE_SCALE[0] <= fit.scale <= PLAUSIBLE_SCALE[1]:
        log.warning("the fitted scale is %.3g: the measured level is off by more than a "
                    "reference or alignment error explains (wrong unit or column?); the "
                    "thickness rests on the fringe positions alone", fit.scale)
    if not fit_scale and fit.residual_rms > 0:
        free = _fit(wl, y, angle_deg, n1, n2, lo, hi, grid_step_nm, True)
        if (free.residual_rms < SCALED_RESIDUAL_RATIO * fit.residual_rms
                and abs(free.scale - 1) > SCALED_BY):
            log.warning("the spectrum looks scaled: with its level trusted the best thickness "
                        "is %.1f nm (RMS residual %.3g), with a fitted scale %.3g it is %.1f nm "
                        "(RMS residual %.3g); fit the scale unless the level is calibrated",
                        fit.thickness_nm, fit.residual_rms, free.scale, free.thickness_nm,
                        free.residual_rms)
    return fit


def _fit(wl, y, angle_deg, n1, n2, lo, hi, grid_step_nm, fit_scale) -> SpectrumFit:
    """The global scan and refinement of :func:`fit_thickness` (arguments checked)."""
    grid = np.linspace(lo, hi, int(np.ceil((hi - lo) / grid_step_nm)) + 1)
    res = np.empty(grid.size)
    block = max(1, _SCAN_ELEMENTS // wl.size)   # bounded memory whatever the range
    for b in range(0, grid.size, block):
        res[b:b + block], _ = _residual(_model(wl, angle_deg, grid[b:b + block], n1, n2), y,
                                        fit_scale)

    # Local minima of the scan (ends count when lower than their neighbour).
    padded = np.concatenate([[np.inf], res, [np.inf]])
    is_min = (padded[1:-1] <= padded[:-2]) & (padded[1:-1] < padded[2:])
    cand = np.flatnonzero(is_min)
    cand = cand[np.argsort(res[cand])][:6]

    def objective(d):
        r, _ = _residual(_model(wl, angle_deg, np.array([d]), n1, n2), y, fit_scale)
        return float(r[0])

    refined = []
    for i in cand:
        a, b = grid[max(i - 1, 0)], grid[min(i + 1, grid.size - 1)]
        if b > a:
            opt = optimize.minimize_scalar(objective, bounds=(a, b), method="bounded",
                                  options={"xatol": 1e-6})
            d_best, r_best = float(opt.x), float(opt.fun)
            if res[i] < r_best:
                d_best, r_best = float(grid[i]), float(res[i])
        else:
            d_best, r_best = float(grid[i]), float(res[i])
        refined.append((r_best, d_best))
    refined.sort()
    best_r, best_d = refined[0]
    runner = next(((r, d) for r, d in refined[1:] if abs(d - best_d) > 2 * grid_step_nm),
                  (np.nan, np.nan))
    _, s = _residual(_model(wl, angle_deg, np.array([best_d]), n1, n2), y, fit_scale)
    return SpectrumFit(
        thickness_nm=best_d, residual_rms=best_r, runner_up_thickness_nm=float(runner[1]),
        runner_up_residual_rms=float(runner[0]), scale=float(s[0]), angle_deg=float(angle_deg),
        grid_thickness_nm=grid, grid_residual_rms=res, scale_fitted=bool(fit_scale))
