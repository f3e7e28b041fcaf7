"""The distributions stage: the thickness mixture and the NDF, and whether the data
determine them (:mod:`.identification`).

Joint mode (:func:`fit_joint_distributions`)
    * **Thickness**: one sample per facet (its thickness, its 1-σ error, its area), the
      mixture deconvolved from the errors (:func:`~.mixtures.fit_thickness_mixture`) with
      the number of independent thickness regions as ``n_eff`` (the area-weighted count
      of :func:`~.sampling.thickness_regions`). Dark (censored) facets and facets whose
      colour the model does not explain (:func:`~.identification.unexplained_facets`) are
      left out.
    * **NDF**: one sample per facet with a height tilt (its plane's slope, the slope noise of
      the fit, its area), deconvolved; dark facet-sized areas (tilted past the acceptance)
      and planes steeper than it enter as censored samples (:func:`~.ndf_fit.fit_ndf_mixture`);
      ``n_eff`` = facets. Without any facet plane, the per-pixel tilts are fitted for
      inspection only (never identified).

Seed mode (:func:`fit_seed_distributions`)
    The seed's per-pixel histograms: thickness per ROI, tilt per pixel from colour alone.

References
----------
.. [1] N. Nagata et al., the seed, §3.3.3 and Figs. 18-19 (three Gaussians of thickness, two
   zero-mean lobes of the normals).
.. [2] J. Bovy, D. W. Hogg, S. T. Roweis, "Extreme deconvolution", Ann. Appl. Stat. 5 (2011)
   1657-1677, doi:10.1214/10-AOAS439.
"""

from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass, field

import numpy as np

from ..core.lazy import load
from .consistency import (
    ALIAS_SD,
    MOVE_MIN_SHARE,
    candidate_alias,
    component_orders,
    distinct_populations,
    misread_components,
    nearest_component,
    order_move,
    scattered_components,
)
from .identification import (
    NO_SAMPLES,
    Judgement,
    NdfEvidence,
    ambiguous_order,
    colour_tilt_contrast,
    dome_judgement,
    ndf_judgement,
    seed_ndf_judgement,
    thickness_judgement,
    unexplained_facets,
)
from .mixtures import MixtureFit, fit_thickness_mixture
from .ndf_fit import fit_ndf_mixture, width_relative_error
from .options import FitOptions
from .planes import MAX_SLOPE_SIGMA, deconvolved_rms_slope
from .sampling import thickness_regions
from .segmentation import neighbour_pairs
from .self_check import measured_rms_slope

__all__ = ["Distributions", "PooledOrders", "calibrate_dome_share", "correct_ndf_width",
           "fit_joint_distributions", "fit_seed_distributions", "pool_interference_orders"]

sparse = load("scipy.sparse")
csgraph = load("scipy.sparse.csgraph")
optimize = load("scipy.optimize")

#: The NDF's width is corrected by the self-check (:func:`correct_ndf_width`) only where the
#: planes its second moment is measured on (below the acceptance, slope noise below
#: :data:`~.planes.MAX_SLOPE_SIGMA`) cover at least this share of the NDF's planes' area:
#: elsewhere it describes a selection, not the NDF. On stacks without focus texture a third
#: or more of the planes are noise read steeper than the acceptance or too noisy for a slope
#: (seed-30 g008 of the sweep: 0.49; the textured scenes: median 0.95, 10th percentile 0.81),
#: and their lobes, already wide, were widened further (docs/accuracy.md, "One width for
#: the lobes and the self-check").
SECOND_MOMENT_MIN_COVERAGE = 0.8
#: A facet more than this fraction of whose pixels are dark is censored (tilted past the
#: acceptance): it carries neither a thickness nor a measured tilt.
CENSORED_FACET_FRACTION = 0.5
#: A candidate's runner-up order is within the populations' own misfit when it fits the
#: candidate's facets no worse than this percentile of the populations' facets' ΔE00 (the
#: colours then do not tell the orders apart). Of the 27 reported candidates of the
#: sweep's seeds 0-2 (before the flat field), 11 lay on a component an order away: the
#: median caught 4 of them, this percentile 10, and no candidate that is a population of
#: its own (docs/accuracy.md).
ALIAS_MISFIT_PERCENTILE = 90.0


@dataclass
class Distributions:
    """The two fitted distributions and whether the data determine them.

    Attributes
    ----------
    thickness, ndf : MixtureFit or None
        None without samples.
    thickness_judgement, ndf_judgement : Judgement
    roi_ambiguous : ndarray of bool
        ROIs whose runner-up interference order fits within ``fits.ambiguous_order_de``.
    roi_fitted : ndarray of bool
        ROIs with a thickness.
    exposure_readings : ExposureReadings or None
        Joint mode with two exposure readings: what the facets decided between
        (:class:`~.joint.ExposureReadings`); an ambiguous pair leaves the order undecided.
    """

    thickness: MixtureFit | None
    ndf: MixtureFit | None
    thickness_judgement: Judgement
    ndf_judgement: Judgement
    roi_ambiguous: np.ndarray = field(default_factory=lambda: np.zeros(0, bool))
    roi_fitted: np.ndarray = field(default_factory=lambda: np.zeros(0, bool))
    exposure_readings: object = None


def _roi_flags(roi, options):
    fitted = np.isfinite(roi.thickness_nm)
    return fitted & ambiguous_order(roi.ambiguity_delta_e, options.ambiguous_order_de), fitted


