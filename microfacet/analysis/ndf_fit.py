"""Fitting the NDF: zero-mean Gaussian-slope lobes, deconvolved from slope noise, censored.

Model
    A facet's slope vector is drawn from ``Σ w_k N(0, s_k² I)`` (a lobe of RMS slope
    ``s_k √2``, ``sd_deg = atan s_k``); its magnitude ``m = tan θ`` is then a Rayleigh mixture.
    A slope *measured* with isotropic noise ``N(0, σ_i² I)`` (a plane fitted to noisy
    heights) has magnitude Rayleigh with ``s_k² + σ_i²``: the lobes are fitted to the
    measurements with that noise model, by EM with the true slope as the latent variable
    (extreme deconvolution, Bovy, Hogg & Roweis 2011): posterior
    ``E[|m|² | m̂, k] = (s_k²/V)² m̂² + 2 s_k² σ_i² / V`` with ``V = s_k² + σ_i²``.

Censoring
    Facets tilted past the objective's acceptance (asin(NA)/2 under coaxial light) reflect
    outside it: they are dark, and their tilt is not measured — but it is known to exceed
    the limit. Dropping them biases every lobe narrow (a 22° lobe read as 12.5° at NA 0.8).
    They enter as censored observations of weight = their area: likelihood
    ``Σ w_k exp(−L² / 2 s_k²)`` with ``L = tan θ_lim``, and in the EM
    ``E[|m|² | |m| > L, k] = L² + 2 s_k²`` (the Rayleigh tail is memoryless in m²).

Weights and the model choice
    Samples are weighted by area (the NDF is a distribution per unit projected area); K by
    the BIC of :mod:`microfacet.analysis.mixtures` with its honest ``n_eff`` (facets, not
    pixels) and its admissibility rules.

References
----------
.. [1] N. Nagata, M. Kamei, K. Takahashi, K. Tobitani, T. Akagi, S. Yamamura, "Simulation
   Technology for Titanium Oxide Layer Interference Color", Technical Report (the seed paper),
   §3.3.3 and Fig. 19 (the normals as two zero-mean Gaussian lobes).
.. [2] A. P. Dempster, N. M. Laird, D. B. Rubin, "Maximum likelihood from incomplete data via
   the EM algorithm", J. R. Stat. Soc. B 39(1) (1977) 1-38,
   doi:10.1111/j.2517-6161.1977.tb01600.x.
.. [3] J. Bovy, D. W. Hogg, S. T. Roweis, "Extreme deconvolution: inferring complete
   distribution functions from noisy, heterogeneous and incomplete observations", Ann. Appl.
   Stat. 5(2B) (2011) 1657-1677, doi:10.1214/10-AOAS439.
.. [4] G. Schwarz, "Estimating the dimension of a model", Ann. Statist. 6(2) (1978) 461-464,
   doi:10.1214/aos/1176344136.
.. [5] B. Walter, S. R. Marschner, H. Li, K. E. Torrance, "Microfacet models for refraction
   through rough surfaces", Eurographics Symposium on Rendering (2007) 195-206,
   doi:10.2312/EGWR/EGSR07/195-206 (Beckmann lobes).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from ..core.distributions import NDFMixture
from ..core.lazy import load
from .mixtures import (
    MixtureFit,
    bic_score,
    choose_k,
    k_max_for,
    k_note,
    run_em,
    single_thread,
)
from .options import FitOptions
from .sampling import Samples, collapse, prepare

optimize = load("scipy.optimize")

__all__ = ["fit_ndf_mixture", "width_relative_error"]

_DEG = math.pi / 180.0
_M_LOG_FLOOR = 1e-6  # slope magnitude at which log m is evaluated for tilts of exactly 0
_S2_CEIL = math.tan(88.9 * _DEG) ** 2  # NDFMixture needs sd_deg < 89


def _rayleigh_em(data, censor, start, s2_floor, *, max_iter=1000, tol=1e-7):
    """Weighted, deconvolved, censored Rayleigh-mixture EM from ``start = (w, s2)``;
    returns (w, s2, ℓ′).

    ``data = (m2, v, a)``: squared measured slopes, their noise variance per axis, weights;
    ``censor = (C, L2)``: the censored weight (slopes above ``√L2``). ℓ′ omits the model-independent
    Σ a log m̂ term. Stops when an iteration raises ℓ′ by less than ``tol`` × total weight
    (:func:`~.mixtures.run_em`).

    The arrays are laid out (lobe, sample), reused, and the M-step uses the sums
    ``Σ q m̂²/V`` and ``Σ q σ²`` (``q = a r / V``): ``Σ a r E[|m|²] = s⁴ Σ q m̂²/V + 2 s² Σ q σ²``.
    """
    (m2, v, a), (C, L2), (w, s2) = data, censor, start
    W = float(a.sum() + C)
    half_m2 = 0.5 * m2
    work = [np.empty((len(s2), m2.size)) for _ in range(3)]     # reused (K, n) arrays

    def step(p):
        w, s2 = p
        lp, iv, h = work
        lw = np.log(np.maximum(w, 1e-300))
        np.add(s2[:, None], v, out=lp)            # V = s² + σ²
        np.divide(1.0, lp, out=iv)
        np.log(lp, out=lp)
        np.multiply(half_m2, iv, out=h)           # m̂² / 2V
        lp += h
        np.subtract(lw[:, None], lp, out=lp)      # log w − log V − m̂² / 2V
        mx = lp.max(axis=0)
        lp -= mx
        e = np.exp(lp, out=lp)
        tot = e.sum(axis=0)
        lt = np.log(tot)
        lt += mx
        ll = float(a @ lt)
        if C > 0:
            lc = lw - L2 / (2.0 * s2)
            mc = lc.max()
            ec = np.exp(lc - mc)
            ll += C * float(mc + np.log(ec.sum()))
        at = np.divide(a, tot, out=tot)           # a r = e · a / tot
        nk = e @ at
        q = e
        q *= at
        q *= iv                                   # a r / V
        num = s2 * s2 * np.einsum("kn,kn->k", q, h) + s2 * (q @ v)
        if C > 0:
            rc = C * ec / ec.sum()
            num = num + 0.5 * rc * (L2 + 2.0 * s2)
            nk = nk + rc
        nk = np.maximum(nk, 1e-300)
        return ll, (nk / W, np.clip(num / nk, s2_floor, _S2_CEIL))

    p0 = (np.asarray(w, dtype=np.float64) / np.sum(w),
          np.clip(np.asarray(s2, dtype=np.float64), s2_floor, _S2_CEIL))
    (w, s2), ll = run_em(step, p0, max_iter=max_iter, tol=tol * W)
    return w, s2, ll


def width_relative_error(tilt_deg, slope_sigma, weights, n_effective) -> float:
    """Relative 1-σ error of the width of one lobe fitted to these measured tilts.

    From the Fisher information of ``s²`` in the deconvolved Rayleigh model at the
    single-lobe fit, ``I = Σ a_i / V_i²`` (``V_i = s² + σ_i²``, weights scaled to sum to
    ``n_effective``); the error of ``s`` is ``1 / (2 s² √I)``: ``1/(2√n)`` for exact slopes,
    growing as (1 + σ²/s²) when the noise is comparable to the lobe. Censored samples are
    left out (conservative).

    Examples
    --------
    >>> t = np.full(100, 5.0)
    >>> round(width_relative_error(t, 0.0, 1.0, 100), 3)
    0.05
    """
    th = np.asarray(tilt_deg, dtype=np.float64).ravel()
    sg = np.broadcast_to(np.asarray(slope_sigma, dtype=np.float64), th.shape).ravel()
    a = np.broadcast_to(np.asarray(weights, dtype=np.float64), th.shape).ravel()
    ok = np.isfinite(th) & np.isfinite(sg) & (a > 0)
    if ok.sum() < 2:
        return float("inf")
    m2 = np.tan(th[ok] * _DEG) ** 2
    v = sg[ok] ** 2
    a = a[ok] * (n_effective / a[ok].sum())

    def nll(log_s2):
        V = math.exp(log_s2) + v
        return float(np.sum(a * (np.log(V) + m2 / (2.0 * V))))

    hi = math.log(max(float(np.max(m2)), 1e-6) * 10.0)
    opt = optimize.minimize_scalar(nll, bounds=(math.log(1e-10), hi), method="bounded",
                                   options={"xatol": 1e-4})
    s2 = math.exp(opt.x)
    info = float(np.sum(a / (s2 + v) ** 2))
    return 1.0 / (2.0 * s2 * math.sqrt(info)) if info > 0 else float("inf")


def _ndf_starts(k, d, sols):
    """Starting points of the EM for K = ``k``: quantile blocks of m², a geometric spread
    about the mean square slope; with ``k`` > 1 the K − 1 solution plus one wide or one
    narrow lobe, or with its heaviest lobe split in two."""
    starts = [(np.ones(k), np.array([max(b.mean() / 2.0, d.s2_floor) if b.size else d.base
                                     for b in np.array_split(d.order, k)])),
              (np.ones(k), d.base * np.geomspace(1 / 9.0, 9.0, k))]
    if k > 1:
        wp, sp = sols[k - 1]
        starts.append((np.append(wp * 0.9, 0.1), np.append(sp, sp.max() * 4.0)))
        starts.append((np.append(wp * 0.9, 0.1), np.append(sp, max(sp.min() / 4.0,
                                                                    d.s2_floor))))
        j = int(np.argmax(wp))
        ws, ss = wp.copy(), sp.copy()
        ws[j] /= 2.0
        ss[j] /= 1.5
        starts.append((np.append(ws, wp[j] / 2.0), np.append(ss, sp[j] * 1.5)))
    return starts


@dataclass
class _Data:
    """The prepared samples of one NDF fit and what every K shares."""

    collapsed: tuple
    censor: tuple
    order: np.ndarray
    base: float
    s2_floor: float
    bounded: bool


def _censoring(censored, tilt_deg, weights, a_sum):
    """``(C, L2)``: the censored weight in the units of the fitted samples' weights and the
    squared slope of the limit (0, 0 without censoring)."""
    if censored is None:
        return 0.0, 0.0
    C, limit = float(censored[0]), censored[1]
    if not (math.isfinite(C) and C >= 0):
        raise ValueError(f"censored: weight must be finite and >= 0, got {censored[0]!r}")
    if C == 0:
        return 0.0, 0.0
    if limit is None or not (0 < float(limit) < 90):
        raise ValueError("censored: a limit in (0, 90) degrees is needed with a weight > 0")
    t_all = np.asarray(tilt_deg, dtype=np.float64)
    w_all = (np.ones(t_all.shape) if weights is None
             else np.broadcast_to(np.asarray(weights, dtype=np.float64), t_all.shape))
    C = C * a_sum / float(np.sum(w_all[np.isfinite(t_all)]))
    return C, math.tan(float(limit) * _DEG) ** 2


def fit_ndf_mixture(tilt_deg, *, slope_sigma=None, weights=None, censored=None, group=None,
                    n_effective=None, options: FitOptions | None = None, seed=0) -> MixtureFit:
    """Mixture of zero-mean Gaussian-slope lobes fitted to measured tilts, K by BIC.

    Parameters
    ----------
    tilt_deg : array_like, any shape
        Measured tilt of each sample (facet or pixel) from the mean normal, degrees, in
        [0, 90). NaN is ignored.
    slope_sigma : array_like or float, optional
        Isotropic noise of each measured slope vector, per axis, as a slope (e.g.
        :attr:`~microfacet.analysis.planes.FacetFit.slope_sigma`): deconvolved.
    weights : array_like, same shape, optional
        Sample weights (facet areas; one pixel = one unit of projected area by default).
    censored : (float, float), optional
        ``(weight, limit_deg)``: the total weight (area) of samples whose tilt is only known
        to exceed ``limit_deg`` (dark facets past the acceptance asin(NA)/2).
    group : array_like, optional
        Facet id per sample (per-pixel input): distinct ids are the independent samples.
    n_effective : float, optional
        Independent samples (default: groups, else the Kish size of the weights) — the
        censored weight is counted in proportion.
    options : FitOptions, optional
        ``max_components`` (also limited to ``2K − 1 ≤ n_effective`` and distinct values),
        ``ndf_sd_floor_deg`` (smallest lobe SD; lobe SDs are also capped at 88.9°; all-zero
        tilts give one lobe at the floor, ``degenerate`` says so; for K ≥ 2 a lobe at the
        floor is not admissible), ``ndf_min_component_samples`` (fewest independent samples
        a lobe of a K ≥ 2 solution needs), ``ndf_max_samples`` (larger inputs are
        subsampled with ``seed``).
    seed : int, optional

    Returns
    -------
    MixtureFit
        ``mixture`` is an :class:`~microfacet.core.distributions.NDFMixture`; the BIC uses
        the log-likelihood of the tilt density per degree. ``info`` holds
        ``censored_fraction``.

    Raises
    ------
    ValueError
        No finite tilts, tilts outside [0, 90), or a bad censoring.

    Examples
    --------
    >>> rng = np.random.default_rng(1)
    >>> s, noise = np.tan(np.radians(5.0)), 0.05
    >>> slopes = rng.normal(0, s, (2, 4000)) + rng.normal(0, noise, (2, 4000))
    >>> tilt = np.degrees(np.arctan(np.hypot(*slopes)))
    >>> fit = fit_ndf_mixture(tilt, slope_sigma=noise)
    >>> fit.n_components, round(float(fit.mixture.sds_deg[0]), 1)
    (1, 5.0)
    """
    opts = FitOptions() if options is None else options
    sd_floor_deg = opts.ndf_sd_floor_deg
    th, a, sg, n, n_eff = prepare(Samples(tilt_deg, slope_sigma, weights, group, n_effective,
                                          "tilt_deg", "slope_sigma"),
                                  max_samples=opts.ndf_max_samples, seed=seed)
    if np.any(th < 0) or np.any(th >= 90):
        raise ValueError("tilt_deg: tilts must be in [0, 90) degrees")
    a_sum = float(a.sum())
    C, L2 = _censoring(censored, tilt_deg, weights, a_sum)
    if C > 0 and n_effective is None:
        n_eff *= (a_sum + C) / a_sum
    W = a_sum + C
    rad = th * _DEG
    m2 = np.tan(rad) ** 2
    v = sg * sg
    s2_floor = math.tan(sd_floor_deg * _DEG) ** 2
    # model-independent part of the log density per degree: log m + 2 log sec θ + log(π/180)
    const = float(np.sum(a * (np.log(np.maximum(np.tan(rad), _M_LOG_FLOOR))
                              - 2.0 * np.log(np.cos(rad)) + math.log(_DEG))))
    info = {"censored_fraction": C / W if W > 0 else 0.0}
    uniq = np.unique(th)
    if np.all(m2 == 0) and not np.any(v > 0) and C == 0:
        ll = a_sum * -math.log(s2_floor) + const
        bic = bic_score(ll, W, n_eff, 1)
        return MixtureFit(NDFMixture([(1.0, sd_floor_deg)]), bic, {1: bic}, n, n_eff,
                          f"all tilts are 0: one lobe with floor sd {sd_floor_deg:g} deg",
                          th.size, {1: ll}, info=info)
    k_max = k_max_for(opts.max_components, uniq.size + (C > 0), n_eff, 2, -1)
    ac, m2c, vc = collapse(a, m2, v)   # the EM on distinct (tilt, noise) pairs
    base = max(float(np.average(np.maximum(m2 - 2 * v, 0.0), weights=a)) / 2.0, s2_floor)
    if C > 0:
        base = max(base, L2 / 4.0 * C / W)
    # A lobe at the floor is a spike unless the slope noise bounds its likelihood
    # (as in fit_thickness_mixture).
    d = _Data((m2c, vc, ac), (C, L2), np.sort(m2), base, s2_floor,
              float(np.average(v, weights=a)) >= 4.0 * s2_floor)
    sols, lls, fits = {}, {}, {}
    with single_thread():
        for k in range(1, k_max + 1):
            runs = [_rayleigh_em(d.collapsed, d.censor, st, s2_floor, max_iter=25)
                    for st in _ndf_starts(k, d, sols)]
            w, s2, ll = _rayleigh_em(d.collapsed, d.censor, max(runs, key=lambda r: r[2])[:2],
                                     s2_floor)
            sols[k] = (w, s2)
            lls[k] = max(ll + const, lls.get(k - 1, -np.inf))
            at_floor = k > 1 and bool(np.any(s2 <= s2_floor * 1.0001)) and not d.bounded
            fits[k] = (bic_score(lls[k], W, n_eff, 2 * k - 1), w, at_floor)
    k_best, margin, ok = choose_k(fits, n_eff, opts.ndf_min_component_samples)
    bics = {k: f[0] for k, f in fits.items()}
    w, s2 = sols[k_best]
    sd = np.degrees(np.arctan(np.sqrt(s2)))
    info["inadmissible_k"] = sorted(set(bics) - set(ok))
    return MixtureFit(NDFMixture([(float(x), float(y)) for x, y in zip(w, sd) if x > 1e-12]),
                      bics[k_best], bics, n, n_eff,
                      k_note(k_max, opts.max_components, uniq.size, n_eff, "tilts"), th.size,
                      lls, bic_margin=margin, info=info)
