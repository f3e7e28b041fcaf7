"""Whether the summaries agree with the maps they summarize.

The thickness mixture is fitted to the facets; the per-pixel thickness map is what a user
looks at. :func:`mixture_map_check` assigns every mapped pixel to the component most likely
to have produced it (each component widened by the map's own error floor) and compares the
area fractions and means with the mixture's: a mixture that reads two close components where
the map holds three populations, or leaves a fifth of the map unexplained, says so.

A region of interest's single least-ΔE thickness is one number for all its pixels; where
the ROI spans several populations it can land on another interference order altogether
while its pixels read the right one. :func:`roi_pixel_check` flags a ROI whose single fit
lies further from the median of its own pixels' thicknesses than their spread allows.

A component of the mixture can be another component read in a neighbouring interference
order: its facets' colours fit both orders within the ambiguity margin, and the least-ΔE
pick put some of them an order away. :func:`component_orders` says, per component, how much
of its area has a runner-up order that close, where that order lies, and whether it lies on
another component (an order alias: on the generalization sweep only g016's 139.6 nm
component, whose facets are truly at 250 nm beside a 252.3 nm component, docs/accuracy.md).

Examples
--------
>>> from microfacet.core.distributions import ThicknessMixture
>>> t = np.concatenate([np.full(700, 130.0), np.full(300, 150.0)])
>>> c = mixture_map_check(t, ThicknessMixture([(0.7, 130.0, 1.0), (0.3, 150.0, 1.0)]))
>>> c.consistent, [round(f, 2) for f in c.map_fractions]
(True, [0.7, 0.3])
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from ..core import threads
from ..core.threads import chunks
from .mixtures import colour_explained
from .sampling import SCATTERED_MAX_FACETS, facets_per_region, weighted_median

__all__ = ["MapCheck", "OrderMove", "candidate_alias", "component_orders",
           "distinct_populations", "interior_share", "misread_components", "mixture_map_check",
           "nearest_component", "order_alias_of", "order_move", "region_components",
           "roi_pixel_check", "scattered_components"]

#: The per-pixel map's error floor (nm) each component is widened by: the thickness per true
#: region errs by a median 0.6-0.8 nm on the generalization sweep (docs/accuracy.md).
MAP_FLOOR_NM = 1.0
#: A pixel further than this many (widened) SDs from every component is unexplained.
UNEXPLAINED_SD = 4.0
#: Largest differences for a mixture that agrees with its map: area fraction per component,
#: mean per component (nm), unexplained area fraction.
MAX_FRACTION_DIFFERENCE = 0.1
MAX_MEAN_DIFFERENCE_NM = 2.0
MAX_UNEXPLAINED = 0.15
#: A ROI's single fit disagrees with its pixels beyond max(3 × their robust SD, this) (nm).
ROI_MIN_GAP_NM = 5.0


@dataclass(frozen=True)
class MapCheck:
    """The mixture against the per-pixel thickness map (:func:`mixture_map_check`).

    Attributes
    ----------
    map_fractions, map_means_nm : list of float
        Per component: the area fraction of the explained pixels it is most likely for, and
        their mean thickness (NaN without pixels).
    unexplained_fraction : float
        Mapped pixels further than :data:`UNEXPLAINED_SD` widened SDs from every component.
    max_fraction_difference, max_mean_difference_nm : float
        Against the mixture's weights and means.
    consistent : bool
        Within :data:`MAX_FRACTION_DIFFERENCE`, :data:`MAX_MEAN_DIFFERENCE_NM` and
        :data:`MAX_UNEXPLAINED`.
    """

    map_fractions: list
    map_means_nm: list
    unexplained_fraction: float
    max_fraction_difference: float
    max_mean_difference_nm: float
    consistent: bool

    def to_json(self) -> dict:
        return {"map_fractions": [float(v) for v in self.map_fractions],
                "map_means_nm": [float(v) for v in self.map_means_nm],
                "unexplained_fraction": float(self.unexplained_fraction),
                "max_fraction_difference": float(self.max_fraction_difference),
                "max_mean_difference_nm": float(self.max_mean_difference_nm),
                "consistent": bool(self.consistent)}


def mixture_map_check(thickness_nm, mixture) -> MapCheck | None:
    """The mixture's components against the map's pixels (module notes).

    Parameters
    ----------
    thickness_nm : ndarray, any shape
        The per-pixel thickness map, nm (NaN: not mapped).
    mixture : ThicknessMixture

    Returns
    -------
    MapCheck or None
        None without mapped pixels or components.
    """
    t = np.asarray(thickness_nm, dtype=np.float64).ravel()
    t = t[np.isfinite(t)]
    comps = np.asarray(mixture.components, dtype=np.float64) if mixture is not None else ()
    if t.size == 0 or len(comps) == 0:
        return None
    w, mu, sd = comps[:, 0], comps[:, 1], np.hypot(comps[:, 2], MAP_FLOOR_NM)
    # each pixel's closest component and most likely one, a chunk of pixels at a time (the
    # (pixels, components) arrays would hold 24 bytes per pixel and component)
    explained, likely = np.empty(t.size, bool), np.empty(t.size, np.intp)
    for a, b in chunks(t.size, threads.BLOCK_VALUES // len(w)):
        z = (t[a:b, None] - mu[None, :]) / sd[None, :]
        explained[a:b] = np.min(np.abs(z), axis=1) <= UNEXPLAINED_SD
        logp = np.log(np.maximum(w, 1e-300))[None, :] - np.log(sd)[None, :] - 0.5 * z * z
        likely[a:b] = np.argmax(logp, axis=1)
    k = likely[explained]
    te = t[explained]
    n = max(te.size, 1)
    frac = np.bincount(k, minlength=len(w)) / n
    means = np.array([te[k == j].mean() if np.any(k == j) else np.nan for j in range(len(w))])
    dfrac = float(np.max(np.abs(frac - w / w.sum())))
    dmean = float(np.nanmax(np.abs(means - mu))) if np.isfinite(means).any() else np.inf
    unexplained = 1.0 - float(explained.mean())
    ok = (dfrac <= MAX_FRACTION_DIFFERENCE and dmean <= MAX_MEAN_DIFFERENCE_NM
          and unexplained <= MAX_UNEXPLAINED)
    return MapCheck([float(f) for f in frac], [float(m) for m in means], unexplained, dfrac,
                    dmean, bool(ok))


def roi_pixel_check(roi, thickness_nm) -> tuple[np.ndarray, np.ndarray]:
    """Per ROI: the median of its pixels' thicknesses, and whether its single fit lies
    further from it than max(3 × their robust SD, :data:`ROI_MIN_GAP_NM`).

    Parameters
    ----------
    roi : RoiFit
        The ROIs (their fits and :meth:`~.roi.RoiFit.pixel_values`).
    thickness_nm : ndarray (H, W)
        The per-pixel thickness map.

    Returns
    -------
    pixel_median_nm : ndarray (R,)
        NaN where the ROI has no mapped pixel.
    disagrees : ndarray of bool (R,)
    """
    n = roi.thickness_nm.size
    med, gap = np.full(n, np.nan), np.full(n, np.inf)
    for i, v in roi.pixel_values(thickness_nm):
        med[i] = np.median(v)
        gap[i] = max(3.0 * 1.4826 * np.median(np.abs(v - med[i])), ROI_MIN_GAP_NM)
    fit = np.asarray(roi.thickness_nm, dtype=np.float64)
    with np.errstate(invalid="ignore"):
        disagrees = np.isfinite(fit) & np.isfinite(med) & (np.abs(fit - med) > gap)
    return med, disagrees


#: Smallest share of a component's area with a close runner-up order for it to be checked
#: as a possible order alias.
ALIAS_MIN_AMBIGUOUS = 0.2
#: The runner-up order's median thickness lies on another component when it is within this
#: many SD of it (the component's SD and :data:`MAP_FLOOR_NM` twice, in quadrature).
ALIAS_SD = 3.0


def _own_component(mixture, thickness_nm):
    """Each sample's most likely component within :data:`UNEXPLAINED_SD` widened SD, -1 for
    none (or NaN); and the components' means and widened SDs."""
    z, ok, mu, sd = _component_z(mixture, thickness_nm)
    return np.where(ok & (z.min(axis=1) <= UNEXPLAINED_SD), np.argmin(z, axis=1), -1), mu, sd