def _censored_fraction(joint) -> np.ndarray:
    """Per facet, the share of its pixels that are censored (dark)."""
    return (np.bincount(joint.facets.ravel(), weights=joint.censored.ravel(),
                        minlength=joint.area_px.size) / np.maximum(joint.area_px, 1))


def _thickness_samples(joint, options, cens_frac=None):
    """The facets that carry a thickness sample, those the film does not explain, and the
    number of independent thickness regions among the samples; ``cens_frac``:
    :func:`_censored_fraction` of ``joint``, where the caller has it."""
    th = joint.thickness
    # Facets whose colour the film model does not explain (dust, pit floors, mixed or dark
    # facets: ΔE a robust outlier among the facets') and censored (dark) facets carry no
    # thickness: they are left out of the mixture, and counted.
    unexplained = unexplained_facets(th.delta_e, options.unexplained_mads)
    ok = (np.isfinite(th.thickness_nm) & (joint.area_px > 0)
          & ((_censored_fraction(joint) if cens_frac is None else cens_frac)
             < CENSORED_FACET_FRACTION) & ~unexplained)
    return ok, unexplained, _regions(joint, ok)


def _regions(joint, ok):
    """The thickness regions of the facets ``ok`` (None for fewer than two)."""
    th = joint.thickness
    return (thickness_regions(joint.facets, np.where(ok, th.thickness_nm, np.nan),
                              th.sigma_nm) if ok.sum() >= 2 else None)


def _thickness_fit(joint, ok, regions, options, seed) -> MixtureFit:
    th = joint.thickness
    return fit_thickness_mixture(th.thickness_nm[ok], sigma_nm=th.sigma_nm[ok],
                                 weights=joint.area_px[ok].astype(np.float64),
                                 n_effective=regions, options=options, background=True,
                                 seed=seed)


#: Most rounds of setting misread components aside (:func:`_set_aside_misread`), one refit
#: each.
MAX_MISREAD_ROUNDS = 2


def _median(x) -> float | None:
    x = x[np.isfinite(x)]
    return float(np.median(x)) if x.size else None


def _misread(fit, th, ok, regions, area, delta_e_at_estimate=None, *, pairs=None) -> list:
    """The components of ``fit`` that are misread facets: ``(k, record, facets)`` each,
    by colour where they do not cover grains (:func:`~.consistency.misread_components`,
    ``pairs`` the facets' neighbours; where ``delta_e_at_estimate()`` is given, at the
    image's balance and at the white-balance estimate's alike) or scattered in regions of a
    few facets (:func:`~.consistency.scattered_components`; ``area``: the facets' px); at
    least one component is kept."""
    thick = np.where(ok, th.thickness_nm, np.nan)
    out = {k: (k, {"why": "colour", "delta_e": a, "delta_e_populations": b}, mine)
           for k, a, b, mine in misread_components(fit.mixture, thick, th.delta_e,
                                                   pairs=pairs, area=area)}
    if delta_e_at_estimate is not None and out:
        also = {k for k, *_ in misread_components(fit.mixture, thick, delta_e_at_estimate(),
                                                  pairs=pairs, area=area)}
        out = {k: v for k, v in out.items() if k in also}
    for k, f, mine in scattered_components(fit.mixture, thick, regions, area):
        if k not in out and len(out) < len(fit.mixture.components) - 1:
            de = th.delta_e
            out[k] = (k, {"why": "scattered", "delta_e": _median(de[mine & ok]),
                          "delta_e_populations": _median(de[ok & ~mine]),
                          "facets_per_region": f}, mine)
    return list(out.values())


def _set_aside_misread(joint, fit, samples, options, seed, delta_e_at_estimate=None, *,
                       pairs=None):
    """The mixture refitted without the facets of its misread components
    (:func:`_misread`: minor components whose colours the film explains much worse than the
    populations', by the rule a candidate population's colours must pass, and that do not
    cover grains of the surface, or whose facets lie scattered, in regions of a few facets);
    up to :data:`MAX_MISREAD_ROUNDS` times. Their facets join the unexplained ones. Returns the
    fit, the samples ``(ok, unexplained, regions)`` and one record per component set aside
    (mean and weight in the mixture it was found in, why, its facets' and the populations'
    median ΔE00, for scattered ones their facets per region, its facets). ``pairs``: the
    facets' neighbour pairs (:func:`~.segmentation.neighbour_pairs` of ``joint.facets``),
    where the caller has them.

    The number of independent regions grows with the field, and facets misread the same way
    (a stain's colour, an order's look-alike) then pay for a component of their own: on the
    generalization sweep at 1024² px such components made two to five populations of one to
    three (docs/accuracy.md, "Misread facets, and a field 16× larger").
    """
    th = joint.thickness
    ok, unexplained, regions = samples
    records = []
    pairs = neighbour_pairs(joint.facets) if pairs is None else pairs
    for _ in range(MAX_MISREAD_ROUNDS):
        bad = _misread(fit, th, ok, regions, joint.area_px.astype(np.float64),
                       delta_e_at_estimate, pairs=pairs)
        if not bad:
            break
        drop = np.logical_or.reduce([mine for *_, mine in bad])
        left = _regions(joint, ok & ~drop)
        if left is None:
            break
        for k, rec, mine in bad:
            w, mu, _ = fit.mixture.components[k]
            records.append({"mean_nm": float(mu), "weight": float(w), **rec,
                            "facets": int(mine.sum())})
        ok, unexplained, regions = ok & ~drop, unexplained | drop, left
        fit = _thickness_fit(joint, ok, regions, options, seed)
    return fit, (ok, unexplained, regions), records


