"""Fitting the thickness mixture, and the model choice both mixture fits use.

Thickness (:func:`fit_thickness_mixture`)
    A 1-D Gaussian mixture with free means fitted by EM with per-sample noise ("extreme
    deconvolution", Bovy, Hogg & Roweis 2011, in one dimension): sample ``i`` measured with
    error σ_i has density ``Σ w_k N(x_i; μ_k, s_k² + σ_i²)``, so the components describe the
    *true* thickness, not the noisy estimates. Samples may carry weights (area). This is our
    own EM rather than scikit-learn's ``GaussianMixture``, which takes neither per-sample
    noise nor sample weights.

Facet normals
    :func:`microfacet.analysis.ndf_fit.fit_ndf_mixture` (zero-mean Gaussian-slope lobes,
    the same deconvolution, plus censoring), with the model choice below.

Model choice with an honest number of independent samples (both fitters)
    ``BIC = −2 (n_eff / W) ℓ + p log n_eff``, where ℓ is the (weighted) log-likelihood of
    the samples the mixture was fitted to, W their total weight and ``p`` the number of free
    parameters (3K − 1 for the thickness, 2K − 1 for the NDF).

    **Per-pixel values are not independent**: a thickness region or a facet of thousands of
    pixels shares one thickness or tilt, and the usual BIC, with n in the tens of thousands,
    rewards a narrow component for every large region. ``n_eff`` is therefore the number of
    independent observations: ``n_effective`` when given (the number of independent
    thickness regions, :attr:`microfacet.analysis.sampling.Regions.effective_count`, or
    the number of facets), else the number of distinct ``group`` ids, else the Kish size
    ``(Σw)² / Σw²`` of the weights, else the number of samples.

    A K whose solution has a component carried by fewer than ``min_component_samples``
    regions (``w_k`` × the regions' plain count when their ``Regions`` are given, else
    ``n_eff``) or with its SD at the floor describes a sample or a spike, not a population:
    it is not admissible, whatever its BIC. K is also limited to the number of distinct
    values and to ``p ≤`` that number of regions; ``degenerate`` says when a limit applied.
    (The Kish size weighs a population on one small region below one region: counted so, a
    population 190 nm from the others was left out at eight regions.) The thickness
    components' SD also has a ceiling where ``thickness_max_sd_nm`` sets one (a population
    does not span interference orders).
    Of the admissible K, the smallest within 2 of the least BIC is chosen (a larger K must
    earn "positive evidence"). ``bic_margin`` is the least BIC of the other admissible K minus
    that of the chosen one (≥ 10: very strong evidence for the choice; near 0 or negative,
    down to −2: a toss-up decided for the simpler model).

The EM (both fitters)
    For each K a few starts (quantiles, the K − 1 solution split or with a component added)
    take 25 EM updates, and the most likely is run to convergence (:func:`run_em`).
    Identical samples are fitted as one, with their summed weight
    (:func:`~microfacet.analysis.sampling.collapse`); the updates are computed from sums
    over (component, sample) arrays, without per-update temporaries.

References
----------
.. [1] N. Nagata, M. Kamei, K. Takahashi, K. Tobitani, T. Akagi, S. Yamamura, "Simulation
   Technology for Titanium Oxide Layer Interference Color", Technical Report (the seed paper),
   §3.3.3 and Fig. 18 (the thickness distribution as three Gaussians).
.. [2] A. P. Dempster, N. M. Laird, D. B. Rubin, "Maximum likelihood from incomplete data via
   the EM algorithm", J. R. Stat. Soc. B 39(1) (1977) 1-38,
   doi:10.1111/j.2517-6161.1977.tb01600.x.
.. [3] J. Bovy, D. W. Hogg, S. T. Roweis, "Extreme deconvolution: inferring complete
   distribution functions from noisy, heterogeneous and incomplete observations", Ann. Appl.
   Stat. 5(2B) (2011) 1657-1677, doi:10.1214/10-AOAS439.
.. [4] G. Schwarz, "Estimating the dimension of a model", Ann. Statist. 6(2) (1978) 461-464,
   doi:10.1214/aos/1176344136.
.. [5] R. E. Kass, A. E. Raftery, "Bayes factors", J. Am. Stat. Assoc. 90(430) (1995) 773-795,
   doi:10.1080/01621459.1995.10476572 (the evidence scale of BIC differences).
.. [6] L. Kish, *Survey Sampling*, Wiley, New York (1965) (the effective sample size).
"""

from __future__ import annotations

import math
from dataclasses import asdict, dataclass, field

import numpy as np

from ..core.distributions import ThicknessMixture
from ..core.lazy import load
from ..io.jsonfile import json_safe
from .options import FitOptions
from .sampling import GRAIN_MIN_SCALE, Regions, Samples, area_weighted_size, collapse, prepare
from .sampling import special as _special

threadpoolctl = load("threadpoolctl")

__all__ = ["MixtureFit", "PopulationCandidate", "choose_k", "fit_thickness_mixture",
           "population_candidates"]