def _component_z(mixture, values_nm, sigma_nm=0.0):
    """``(z, ok, mu, sd)``: each value's distance (S, K) from each component of ``mixture``
    in units of its SD widened by :data:`MAP_FLOOR_NM` (``sd``) and the value's own error
    ``sigma_nm``, in quadrature; ``ok`` the finite values, ``mu`` the means."""
    comps = mixture.components
    mu = np.array([c[1] for c in comps])
    sd = np.sqrt(np.array([c[2] for c in comps]) ** 2 + MAP_FLOOR_NM ** 2)
    d = np.asarray(values_nm, dtype=np.float64)
    ok = np.isfinite(d)
    sig = np.nan_to_num(np.asarray(sigma_nm, dtype=np.float64), nan=0.0)
    z = np.abs(np.where(ok, d, 0.0)[:, None] - mu) / np.sqrt(
        sd ** 2 + np.broadcast_to(sig, d.shape)[:, None] ** 2)
    return z, ok, mu, sd


def component_orders(mixture, thickness_nm, other_thickness_nm, weights, ambiguous) -> list:
    """Per component: how much of its samples' weight has an ambiguous interference order,
    where the runner-up order lies, and the component it lies on, if any.

    Each sample (facet) belongs to its most likely component within
    :data:`UNEXPLAINED_SD` widened SD. Returns one dict per component:
    ``order_ambiguous_fraction``, ``other_order_nm`` (weighted median of the ambiguous
    samples' runner-up thickness; None without any), ``alias_of_nm`` (the mean of the
    other component it lies on (:func:`order_alias_of`) when at least
    :data:`ALIAS_MIN_AMBIGUOUS` of the weight is ambiguous, or when that component's
    runner-up order lies on this one in turn, whatever the shares: two components each
    other's runner-up order are one population's colours read in two orders as much as
    two populations; else None) and ``alias_both_ways`` (the latter).

    >>> from microfacet.core.distributions import ThicknessMixture
    >>> m = ThicknessMixture([(0.8, 250.0, 1.0), (0.2, 140.0, 1.0)])
    >>> d = np.array([250.0, 251.0, 140.0, 139.5])
    >>> out = component_orders(m, d, np.array([140.0, 360.0, 252.0, 251.0]), np.ones(4),
    ...                        np.array([False, False, True, False]))
    >>> [(o["order_ambiguous_fraction"], o["alias_of_nm"]) for o in out]   # by mean
    [(0.5, 250.0), (0.0, None)]
    >>> out = component_orders(m, d, np.array([141.0, 360.0, 252.0, 251.0]), np.ones(4),
    ...                        np.array([True, False, True, False]))
    >>> [(o["alias_of_nm"], o["alias_both_ways"]) for o in out]   # 50 % each way
    [(250.0, True), (140.0, True)]
    """
    own, mu, _ = _own_component(mixture, thickness_nm)
    w = np.asarray(weights, dtype=np.float64)
    fracs, others, onto = [], [], []
    for k in range(mu.size):
        mine = own == k
        amb = mine & np.asarray(ambiguous, bool) & np.isfinite(other_thickness_nm)
        fracs.append(float(w[amb].sum() / w[mine].sum()) if w[mine].sum() > 0 else 0.0)
        others.append(weighted_median(np.asarray(other_thickness_nm)[amb], w[amb]))
        onto.append(-1 if others[k] is None else
                    int(nearest_component(mixture, others[k], exclude=k)[0]))
    out = []
    for k in range(mu.size):
        j = onto[k]
        both = j >= 0 and onto[j] == k
        alias = float(mu[j]) if j >= 0 and (fracs[k] >= ALIAS_MIN_AMBIGUOUS or both) else None
        out.append({"order_ambiguous_fraction": fracs[k], "other_order_nm": others[k],
                    "alias_of_nm": alias, "alias_both_ways": bool(both)})
    return out