#: Most components moved to another's interference order (:func:`pool_interference_orders`),
#: one per refitted mixture.
MAX_ORDER_MOVES = 2


@dataclass
class PooledOrders:
    """What :func:`pool_interference_orders` did.

    Attributes
    ----------
    joint : JointResult
        The facets, those of a component read in another's order moved to it.
    moves : list of OrderMove
    samples, fit : tuple or None, MixtureFit or None
        The thickness samples of ``joint``'s facets (``(ok, unexplained, regions)``) and
        their mixture, where the last round fitted them (None after a move, which the
        mixture stage then fits): :func:`fit_joint_distributions` reuses them.
    cut : dict or None
        The facets the order cut read in their runner-up order after the moves
        (:func:`~.order_cut.order_cut`): ``facets`` and ``area_fraction`` of the facets'
        pixels; None where it did not run.
    pairs : ndarray or None
        The facets' neighbour pairs (:func:`~.segmentation.neighbour_pairs` of
        ``joint.facets``) where the cut scanned them: the mixture stage reuses them.
    """

    joint: object
    moves: list = field(default_factory=list)
    samples: tuple | None = None
    fit: MixtureFit | None = None
    cut: dict | None = None
    pairs: np.ndarray | None = None


def pool_interference_orders(joint, resolve, *, period_nm, window_nm, options: FitOptions,
                             seed=0):
    """The facets of a component that is another read in a neighbouring interference order,
    moved to that order (:func:`~.consistency.order_move`), and the mixture refitted; up to
    :data:`MAX_ORDER_MOVES` times.

    A population whose colours fit two orders about alike (within
    ``options.ambiguous_order_de`` on average) has its facets split between the orders by
    noise, white balance or tilt errors, and the mixture counts it twice. Where a
    component's facets fit the order of another component that well, they are read in it:
    one population, not two an order apart. The order itself stays not established (its
    facets' runner-up order fits within the margin: :func:`~.identification.order_check`).
    A move is kept only where, solved again in the other order, at least
    :data:`~.consistency.MOVE_MIN_SHARE` of the component's area lies on the component of
    that order (a facet whose own order still fits better by ``joint.order_switch_de`` keeps
    it); the move records that share and those facets. A facet moves once: a later move
    cannot take it back (its old order, now its runner-up, fits it better, and would
    otherwise draw its new component back the way the colours rejected).

    Parameters
    ----------
    joint : JointResult
        Facets with their thicknesses and runner-up orders.
    resolve : callable
        ``resolve(joint, moved, centre_nm)``: ``joint`` with the facets ``moved`` solved in
        the order about ``centre_nm`` (:func:`~.joint.facets_in_other_order`).
    period_nm, window_nm : float
        The colours' period in thickness (:attr:`~.FilmColourModel.period_nm`) and the
        half-width of a facet's order window (``joint.order_window_fraction`` periods): a
        runner-up order lies at least ``period_nm - window_nm`` away, so components closer
        than that are not an order apart; a component whose :data:`~.consistency.ALIAS_SD`
        band is wider than the window is no order (:func:`~.consistency.order_move`).
    options : FitOptions

    Returns
    -------
    PooledOrders
    """
    moves = []
    done = np.zeros(joint.area_px.shape, bool)      # a facet moves once: no move undoes one
    cens_frac = _censored_fraction(joint)           # the moves change no facet's darkness
    for _ in range(MAX_ORDER_MOVES):
        samples = _thickness_samples(joint, options, cens_frac)
        ok, _, regions = samples
        if regions is None:
            break
        th = joint.thickness
        fit = _thickness_fit(joint, ok, regions, options, seed)
        mv, moved = order_move(fit.mixture, np.where(ok, th.thickness_nm, np.nan),
                               np.where(done, np.nan, th.thickness_other_order_nm),
                               th.delta_e_other_order - th.delta_e, joint.area_px,
                               margin_de=options.ambiguous_order_de,
                               min_separation_nm=period_nm - window_nm,
                               max_sd_nm=window_nm / ALIAS_SD)
        if mv is None:
            return PooledOrders(joint, moves, samples, fit)
        after = resolve(joint, moved, th.thickness_other_order_nm)
        landed = moved & _on_component(after.thickness.thickness_nm, fit.mixture, mv.to_nm)
        a = joint.area_px.astype(np.float64)
        share = float(a[landed].sum() / (a[moved].sum() / mv.area_share))
        if share < MOVE_MIN_SHARE:      # solved in that order, most of its facets keep their own
            return PooledOrders(joint, moves, samples, fit)
        joint, done = after, done | landed
        moves.append(dataclasses.replace(mv, area_share=share, facets=int(landed.sum())))
    return PooledOrders(joint, moves)


def _on_component(thickness_nm, mixture, mean_nm) -> np.ndarray:
    """Samples that lie on the component of ``mixture`` with mean ``mean_nm``
    (:func:`~.consistency.nearest_component`)."""
    k = [c[1] for c in mixture.components].index(mean_nm)
    return nearest_component(mixture, thickness_nm) == k