_LOG_2PI = math.log(2.0 * math.pi)


@dataclass
class MixtureFit:
    """Result of :func:`fit_thickness_mixture` or :func:`fit_ndf_mixture`.

    Attributes
    ----------
    mixture : ThicknessMixture or NDFMixture
        The mixture with the chosen number of components K.
    bic : float
        BIC of the chosen K (see the module notes).
    bic_by_k : dict of int to float
        BIC of every K that was fitted (``info["inadmissible_k"]`` lists those not
        allowed to win: a component on fewer than ``min_component_samples`` independent
        samples or at the SD floor).
    n_samples : int
        Finite samples given (after dropping NaN and zero weights).
    n_effective : float
        The number of independent observations the BIC used.
    degenerate : bool or str
        ``False``, or a short description of the degenerate case handled.
    n_fit : int
        Samples the mixture was actually fitted to (≤ ``max_samples``).
    log_likelihood_by_k : dict of int to float
        Weighted log-likelihood of the fitted samples for each K (density per nm, or tilt
        density per degree), before the ``n_eff / W`` scaling.
    bic_margin : float or None
        BIC of the best other admissible K minus the chosen one's (None: only one K).
    info : dict
        Fit-specific numbers (e.g. censored fraction, facets used).
    """

    mixture: object
    bic: float
    bic_by_k: dict
    n_samples: int
    n_effective: float
    degenerate: object = False
    n_fit: int = 0
    log_likelihood_by_k: dict = field(default_factory=dict, repr=False)
    bic_margin: float | None = None
    info: dict = field(default_factory=dict)

    @property
    def n_components(self) -> int:
        return len(self.mixture.components)

    def to_json(self) -> dict:
        """``{"components": [...], "bic", "bic_by_k", "bic_margin", "n_effective", ...}``
        (plus ``form`` for the NDF; whether it is identified is the analysis' judgement,
        :mod:`.identification`); ``bic_by_k`` keys are strings; JSON-safe."""
        out = dict(self.mixture.to_json())
        out.update(bic=self.bic, bic_by_k={str(k): v for k, v in sorted(self.bic_by_k.items())},
                   bic_margin=self.bic_margin, n_effective=self.n_effective,
                   n_samples=int(self.n_samples),
                   degenerate=self.degenerate if isinstance(self.degenerate, str)
                   else bool(self.degenerate))
        out.update(self.info)
        if "candidates" in out:
            out["candidates"] = [c.to_json() for c in out["candidates"]]
        return json_safe(out)


def single_thread():
    """Limit BLAS/OpenMP to one thread: 1-D mixtures gain nothing from threads, and on a
    busy machine thread contention makes them many times slower."""
    return threadpoolctl.threadpool_limits(limits=1)


def bic_score(loglik_fit, w_total, n_eff, p):
    """BIC with the log-likelihood of samples of total weight ``w_total`` rescaled to
    ``n_eff`` independent observations."""
    return -2.0 * loglik_fit * (n_eff / w_total) + p * math.log(max(n_eff, 1.0))


def k_max_for(max_components, n_unique, n_eff, params_per_k, extra):
    """Largest K with K ≤ distinct values and p = params_per_k·K + extra ≤ n_eff (≥ 1)."""
    k_by_p = int(math.floor((n_eff - extra) / params_per_k + 1e-9))
    return max(1, min(max_components, n_unique, k_by_p))


def k_note(k_max, max_components, n_unique, n_eff, what):
    if k_max >= max_components:
        return False
    if n_unique <= k_max:
        return f"only {n_unique} distinct {what}: max_components reduced to {k_max}"
    return (f"{n_eff:g} independent samples (regions or facets): max_components reduced to "
            f"{k_max} (parameters <= independent samples)")


#: A larger K must beat every smaller admissible K by at least this much BIC ("positive
#: evidence", Kass & Raftery 1995); below it the data do not ask for the extra component.
PARSIMONY_BIC = 2.0
#: Largest weight of the thickness fit's uniform background (the samples no population
#: explains: a few isolated facets; facets whose colour the model does not explain are left
#: out before the fit). A background that may hold more than that is a cheaper explanation
#: of a small population than a Gaussian with its parameters, at every K alike, and takes
#: the evidence for it: without a cap the fixture re-exposed by -5 % lost populations
#: (tests/analysis/test_pipeline.py -k encoding), and at 5 % a population of 14 % of the
#: area lost a third of its weight to it and was not found (accuracy-sweep seed 3 g020).
#: Refitted on the five sweep draws' facets, the true count by cap: 0 (no background) 82,
#: 0.005 113, 0.01 112, 0.02 108, 0.05 107 of 150 (docs/accuracy.md): what it must absorb
#: is about a percent, half the smallest population the sweep counts (2 % of the area).
BACKGROUND_MAX = 0.01


