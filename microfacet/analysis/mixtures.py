"""Fitting the thickness mixture to per-pixel samples, and the model choice both fits use.

Thickness (:func:`fit_thickness_mixture`)
    A 1-D Gaussian mixture with free means, fitted with scikit-learn's
    ``GaussianMixture`` for K = 1 … ``max_components``; K is chosen by BIC.

Facet normals
    :func:`microfacet.analysis.ndf_fit.fit_ndf_mixture` (zero-mean Gaussian-slope lobes),
    with the model choice below.

Model choice and correlated samples (both fitters)
    ``BIC = −2 (n_eff / n_fit) ℓ + p log n_eff``, where ℓ is the log-likelihood of the
    ``n_fit`` samples the mixture was fitted to (all finite samples, or a reproducible
    subsample of ``max_samples``), and ``p`` the number of free parameters (3K − 1 for
    the thickness, 2K − 1 for the NDF). Without ``group`` the samples are taken as
    independent, ``n_eff = n_fit`` (the Kish effective size ``(Σw)² / Σw²`` with
    thickness ``weights``), and this is the usual BIC.

    **Per-pixel values are not independent**: a grain or facet of thousands of pixels
    shares one thickness/tilt, so the usual BIC, with n in the tens of thousands, rewards
    a narrow component for every large region and overfits badly. Pass ``group`` (a
    region/facet id per sample): the mixture is still fitted to the pixel samples (so it
    describes the per-pixel, i.e. area-weighted, distribution), but the BIC counts the
    distinct groups (among all finite samples) as the independent observations,
    ``n_eff = n_groups``: the log-likelihood is scaled by ``n_groups / n_fit`` (with equal
    group sizes, each group contributes its average per-pixel log-likelihood) and the
    penalty is ``p log n_groups``. This is an effective-sample-size heuristic, not an
    exact likelihood; it needs enough groups (a few tens) to resolve several components.

    In either case K is also limited to the number of distinct values and so that the
    model has no more parameters than effective observations (``p ≤ n_eff``); the
    ``degenerate`` field of the result says when that limit was applied.

"""

from __future__ import annotations

import math
import warnings
from dataclasses import dataclass, field

import numpy as np

from ..core.distributions import ThicknessMixture
from ..core.lazy import load

sklearn_mixture = load("sklearn.mixture")
sklearn_exceptions = load("sklearn.exceptions")
threadpoolctl = load("threadpoolctl")

__all__ = [
    "MixtureFit",
    "bic_score",
    "fit_thickness_mixture",
    "k_max_for",
    "k_note",
    "positive_int",
    "prepare",
    "single_thread",
]

_DEG = math.pi / 180.0
_LOG_2PI = math.log(2.0 * math.pi)


@dataclass
class MixtureFit:
    """Result of :func:`fit_thickness_mixture` or :func:`fit_ndf_mixture`.

    Attributes
    ----------
    mixture : ThicknessMixture or NDFMixture
        The mixture with the chosen number of components K.
    bic : float
        BIC of the chosen K (see the module docstring for the ``group`` handling).
    bic_by_k : dict of int to float
        BIC of every K that was fitted (K that exceed the number of distinct values or
        the effective sample size are not fitted and absent).
    n_samples : int
        Finite samples given (after dropping NaN and zero weights).
    n_effective : float
        The number of independent observations the BIC used: the number of distinct
        groups with ``group``, else the number of samples fitted (after subsampling; the
        Kish effective size with ``weights``).
    degenerate : bool or str
        ``False``, or a short description of the degenerate case handled (e.g. a single
        distinct value fitted as one component with the floor sd).
    n_fit : int
        Samples the mixture was actually fitted to (≤ ``max_samples``).
    log_likelihood_by_k : dict of int to float
        Log-likelihood of the ``n_fit`` samples for each K (thickness density per nm, or
        tilt density per degree), before the ``n_eff / n_fit`` scaling.
    """

    mixture: object
    bic: float
    bic_by_k: dict
    n_samples: int
    n_effective: float
    degenerate: object = False
    n_fit: int = 0
    log_likelihood_by_k: dict = field(default_factory=dict, repr=False)

    @property
    def n_components(self) -> int:
        return len(self.mixture.components)

    def to_json(self) -> dict:
        """``{"components": [...], "bic", "bic_by_k", "n_effective"}`` (plus ``form`` for
        the NDF, ``n_samples`` and ``degenerate``); ``bic_by_k`` keys are strings."""
        out = dict(self.mixture.to_json())
        out["bic"] = _json_float(self.bic)
        out["bic_by_k"] = {str(k): _json_float(v) for k, v in sorted(self.bic_by_k.items())}
        out["n_effective"] = _json_float(self.n_effective)
        out["n_samples"] = int(self.n_samples)
        out["degenerate"] = self.degenerate if isinstance(self.degenerate, str) else bool(
            self.degenerate)
        return out