def _joint_thickness(joint, roi, options, scene, cens_frac, pooled: PooledOrders | None = None,
                     gain_shifts_nm=None, delta_e_at_estimate=None):
    """The thickness mixture of the facets, and its judgement; each candidate population
    with the side of the square field (µm) that would decide it, each component's mean with
    its uncertainty (:func:`mean_uncertainty`). ``pooled``: the samples and mixture
    :func:`pool_interference_orders` fitted to these facets, where it did."""
    th = joint.thickness
    area = joint.area_px.astype(np.float64)
    ready = pooled is not None and pooled.joint is joint and pooled.fit is not None
    ok, unexplained, regions = (pooled.samples if ready
                                else _thickness_samples(joint, options, cens_frac))
    if regions is None:
        return None, NO_SAMPLES["thickness"]
    fit = pooled.fit if ready else _thickness_fit(joint, ok, regions, options, scene.seed)
    scanned = (pooled is not None and pooled.pairs is not None
               and pooled.joint.facets is joint.facets)
    pairs = pooled.pairs if scanned else neighbour_pairs(joint.facets)   # one scan of the map
    fit, (ok, unexplained, regions), misread = _set_aside_misread(
        joint, fit, (ok, unexplained, regions), options, scene.seed, delta_e_at_estimate,
        pairs=pairs)
    fit.info["misread_components"] = misread
    _describe_candidates(fit, regions, th, area, ok,
                         joint.facets.size * float(np.prod(scene.pixel_size_um)))
    fit.info["mean_uncertainty"] = mean_uncertainty(
        fit.mixture, regions, np.where(ok, th.thickness_nm, np.nan), area,
        touching=touching_regions(pairs, regions.patch_region),
        gain_shifts_nm=gain_shifts_nm)
    fit.info["sd_one_region"] = one_region_components(fit.info["mean_uncertainty"])
    a_t = area[ok].sum()
    edge = float(area[ok & th.at_window_edge].sum() / a_t)
    amb = ok & ambiguous_order(th.delta_e_other_order - th.delta_e, options.ambiguous_order_de)
    other = float(area[amb].sum() / a_t)
    orders = component_orders(fit.mixture, np.where(ok, th.thickness_nm, np.nan),
                              th.thickness_other_order_nm, area, amb)
    fit.info.update({"component_orders": orders,
                     "distinct_populations": distinct_populations(fit.mixture, orders),
                     "facets": int(ok.sum()),
                     "unexplained_area_fraction": float(area[unexplained].sum()
                                                        / max(area.sum(), 1.0)),
                     "thickness_regions": regions.count, "order_edge_fraction": edge,
                     "order_ambiguous_fraction": other})
    return fit, thickness_judgement(roi, options, edge_fraction=edge,
                                    other_order_fraction=other)


#: Fewest separate (not touching) groups of regions (:func:`mean_uncertainty`) over which a
#: component's SD measures its population's spread.
MIN_SPREAD_GROUPS = 2
#: A component whose regions' Kish count is below this rests on one region.
ONE_REGION_KISH = 1.5


def one_region_components(uncertainty) -> list:
    """Indices of the components that rest on one thickness region (Kish count below
    :data:`ONE_REGION_KISH`) and whose spread is not measured (:func:`mean_uncertainty`'s
    entries): their SD, at or above the floor, is that region's own scatter.

    >>> one_region_components([{"regions": 1.0, "spread_measured": False},
    ...                        {"regions": 9.0, "spread_measured": False}])
    [0]
    """
    return [i for i, u in enumerate(uncertainty)
            if u["regions"] < ONE_REGION_KISH and not u["spread_measured"]]