def choose_k(fits, n_eff, min_component_samples):
    """The smallest admissible K within :data:`PARSIMONY_BIC` of the least BIC, and its
    margin (the least BIC of the other admissible K minus its own).

    ``fits``: K → (bic, weights, inadmissible). Returns ``(k, margin, admissible_bics)``.
    K = 1 is always admissible.
    """
    ok = {}
    for k, (bic, w, bad) in fits.items():
        if k == 1 or (np.min(w) * n_eff >= min_component_samples and not bad):
            ok[k] = bic
    least = min(ok.values())
    k_best = min(k for k, v in ok.items() if v <= least + PARSIMONY_BIC)
    others = [v for k, v in ok.items() if k != k_best]
    margin = (min(others) - ok[k_best]) if others else None
    return k_best, margin, ok


# -------------------------------------------------------------------------------- EM


def run_em(step, params, *, max_iter, tol):
    """Iterate an EM map from ``params``; returns ``(params, ℓ(params))``.

    ``step(params) -> (ℓ(params), next params)``. Stops after ``max_iter`` updates or when an
    update raises ℓ by at most ``tol``, returning the last parameters evaluated.
    """
    ll0, p1 = step(params)
    for _ in range(max_iter):
        ll1, p2 = step(p1)
        if ll1 - ll0 <= tol:
            return p1, ll1
        ll0, params, p1 = ll1, p1, p2
    return params, ll0


def _xd_em(data, start, s2_floor, *, bg=0.0, s2_max=math.inf, max_iter=300, tol=1e-8):
    """Weighted 1-D extreme-deconvolution EM from ``start = (w, mu, s2)`` on
    ``data = (x, v, a)`` (values, error variances, weights); returns (w, mu, s2, ℓ, w_bg).
    The variances are kept within ``[s2_floor, s2_max]``.

    ``bg`` > 0: a uniform background of that density (1/span) joins the Gaussians with its
    own weight ``w_bg`` ≤ :data:`BACKGROUND_MAX` (the samples no population explains); ``w``
    and ``w_bg`` sum to 1.
    Stops when an iteration raises ℓ by less than ``tol`` × total weight (:func:`run_em`).

    The arrays are laid out (component, sample), reused, and the M-step uses the sums
    ``Σ q d``, ``Σ q d²/V`` and ``Σ q σ²`` (``q = a r / V``, ``d = x − μ``): with the
    posterior mean ``b = μ + s² d / V`` and variance ``B = s² σ² / V`` of the true value,
    ``Σ a r b = n μ + s² Σ q d`` and ``Σ a r ((b − μ′)² + B) = s⁴ Σ q d²/V + s² Σ q σ²
    − n (μ′ − μ)²``: the textbook updates without their (K, n) temporaries.
    """
    x, v, a = data
    w, mu, s2 = start
    W = float(a.sum())
    w = np.asarray(w, dtype=np.float64) / np.sum(w)
    w_bg = 0.0
    if bg > 0:
        w, w_bg = w * (1.0 - BACKGROUND_MAX), BACKGROUND_MAX
    work = [np.empty((len(w), x.size)) for _ in range(3)]     # reused (K, n) arrays
    log_bg = math.log(bg) if bg > 0 else 0.0
    x0 = float(np.mean(x))
    x_rel = x - x0                                # Σ q d = Σ q (x − x0) − (μ − x0) Σ q

    def step(p):
        w, mu, s2, w_bg = p
        lp, iv, z = work
        np.add(s2[:, None], v, out=lp)            # V = s² + σ²
        np.divide(1.0, lp, out=iv)
        np.log(lp, out=lp)
        np.subtract(x, mu[:, None], out=z)
        z *= z
        z *= iv                                   # (x − μ)² / V
        lp += z
        lp *= -0.5
        lp += (np.log(np.maximum(w, 1e-300)) - 0.5 * _LOG_2PI)[:, None]
        m = lp.max(axis=0)
        if bg > 0:
            lbg = math.log(max(w_bg, 1e-300)) + log_bg
            np.maximum(m, lbg, out=m)
        lp -= m
        e = np.exp(lp, out=lp)
        tot = e.sum(axis=0)
        if bg > 0:
            e_bg = np.exp(lbg - m)
            tot += e_bg
        lt = np.log(tot)
        lt += m
        ll = float(a @ lt)
        at = np.divide(a, tot, out=tot)           # a r = e · a / tot
        n_raw = e @ at
        nk = np.maximum(n_raw, 1e-300)
        q = e
        q *= at
        q *= iv                                   # a r / V
        shift = s2 * (q @ x_rel - (mu - x0) * q.sum(axis=1)) / nk
        s2_new = (s2 * s2 * np.einsum("kn,kn->k", q, z) + s2 * (q @ v)) / nk - shift * shift
        wk, wb = nk / W, float(at @ e_bg / W) if bg > 0 else 0.0
        if wb > BACKGROUND_MAX:                   # the background explains outliers only
            wk, wb = wk * (1.0 - BACKGROUND_MAX) / max(1.0 - wb, 1e-12), BACKGROUND_MAX
        return ll, (wk, np.where(n_raw > 0, mu + shift, 0.0),
                    np.clip(s2_new, s2_floor, s2_max), wb)

    p0 = (w, np.array(mu, dtype=np.float64),
          np.clip(np.asarray(s2, dtype=np.float64), s2_floor, s2_max), w_bg)
    (w, mu, s2, w_bg), ll = run_em(step, p0, max_iter=max_iter, tol=tol * W)
    return w, mu, s2, ll, w_bg