def _json_float(x):
    x = float(x)
    return x if math.isfinite(x) else None


# ----------------------------------------------------------------------------- inputs


def positive_int(x, name):
    if isinstance(x, bool) or not isinstance(x, (int, np.integer)) or x < 1:
        raise ValueError(f"{name}: expected an integer >= 1, got {x!r}")
    return int(x)


def prepare(values, name, weights, group, max_samples, random_state):
    """Flatten, drop NaN / zero weight, subsample reproducibly.

    Returns ``x_fit, n_samples, n_eff, n_groups`` where ``n_eff`` is the effective number
    of independent observations for the BIC.
    """
    try:
        x = np.asarray(values, dtype=np.float64)
    except (TypeError, ValueError):
        raise ValueError(f"{name}: expected an array of numbers") from None
    shape = x.shape
    x = x.ravel()
    if np.isinf(x).any():
        raise ValueError(f"{name}: contains infinite values")
    keep = ~np.isnan(x)

    w = None
    if weights is not None:
        try:
            w = np.asarray(weights, dtype=np.float64)
        except (TypeError, ValueError):
            raise ValueError("weights: expected an array of numbers") from None
        if w.size != x.size:
            raise ValueError(f"weights: shape {w.shape} does not match {name} {shape}")
        w = w.ravel()
        if not np.all(np.isfinite(w)) or np.any(w < 0):
            raise ValueError("weights: must be finite and >= 0")
        keep &= w > 0

    g = None
    if group is not None:
        g = np.asarray(group)
        if g.size != x.size:
            raise ValueError(f"group: shape {g.shape} does not match {name} {shape}")
        g = g.ravel()

    x = x[keep]
    n = x.size
    if n == 0:
        raise ValueError(f"{name}: no finite values" + (" with weight > 0" if w is not None
                                                        else ""))
    rng = np.random.default_rng(random_state)
    if w is not None:
        w = w[keep]
        p = w / w.sum()
        kish = 1.0 / float(np.sum(p * p))
        size = min(n, max_samples)
        idx = np.sort(rng.choice(n, size=size, replace=True, p=p))
        n_fit_eff = min(kish, float(size))
    elif n > max_samples:
        idx = np.sort(rng.choice(n, size=max_samples, replace=False))
        n_fit_eff = float(max_samples)
    else:
        idx = None
        n_fit_eff = float(n)
    x_fit = x if idx is None else x[idx]

    n_groups = None
    if g is not None:
        n_groups = int(np.unique(g[keep]).size)
        n_eff = float(min(n_groups, n_fit_eff))
    else:
        n_eff = n_fit_eff
    return x_fit, n, n_eff, n_groups


def single_thread():
    """Limit BLAS/OpenMP to one thread: 1-D mixtures gain nothing from threads, and on a
    busy machine thread contention makes them many times slower."""
    return threadpoolctl.threadpool_limits(limits=1)


def bic_score(loglik_fit, n_fit, n_eff, p):
    """BIC with the log-likelihood of ``n_fit`` samples rescaled to ``n_eff`` observations."""
    return -2.0 * loglik_fit * (n_eff / n_fit) + p * math.log(n_eff)


def k_max_for(max_components, n_unique, n_eff, params_per_k, extra):
    """Largest K with K ≤ distinct values and p = params_per_k·K + extra ≤ n_eff (≥ 1)."""
    k_by_p = int(math.floor((n_eff - extra) / params_per_k + 1e-9))
    return max(1, min(max_components, n_unique, k_by_p))


# -------------------------------------------------------------------------- thickness