def mean_uncertainty(mixture, regions, thickness_nm, area, *, touching=None,
                     gain_shifts_nm=None) -> list:
    """Each component's mean with its 1-σ uncertainty, the systematic part included.

    * **Sampling**: the component's SD over the regions it rests on, ``sd / √n``, ``n`` the
      area-weighted (Kish) count of the thickness regions on it
      (:func:`~.sampling.thickness_regions`, whose count errs high: a true region split
      where noise steps between patches counts more than once; on five draws of the
      generalization sweep 2σ still covers 84–95 % of the true means, docs/accuracy.md).
      Its SD measures the population's spread only over separate regions: where the regions
      on it form fewer than :data:`MIN_SPREAD_GROUPS` groups that do not touch
      (``touching``: one region, or pieces of one), the area-weighted RMS SD of the measured
      components stands in (``spread_measured`` false); none measured, the sampling part is unknown
      (None). The regions' own errors add in quadrature.
    * **White balance**, shared by every facet: the area-weighted mean move of the
      component's facets when the R gain, then the B gain, is off by its own 1σ
      (``gain_shifts_nm``: :func:`~.joint.gain_thickness_shifts` at
      :meth:`~.white_balance.WhiteBalance.log_gain_sigma`), the two in quadrature. None:
      not known (no estimate of the gains).

    Parameters
    ----------
    mixture : ThicknessMixture
    regions : Regions
        The samples' thickness regions (:func:`~.sampling.thickness_regions`).
    thickness_nm, area : ndarray, shape (S,)
        Each facet's thickness (NaN: not a sample) and area (px).
    touching : ndarray of int, shape (P, 2), optional
        Pairs of regions (indices into ``regions``) that touch in the image.
    gain_shifts_nm : ndarray, shape (2, S), optional

    Returns
    -------
    list of dict
        Per component (in the order of ``mixture.components``): ``sigma_nm`` (the parts in
        quadrature; None where the sampling part is unknown), ``sampling_nm``,
        ``white_balance_nm``, ``regions`` (the Kish count of its regions; 0: none lies on
        it), ``groups`` (separate groups of them) and ``spread_measured``.

    Examples
    --------
    >>> from microfacet.core.distributions import ThicknessMixture
    >>> from microfacet.analysis.sampling import Regions
    >>> m = ThicknessMixture([(0.5, 100.0, 2.0), (0.5, 140.0, 0.1)])
    >>> d = np.array([98.0, 100.0, 102.0, 99.5, 140.0])
    >>> r = Regions(np.arange(5), d, np.full(5, 0.2), np.full(5, 100), 0.0)
    >>> u = mean_uncertainty(m, r, d, np.full(5, 100), gain_shifts_nm=np.full((2, 5), 0.3))
    >>> [(x["sampling_nm"], x["white_balance_nm"], x["regions"]) for x in u]
    [(1.005, 0.4243, 4.0), (2.01, 0.4243, 1.0)]
    >>> u = mean_uncertainty(m, r, d, np.full(5, 100), touching=np.array([[0, 1], [1, 2],
    ...                                                                     [2, 3]]))
    >>> u[0]["groups"], u[0]["spread_measured"], u[0]["sampling_nm"]   # pieces of one
    (1, False, None)
    """
    comps = mixture.components
    sd = np.array([c[2] for c in comps])
    w = np.array([c[0] for c in comps])
    on_r = nearest_component(mixture, regions.value)
    group = _region_groups(on_r, touching)
    ra = regions.area.astype(np.float64)
    counts = []
    for k in range(len(comps)):
        a = ra[(on_r == k) & (ra > 0)]
        counts.append((float(a.sum() ** 2 / np.sum(a * a)) if a.size else 0.0,
                       np.unique(group[(on_r == k) & (ra > 0)]).size))
    measured = np.array([g >= MIN_SPREAD_GROUPS for _, g in counts])
    spread = (float(np.sqrt(np.average(sd[measured] ** 2, weights=w[measured])))
              if measured.any() else None)
    on_f = nearest_component(mixture, thickness_nm)
    out = []
    for k, (n, groups) in enumerate(counts):
        a, sg = ra[on_r == k], regions.sigma[on_r == k]
        own = float(np.sum((a * sg) ** 2) / a.sum() ** 2) if a.sum() > 0 else 0.0
        s_k = float(sd[k]) if measured[k] else spread
        samp = None if s_k is None else math.sqrt(s_k ** 2 / max(n, 1.0) + own)
        wb = None
        if gain_shifts_nm is not None:
            f = (on_f == k) & np.all(np.isfinite(gain_shifts_nm), axis=0)
            if f.any():
                wb = float(np.hypot(*np.average(gain_shifts_nm[:, f], axis=1,
                                                weights=area[f])))
        total = None if samp is None else math.hypot(samp, wb or 0.0)
        out.append({"sigma_nm": _round(total), "sampling_nm": _round(samp),
                    "white_balance_nm": _round(wb), "regions": round(n, 2),
                    "groups": int(groups), "spread_measured": bool(measured[k])})
    return out


def _region_groups(component, touching) -> np.ndarray:
    """Per region, its group: regions of one component (``component``, -1: none) joined
    through the touching pairs between them (connected components)."""
    R = component.size
    if touching is None or len(touching) == 0:
        return np.arange(R)
    t = np.asarray(touching, dtype=np.int64)
    same = (component[t[:, 0]] == component[t[:, 1]]) & (component[t[:, 0]] >= 0)
    t = t[same]
    graph = sparse.coo_matrix((np.ones(len(t)), (t[:, 0], t[:, 1])), shape=(R, R))
    return csgraph.connected_components(graph, directed=False)[1]


def touching_regions(patch_pairs, patch_region) -> np.ndarray:
    """Pairs of regions (indices, shape (P, 2), i < j, sorted) whose patches touch: the
    patches' own neighbour pairs (:func:`~.segmentation.neighbour_pairs` of the patch
    labels) mapped to their regions (patches without a region, -1, take no part)."""
    r = np.asarray(patch_region, dtype=np.int64)[np.asarray(patch_pairs, np.int64).reshape(-1, 2)]
    r = r[(r >= 0).all(axis=1) & (r[:, 0] != r[:, 1])]
    return np.unique(np.sort(r, axis=1), axis=0).reshape(-1, 2)


def _round(v):
    return None if v is None else round(float(v), 4)


def _describe_candidates(fit, regions, th, area, ok, field_um2) -> None:
    """Each candidate population's field side (µm), its facets' colour misfit beside the
    populations' (a candidate the film does not explain is mis-read regions), and whether
    it may be a component read in another order: its facets' runner-up order (area-weighted
    median) lies on a component and fits them within the populations' own misfit (the
    :data:`ALIAS_MISFIT_PERCENTILE` th percentile of their facets' ΔE00), so the colours do
    not tell the two orders apart."""
    cands = fit.info.get("candidates", [])
    if not cands:
        return
    region = np.where(ok, regions.patch_region, -1)
    taken = np.isin(region, np.concatenate([c.region_index for c in cands]))
    de = th.delta_e
    rest = ok & ~taken & np.isfinite(de)
    pop_de = float(np.median(de[rest])) if rest.any() else None
    misfit = float(np.percentile(de[rest], ALIAS_MISFIT_PERCENTILE)) if rest.any() else None
    for c in cands:
        mine = np.isin(region, c.region_index) & np.isfinite(de)
        c.delta_e = float(np.median(de[mine])) if mine.any() else None
        c.delta_e_populations = pop_de
        if c.field_scale is not None:
            c.decided_at_field_um = math.sqrt(c.field_scale * field_um2)
        if misfit is not None:
            c.alias_of_nm, c.order_gap_de = candidate_alias(
                fit.mixture, th.thickness_other_order_nm[mine],
                th.delta_e_other_order[mine] - de[mine], area[mine], misfit)