# -------------------------------------------------------------------------- thickness


def _unexplained_cluster(x, a, dens, floor_density, *, width=2.0):
    """Centre of the heaviest cluster (Gaussian kernel of ``width`` nm, on a grid of
    width/4) of samples weighted by how badly the current components explain them
    (area / (1 + density / floor))."""
    u = a / (1.0 + dens / floor_density)
    step = width / 4.0
    i = np.floor((x - x.min()) / step).astype(np.int64)
    h = np.bincount(i, weights=u)
    kern = np.exp(-0.5 * (np.arange(-16, 17) / 4.0) ** 2)
    s = np.convolve(h, kern, mode="same")
    return float(x.min() + (int(np.argmax(s)) + 0.5) * step)


def _weighted_quantiles(x, a, q):
    o = np.argsort(x)
    c = np.cumsum(a[o])
    return np.interp(np.asarray(q) * c[-1], c - 0.5 * a[o], x[o])


def _thickness_starts(k, d, sols, bg):
    """Starting points of the EM for K = ``k``: quantiles; with ``k`` > 1 the K − 1 solution
    with its widest-heaviest component split, or with a component added at the worst-fitted
    sample or at the heaviest cluster of badly fitted samples."""
    x, a, v = d.x, d.a, d.v
    q = _weighted_quantiles(x, a, (np.arange(k) + 0.5) / k)
    starts = [(np.ones(k), q, np.full(k, (d.spread / k) ** 2))]
    if k == 1:
        return starts
    wp, mp, sp = sols[k - 1]
    j = int(np.argmax(wp * np.sqrt(sp)))           # split the widest-heaviest
    dj = math.sqrt(sp[j])
    starts.append((np.append(np.delete(wp, j), [wp[j] / 2] * 2),
                   np.append(np.delete(mp, j), [mp[j] - dj, mp[j] + dj]),
                   np.append(np.delete(sp, j), [sp[j] / 2] * 2)))
    dens = np.zeros(x.size)
    for wk, mk, sk in zip(wp, mp, sp):
        V = sk + v
        dens += wk * np.exp(-(x - mk) ** 2 / (2 * V)) / np.sqrt(V)
    i = int(np.argmin(dens))
    starts.append((np.append(wp * 0.9, 0.1), np.append(mp, x[i]),
                   np.append(sp, (d.spread / k) ** 2)))
    c = _unexplained_cluster(x, a, dens, max(bg, 1e-3 / max(d.spread, 1e-9)))
    starts.append((np.append(wp * 0.9, 0.1), np.append(mp, c),
                   np.append(sp, max(float(np.median(v)), d.s2_floor))))
    return starts


@dataclass
class _Data:
    """The prepared samples of one fit and what every K shares: ``n_eff`` the independent
    samples admissibility counts (the regions' plain count when given), ``n_bic`` those
    the BIC counts (their Kish count)."""

    x: np.ndarray
    a: np.ndarray
    v: np.ndarray
    collapsed: tuple
    s2_floor: float
    spread: float
    n_eff: float
    min_samples: float
    bounded: bool
    n_bic: float
    max_s2: float = math.inf


def _thickness_data(x, a, v, opts: FitOptions, n_count, n_eff) -> _Data:
    """What every K of a thickness fit shares (:class:`_Data`): the distinct (value, error)
    pairs the EM runs on, the SD floor and ceiling, the samples' spread beyond their errors."""
    s2_floor = opts.thickness_sd_floor_nm ** 2
    ceiling = opts.thickness_max_sd_nm
    spread = float(np.sqrt(max(np.average((x - np.average(x, weights=a)) ** 2, weights=a)
                               - np.average(v, weights=a), s2_floor)))
    ac, xc, vc = collapse(a, x, v)   # the EM on distinct (value, error) pairs
    # With measurement errors well above the floor, a component at the floor has a bounded
    # likelihood (its spread is below the resolution, e.g. a population seen in one region):
    # admissible. Without, it is a spike on repeated values: not admissible.
    return _Data(x, a, v, (xc, vc, ac), s2_floor, spread, n_count,
                 opts.thickness_min_component_samples,
                 float(np.average(v, weights=a)) >= 4.0 * s2_floor, n_eff,
                 math.inf if ceiling is None else float(ceiling) ** 2)