#: Largest weight a component of the mixture may have and still be set aside as misread
#: facets (:func:`misread_components`): facets the film does not explain — dust and stains
#: on a facet, groove walls, facets read in another order — are a minority of the film; the
#: components set aside on the generalization sweeps weighed 0.01-0.19 (docs/accuracy.md,
#: "Misread facets, and a field 16× larger").
MISREAD_MAX_WEIGHT = 0.2
#: Smallest share of a component's area in facets none of whose neighbours belongs to
#: another component for it to cover grains of the surface (:func:`interior_share`): a
#: population covers grains, each of many facets, while facets misread alike — groove
#: walls, dust, stains, facets read in another order — lie between other facets. A
#: component that covers grains is a population even where its colours fit worse than the
#: others' (:func:`misread_components`): a minority population's small regions mix their
#: colours with their neighbours' at the edges. Read off the generalization sweep's seeds
#: 0-17 (docs/accuracy.md, "A population that covers grains is not misread facets"): over
#: the 720 scenes it keeps the 11 true populations the colour rule set aside and 4 of its
#: 40 misread components.
GRAIN_INTERIOR_SHARE = 0.18


def misread_components(mixture, thickness_nm, delta_e, *,
                       max_weight=MISREAD_MAX_WEIGHT, pairs=None, area=None) -> list:
    """The minor components of ``mixture`` whose samples' colours the film explains much
    worse than the other components' samples': misread facets, not a population.

    Each sample (facet) belongs to its most likely component within
    :data:`UNEXPLAINED_SD` widened SD. From the lightest component up, a component of weight
    at most ``max_weight`` is misread where the median ΔE00 of its samples is not
    :func:`~.mixtures.colour_explained` beside the median of the samples of the components
    still kept (the rule a candidate population's colours must pass) and, where the facets'
    neighbours are given, it does not cover grains (:func:`interior_share` against the other
    components' samples below :data:`GRAIN_INTERIOR_SHARE`); at least one component is kept.

    Parameters
    ----------
    mixture : ThicknessMixture
    thickness_nm, delta_e : array_like, shape (S,)
        Each sample's thickness (nm; NaN: none) and its colour misfit ΔE00.
    max_weight : float, optional
    pairs : ndarray of int, shape (P, 2), optional
        The facets' neighbour pairs (:func:`~.segmentation.neighbour_pairs` of the facet
        labels), with ``area`` (each facet's px): a component that covers grains is kept.
    area : array_like, shape (S,), optional

    Returns
    -------
    list of (int, float, float, ndarray of bool)
        Per misread component: its index, its samples' median ΔE00, the kept ones', and its
        samples.

    Examples
    --------
    >>> from microfacet.core.distributions import ThicknessMixture
    >>> m = ThicknessMixture([(0.85, 130.0, 1.0), (0.15, 250.0, 1.0)])
    >>> d = np.r_[np.full(85, 130.0), np.full(15, 250.0)]
    >>> de = np.r_[np.full(85, 1.0), np.full(15, 4.0)]
    >>> [(k, a, b, int(s.sum())) for k, a, b, s in misread_components(m, d, de)]   # 4 > 2
    [(1, 4.0, 1.0, 15)]
    >>> misread_components(m, d, de, max_weight=0.1)
    []
    """
    own, _, _ = _own_component(mixture, thickness_nm)
    de = np.asarray(delta_e, dtype=np.float64)
    kept = list(range(len(mixture.components)))
    out = []
    for k in sorted(kept, key=lambda i: mixture.components[i][0]):
        mine = (own == k) & np.isfinite(de)
        rest = np.isin(own, [j for j in kept if j != k]) & np.isfinite(de)
        if (len(kept) == 1 or not mine.any() or not rest.any()
                or mixture.components[k][0] > max_weight):
            continue
        de_k, de_rest = float(np.median(de[mine])), float(np.median(de[rest]))
        if not colour_explained(de_k, de_rest) and not (
                pairs is not None
                and interior_share(own == k, pairs, area, others=(own >= 0) & (own != k))
                >= GRAIN_INTERIOR_SHARE):
            kept.remove(k)
            out.append((k, de_k, de_rest, own == k))
    return out