@dataclass
class _PlaneSamples:
    """The NDF's samples: the facets whose plane it uses, their areas, and the censored
    weight (area) counted against all the film seen."""

    use: np.ndarray
    area: np.ndarray
    censored: float

    @property
    def n_effective(self) -> float:
        """Facets with a plane, plus the censored weight in facets of their mean area."""
        a = self.area[self.use] if self.use.any() else self.area
        return float(self.use.sum()) + self.censored / max(float(a.mean()), 1.0)

    def fit(self, planes, max_tilt_deg, options, seed) -> MixtureFit:
        """The lobes of the planes' slopes (and slope noise)."""
        u, C = self.use, self.censored
        return fit_ndf_mixture(planes.tilt_deg[u], slope_sigma=planes.slope_sigma[u],
                               weights=self.area[u],
                               censored=(C, max_tilt_deg) if C > 0 else None,
                               n_effective=max(self.n_effective, 1.0), options=options,
                               seed=seed)


def _plane_samples(joint, cens_frac) -> _PlaneSamples:
    pl = joint.slope_planes
    area = joint.area_px.astype(np.float64)
    use = pl.fitted & np.isfinite(pl.tilt_deg) & (cens_frac < CENSORED_FACET_FRACTION)
    # Only what is dark is censored. A bright facet whose plane reads steeper than the
    # acceptance is seen, so it is not past it: its plane is a noisy sample like the others
    # (counted as censored, slope noise alone turned instrument-measured surfaces with
    # almost nothing past the limit into a wide lobe).
    C = float(joint.censored.sum())
    # The facets seen without a plane (too little texture for one) are not past the limit
    # either: the planes sample the seen film, so the censored share is of all of it
    # (counted against the planes alone, it read 0.29 on a sweep scene with no facet past
    # the limit: docs/accuracy.md).
    # Seen: not censored, and at least half the facet's pixels usable film (not dust or
    # shadow, whose tilt is as unknown as the planes' absence says nothing of).
    seen_all = float(area[_seen_facets(joint, cens_frac) | use].sum())
    C = C * float(area[use].sum()) / seen_all if use.any() and seen_all > 0 else C
    return _PlaneSamples(use, area, C)


def _joint_ndf(joint, model, cens_frac, max_tilt_deg, options, seed):
    """The NDF of the facet planes (censored), and its judgement."""
    th, pl = joint.thickness, joint.slope_planes
    ps = _plane_samples(joint, cens_frac)
    use, area, C = ps.use, ps.area, ps.censored
    d_med = float(np.nanmedian(th.thickness_nm)) if np.isfinite(th.thickness_nm).any() else 0.0
    contrast = colour_tilt_contrast(model, d_med) if d_med > 0 else 0.0
    c_err = float(np.nanmedian(joint.colour_sigma_de / np.sqrt(np.maximum(area, 1))))
    fit, rel = None, math.inf
    if use.sum() >= 2:
        fit = ps.fit(pl, max_tilt_deg, options, seed)
        fit.info["samples"] = "facet plane tilts (height from focus)"
        rel = width_relative_error(pl.tilt_deg[use], pl.slope_sigma[use], area[use],
                                   float(use.sum()))
    elif np.isfinite(joint.pixels.tilt_deg).sum() >= 2:
        # No facet planes: for inspection only (never identified), the per-pixel tilts, one
        # independent sample per facet.
        okp = np.isfinite(joint.pixels.tilt_deg)
        fit = fit_ndf_mixture(joint.pixels.tilt_deg[okp], group=joint.facets[okp],
                              options=options, seed=seed)
        fit.info["samples"] = "per-pixel tilt (no facet has a height plane)"
    if fit is None:
        return None, NO_SAMPLES["ndf"]
    seen = float(area[use].sum()) + C if use.any() else float(area.sum())
    fit.info.update({"facets": int(use.sum()), "facets_total": int(area.size),
                     "width_relative_error": float(rel) if math.isfinite(rel) else None,
                     "colour_tilt_contrast_de": contrast})
    evidence = NdfEvidence(int(use.sum()), int(area.size),
                           float(area[pl.fitted].sum() / max(area.sum(), 1)), rel,
                           C / max(seen, 1.0), contrast, c_err, d_med)
    share = _dome_share(joint.dome_ms_slope, pl, use, area)
    fit.info["dome_share"] = share
    return fit, dome_judgement(ndf_judgement(evidence, options), share, options)


def _seen_facets(joint, cens_frac) -> np.ndarray:
    """Facets seen as film: not censored, at least half their pixels usable."""
    usable = np.bincount(joint.facets.ravel(), weights=joint.usable.ravel(),
                         minlength=joint.area_px.size)
    return ((cens_frac < CENSORED_FACET_FRACTION) & (joint.area_px > 0)
            & (usable >= 0.5 * joint.area_px))


