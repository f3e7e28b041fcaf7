"""How many independent samples a thickness map holds: its regions.

Neighbouring facets of one thickness region are not independent samples of the thickness
distribution: a region of many facets holds one draw of it. :func:`thickness_regions`
merges neighbouring facets while their values agree (beyond their errors and the scatter
between facets of one region); the area-weighted (Kish) number of the regions is the
number of independent samples the mixtures' model choice counts (:mod:`.mixtures`,
:mod:`.identification`).

A spatial-autocorrelation estimate (integral area of the map's autocorrelation) was tried
first and dropped: on the generalization sweep it gave 0.6–3× the true regions' count,
erratically, where the region count gives 1–2× (docs/accuracy.md).

The samples the mixtures are fitted to are prepared here too: :func:`prepare` (finite
values, weights, errors; a reproducible subsample; the Kish size of the weights) and
:func:`collapse` (identical samples as one, carrying their summed weight: per-pixel values
repeat their region's or facet's, and the fits' cost grows with the samples).

References
----------
.. [1] N. Nagata, M. Kamei, K. Takahashi, K. Tobitani, T. Akagi, S. Yamamura, "Simulation
   Technology for Titanium Oxide Layer Interference Color", Technical Report (the seed paper),
   §3.3.3 and Fig. 18 (thickness regions).
.. [2] L. Kish, *Survey Sampling*, Wiley, New York (1965) (the effective sample size).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from ..core.lazy import load
from .segmentation import merge_adjacent, neighbour_pairs

# scipy.special, not scipy.stats (0.19 s more to import) for a χ² quantile
special = load("scipy.special")

__all__ = ["GRAIN_MIN_SCALE", "SCATTERED_MAX_FACETS", "Regions", "Samples",
           "area_weighted_size", "collapse", "facets_per_region", "prepare", "region_scale_px",
           "thickness_regions", "weighted_median"]


@dataclass
class Regions:
    """Patches merged into regions of one value (:func:`thickness_regions`).

    Attributes
    ----------
    patch_region : ndarray of int, shape (S,)
        Region of each patch (-1: the patch has no value).
    value, sigma : ndarray, shape (R,)
        Weighted mean value of each region and its 1-σ error.
    area : ndarray, shape (R,)
        Pixels per region.
    scatter : float
        τ: the scatter between neighbouring patches of one region beyond their errors.
    """

    patch_region: np.ndarray
    value: np.ndarray
    sigma: np.ndarray
    area: np.ndarray
    scatter: float

    @property
    def count(self) -> int:
        return int(self.value.size)

    @property
    def effective_count(self) -> float:
        """Area-weighted (Kish) number of regions, (Σ a)² / Σ a²: small regions split off
        at noisy patches count for little (measured on synthetic scenes: 1–2× the true
        regions' own Kish count, where the plain count is 3–8×)."""
        a = self.area.astype(np.float64)
        return float(a.sum() ** 2 / np.sum(a * a)) if a.size and a.sum() > 0 else 0.0


#: A population covers grains of the surface, each of many facets; facets misread alike
#: (groove walls, facets read in another interference order, dust) lie apart, in regions of
#: a facet or a few. A minor component whose own regions (those whose mean lies on it,
#: :func:`~.consistency.region_components`) hold fewer facets than this (area-weighted,
#: :func:`facets_per_region`) is scattered facets, not a population
#: (:func:`~.consistency.scattered_components`). Read off the generalization sweeps
#: (docs/accuracy.md, "Grains and scattered facets"): the components that were no true
#: population mostly measured 1.5-5.3, a population 3.0-5.3 only on three scenes read an
#: interference order off, else 6 and more.
SCATTERED_MAX_FACETS = 6.0
#: A candidate population whose regions are at least this share of the other regions' size
#: (area-weighted mean area, :func:`area_weighted_size`) is a grain of the surface and taken as
#: a population (:meth:`~.mixtures.PopulationCandidate.is_grain`); candidates with a true
#: population measured 0.11-0.97 on the sweeps (19 of 22), the others mostly 0.01-0.09.
GRAIN_MIN_SCALE = 0.1


def region_scale_px(patch_region, region_area, members) -> float:
    """Area-weighted mean area (px) of the regions the patches ``members`` lie in:
    ``Σ a² / Σ a`` over those regions, NaN for none. A region is one thickness of the
    surface (:func:`thickness_regions`); a population's regions are its grains, misread
    facets make regions of their own size.

    >>> pr, area = np.array([0, 0, 1, 2, 3]), np.array([400.0, 10.0, 10.0, 10.0])
    >>> region_scale_px(pr, area, np.array([1, 1, 0, 0, 0], bool))   # one region of 400 px
    400.0
    >>> region_scale_px(pr, area, np.array([0, 0, 1, 1, 1], bool))   # three of 10 px
    10.0
    """
    r = np.unique(np.asarray(patch_region)[np.asarray(members, bool)])
    return area_weighted_size(np.asarray(region_area)[r[r >= 0]])


def area_weighted_size(area) -> float:
    """``Σ a² / Σ a``: the mean area of the pieces ``area``, each weighted by its area (the
    size a random pixel's piece has); NaN for none.

    >>> area_weighted_size([400.0, 10.0, 10.0])
    381.42857142857144
    """
    a = np.asarray(area, dtype=np.float64)
    return float(np.sum(a * a) / a.sum()) if a.size and a.sum() > 0 else float("nan")


def facets_per_region(patch_region, region_area, patch_area, members) -> float:
    """How many of their own patches (facets) the regions of the patches ``members`` hold:
    :func:`region_scale_px` over the patches' own area-weighted mean area (NaN for none).

    >>> pr, area = np.array([0, 0, 1, 2, 3]), np.array([400.0, 10.0, 10.0, 10.0])
    >>> facets_per_region(pr, area, np.array([200.0, 200.0, 10.0, 10.0, 10.0]),
    ...                   np.array([1, 1, 0, 0, 0], bool))       # two facets in one region
    2.0
    """
    m = np.asarray(members, bool)
    return (region_scale_px(patch_region, region_area, m)
            / area_weighted_size(np.asarray(patch_area)[m]))


def thickness_regions(labels, value, sigma, *, alpha=1e-4) -> Regions:
    """Regions the data can tell apart: neighbouring patches merged while their values agree.

    Each patch (a facet: one thickness ± σ) also scatters about its region's value by τ,
    the robust SD of the differences between neighbouring patches beyond their errors
    (most neighbours share a region; the steps between regions are the outliers).
    Neighbouring regions are merged, mutual best pairs first, while their means (weights
    1/(σ² + τ²)) differ by less than chance allows (χ² with one degree of freedom,
    ``p > alpha``, 10⁻⁴ by default: every merge is one of hundreds of tests on groups the
    merging itself selected; at 0.01 the fixture's regions were several times its true 12,
    and the population count followed the slices' encoding: tests/analysis/test_pipeline.py
    ``-k encoding``). Every region is
    then one draw of the thickness distribution: the independent samples the mixture's model
    choice counts. The greedy order still sorts a homogeneous field of many patches into a
    few sub-regions of low and high values (tests/analysis/test_sampling.py): the count
    errs high.

    Parameters
    ----------
    labels : ndarray of int, shape (H, W)
        Patches 0..S-1.
    value, sigma : ndarray, shape (S,)
        Value of each patch and its 1-σ error (NaN value: the patch takes no part).

    Returns
    -------
    Regions

    Examples
    --------
    >>> labels = np.repeat(np.arange(6), 5)[None, :].repeat(3, 0)   # 6 patches in a row
    >>> r = thickness_regions(labels, np.array([1.0, 1.1, 0.9, 5.0, 5.05, 4.95]),
    ...                       np.full(6, 0.1))
    >>> r.count, r.patch_region.tolist(), [round(float(v), 2) for v in r.value]
    (2, [0, 0, 0, 1, 1, 1], [1.0, 5.0])
    """

    labels = np.asarray(labels)
    S = int(labels.max()) + 1
    val = np.asarray(value, dtype=np.float64)
    sg = np.nan_to_num(np.asarray(sigma, dtype=np.float64), nan=np.inf)
    ok = np.isfinite(val) & np.isfinite(sg)
    pairs = neighbour_pairs(labels)
    both = ok[pairs[:, 0]] & ok[pairs[:, 1]] if pairs.size else np.zeros(0, bool)
    threshold = float(special.chdtri(1, alpha))   # scipy.stats.chi2.isf(alpha, 1), to the bit
    tau2 = 0.0
    if both.sum() >= 10:
        i, j = pairs[both, 0], pairs[both, 1]
        d = val[i] - val[j]
        mad = 1.4826 * float(np.median(np.abs(d - np.median(d))))
        tau2 = max(0.0, mad ** 2 / 2.0 - float(np.median((sg[i] ** 2 + sg[j] ** 2) / 2.0)))
    w = np.where(ok, 1.0 / np.maximum(sg ** 2 + tau2, 1e-12), 0.0)
    area = np.bincount(labels.ravel(), minlength=S).astype(np.float64)
    moments = np.stack([w, w * np.where(ok, val, 0.0), np.where(ok, area, 0.0)], axis=1)

    def cost(mi, mj):
        wi, wj = mi[:, 0], mj[:, 0]
        good = (wi > 0) & (wj > 0)
        with np.errstate(invalid="ignore", divide="ignore"):
            d2 = (mi[:, 1] / wi - mj[:, 1] / wj) ** 2 / (1.0 / wi + 1.0 / wj)
        d2 = np.where(good, d2, np.inf)
        return good & (d2 < threshold), d2

    merged, m = merge_adjacent(labels, moments, cost, max_rounds=500, pairs=pairs)
    # the region of each patch (a patch lies in one region: take any of its pixels)
    first = np.full(S, -1, np.int64)
    flat_l, flat_m = labels.ravel(), merged.ravel()
    first[flat_l] = flat_m
    has = m[:, 0] > 0
    index = np.full(m.shape[0], -1, np.int64)
    index[has] = np.arange(int(has.sum()))
    patch_region = np.where(ok & (first >= 0), index[np.maximum(first, 0)], -1)
    mh = m[has]
    return Regions(patch_region, mh[:, 1] / mh[:, 0], 1.0 / np.sqrt(mh[:, 0]), mh[:, 2],
                   math.sqrt(tau2))


# ------------------------------------------------------------- the fits' samples


def _positive_int(x, name):
    if isinstance(x, bool) or not isinstance(x, (int, np.integer)) or x < 1:
        raise ValueError(f"{name}: expected an integer >= 1, got {x!r}")
    return int(x)


def _array(values, name, size=None, shape=None):
    try:
        a = np.asarray(values, dtype=np.float64)
    except (TypeError, ValueError):
        raise ValueError(f"{name}: expected an array of numbers") from None
    if size is not None and a.size != size:
        raise ValueError(f"{name}: shape {a.shape} does not match {shape}")
    return a.ravel()


@dataclass
class Samples:
    """Samples a mixture is fitted to, as given.

    Attributes
    ----------
    values : array_like, any shape
        The samples (NaN ignored).
    sigma : array_like or float, optional
        1-σ measurement error of each sample: the components are deconvolved from it.
    weights : array_like, same shape, optional
        Non-negative sample weights (e.g. facet areas).
    group : array_like, same shape, optional
        Region / facet id per sample: without ``n_effective``, the number of distinct
        groups is the number of independent observations.
    n_effective : float, optional
        The number of independent observations (see the notes of :mod:`.mixtures`).
    name, sigma_name : str
        How messages name the values and their errors.
    """

    values: object
    sigma: object = None
    weights: object = None
    group: object = None
    n_effective: float | None = None
    name: str = "values"
    sigma_name: str = "sigma"


def prepare(samples: Samples, *, max_samples, seed=0):
    """Flatten, drop NaN / zero weight, subsample reproducibly (``max_samples`` at most, drawn
    with ``seed``).

    Returns
    -------
    x, w, s : ndarray
        Values, weights (ones without ``weights``) and per-sample noise (zeros without
        ``sigma``) of the fitted samples.
    n : int
        Finite samples given.
    n_eff : float
        Independent observations for the BIC (see the notes of :mod:`.mixtures`).
    """
    x, w, s, keep, g = _checked(samples)
    n = int(keep.sum())
    if n == 0:
        raise ValueError(f"{samples.name}: no finite values" + (
            " with weight > 0" if samples.weights is not None else ""))
    x, w, s = x[keep], w[keep], np.asarray(s, dtype=np.float64)[keep]
    p = w / w.sum()
    kish = 1.0 / float(np.sum(p * p))
    if n > max_samples:
        idx = np.sort(np.random.default_rng(seed).choice(n, size=max_samples, replace=False))
        x, w, s = x[idx], w[idx], s[idx]
        kish = min(kish, float(max_samples))
    if samples.n_effective is not None:
        n_eff = float(samples.n_effective)
        if not (math.isfinite(n_eff) and n_eff > 0):
            raise ValueError(f"n_effective: must be finite and > 0, got {samples.n_effective!r}")
    elif g is not None:
        n_eff = float(min(np.unique(g[keep]).size, kish))
    else:
        n_eff = kish
    return x, w, s, n, n_eff


def _checked(samples: Samples):
    """Values, weights, errors, the finite mask and groups of ``samples`` (flat), checked."""
    name, values = samples.name, samples.values
    x = _array(values, name)
    shape = np.shape(values)
    if np.isinf(x).any():
        raise ValueError(f"{name}: contains infinite values")
    keep = ~np.isnan(x)
    w = np.ones(x.size)
    if samples.weights is not None:
        w = _array(samples.weights, "weights", x.size, shape)
        if not np.all(np.isfinite(w)) or np.any(w < 0):
            raise ValueError("weights: must be finite and >= 0")
        keep &= w > 0
    s = np.zeros(x.size)
    sigma = samples.sigma
    if sigma is not None:
        s = np.broadcast_to(_array(sigma, samples.sigma_name), x.shape) if np.size(sigma) == 1 \
            else _array(sigma, samples.sigma_name, x.size, shape)
        if np.any(np.asarray(s)[keep] < 0) or np.isinf(np.asarray(s)[keep]).any():
            raise ValueError(f"{samples.sigma_name}: must be finite and >= 0")
        keep &= np.isfinite(s)
    g = None
    if samples.group is not None:
        g = np.asarray(samples.group)
        if g.size != x.size:
            raise ValueError(f"group: shape {g.shape} does not match {name} {shape}")
        g = g.ravel()
    return x, w, s, keep, g


def collapse(a, *cols):
    """Identical samples (equal in every column of ``cols``) as one sample carrying their
    summed weight, in a canonical (sorted) order: the weighted likelihood and the EM
    updates are those of the samples given (to rounding), on fewer samples when values
    repeat (per-pixel values share their region's or facet's value); integer weights and
    as many repeats of a sample give the same samples.

    Returns ``(a, *cols)``.

    >>> a, x = collapse(np.ones(4), np.array([2.0, 1.0, 2.0, 3.0]))
    >>> a.tolist(), x.tolist()
    ([1.0, 2.0, 1.0], [1.0, 2.0, 3.0])
    """
    order = np.lexsort(cols[::-1])
    srt = [c[order] for c in cols]
    new = np.zeros(a.size, bool)
    new[:1] = True
    for c in srt:
        new[1:] |= c[1:] != c[:-1]
    return (np.bincount(np.cumsum(new) - 1, weights=a[order]), *(c[new] for c in srt))


def weighted_median(x, w) -> float | None:
    """The smallest value of ``x`` at which the cumulative weight ``w`` reaches half the
    total (None without values or weight).

    >>> weighted_median(np.array([3.0, 1.0, 2.0]), np.array([1.0, 1.0, 5.0]))
    2.0
    """
    x, w = np.asarray(x, dtype=np.float64), np.asarray(w, dtype=np.float64)
    if x.size == 0 or w.sum() <= 0:
        return None
    o = np.argsort(x)
    c = np.cumsum(w[o])
    return float(x[o][np.searchsorted(c, 0.5 * c[-1])])