def interior_share(mine, pairs, area, *, others=None) -> float:
    """Share of the area of the facets ``mine`` in facets none of whose neighbours is one of
    ``others`` (default: every facet not ``mine``): the interiors of the grains they cover
    (0 for none). Facets that are neither — masked, unexplained, no sample — are holes in a
    grain, not its edge, where ``others`` leaves them out.

    Parameters
    ----------
    mine : ndarray of bool, shape (S,)
    pairs : ndarray of int, shape (P, 2)
        Neighbouring facets (:func:`~.segmentation.neighbour_pairs`).
    area : array_like, shape (S,)
        Each facet's area (px).
    others : ndarray of bool, shape (S,), optional

    Examples
    --------
    >>> from microfacet.analysis.segmentation import neighbour_pairs
    >>> labels = np.arange(25).reshape(5, 5)                # 25 facets of one pixel
    >>> mine = np.zeros(25, bool); mine[[6, 7, 8, 11, 12, 13, 16, 17, 18]] = True
    >>> interior_share(mine, neighbour_pairs(labels), np.ones(25))   # the centre of nine
    0.1111111111111111
    >>> others = ~mine; others[[1, 2, 3]] = False     # the row above no sample: a hole
    >>> interior_share(mine, neighbour_pairs(labels), np.ones(25), others=others)
    0.2222222222222222
    >>> scattered = np.zeros(25, bool); scattered[[0, 2, 4, 10, 14, 20, 22, 24]] = True
    >>> interior_share(scattered, neighbour_pairs(labels), np.ones(25))
    0.0
    """
    mine = np.asarray(mine, bool)
    others = ~mine if others is None else np.asarray(others, bool)
    a = np.asarray(area, dtype=np.float64)
    total = float(a[mine].sum())
    if total <= 0:
        return 0.0
    i, j = np.asarray(pairs, dtype=np.int64).reshape(-1, 2).T
    edge = np.zeros(mine.shape, bool)
    edge[i[mine[i] & others[j]]] = True
    edge[j[mine[j] & others[i]]] = True
    return float(a[mine & ~edge].sum() / total)