def _dome_share(dome, pl, use, area) -> float | None:
    """The upper end (+2 standard errors) of the mean square slope inside the facets over
    the planes' own: how much wider the per-pixel NDF may be than the planes'. None without
    planes (nothing to judge); NaN where the planes' facets are too few or too small to
    measure it (:func:`~.planes.dome_mean_square_slope` gives None), or where the planes'
    own slope is all noise and the dome term is not 0: their flatness is not shown either.
    The planes' RMS slope leaves out slivers (:func:`~.planes.deconvolved_rms_slope`)."""
    if not use.any():
        return None
    if dome is None:
        return math.nan
    rms = deconvolved_rms_slope(pl, use, area[use])        # slivers left out there
    top = max(dome[0] + 2.0 * dome[1], 0.0)
    if not rms > 0:
        return 0.0 if top == 0.0 else math.nan
    return float(top / rms ** 2)


def fit_joint_distributions(joint, roi, model, scene, options: FitOptions, *,
                            pooled: PooledOrders | None = None,
                            gain_shifts_nm=None, delta_e_at_estimate=None) -> Distributions:
    """Thickness mixture and NDF of a :class:`~.joint.JointResult`, with identification.

    Parameters
    ----------
    joint : JointResult
        With its per-pixel estimates.
    roi : RoiFit
    model : FilmColourModel
        At the joint stage's exposure (for the colour's tilt contrast).
    scene : Scene
        The acceptance limit (censoring) and the seed.
    options : FitOptions
    pooled : PooledOrders, optional
        :func:`pool_interference_orders` on these facets: its thickness mixture is reused
        where it fitted one to them (the same samples and seed give the same fit), and its
        moves are recorded (``info["order_moves"]``).
    gain_shifts_nm : ndarray, shape (2, S), optional
        Each facet's thickness move for a 1σ error of the R and B gains
        (:func:`~.joint.gain_thickness_shifts`): the white-balance part of the components'
        mean uncertainty (``info["mean_uncertainty"]``, :func:`mean_uncertainty`).
    delta_e_at_estimate : callable, optional
        ``delta_e_at_estimate()``: each facet's colour misfit (shape (S,)) at the scene's
        white-balance estimate, where it was not applied (:func:`~.joint.delta_e_rebalanced`;
        called only where a component would be set aside by colour): a component is misread
        by colour only where its colours fit worse than the populations' at the image's
        balance and at the estimate's alike (a white-balance error fits some thicknesses
        worse than others).
    """
    cens_frac = _censored_fraction(joint)
    tfit, tj = _joint_thickness(joint, roi, options, scene, cens_frac, pooled, gain_shifts_nm,
                                delta_e_at_estimate)
    if tfit is not None and pooled is not None:
        tfit.info["order_moves"] = [m.to_json() for m in pooled.moves]
        if pooled.cut is not None:
            tfit.info["order_cut"] = pooled.cut
    nfit, nj = _joint_ndf(joint, model, cens_frac, scene.max_tilt_deg, options, scene.seed)
    return Distributions(tfit, nfit, tj, nj, *_roi_flags(roi, options))


def calibrate_dome_share(dist: Distributions, check, options: FitOptions) -> Distributions:
    """The planar-facet check over what the heights show of a facet's curvature.

    The dome term the analysis measures inside its facets (``ndf.info["dome_share"]``, the
    upper end of its mean square slope over the planes') is what the heights show of it: the
    self-check's ``dome_transfer`` g (:class:`~.self_check.SelfCheck`: recovered over
    injected dome coefficients) says how much that is. The share is divided by g² (g capped
    at 1: heights that exaggerate domes are not credited) and the NDF judged again
    (:func:`~.identification.dome_judgement`); the measured share is kept as
    ``info["dome_share_measured"]``. Heights that flatten domes to nothing (g ≤ 0) cannot
    show the facets planar: the share is infinite. Unchanged without a self-check, an NDF,
    a measured share or a measured transfer.

    >>> from microfacet.analysis.identification import Judgement
    >>> from microfacet.analysis.ndf_fit import MixtureFit
    >>> from microfacet.analysis.self_check import SelfCheck
    >>> fit = MixtureFit.__new__(MixtureFit); fit.info = {"dome_share": 0.1}
    >>> d = Distributions(None, fit, Judgement(True), Judgement(True))
    >>> check = SelfCheck([], [], [], 1.0, 0.0, 10, dome_transfer=0.5)
    >>> out = calibrate_dome_share(d, check, FitOptions())
    >>> out.ndf.info["dome_share"], out.ndf_judgement.identified
    (0.4, False)
    """
    g = math.nan if check is None else check.dome_transfer
    share = None if dist.ndf is None else dist.ndf.info.get("dome_share")
    if share is None or not math.isfinite(share) or not math.isfinite(g):
        return dist
    cal = share / min(g, 1.0) ** 2 if g > 0 else (math.inf if share > 0 else 0.0)
    dist.ndf.info["dome_share_measured"] = share
    dist.ndf.info["dome_share"] = cal
    return dataclasses.replace(dist, ndf_judgement=dome_judgement(dist.ndf_judgement, cal,
                                                                  options))


