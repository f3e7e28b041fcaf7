"""Fitting the NDF: a mixture of zero-mean Gaussian-slope lobes to per-pixel tilts.

The slope magnitude ``m = tan θ`` of a pixel is a mixture of Rayleigh distributions,
``f(m) = Σ w_k (m / σ_k²) exp(−m² / 2σ_k²)``, fitted by EM: responsibilities
``r_k ∝ w_k σ_k⁻² exp(−m² / 2σ_k²)``, ``σ_k² = Σ r_k m² / (2 Σ r_k)``, ``w_k = Σ r_k / n``.
Several deterministic starts (quantile blocks, a geometric spread, the K − 1 solution plus a
wide or a narrow lobe, or with its heaviest lobe split), each run briefly, the best one to
convergence; K = 1 … ``max_components`` by BIC with ``p = 2K − 1`` parameters, with the
effective sample size of :mod:`microfacet.analysis.mixtures`.
"""

from __future__ import annotations

import math

import numpy as np

from ..core.distributions import NDFMixture
from .mixtures import (
    MixtureFit,
    bic_score,
    fit_thickness_mixture,
    k_max_for,
    k_note,
    positive_int,
    prepare,
    single_thread,
)

__all__ = ["fit_distributions", "fit_ndf_mixture"]

_DEG = math.pi / 180.0
_M_LOG_FLOOR = 1e-6  # slope magnitude at which log m is evaluated for tilts of exactly 0


_S2_CEIL = math.tan(88.9 * _DEG) ** 2  # NDFMixture needs sd_deg < 89


def _rayleigh_em(m2, w, s2, s2_floor, max_iter=1000, tol=1e-4):
    """EM for a zero-mean Rayleigh mixture on squared slopes ``m2``; returns (w, s2, ℓ′).

    ℓ′ is the log-likelihood without the model-independent Σ log m term. Stops when an
    iteration raises the total log-likelihood by less than ``tol`` (BIC differences that
    matter are of order 1) or after ``max_iter`` iterations.
    """
    n = m2.size
    w = np.asarray(w, dtype=np.float64) / np.sum(w)
    s2 = np.clip(np.asarray(s2, dtype=np.float64), s2_floor, _S2_CEIL)
    m2c = m2[:, None]
    prev = -np.inf
    ll = -np.inf
    for it in range(max_iter + 1):
        a = (np.log(w) - np.log(s2)) - m2c * (0.5 / s2)
        amax = a.max(axis=1, keepdims=True)
        e = np.exp(a - amax)
        tot = e.sum(axis=1, keepdims=True)
        ll = float(np.sum(amax) + np.sum(np.log(tot)))
        if it == max_iter or ll - prev <= tol:
            break
        prev = ll
        r = e / tot
        nk = r.sum(axis=0)
        w = np.maximum(nk / n, 1e-300)
        w = w / w.sum()
        s2 = np.clip((m2 @ r) / np.maximum(2.0 * nk, 1e-300), s2_floor, _S2_CEIL)
    return w, s2, ll


def _rayleigh_em_multistart(m2, starts, s2_floor, *, burn_in=25):
    """Run every start for ``burn_in`` iterations, then the best one to convergence."""
    runs = [_rayleigh_em(m2, w0, s0, s2_floor, max_iter=burn_in) for w0, s0 in starts]
    w, s2, _ = max(runs, key=lambda r: r[2])
    return _rayleigh_em(m2, w, s2, s2_floor)