def scattered_components(mixture, thickness_nm, regions, patch_area, *,
                         max_weight=MISREAD_MAX_WEIGHT,
                         max_facets=SCATTERED_MAX_FACETS) -> list:
    """The minor components of ``mixture`` whose samples lie scattered, in thickness regions
    of a few facets each: misread facets, not a population.

    Each sample (a facet, a patch of ``regions``) belongs to its most likely component
    within :data:`UNEXPLAINED_SD` widened SD, and each region to the component its mean lies
    nearest (:func:`region_components`). A component of weight at most ``max_weight`` is
    scattered where its own regions hold fewer than ``max_facets`` facets
    (:func:`~.sampling.facets_per_region` over the facets of those regions, area-weighted),
    or where no region is its own (its facets all lie in regions of other components: the
    tail of a population, not one); at least one component is kept. The field grows the
    number of independent regions, and facets misread alike, a few percent of a large field,
    then pay for a component (on the generalization sweep at 1024² px: a population's other
    interference order in hundreds of separate regions).

    Parameters
    ----------
    mixture : ThicknessMixture
    thickness_nm : array_like, shape (S,)
        Each sample's thickness (nm; NaN: none).
    regions : Regions
        The samples' thickness regions (:func:`~.sampling.thickness_regions`).
    patch_area : array_like, shape (S,)
        Each sample's area (px).
    max_weight, max_facets : float, optional

    Returns
    -------
    list of (int, float, ndarray of bool)
        Per scattered component: its index, its samples' facets per region, its samples.

    Examples
    --------
    >>> from microfacet.analysis.sampling import Regions
    >>> from microfacet.core.distributions import ThicknessMixture
    >>> m = ThicknessMixture([(0.9, 130.0, 1.0), (0.1, 250.0, 1.0)])
    >>> d = np.r_[np.full(9, 130.0), np.full(10, 250.0)]        # 9 facets in one region,
    >>> pr = np.r_[np.zeros(9, int), np.arange(1, 11)]          # 10 each in a region of its own
    >>> reg = Regions(pr, np.r_[130.0, np.full(10, 250.0)], np.ones(11),
    ...               np.r_[900.0, np.full(10, 100.0)], 0.0)
    >>> [(k, f, int(s.sum())) for k, f, s in scattered_components(m, d, reg, np.full(19, 100.0))]
    [(1, 1.0, 10)]
    """
    own, _, _ = _own_component(mixture, thickness_nm)
    region_own = region_components(mixture, regions)
    out = []
    for k in sorted(range(len(mixture.components)), key=lambda i: mixture.components[i][0]):
        mine = own == k
        if (len(out) == len(mixture.components) - 1 or not mine.any()
                or mixture.components[k][0] > max_weight):
            continue
        in_own = np.isin(regions.patch_region, np.flatnonzero(region_own == k))
        f = facets_per_region(regions.patch_region, regions.area, patch_area, in_own)
        f = f if math.isfinite(f) else 0.0
        if f < max_facets:
            out.append((k, f, mine))
    return out