def _fit_k(k, d, sols, bg):
    """The most likely admissible of the starts for K = ``k`` after 25 EM updates, converged;
    returns (w, mu, s2, ℓ, w_bg, admissible)."""
    def admissible(r):
        return k == 1 or (np.min(r[0]) * d.n_eff >= d.min_samples and not (
            np.any(r[2] <= d.s2_floor * 1.0001) and not d.bounded))

    runs = [_xd_em(d.collapsed, st, d.s2_floor, bg=bg, s2_max=d.max_s2, max_iter=25)
            for st in _thickness_starts(k, d, sols, bg)]
    # the most likely admissible start, converged (a spike on a few samples may be more
    # likely, and is not a population); then checked again
    pre = [r for r in runs if admissible(r)] or runs
    w, mu, s2, ll, w_bg = _xd_em(d.collapsed, max(pre, key=lambda r: r[3])[:3], d.s2_floor,
                                 bg=bg, s2_max=d.max_s2)
    return w, mu, s2, ll, w_bg, admissible((w, mu, s2))


def fit_thickness_mixture(thickness_nm, *, sigma_nm=None, weights=None, group=None,
                          n_effective=None, options: FitOptions | None = None,
                          background=False, seed=0) -> MixtureFit:
    """Gaussian mixture of the true oxide thickness, number of components by BIC.

    Parameters
    ----------
    thickness_nm : array_like, any shape
        Thickness samples in nm (per pixel, per facet, per region). NaN is ignored.
    sigma_nm : array_like or float, optional
        1-σ measurement error of each sample (nm): the components are deconvolved from it.
    weights : array_like, same shape, optional
        Non-negative sample weights (e.g. facet areas).
    group : array_like, same shape, optional
        Region / facet id per sample: without ``n_effective``, the number of distinct groups
        is the number of independent observations.
    n_effective : float or Regions, optional
        The number of independent observations (see the module notes). Given the samples'
        :class:`~microfacet.analysis.sampling.Regions`, the BIC counts their
        ``effective_count`` (at least 1) and admissibility and the limit on K their plain
        ``count`` (``w_k`` × count ≥ ``thickness_min_component_samples``, ``3K − 1`` ≤
        count): the Kish count of the regions' areas weighs a population on one small
        region below one region, and at a few regions left a population 190 nm from the
        others out (accuracy-sweep g028).
    options : FitOptions, optional
        ``max_components`` (largest K tried; also limited to the number of distinct values
        and to ``3K − 1 ≤ n_effective``); ``thickness_sd_floor_nm`` (smallest component SD:
        a single distinct value is one component at the floor, ``degenerate`` says so; for
        K ≥ 2 a component at the floor is not admissible unless the samples' errors, mean
        σ² ≥ 4 floor², bound its likelihood); ``thickness_max_sd_nm`` (largest component
        SD, a ceiling: the EM's variance update is clipped to it, the constrained maximum;
        None: none; ``info["sd_ceiling_nm"]`` records it);
        ``thickness_min_component_samples`` (fewest independent samples ``w_k n_eff`` a
        component of a K ≥ 2 solution needs); ``thickness_max_samples`` (larger inputs are
        subsampled with ``seed``).
    background : bool, optional
        Fit, beside the K Gaussians, a uniform background over the samples' span with its
        own weight (one more parameter for every K): samples no population explains (dust,
        pit floors, mis-fitted facets) then neither ask for components of their own nor
        widen the populations. The components returned are the populations' mixture
        (weights renormalised without it); ``info["background_weight"]`` is its weight.
    seed : int, optional

    Returns
    -------
    MixtureFit
        ``mixture`` is a :class:`~microfacet.core.distributions.ThicknessMixture`.

    Raises
    ------
    ValueError
        No finite values, infinite values, or bad samples (the message names the argument).

    Examples
    --------
    >>> rng = np.random.default_rng(0)
    >>> d = np.concatenate([rng.normal(120, 3, 4000), rng.normal(140, 3, 6000)])
    >>> fit = fit_thickness_mixture(d + rng.normal(0, 2, d.size), sigma_nm=2.0)
    >>> fit.n_components, [round(m) for m in fit.mixture.means_nm]
    (2, [120, 140])
    >>> [round(float(s), 1) for s in fit.mixture.sds_nm]     # the noise of 2 nm deconvolved
    [3.0, 3.0]
    """
    opts = FitOptions() if options is None else options
    sd_floor_nm = opts.thickness_sd_floor_nm
    n_regions, regions = None, n_effective
    if isinstance(n_effective, Regions):
        n_regions, n_effective = n_effective.count, max(1.0, n_effective.effective_count)
    x, a, s, n, n_eff = prepare(Samples(thickness_nm, sigma_nm, weights, group, n_effective,
                                        "thickness_nm", "sigma_nm"),
                                max_samples=opts.thickness_max_samples, seed=seed)
    v = s * s
    W = float(a.sum())
    uniq = np.unique(x)
    if uniq.size == 1 and not np.any(v > 0):
        val = float(uniq[0])
        ll = W * (-math.log(sd_floor_nm) - 0.5 * _LOG_2PI)
        bic = bic_score(ll, W, n_eff, 2)
        return MixtureFit(ThicknessMixture([(1.0, val, sd_floor_nm)]), bic, {1: bic}, n, n_eff,
                          f"single value {val:g} nm: one component with floor sd "
                          f"{sd_floor_nm:g} nm", x.size, {1: ll})
    n_count = n_eff if n_regions is None else max(float(n_regions), n_eff)
    k_max = k_max_for(opts.max_components, uniq.size, n_count, 3, -1)
    d = _thickness_data(x, a, v, opts, n_count, n_eff)
    # the background: uniform over the samples' span (padded by the SD floor and errors)
    span = float(x.max() - x.min()) + 4.0 * float(np.sqrt(np.max(v)) if v.size else 0.0) \
        + 2.0 * sd_floor_nm
    bg = 1.0 / span if background and uniq.size > 2 else 0.0
    sols, lls, fits, bgw = {}, {}, {}, {}
    with single_thread():
        for k in range(1, k_max + 1):
            w, mu, s2, ll, bgw[k], good = _fit_k(k, d, sols, bg)
            sols[k] = (w, mu, s2)
            lls[k] = max(ll, lls.get(k - 1, -np.inf))      # never below the nested optimum
            fits[k] = (bic_score(lls[k], W, n_eff, 3 * k - 1 + (bg > 0)), w, not good)
    k_best, margin, ok = choose_k(fits, n_count, d.min_samples)
    bics = {k: f[0] for k, f in fits.items()}
    mixture = _as_mixture(*sols[k_best])
    info = {"inadmissible_k": sorted(set(bics) - set(ok)), "background_weight": bgw[k_best],
            "sd_ceiling_nm": opts.thickness_max_sd_nm}
    bic = bics[k_best]
    if n_regions is not None:
        sol, ll, k = _grains_taken(d, (sols[k_best], lls[k_best], bg), regions, k_max, info)
        if k > k_best:
            mixture, bic = _as_mixture(*sol), bic_score(ll, W, n_eff, 3 * k - 1 + (bg > 0))
    info["sd_at_floor"] = [i for i, c in enumerate(mixture.components)
                           if c[2] <= sd_floor_nm * 1.0001]
    return MixtureFit(mixture, bic, bics, n, n_eff,
                      k_note(k_max, opts.max_components, uniq.size, n_count, "values"), x.size,
                      lls, bic_margin=margin, info=info)