def correct_ndf_width(dist: Distributions, joint, scene, options: FitOptions,
                      check) -> Distributions:
    """The NDF's lobes scaled to the RMS slope the self-check vouches for.

    The self-check (:mod:`.self_check`) measures, on the stack itself, how much of the true
    RMS slope the facet planes keep once their slope noise is removed: the RMS of the planes
    below the acceptance, noise removed in quadrature (:func:`~.self_check.measured_rms_slope`),
    over the true one (``check.width_transfer``). That second moment, divided by the
    transfer, is the width the stack's own measurement supports. The lobes' shape — how many,
    their weights and relative widths — is the mixture fit's (per-facet slope noise,
    censoring, the lobe count by BIC), but their RMS slope is not the second moment the
    transfer was measured for: the fit's censored weight and its lobe count move it by a
    scene-dependent factor (docs/accuracy.md, "One width for the lobes and the self-check").
    So the lobes are scaled together (:meth:`~microfacet.core.distributions.NDFMixture.scaled`)
    until their RMS slope below the acceptance
    (:meth:`~microfacet.core.distributions.NDFMixture.rms_slope`) is that width.

    Done where ``fits.self_check_correct`` is on and the self-check measured both its slope
    gain (``check.transfer``) and its width transfer between ``fits.self_check_min_transfer``
    and the top of ``fits.self_check_range`` (a correction of at most 1 /
    ``self_check_min_transfer``; a width transfer beside a slope gain far below it is a
    stack without focus texture, whose planes are noise and whose noise model sets the
    width: no measured gain) and where the planes that second moment is measured on cover at
    least :data:`SECOND_MOMENT_MIN_COVERAGE` of the NDF's planes' area, identified or not;
    the lobes as fitted, the transfer, the
    planes' RMS slope and the factor are kept in ``info["width_correction"]``. The
    correction's size stays in the width's total error
    (:meth:`~.self_check.SelfCheck.width_error`). Otherwise ``dist`` unchanged.
    """
    if dist.ndf is None or not options.self_check_correct or not _correctable(check, options):
        return dist
    ps = _plane_samples(joint, _censored_fraction(joint))
    planes_rms = measured_rms_slope(joint, scene.max_tilt_deg)
    if (ps.use.sum() < 2 or not planes_rms     # the NDF is of per-pixel tilts, or no planes
            or _second_moment_coverage(joint.slope_planes, ps, scene.max_tilt_deg)
            < SECOND_MOMENT_MIN_COVERAGE):
        return dist
    g = check.width_transfer
    mixture = dist.ndf.mixture
    factor = _rms_scale(mixture, planes_rms / g, scene.max_tilt_deg)
    if not math.isfinite(factor):
        return dist
    info = {**dist.ndf.info,
            "width_correction": {"slope_gain": float(g), "planes_rms_slope": float(planes_rms),
                                 "rms_slope": float(planes_rms / g), "scale": float(factor),
                                 "uncorrected": mixture.to_json()["components"]}}
    return dataclasses.replace(dist, ndf=dataclasses.replace(
        dist.ndf, mixture=mixture.scaled(factor), info=info))


def _second_moment_coverage(planes, ps, max_tilt_deg) -> float:
    """The share of the NDF's planes' area (``ps.use``) that the second moment the self-check
    calibrates is measured on: planes below the acceptance with a measurable slope."""
    u = ps.use
    seen = u & (planes.tilt_deg < max_tilt_deg) & (planes.slope_sigma < MAX_SLOPE_SIGMA)
    return float(ps.area[seen].sum() / max(float(ps.area[u].sum()), 1e-300))


def _correctable(check, options: FitOptions) -> bool:
    """Whether the self-check measured both transfers in ``[self_check_min_transfer, top of
    self_check_range]``."""
    if check is None:
        return False
    low, high = options.self_check_min_transfer, options.self_check_range[1]
    return all(math.isfinite(v) and low <= v <= high
               for v in (check.transfer, check.width_transfer))


def _rms_scale(mixture, rms_slope, max_tilt_deg) -> float:
    """The factor by which every lobe's slope is multiplied for the mixture's RMS slope below
    ``max_tilt_deg`` to be ``rms_slope`` (NaN where no factor in [10⁻³, 10³] gives it)."""
    def gap(log_f):
        return math.log(mixture.scaled(math.exp(log_f)).rms_slope(max_tilt_deg) / rms_slope)
    lo, hi = math.log(1e-3), math.log(1e3)
    try:
        return math.exp(optimize.brentq(gap, lo, hi, xtol=1e-10))
    except ValueError:
        return math.nan


def fit_seed_distributions(pixels, roi, model, noise_de, options: FitOptions, *,
                           seed=0) -> Distributions:
    """The seed's fits on per-pixel estimates (thickness per ROI, tilt from colour alone).

    The NDF is identified only if colour carries tilt at the median thickness
    (:func:`~.identification.colour_tilt_contrast` above ``options.colour_contrast_factor`` ×
    the pixel noise ``noise_de``).
    """
    ok = np.isfinite(pixels.thickness_nm)
    tfit, tj = None, NO_SAMPLES["thickness"]
    if ok.sum() >= 2:
        tfit = fit_thickness_mixture(pixels.thickness_nm[ok], group=pixels.thickness_group[ok],
                                     options=options, seed=seed)
        tj = thickness_judgement(roi, options)
    okt = np.isfinite(pixels.tilt_deg)
    nfit, nj = None, NO_SAMPLES["ndf"]
    if okt.sum() >= 2:
        nfit = fit_ndf_mixture(pixels.tilt_deg[okt], group=pixels.thickness_group[okt],
                               options=options, seed=seed)
        d_med = float(np.nanmedian(pixels.thickness_nm))
        contrast = colour_tilt_contrast(model, d_med)
        nj = seed_ndf_judgement(contrast, d_med, noise_de, options)
        nfit.info["colour_tilt_contrast_de"] = contrast
    return Distributions(tfit, nfit, tj, nj, *_roi_flags(roi, options))