def region_components(mixture, regions) -> np.ndarray:
    """Per thickness region (:class:`~.sampling.Regions`), the component of ``mixture`` its
    mean lies nearest: in units of the component's SD widened by the region mean's σ and
    :data:`MAP_FLOOR_NM`; -1 for a region without a value.

    >>> from microfacet.analysis.sampling import Regions
    >>> from microfacet.core.distributions import ThicknessMixture
    >>> m = ThicknessMixture([(0.9, 200.0, 3.0), (0.1, 215.0, 1.0)])
    >>> reg = Regions(np.zeros(3, int), np.array([201.0, 212.0, np.nan]), np.full(3, 0.5),
    ...               np.full(3, 100.0), 0.0)
    >>> region_components(m, reg).tolist()
    [0, 1, -1]
    """
    z, ok, mu, _ = _component_z(mixture, regions.value, regions.sigma)
    return np.where(ok, np.argmin(z, axis=1), -1) if mu.size else np.full(ok.size, -1)


def nearest_component(mixture, values_nm, *, exclude=None) -> np.ndarray:
    """Per value, the index of the component of ``mixture`` it lies on: the nearest in SD
    units, where within :data:`ALIAS_SD` of its SD and :data:`MAP_FLOOR_NM` twice, in
    quadrature; -1 for none (or NaN). ``exclude``: a component index never chosen.

    >>> from microfacet.core.distributions import ThicknessMixture
    >>> m = ThicknessMixture([(0.8, 250.0, 1.0), (0.2, 140.0, 1.0)])
    >>> nearest_component(m, [251.5, 260.0, 139.0, np.nan]).tolist()   # by mean: 140, 250
    [1, -1, 0, -1]
    """
    comps = mixture.components
    mu = np.array([c[1] for c in comps])
    sd = np.sqrt(np.array([c[2] for c in comps]) ** 2 + 2.0 * MAP_FLOOR_NM ** 2)
    v = np.atleast_1d(np.asarray(values_nm, dtype=np.float64))
    with np.errstate(invalid="ignore"):
        zz = np.abs(v[:, None] - mu) / sd
    if exclude is not None:
        zz[:, exclude] = np.inf
    j = np.argmin(np.nan_to_num(zz, nan=np.inf), axis=1)
    on = np.isfinite(v) & (zz[np.arange(v.size), j] <= ALIAS_SD)
    return np.where(on, j, -1)