def fit_thickness_mixture(thickness_nm, *, max_components=5, weights=None, group=None,
                          random_state=0, max_samples=20000, sd_floor_nm=0.1) -> MixtureFit:
    """Gaussian mixture of oxide thickness, number of components chosen by BIC.

    Parameters
    ----------
    thickness_nm : array_like, any shape
        Per-pixel (or per-region) thickness in nm. NaN is ignored.
    max_components : int, optional
        Largest K tried (K = 1 … max). Also limited to the number of distinct values and
        to ``3K − 1 ≤ n_effective``.
    weights : array_like, same shape as ``thickness_nm``, optional
        Non-negative sample weights (e.g. pixel area). ``GaussianMixture`` takes no
        weights, so the fit uses a reproducible weighted resample (with replacement) of
        ``min(n, max_samples)`` values; the BIC then uses the Kish effective sample size.
    group : array_like, same shape as ``thickness_nm``, optional
        Region / facet id per sample. When given, the BIC counts the number of distinct
        groups as the number of independent observations (log-likelihood scaled by
        ``n_groups / n_fit``, penalty ``p log n_groups``); see the module docstring.
        Without it, spatially correlated pixels make the BIC overfit.
    random_state : int, optional
        Seed for the subsample and the k-means initialisation (results are reproducible).
    max_samples : int, optional
        Larger inputs are subsampled (without replacement) to this many values.
    sd_floor_nm : float, optional
        Smallest component sd, nm (added as a variance regulariser ``sd_floor_nm²``).
        A single distinct value is returned as one component with this sd, and
        ``degenerate`` says so. Thickness quantised to a grid (e.g. a lookup table with a
        1 nm step) with few distinct values invites a spike per grid value: set the floor
        to about the step.

    Returns
    -------
    MixtureFit
        ``mixture`` is a :class:`~microfacet.core.distributions.ThicknessMixture`.

    Raises
    ------
    ValueError
        No finite values, infinite values, or bad options (the message names the argument).

    Examples
    --------
    >>> rng = np.random.default_rng(0)
    >>> d = np.concatenate([rng.normal(120, 3, 4000), rng.normal(140, 3, 6000)])
    >>> fit = fit_thickness_mixture(d)
    >>> fit.n_components, [round(m) for m in fit.mixture.means_nm]
    (2, [120, 140])
    """
    max_components = positive_int(max_components, "max_components")
    max_samples = positive_int(max_samples, "max_samples")
    sd_floor_nm = float(sd_floor_nm)
    if not (math.isfinite(sd_floor_nm) and sd_floor_nm > 0):
        raise ValueError(f"sd_floor_nm: must be finite and > 0, got {sd_floor_nm!r}")
    x, n, n_eff, _ = prepare(thickness_nm, "thickness_nm", weights, group, max_samples,
                              random_state)
    n_fit = x.size
    uniq = np.unique(x)

    if uniq.size == 1:
        v = float(uniq[0])
        ll = n_fit * (-math.log(sd_floor_nm) - 0.5 * _LOG_2PI)
        bic = bic_score(ll, n_fit, n_eff, 2)
        return MixtureFit(ThicknessMixture([(1.0, v, sd_floor_nm)]), bic, {1: bic}, n, n_eff,
                          f"single value {v:g} nm: one component with floor sd "
                          f"{sd_floor_nm:g} nm", n_fit, {1: ll})

    k_max = k_max_for(max_components, uniq.size, n_eff, 3, -1)
    X = x[:, None]
    fits, bics, lls = {}, {}, {}
    with single_thread(), warnings.catch_warnings():
        # an unconverged over-sized K only loses in the BIC; no need to warn
        warnings.simplefilter("ignore", sklearn_exceptions.ConvergenceWarning)
        for k in range(1, k_max + 1):
            # two starts: k-means (seeded) and the k quantiles; keep the higher likelihood
            q = np.quantile(x, (np.arange(k) + 0.5) / k)[:, None]
            best = None
            for kw in ({"init_params": "kmeans"}, {"means_init": q}):
                gm = sklearn_mixture.GaussianMixture(n_components=k, covariance_type="full",
                                     reg_covar=sd_floor_nm ** 2, max_iter=500, tol=1e-5,
                                     random_state=random_state, **kw)
                gm.fit(X)
                ll = float(gm.score(X)) * n_fit
                if best is None or ll > best[1]:
                    best = (gm, ll)
            fits[k], lls[k] = best
            if k > 1 and lls[k] < lls[k - 1]:  # EM stuck below the nested K − 1 optimum
                lls[k] = lls[k - 1]
            bics[k] = bic_score(lls[k], n_fit, n_eff, 3 * k - 1)
    k_best = min(bics, key=bics.get)
    gm = fits[k_best]
    comps = [(float(w), float(m), float(math.sqrt(c)))
             for w, m, c in zip(gm.weights_, gm.means_[:, 0], gm.covariances_.ravel())
             if w > 0]
    return MixtureFit(ThicknessMixture(comps), bics[k_best], bics, n, n_eff,
                      k_note(k_max, max_components, uniq.size, n_eff, "values"), n_fit, lls)


def k_note(k_max, max_components, n_unique, n_eff, what):
    if k_max >= max_components:
        return False
    if n_unique <= k_max:
        return f"only {n_unique} distinct {what}: max_components reduced to {k_max}"
    return f"n_effective {n_eff:g}: max_components reduced to {k_max} (parameters <= n_effective)"