def fit_ndf_mixture(tilt_deg, *, max_components=5, group=None, random_state=0,
                    max_samples=50000, sd_floor_deg=0.05) -> MixtureFit:
    """Mixture of zero-mean Gaussian-slope lobes fitted to per-pixel tilts, K by BIC.

    The slope magnitude ``m = tan θ`` of a Gaussian-slope lobe is Rayleigh with parameter
    ``s = tan(sd_deg)``; the Rayleigh mixture is fitted by EM (vectorised) from several
    deterministic starts per K, keeping the highest likelihood.

    Parameters
    ----------
    tilt_deg : array_like, any shape
        Per-pixel tilt of the surface normal from the mean normal, degrees, in [0, 90).
        NaN is ignored. One pixel = one unit of projected area (as
        :meth:`NDFMixture.tilt_pdf` assumes).
    max_components : int, optional
        Largest number of lobes K tried; also limited to ``2K − 1 ≤ n_effective`` and the
        number of distinct values.
    group : array_like, same shape as ``tilt_deg``, optional
        Region / facet id per sample; the BIC then uses the number of distinct groups as
        the effective sample size (see the module docstring).
    random_state : int, optional
        Seed of the subsample taken when there are more than ``max_samples`` values.
    max_samples : int, optional
        Larger inputs are subsampled reproducibly to this many values.
    sd_floor_deg : float, optional
        Smallest lobe sd, degrees (lobe sds are also capped at 88.9°). All-zero tilts
        give one lobe with this sd and ``degenerate`` says so. Many tilts of exactly 0
        (flat pixels) are a real spike at 0 and may be fitted as a lobe at the floor.

    Returns
    -------
    MixtureFit
        ``mixture`` is an :class:`~microfacet.core.distributions.NDFMixture`; ``bic`` is based on
        the log-likelihood of the tilt density per degree (:meth:`NDFMixture.tilt_pdf`),
        with ``log tan θ`` evaluated at ``tan θ ≥ 1e-6`` for tilts of exactly 0 (a term
        that is the same for every K, so it does not affect the choice).

    Raises
    ------
    ValueError
        No finite tilts, tilts outside [0, 90), or bad options.

    Examples
    --------
    >>> rng = np.random.default_rng(1)
    >>> s = np.tan(np.radians(5.0))
    >>> tilt = np.degrees(np.arctan(np.hypot(*rng.normal(0, s, (2, 5000)))))
    >>> fit = fit_ndf_mixture(tilt)
    >>> fit.n_components, round(float(fit.mixture.sds_deg[0]), 1)
    (1, 5.0)
    """
    max_components = positive_int(max_components, "max_components")
    max_samples = positive_int(max_samples, "max_samples")
    sd_floor_deg = float(sd_floor_deg)
    if not (math.isfinite(sd_floor_deg) and 0 < sd_floor_deg < 89):
        raise ValueError(f"sd_floor_deg: must be in (0, 89), got {sd_floor_deg!r}")
    th, n, n_eff, _ = prepare(tilt_deg, "tilt_deg", None, group, max_samples, random_state)
    if np.any(th < 0) or np.any(th >= 90):
        raise ValueError("tilt_deg: tilts must be in [0, 90) degrees")
    n_fit = th.size
    rad = th * _DEG
    m = np.tan(rad)
    m2 = m * m
    s2_floor = math.tan(sd_floor_deg * _DEG) ** 2
    # model-independent part of the log density per degree: log m + 2 log sec θ + log(π/180)
    const = float(np.sum(np.log(np.maximum(m, _M_LOG_FLOOR)) - 2.0 * np.log(np.cos(rad))))
    const += n_fit * math.log(_DEG)

    uniq = np.unique(th)
    if np.all(m2 == 0):
        # the likelihood of all-zero slopes under one lobe at the floor width
        ll = n_fit * -math.log(s2_floor) + const
        bic = bic_score(ll, n_fit, n_eff, 1)
        return MixtureFit(NDFMixture([(1.0, sd_floor_deg)]), bic, {1: bic}, n, n_eff,
                          f"all tilts are 0: one lobe with floor sd {sd_floor_deg:g} deg",
                          n_fit, {1: ll})

    k_max = k_max_for(max_components, uniq.size, n_eff, 2, -1)
    order = np.sort(m2)
    med = float(np.median(m2))
    q_lo, q_hi = (float(v) for v in np.quantile(m2, [0.05, 0.95]))
    sols, bics, lls = {}, {}, {}
    with single_thread():
        for k in range(1, k_max + 1):
            # 1. quantile blocks of m²: σ² = mean(m²)/2 within each equal-count block
            starts = [(np.ones(k), np.array([b.mean() / 2.0 for b in np.array_split(order, k)]))]
            # 2. geometric spread about the median (median of a Rayleigh: σ √(2 ln 2))
            centre = max(med, s2_floor) / (2.0 * math.log(2.0))
            starts.append((np.ones(k), centre * np.geomspace(1 / 9.0, 9.0, k)))
            if k > 1:
                # 3./4. the K − 1 solution plus one wide or one narrow lobe;
                # 5. the K − 1 solution with its heaviest lobe split in two
                wp, sp = sols[k - 1]
                hi = max(q_hi / 2.0, sp.max() * 4.0)
                lo = max(min(q_lo / 2.0, sp.min() / 4.0), s2_floor)
                starts.append((np.append(wp * 0.9, 0.1), np.append(sp, hi)))
                starts.append((np.append(wp * 0.9, 0.1), np.append(sp, lo)))
                j = int(np.argmax(wp))
                ws, ss = wp.copy(), sp.copy()
                ws[j] /= 2.0
                ss[j] /= 1.5
                starts.append((np.append(ws, wp[j] / 2.0), np.append(ss, sp[j] * 1.5)))
            w, s2, ll = _rayleigh_em_multistart(m2, starts, s2_floor)
            sols[k] = (w, s2)
            # never below the nested K − 1 optimum (EM stopped early / poor start)
            lls[k] = max(ll + const, lls.get(k - 1, -np.inf))
            bics[k] = bic_score(lls[k], n_fit, n_eff, 2 * k - 1)
    k_best = min(bics, key=bics.get)
    w, s2 = sols[k_best]
    sd = np.degrees(np.arctan(np.sqrt(s2)))
    comps = [(float(a), float(b)) for a, b in zip(w, sd) if a > 1e-12]
    return MixtureFit(NDFMixture(comps), bics[k_best], bics, n, n_eff,
                      k_note(k_max, max_components, uniq.size, n_eff, "tilts"), n_fit, lls)


def fit_distributions(pixels, *, max_components=5, facets=None):
    """The distributions stage: the thickness mixture and the NDF lobes of per-pixel estimates.

    Parameters
    ----------
    pixels : PixelEstimates
        Per-pixel thickness and tilt; ``thickness_group`` sets the thickness model choice's
        independent samples.
    max_components : int
    facets : ndarray of int (H, W), optional
        Facet labels: the NDF's independent samples (joint mode).

    Returns
    -------
    thickness_fit, ndf_fit : MixtureFit or None
        None where fewer than two pixels have a value.
    """
    ok = np.isfinite(pixels.thickness_nm)
    tfit = (fit_thickness_mixture(pixels.thickness_nm[ok], max_components=max_components,
                                  group=pixels.thickness_group[ok]) if ok.sum() >= 2 else None)
    okt = np.isfinite(pixels.tilt_deg)
    nfit = (fit_ndf_mixture(pixels.tilt_deg[okt], max_components=max_components,
                            group=facets[okt] if facets is not None else None)
            if okt.sum() >= 2 else None)
    return tfit, nfit