def order_alias_of(mixture, other_nm, *, exclude=None) -> float | None:
    """The mean of the component of ``mixture`` that a runner-up order's thickness
    ``other_nm`` lies on (:func:`nearest_component`), other than component ``exclude`` (an
    index into the components, which are ordered by mean); None if none.

    >>> from microfacet.core.distributions import ThicknessMixture
    >>> m = ThicknessMixture([(0.8, 250.0, 1.0), (0.2, 140.0, 1.0)])
    >>> order_alias_of(m, 251.5), order_alias_of(m, 260.0), order_alias_of(m, 251.5, exclude=1)
    (250.0, None, None)
    """
    j = int(nearest_component(mixture, other_nm, exclude=exclude)[0])
    return float(mixture.components[j][1]) if j >= 0 else None


def candidate_alias(mixture, other_nm, gap_de, weights, misfit_de):
    """Whether a candidate population may be a component of ``mixture`` read in another
    interference order: its facets' runner-up order (``other_nm``, weighted median with
    ``weights``) lies on a component (:func:`order_alias_of`) and fits them within
    ``misfit_de`` of their own fit (``gap_de``: the runner-up's ΔE00 minus the chosen one's,
    median over the facets). Returns ``(alias mean or None, median gap or None)``.

    >>> from microfacet.core.distributions import ThicknessMixture
    >>> m = ThicknessMixture([(0.7, 110.0, 1.0), (0.3, 55.0, 1.0)])
    >>> candidate_alias(m, [54.2, 55.1, 56.0], [2.1, 2.6, 3.0], [1, 1, 1], misfit_de=4.0)
    (55.0, 2.6)
    >>> candidate_alias(m, [54.2, 55.1, 56.0], [6.1, 6.6, 7.0], [1, 1, 1], misfit_de=4.0)
    (None, 6.6)
    """
    other, gap, w = (np.asarray(a, dtype=np.float64) for a in (other_nm, gap_de, weights))
    ok = np.isfinite(other) & np.isfinite(gap) & (w > 0)
    if not ok.any():
        return None, None
    g = float(np.median(gap[ok]))
    at = weighted_median(other[ok], w[ok])
    if at is None or not g <= misfit_de:
        return None, g
    return order_alias_of(mixture, at), g


#: A component is moved to another component's order only when at least this share of its
#: area has its runner-up order on that component.
MOVE_MIN_SHARE = 0.5


@dataclass(frozen=True)
class OrderMove:
    """A component read in another component's interference order (:func:`order_move`).

    Attributes
    ----------
    from_nm, to_nm : float
        The component's mean and the mean of the component whose order its facets take.
    area_share : float
        Share of the component's area that moves (its runner-up order lies on ``to_nm``).
    mean_gap_de : float
        Area-weighted mean of the moved facets' ΔE00 at the runner-up order minus at their
        own (negative: the runner-up fits better).
    facets : int
        Facets moved.
    """

    from_nm: float
    to_nm: float
    area_share: float
    mean_gap_de: float
    facets: int

    def to_json(self) -> dict:
        return {"from_nm": self.from_nm, "to_nm": self.to_nm, "area_share": self.area_share,
                "mean_gap_de": self.mean_gap_de, "facets": self.facets}


