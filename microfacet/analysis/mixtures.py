"""Fitting the thickness mixture and the NDF lobes to per-pixel samples, and comparing them.

Thickness (:func:`fit_thickness_mixture`)
    A 1-D Gaussian mixture with free means, fitted with scikit-learn's
    ``GaussianMixture`` for K = 1 … ``max_components``; K is chosen by BIC.

Facet normals (:func:`fit_ndf_mixture`)
    A mixture of zero-mean Gaussian-slope lobes (:class:`~microfacet.core.distributions.NDFMixture`).
    The slope magnitude ``m = tan θ`` of a pixel is then a mixture of Rayleigh
    distributions, ``f(m) = Σ w_k (m / σ_k²) exp(−m² / 2σ_k²)``, fitted by EM:
    responsibilities ``r_k ∝ w_k σ_k⁻² exp(−m² / 2σ_k²)``,
    ``σ_k² = Σ r_k m² / (2 Σ r_k)``, ``w_k = Σ r_k / n``. Several deterministic starts
    (quantile blocks, a geometric spread, the K − 1 solution plus a wide or a narrow
    lobe, or with its heaviest lobe split), each run briefly, the best one to
    convergence; K = 1 … ``max_components`` by BIC with ``p = 2K − 1`` parameters.

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

Histograms (:func:`histogram_density`, :func:`pdf_table`, :func:`ndf_D_from_tilt_histogram`)
    A histogram of per-pixel tilts counts projected area (one pixel = one unit of
    projected area), so its density already *is* the tilt density ``p(θ)`` that
    :meth:`NDFMixture.tilt_pdf` models — the ``sin θ`` of the solid-angle element is
    inside ``p(θ)``; do not divide the histogram by ``sin θ`` to compare it with the fit.
    Dividing by ``2π sin θ cos θ`` (:func:`ndf_D_from_tilt_histogram`) gives the NDF D
    per steradian for those who want it.

Distances (:func:`wasserstein1`, :func:`wasserstein1_pdf`)
    The 1-D earth mover's distance, between samples or between densities on a grid.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

from ..core.distributions import NDFMixture, ThicknessMixture

__all__ = [
    "MixtureFit",
    "fit_ndf_mixture",
    "fit_thickness_mixture",
    "histogram_density",
    "ndf_D_from_tilt_histogram",
    "pdf_table",
    "wasserstein1",
    "wasserstein1_pdf",
]

_DEG = math.pi / 180.0
_LOG_2PI = math.log(2.0 * math.pi)
_M_LOG_FLOOR = 1e-6  # slope magnitude at which log m is evaluated for tilts of exactly 0


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


def _positive_int(x, name):
    if isinstance(x, bool) or not isinstance(x, (int, np.integer)) or x < 1:
        raise ValueError(f"{name}: expected an integer >= 1, got {x!r}")
    return int(x)


def _prepare(values, name, weights, group, max_samples, random_state):
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


def _single_thread():
    """Limit BLAS/OpenMP to one thread: 1-D mixtures gain nothing from threads, and on a
    busy machine thread contention makes them many times slower."""
    try:
        from threadpoolctl import threadpool_limits
    except ImportError:  # pragma: no cover - threadpoolctl comes with scikit-learn
        import contextlib

        return contextlib.nullcontext()
    return threadpool_limits(limits=1)


def _bic(loglik_fit, n_fit, n_eff, p):
    """BIC with the log-likelihood of ``n_fit`` samples rescaled to ``n_eff`` observations."""
    return -2.0 * loglik_fit * (n_eff / n_fit) + p * math.log(n_eff)


def _k_max(max_components, n_unique, n_eff, params_per_k, extra):
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
    max_components = _positive_int(max_components, "max_components")
    max_samples = _positive_int(max_samples, "max_samples")
    sd_floor_nm = float(sd_floor_nm)
    if not (math.isfinite(sd_floor_nm) and sd_floor_nm > 0):
        raise ValueError(f"sd_floor_nm: must be finite and > 0, got {sd_floor_nm!r}")
    x, n, n_eff, _ = _prepare(thickness_nm, "thickness_nm", weights, group, max_samples,
                              random_state)
    n_fit = x.size
    uniq = np.unique(x)

    if uniq.size == 1:
        v = float(uniq[0])
        ll = n_fit * (-math.log(sd_floor_nm) - 0.5 * _LOG_2PI)
        bic = _bic(ll, n_fit, n_eff, 2)
        return MixtureFit(ThicknessMixture([(1.0, v, sd_floor_nm)]), bic, {1: bic}, n, n_eff,
                          f"single value {v:g} nm: one component with floor sd "
                          f"{sd_floor_nm:g} nm", n_fit, {1: ll})

    import warnings

    from sklearn.exceptions import ConvergenceWarning
    from sklearn.mixture import GaussianMixture

    k_max = _k_max(max_components, uniq.size, n_eff, 3, -1)
    X = x[:, None]
    fits, bics, lls = {}, {}, {}
    with _single_thread(), warnings.catch_warnings():
        # an unconverged over-sized K only loses in the BIC; no need to warn
        warnings.simplefilter("ignore", ConvergenceWarning)
        for k in range(1, k_max + 1):
            # two starts: k-means (seeded) and the k quantiles; keep the higher likelihood
            q = np.quantile(x, (np.arange(k) + 0.5) / k)[:, None]
            best = None
            for kw in ({"init_params": "kmeans"}, {"means_init": q}):
                gm = GaussianMixture(n_components=k, covariance_type="full",
                                     reg_covar=sd_floor_nm ** 2, max_iter=500, tol=1e-5,
                                     random_state=random_state, **kw)
                gm.fit(X)
                ll = float(gm.score(X)) * n_fit
                if best is None or ll > best[1]:
                    best = (gm, ll)
            fits[k], lls[k] = best
            if k > 1 and lls[k] < lls[k - 1]:  # EM stuck below the nested K − 1 optimum
                lls[k] = lls[k - 1]
            bics[k] = _bic(lls[k], n_fit, n_eff, 3 * k - 1)
    k_best = min(bics, key=bics.get)
    gm = fits[k_best]
    comps = [(float(w), float(m), float(math.sqrt(c)))
             for w, m, c in zip(gm.weights_, gm.means_[:, 0], gm.covariances_.ravel())
             if w > 0]
    return MixtureFit(ThicknessMixture(comps), bics[k_best], bics, n, n_eff,
                      _k_note(k_max, max_components, uniq.size, n_eff, "values"), n_fit, lls)


def _k_note(k_max, max_components, n_unique, n_eff, what):
    if k_max >= max_components:
        return False
    if n_unique <= k_max:
        return f"only {n_unique} distinct {what}: max_components reduced to {k_max}"
    return f"n_effective {n_eff:g}: max_components reduced to {k_max} (parameters <= n_effective)"


# -------------------------------------------------------------------------------- NDF


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
    max_components = _positive_int(max_components, "max_components")
    max_samples = _positive_int(max_samples, "max_samples")
    sd_floor_deg = float(sd_floor_deg)
    if not (math.isfinite(sd_floor_deg) and 0 < sd_floor_deg < 89):
        raise ValueError(f"sd_floor_deg: must be in (0, 89), got {sd_floor_deg!r}")
    th, n, n_eff, _ = _prepare(tilt_deg, "tilt_deg", None, group, max_samples, random_state)
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
        bic = _bic(ll, n_fit, n_eff, 1)
        return MixtureFit(NDFMixture([(1.0, sd_floor_deg)]), bic, {1: bic}, n, n_eff,
                          f"all tilts are 0: one lobe with floor sd {sd_floor_deg:g} deg",
                          n_fit, {1: ll})

    k_max = _k_max(max_components, uniq.size, n_eff, 2, -1)
    order = np.sort(m2)
    med = float(np.median(m2))
    q_lo, q_hi = (float(v) for v in np.quantile(m2, [0.05, 0.95]))
    sols, bics, lls = {}, {}, {}
    with _single_thread():
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
            bics[k] = _bic(lls[k], n_fit, n_eff, 2 * k - 1)
    k_best = min(bics, key=bics.get)
    w, s2 = sols[k_best]
    sd = np.degrees(np.arctan(np.sqrt(s2)))
    comps = [(float(a), float(b)) for a, b in zip(w, sd) if a > 1e-12]
    return MixtureFit(NDFMixture(comps), bics[k_best], bics, n, n_eff,
                      _k_note(k_max, max_components, uniq.size, n_eff, "tilts"), n_fit, lls)


# ------------------------------------------------------------------ histograms, tables


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


def _cells(grid):
    g = np.asarray(grid, dtype=np.float64)
    if g.ndim != 1 or g.size < 2 or not np.all(np.isfinite(g)) or np.any(np.diff(g) <= 0):
        raise ValueError("grid: expected a strictly increasing 1-D array of >= 2 finite values")
    mid = 0.5 * (g[1:] + g[:-1])
    edges = np.concatenate([[g[0] - (mid[0] - g[0])], mid, [g[-1] + (g[-1] - mid[-1])]])
    return g, edges


def _mixture_cdf(mixture, x):
    x = np.asarray(x, dtype=np.float64)
    if isinstance(mixture, ThicknessMixture):
        from scipy.special import ndtr

        z = (x[:, None] - mixture.means_nm) / mixture.sds_nm
        return np.sum(mixture.weights * ndtr(z), axis=1)
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
    g, edges = _cells(grid)
    _, hist = histogram_density(values, bins=edges)
    cdf = _mixture_cdf(mixture, edges)
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
    from scipy.stats import wasserstein_distance

    return float(wasserstein_distance(_finite_1d(samples_a, "samples_a"),
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
    from scipy.integrate import cumulative_trapezoid

    g, _ = _cells(grid)
    out = []
    for name, p in (("pdf_a", pdf_a), ("pdf_b", pdf_b)):
        p = np.asarray(p, dtype=np.float64)
        if p.shape != g.shape:
            raise ValueError(f"{name}: shape {p.shape} does not match grid {g.shape}")
        if not np.all(np.isfinite(p)) or np.any(p < 0):
            raise ValueError(f"{name}: must be finite and >= 0")
        F = cumulative_trapezoid(p, g, initial=0.0)
        if not F[-1] > 0:
            raise ValueError(f"{name}: has no mass on the grid")
        out.append(F / F[-1])
    return float(np.trapezoid(np.abs(out[0] - out[1]), g))