# ------------------------------------------------------------------------- candidates

#: A region farther than this many SD (its own error, the population's SD and the floor in
#: quadrature) from every population of the chosen mixture is not explained by it.
CANDIDATE_Z = 4.0
#: A candidate whose facets' median ΔE00 exceeds this multiple of the populations' (+0.5)
#: is not explained by the film model: mis-read regions (a wrong order, dust), not a
#: population.
CANDIDATE_MISFIT = 1.5
#: Largest area multiple of the field at which a reported candidate would be decided (a
#: field 4× the side); candidates that need more are a few regions' worth of area, kept in
#: summary.json only.
CANDIDATE_MAX_FIELD_SCALE = 16.0
#: The field scales tried for the size at which a candidate would be decided (area ×).
_FIELD_SCALES = np.geomspace(1.0, 1e4, 401)


def colour_explained(delta_e, delta_e_populations) -> bool:
    """Whether samples of median colour misfit ``delta_e`` (ΔE00) fit the film as well as
    the populations' (median ``delta_e_populations``): at most :data:`CANDIDATE_MISFIT` ×
    theirs, + 0.5. Else they are mis-read regions or facets, not a population (a candidate's
    :attr:`PopulationCandidate.colour_explained`, a minor component's
    :func:`~.consistency.misread_components`).

    >>> colour_explained(1.9, 1.0), colour_explained(2.1, 1.0)
    (True, False)
    """
    return bool(delta_e <= CANDIDATE_MISFIT * delta_e_populations + 0.5)