def order_move(mixture, thickness_nm, other_thickness_nm, gap_de, weights, *, margin_de,
               min_separation_nm, max_sd_nm=np.inf):
    """The component whose facets are best read in another component's interference order.

    A population's facets whose colours fit two orders about alike split between them by
    noise, and the mixture shows one population twice, an order apart. Component ``k`` is
    that component read in the order of component ``j`` (at least ``min_separation_nm``
    away) when at least :data:`MOVE_MIN_SHARE` of its area has its runner-up order on ``j``
    (:func:`order_alias_of`'s criterion) and those facets fit it within ``margin_de`` on
    average (area-weighted ``gap_de``: ΔE00 at the runner-up minus at the chosen order).
    Both components must be narrower than ``max_sd_nm``: a component as wide as an order's
    window holds samples of any order and is no order to move to or from (nor is one at
    that width, the SD ceiling of the analysis' thickness fit: samples scattered wider hold
    it there).
    Of the pairs that qualify, the one of least mean gap: the colours decide the direction,
    not the areas.

    Returns
    -------
    (OrderMove or None, ndarray of bool)
        The move, and the samples that move (all False without one).

    Examples
    --------
    >>> from microfacet.core.distributions import ThicknessMixture
    >>> m = ThicknessMixture([(0.4, 52.0, 1.0), (0.3, 163.0, 1.0), (0.3, 190.0, 1.0)])
    >>> d = np.array([52.0, 51.0, 163.0, 162.5, 190.0])
    >>> other = np.array([163.0, 162.0, 52.0, 51.5, 80.0])
    >>> gap = np.array([3.0, 4.0, 0.4, 0.6, 5.0])
    >>> mv, moved = order_move(m, d, other, gap, np.ones(5), margin_de=1.0,
    ...                        min_separation_nm=55.0)
    >>> (mv.from_nm, mv.to_nm, mv.facets), moved.tolist()
    ((163.0, 52.0, 2), [False, False, True, True, False])
    """
    own, mu, sd = _own_component(mixture, thickness_nm)
    other = np.asarray(other_thickness_nm, dtype=np.float64)
    gap = np.asarray(gap_de, dtype=np.float64)
    w = np.asarray(weights, dtype=np.float64)
    on = np.isfinite(other) & np.isfinite(gap)
    narrow = np.array([c[2] for c in mixture.components]) < max_sd_nm * (1.0 - 1e-6)
    best = None
    for k in range(mu.size):
        mine = own == k
        for j in range(mu.size):
            if (j == k or abs(mu[j] - mu[k]) < min_separation_nm or not w[mine].sum() > 0
                    or not (narrow[j] and narrow[k])):
                continue
            mov = mine & on & (np.abs(np.where(on, other, 0.0) - mu[j])
                               <= ALIAS_SD * np.sqrt(sd[j] ** 2 + MAP_FLOOR_NM ** 2))
            share = float(w[mov].sum() / w[mine].sum())
            if share < MOVE_MIN_SHARE:
                continue
            g = float(np.sum(w[mov] * gap[mov]) / w[mov].sum())
            if g <= margin_de and (best is None or g < best[0].mean_gap_de):
                best = (OrderMove(float(mu[k]), float(mu[j]), share, g, int(mov.sum())), mov)
    return best if best is not None else (None, np.zeros(own.shape, bool))


def distinct_populations(mixture, orders) -> int:
    """The number of populations when each order alias (``orders`` from
    :func:`component_orders`) is counted with the component it may be: the connected groups
    of the components joined by their aliases.

    >>> from microfacet.core.distributions import ThicknessMixture
    >>> m = ThicknessMixture([(0.2, 140.0, 1.0), (0.3, 180.0, 1.0), (0.5, 250.0, 1.0)])
    >>> distinct_populations(m, [{"alias_of_nm": 250.0}, {"alias_of_nm": None},
    ...                          {"alias_of_nm": 140.0}])
    2
    """
    means = [c[1] for c in mixture.components]
    group = list(range(len(means)))

    def root(i):
        while group[i] != i:
            i = group[i]
        return i

    for i, o in enumerate(orders):
        if o.get("alias_of_nm") is not None and o["alias_of_nm"] in means:
            group[root(i)] = root(means.index(o["alias_of_nm"]))
    return len({root(i) for i in range(len(means))})