@dataclass
class PopulationCandidate:
    """A population the regions suggest but the field does not decide
    (:func:`population_candidates`).

    Attributes
    ----------
    mean_nm : float
        Area-weighted mean thickness of its regions (nm).
    sd_nm : float or None
        Area-weighted SD of its regions' thicknesses (None: one region).
    area_fraction : float
        Its regions' share of the area of all regions with a thickness.
    regions : int
        Regions it covers.
    field_scale : float or None
        How many times the analysed field's area would decide it as a population (the BIC
        of the mixture with it as a component, at the same composition, beats the chosen
        one's by the parsimony margin, and it and K + 1 components pass the region limits);
        None: no field up to 10⁴ × would (it does not look like a population).
    region_index : ndarray of int
        Its regions (indices into the fit's :class:`~.sampling.Regions`; not written).
    delta_e : float or None
        Median colour misfit (ΔE00) of its facets, where the caller knows it.
    delta_e_populations : float or None
        The same of the facets the mixture's populations explain.
    decided_at_field_um : float or None
        Side of the square field that ``field_scale`` means, where the caller knows the
        pixel size.
    alias_of_nm : float or None
        The component its facets' runner-up interference order lies on, where that order
        fits them within the populations' own misfit: the candidate may be that population
        read in another order (or the component this one), not a population of its own.
        Where the caller knows the facets' orders.
    order_gap_de : float or None
        The median over its facets of the runner-up order's ΔE00 minus the chosen one's.
    """

    mean_nm: float
    sd_nm: float | None
    area_fraction: float
    regions: int
    field_scale: float | None
    region_index: np.ndarray = field(default_factory=lambda: np.zeros(0, int), repr=False)
    delta_e: float | None = None
    delta_e_populations: float | None = None
    decided_at_field_um: float | None = None
    alias_of_nm: float | None = None
    order_gap_de: float | None = None

    @property
    def colour_explained(self) -> bool | None:
        """Its colours fit the film as well as the populations' (ΔE00 at most
        :data:`CANDIDATE_MISFIT` × theirs, and +0.5): a population, not mis-read regions."""
        if self.delta_e is None or self.delta_e_populations is None:
            return None
        return colour_explained(self.delta_e, self.delta_e_populations)

    @property
    def reported(self) -> bool:
        """Reported to the user as a candidate population (warning, report): its colour is
        not unexplained, it is not a component's order alias (``alias_of_nm``: that is
        reported as such) and a field of at most :data:`CANDIDATE_MAX_FIELD_SCALE` × the
        area would decide it."""
        return (self.colour_explained is not False and self.alias_of_nm is None
                and self.decidable)

    @property
    def decidable(self) -> bool:
        """A field of at most :data:`CANDIDATE_MAX_FIELD_SCALE` × the area would decide it."""
        return self.field_scale is not None and self.field_scale <= CANDIDATE_MAX_FIELD_SCALE

    def is_grain(self, regions: Regions) -> bool:
        """Whether it is a grain of the surface, taken into the mixture as a population:
        its regions are at least :data:`~.sampling.GRAIN_MIN_SCALE` × as large
        (:func:`~.sampling.area_weighted_size`) as the other regions, and it is
        :attr:`decidable`. The model choice
        counts a region as one draw and cannot decide a population on one or two; a
        coherent patch far (:data:`CANDIDATE_Z`) from every population holds a thickness
        of its own, whose spread only the field does not measure; scattered facets do not."""
        if not self.decidable:
            return False
        rest = np.isfinite(regions.value)
        rest[self.region_index] = False
        return bool(area_weighted_size(regions.area[self.region_index])
                    >= GRAIN_MIN_SCALE * area_weighted_size(regions.area[rest]))

    def to_json(self) -> dict:
        out = {k: v for k, v in asdict(self).items() if k != "region_index"}
        out.update(colour_explained=self.colour_explained, reported=self.reported)
        return json_safe(out)


def population_candidates(d, chosen, regions: Regions, k) -> list[PopulationCandidate]:
    """Groups of regions that no population of the chosen ``k``-component mixture explains.

    A region is unexplained when its thickness is more than :data:`CANDIDATE_Z` SD from
    every component; unexplained regions are grouped by thickness (neighbours in value
    closer than :data:`CANDIDATE_Z` SD of their difference, with the components' median SD
    as a population's spread, are one group). Each group is a candidate: a population too
    small for this field (it rests on one or two regions, and the background or a wider
    component absorbs it) or a few mis-read regions. ``field_scale`` tells them apart: the
    area the field would need, at the same composition, for the model choice to take it.

    ``d`` is the fit's prepared data (:class:`_Data`), ``chosen`` ``((w, mu, s2), ℓ, bg)``
    of the chosen K. Returns the candidates, heaviest first.
    """
    (_, mu, s2), _, _ = chosen
    ok = np.isfinite(regions.value) & (regions.area > 0)
    x, sg, area = regions.value[ok], regions.sigma[ok], regions.area[ok].astype(np.float64)
    far = np.all(np.abs(x[:, None] - mu) > CANDIDATE_Z * np.sqrt(
        s2 + sg[:, None] ** 2 + d.s2_floor), axis=1)
    if not far.any():
        return []
    o = np.argsort(x[far])
    xs, ss, aa = x[far][o], sg[far][o], area[far][o]
    idx = np.flatnonzero(ok)[far][o]
    s_pop2 = float(np.median(s2))
    gap = np.diff(xs) > CANDIDATE_Z * np.sqrt(ss[1:] ** 2 + ss[:-1] ** 2 + 2.0 * s_pop2)
    group = np.concatenate([[0], np.cumsum(gap)])
    out = []
    for g in range(int(group[-1]) + 1):
        m = group == g
        mean = float(np.average(xs[m], weights=aa[m]))
        var = float(np.average((xs[m] - mean) ** 2, weights=aa[m]))
        frac = float(aa[m].sum() / area.sum())
        comp = (frac, mean, max(var, float(np.max(ss[m] ** 2)), s_pop2))
        out.append(PopulationCandidate(mean, math.sqrt(var) if m.sum() > 1 else None, frac,
                                       int(m.sum()), _field_scale(d, chosen, comp, k),
                                       idx[m]))
    return sorted(out, key=lambda c: -c.area_fraction)


def _as_mixture(w, mu, s2) -> ThicknessMixture:
    """The populations' distribution of an EM solution, without the background."""
    w = w / w.sum()
    return ThicknessMixture([(float(a_), float(m_), float(math.sqrt(c_)))
                             for a_, m_, c_ in zip(w, mu, s2) if a_ > 1e-12])


def _grains_taken(d, chosen, regions: Regions, k_max, info):
    """The candidates of the ``chosen = ((w, mu, s2), ℓ, bg)`` solution, with those that
    are grains (:meth:`PopulationCandidate.is_grain`, up to ``k_max`` components) taken in
    as components. Sets ``info["candidates"]`` (those left; and ``info["grains_nm"]``, the
    ones taken); returns the solution ``(w, mu, s2)``, its ℓ and its K."""
    k = len(chosen[0][0])
    cands = population_candidates(d, chosen, regions, k)
    grains = [c for c in cands if c.is_grain(regions) and _far_at_widest(c, chosen[0], d,
                                                                         regions)]
    grains = grains[:max(0, k_max - k)]
    if grains:
        chosen, k = _with_grains(d, chosen, grains), k + len(grains)
        cands = population_candidates(d, chosen, regions, k)
        info["grains_nm"] = [c.mean_nm for c in grains]
    info["candidates"] = cands
    return chosen[0], chosen[1], k


#: Confidence of the upper bound on a population's SD that a grain must stand clear of
#: (:func:`_far_at_widest`).
GRAIN_SD_CONFIDENCE = 0.95


def _far_at_widest(cand, sol, d, regions: Regions) -> bool:
    """Whether ``cand`` lies more than :data:`CANDIDATE_Z` SD from every component of
    ``sol = (w, mu, s2)`` at the widest SD its own regions allow: the upper
    :data:`GRAIN_SD_CONFIDENCE` bound of a normal SD from ``n`` regions, ``s² (n − 1) /
    χ²(n − 1)``, each region (the candidate's apart) on the component it lies nearest; a
    component on one region takes the widest of the others'. A population's SD from two or
    three regions is barely known: a third region of it 4 nm away is no population of its
    own (a 172 nm population read from regions at 172.4 and 173.6 nm, SD 0.46, left its
    third at 168.1 as a candidate: tests/analysis/test_pipeline.py -k cyan)."""
    _, mu, s2 = sol
    keep = np.isfinite(regions.value)
    keep[cand.region_index] = False
    v = regions.value[keep]
    near = np.argmin(np.abs(v[:, None] - mu) / np.sqrt(s2 + d.s2_floor), axis=1)
    n = np.bincount(near, minlength=mu.size)
    dof = np.maximum(n - 1, 1)
    widest = np.where(n >= 2, s2 * dof / _special.chdtri(dof, GRAIN_SD_CONFIDENCE), np.nan)
    if not np.isfinite(widest).any():
        return False
    widest = np.where(np.isfinite(widest), widest, np.nanmax(widest))
    return bool(np.all(np.abs(cand.mean_nm - mu)
                       > CANDIDATE_Z * np.sqrt(widest + d.s2_floor)))


def _with_grains(d, chosen, grains):
    """``chosen = ((w, mu, s2), ℓ, bg)`` with the candidates ``grains`` added as components
    (:meth:`PopulationCandidate.is_grain`), converged by the EM."""
    (w, mu, s2), _, bg = chosen
    frac = np.array([c.area_fraction for c in grains])
    var = np.array([max((c.sd_nm or 0.0) ** 2, float(np.median(s2)), d.s2_floor)
                    for c in grains])
    start = (np.append(w / w.sum() * (1.0 - frac.sum()), frac),
             np.append(mu, [c.mean_nm for c in grains]), np.append(s2, var))
    w2, mu2, s22, ll, _ = _xd_em(d.collapsed, start, d.s2_floor, bg=bg, s2_max=d.max_s2)
    return (w2, mu2, s22), ll, bg


def _field_scale(d, chosen, comp, k) -> float | None:
    """Smallest area multiple ``f`` of the field at which the mixture with ``comp = (weight,
    mean, variance)`` added beats the chosen one: ``−f ΔL + 3 log(f n) ≤ −``
    :data:`PARSIMONY_BIC` (ΔL: twice the gain in log-likelihood per field, in independent
    observations), with ``f`` × the regions enough for the component and for 3K + 2
    parameters."""
    (w, mu, s2), ll_k, bg = chosen
    frac, mean, var = comp
    start = (np.append(w * (1.0 - frac), frac), np.append(mu, mean),
             np.append(s2, max(var, d.s2_floor)))
    ll = _xd_em(d.collapsed, start, d.s2_floor, bg=bg, s2_max=d.max_s2)[3]
    gain = 2.0 * (ll - ll_k) * d.n_bic / float(d.a.sum())
    f = _FIELD_SCALES
    decided = ((-f * gain + 3.0 * np.log(f * d.n_bic) <= -PARSIMONY_BIC)
               & (f * frac * d.n_eff >= d.min_samples) & (3 * k + 2 <= f * d.n_eff))
    return float(f[np.argmax(decided)]) if gain > 0 and decided.any() else None
