"""Thickness per facet from its colour at its tilt, within its interference order.

Colour moves about 2 ΔE00 per nm of thickness but only 0.03-0.3 per degree of tilt: to first
order a tilt θ acts like a thickness change d·(1 − cos θ₁), so a 1 nm thickness change inside
a region masquerades as a 10-20° tilt in the seed's per-pixel inversion. The joint mode
(:mod:`.joint`) therefore takes each facet's tilt from its plane (:mod:`.planes`) and its
thickness from colour at that tilt: the d of least ΔE between the facet's mean interior Lab
and the model (:class:`~microfacet.colour.model.FilmColourModel`), searched over the facet's
interference order (±``order_window_fraction`` of the colour period λ/(2n) around its ROI's
thickness: the colours of the neighbouring orders, a period away, stay out), with a 1-σ error
from the curvature of ΔE² and the tilt's own error. Every search is
:func:`~.search.coarse_to_fine` on a uniform grid.

A facet is often darker than its film: the dark grooves and rims its mean averages in, a
stain, the part of the illumination cone a tilted facet returns outside the objective, the
vignetting the flat field leaves. Each darkens it by a factor k ≤ 1 and leaves its film's
chromaticity, so a facet is compared with the film at the brightness k ∈
[``facet_brightness_min``, 1] that fits it best, at a cost of ``facet_brightness_penalty_de``
ΔE per unit |ln k| in quadrature (:func:`brightness_factors`): compared at the image's
exposure alone, a facet at half the light matched a darker look-alike in another
interference order (docs/accuracy.md, "A facet darker than its film"). The exposure itself
is refined at k = 1 (the film's full brightness).

References
----------
.. [1] N. Nagata et al., the seed, §3.3.3 (2) (thickness of least mean ΔE).
"""

from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass

import numpy as np

from ..core.lazy import load
from ..core.threads import chunk_starts, thread_map
from .colour_image import mean_colour_noise
from .options import JointOptions
from .search import coarse_to_fine, refine

optimize = load("scipy.optimize")

__all__ = ["FacetThickness", "brightness_factors", "facet_thickness",
           "refine_exposure_on_facets"]

#: Facets in flight in the vectorised searches (bounded temporaries; split over the threads).
_CHUNK = 2048
#: Largest ratio between neighbouring brightness factors (:func:`brightness_factors`).
BRIGHTNESS_STEP = 0.9
#: Strides of the coarse-to-fine searches: the 1 nm order window (every other nm, then the
#: nodes next to the best), the fine scan below 1 nm, the whole-range order scan.
_WINDOW_STRIDE, _FINE_STRIDE, _ORDER_STRIDE = 2, 5, 2


@dataclass
class FacetColours:
    """The colour evidence of each facet (arrays of length S).

    Attributes
    ----------
    mean_lab : ndarray, shape (S, 3)
        Mean Lab of the facet's usable interior pixels (all its usable ones where it has no
        interior pixel).
    n_pixels : ndarray
        Pixels averaged.
    roi_thickness_nm : ndarray
        Mean ROI thickness over those pixels: the centre of the facet's order window.
    """

    mean_lab: np.ndarray
    n_pixels: np.ndarray
    roi_thickness_nm: np.ndarray


@dataclass
class FacetImage:
    """The image as facets: labels, Lab, the usable pixels, the interior ones (away from a
    facet's partly shadowed boundary) and the ROI stage's thickness per pixel."""

    labels: np.ndarray
    lab: np.ndarray
    usable: np.ndarray
    interior: np.ndarray
    roi_thickness_px: np.ndarray

    @property
    def n_facets(self) -> int:
        return int(self.labels.max()) + 1

    def colours(self, usable=None) -> FacetColours:
        """Mean Lab, pixel count and mean ROI thickness of every facet's ``usable`` (default:
        all usable) pixels, its interior ones where it has any."""
        S = self.n_facets
        lab_flat = np.asarray(self.lab).reshape(-1, 3)   # gathered, then float64
        u = np.asarray(self.usable if usable is None else usable, bool).ravel()
        lb = self.labels.ravel()
        ui = u & np.asarray(self.interior, bool).ravel()
        has_interior = np.bincount(lb[ui], minlength=S) > 0
        u = np.flatnonzero(np.where(has_interior[lb], ui, u))
        lbu = lb[u]
        cnt = np.bincount(lbu, minlength=S).astype(np.float64)
        mean_lab = np.stack([np.bincount(lbu, weights=lab_flat[u, c].astype(np.float64),
                                         minlength=S)
                             for c in range(3)], axis=-1) / np.maximum(cnt, 1)[:, None]
        v = np.asarray(self.roi_thickness_px).ravel()[u].astype(np.float64)
        ok = np.isfinite(v)
        mv = (np.bincount(lbu[ok], weights=v[ok], minlength=S)
              / np.maximum(np.bincount(lbu[ok], minlength=S), 1))
        return FacetColours(mean_lab, cnt, mv)


@dataclass
class FacetThickness:
    """Thickness per facet (arrays of length S; NaN where a facet has no usable pixel).

    Attributes
    ----------
    thickness_nm, sigma_nm : ndarray
        Thickness and its 1-σ error (colour noise and misfit through the curvature of ΔE²,
        plus the thickness equivalent of the tilt's error).
    delta_e : ndarray
        ΔE between the facet's mean colour and the model at the solution.
    at_window_edge : ndarray of bool
        The minimum lies at the edge of the interference-order window (the colour fits a
        thickness outside the order better: ambiguous).
    n_pixels : ndarray of int
        Pixels whose mean colour was used.
    delta_e_other_order : ndarray
        The least ΔE in the neighbouring orders' windows (one colour period above and
        below; NaN where both lie outside the table): close to ``delta_e``, the order is
        uncertain.
    thickness_other_order_nm : ndarray
        Where that least ΔE lies (1 nm grid; NaN as above).
    """

    thickness_nm: np.ndarray
    sigma_nm: np.ndarray
    delta_e: np.ndarray
    at_window_edge: np.ndarray
    n_pixels: np.ndarray
    delta_e_other_order: np.ndarray
    thickness_other_order_nm: np.ndarray


def brightness_factors(min_factor, penalty_de):
    """The brightness factors k a facet's colour is compared at, and the cost of each (ΔE,
    added in quadrature): k from ``min_factor`` to 1, geometric, neighbours at most
    :data:`BRIGHTNESS_STEP` apart; cost ``penalty_de`` · |ln k|. ``min_factor`` 1: k = 1 only.

    >>> k, cost = brightness_factors(0.5, 4.0)
    >>> len(k), round(float(k[0]), 2), float(k[-1]), round(float(cost[0]), 2), float(cost[-1])
    (8, 0.5, 1.0, 2.77, 0.0)
    """
    if min_factor >= 1.0:
        return np.ones(1), np.zeros(1)
    n = int(math.ceil(math.log(min_factor) / math.log(BRIGHTNESS_STEP) - 1e-9)) + 1
    k = np.geomspace(min_factor, 1.0, n)
    k[-1] = 1.0
    return k, penalty_de * np.abs(np.log(k))


class _Rows:
    """ΔE of a chunk of facets' mean colours against the model at thicknesses of a uniform
    grid per facet, ``clip(centre + offsets[node])``: the objective of the searches: the
    least over the ``brightness`` factors (:func:`brightness_factors`) of the ΔE with the
    model's colour scaled by k and the factor's cost in quadrature (k = 1 alone: the ΔE)."""

    def __init__(self, model, tilt, mean_lab, centre, offsets, brightness):
        self.model, self.tilt, self.offsets = model, tilt[:, None], offsets
        self.lab = mean_lab[:, None, :].astype(np.float32)
        self.centre = centre[:, None]
        self.lo, self.hi = model.thickness_range_nm
        self.brightness = brightness

    def thickness(self, nodes):
        return np.clip(self.centre + self.offsets[nodes], self.lo, self.hi)

    def __call__(self, nodes):
        d = self.thickness(nodes)
        if self.brightness[0].size == 1:
            return self.model.delta_e(self.lab, self.tilt, d).astype(np.float64)
        xyz = self.model.xyz(self.tilt, d)
        lab = self.model.lab_from_xyz(xyz)
        best = None
        for k, cost in zip(*self.brightness):
            de = self.model.difference(self.model.lab_scaled(lab, xyz, k),
                                       self.lab).astype(np.float64)
            if cost > 0:
                de = np.hypot(de, cost)
            best = de if best is None else np.minimum(best, de)
        return best


def _window_minimum(rows):
    """The node of least ΔE in each facet's window (every other node, then the nodes next
    to the best). Returns the thickness, the node and its ΔE."""
    n = rows.offsets.size
    scan = coarse_to_fine(rows, n, rows.centre.shape[0], stride=_WINDOW_STRIDE, reach=1)
    k = scan.node
    return rows.thickness(k[:, None])[:, 0], k, scan.value


def _order_scan(model, tilt, mean_lab, centre, hw, brightness):
    """Least ΔE inside the order window ±``hw`` about ``centre`` and the best thickness and
    ΔE outside it, over the table's whole range at 1 nm (coarse-to-fine, shared coarse
    pass). Returns ``best_in, d_out, de_out`` (inf where a side has no node)."""
    lo, hi = model.thickness_range_nm
    g = np.arange(lo, hi + 1e-9, 1.0)
    rows = _Rows(model, tilt, mean_lab, np.zeros(centre.size), g, brightness)
    inside = np.abs(g[None, :] - centre[:, None]) <= hw
    s_in, s_out = coarse_to_fine(rows, g.size, centre.size, stride=_ORDER_STRIDE, reach=1,
                                 allowed=[inside, ~inside])
    return s_in.value, g[s_out.node], s_out.value


def _fine(model, tilt, mean_lab, d_k, step, brightness):
    """±1 nm at ``step`` about ``d_k``, coarse-to-fine, and the parabola through the least
    ΔE² (:func:`~.search.refine`): thickness, ΔE and d²(ΔE²)/dd² (NaN where not convex)."""
    fine = np.arange(-1.0, 1.0 + 1e-9, step)
    rows = _Rows(model, tilt, mean_lab, d_k, fine, brightness)
    sq = lambda nodes: rows(nodes) ** 2   # noqa: E731 - the objective is ΔE²
    stride = _FINE_STRIDE if fine.size >= 4 * _FINE_STRIDE else 1
    m = refine(coarse_to_fine(sq, fine.size, d_k.size, stride=stride), fine.size)
    d = rows.thickness(m.node[:, None])[:, 0] + m.offset * step
    return d, np.sqrt(np.maximum(m.vertex, 0.0)), m.curvature / step ** 2


def _sigma(model, fine, n_px, tilt, tilt_sigma_deg, search, hw):
    """1-σ thickness error: the colour error of the facet's mean per Lab component (noise
    over its pixels and the JPEG block error over its blocks, or the misfit when larger)
    through the curvature of ΔE², plus the thickness equivalent of the tilt's error; at most
    the SD of a uniform spread over the window (a flat ΔE curve). ``fine`` is
    :func:`_fine`'s (thickness, ΔE, curvature)."""
    d, de, curv = fine
    sc = np.maximum(mean_colour_noise(search.noise_de, search.block_noise, n_px),
                    de / math.sqrt(3.0))
    with np.errstate(divide="ignore", invalid="ignore"):
        s2 = (sc * np.sqrt(2.0 / curv)) ** 2
    if tilt_sigma_deg is not None:
        dd_dth = model.thickness_per_tilt(tilt, d)
        s2 = s2 + (dd_dth * np.radians(np.nan_to_num(tilt_sigma_deg, nan=0.0))) ** 2
    s = np.minimum(np.sqrt(s2), hw / math.sqrt(3.0))
    return np.where(np.isfinite(s), s, hw / math.sqrt(3.0))


def _other_orders(model, tilt, mean_lab, d, window, brightness):
    """The least ΔE in the windows (``window = (hw, offsets)``) one colour period above and
    below ``d``, and the thickness (1 nm grid) where it lies."""
    lo, hi = model.thickness_range_nm
    hw, offsets = window
    alt, alt_d = np.full(d.size, np.inf), np.full(d.size, np.nan)
    for shift in (-model.period_nm, model.period_nm):
        c2 = d + shift
        inside = (c2 + hw >= lo) & (c2 - hw <= hi)
        if inside.any():
            rows = _Rows(model, tilt[inside], mean_lab[inside], c2[inside], offsets,
                         brightness)
            t, _, v = _window_minimum(rows)
            better = v < alt[inside]
            idx = np.flatnonzero(inside)[better]
            alt[idx], alt_d[idx] = v[better], t[better]
    return np.where(np.isfinite(alt), alt, np.nan), alt_d


@dataclass(frozen=True)
class _Search:
    """How :func:`facet_thickness` searches: the whole range for another order and the
    neighbouring orders (``thorough``), the final step, the colour noise, the tilts' error,
    the JPEG block error and the pixels that share it, the brightness factors and their
    costs (:func:`brightness_factors`)."""

    thorough: bool
    step_nm: float
    noise_de: float
    tilt_sigma_deg: np.ndarray | None
    block_noise: tuple
    brightness: tuple


def _chunk(model, colours, ii, tilt, options, search: _Search):
    """:func:`facet_thickness` on the facets ``ii``: (d, σ, ΔE, edge, other-order ΔE, its
    thickness)."""
    hw = options.order_window_fraction * model.period_nm
    t_lo, t_hi = model.theta_range_deg
    th = np.clip(tilt[ii], t_lo, t_hi)
    lab, cen = colours.mean_lab[ii], colours.roi_thickness_nm[ii]
    br = search.brightness
    if search.thorough:
        best_in, d_out, de_out = _order_scan(model, th, lab, cen, hw, br)
        switch = ((de_out < best_in - options.order_switch_de)
                  & (de_out < options.order_switch_ratio * best_in))
        cen = np.where(switch, d_out, cen)
    offsets = np.arange(-hw, hw + 1e-9, 1.0)
    d_k, k, _ = _window_minimum(_Rows(model, th, lab, cen, offsets, br))
    edge = (k == 0) | (k == offsets.size - 1)
    d, de, curv = _fine(model, th, lab, d_k, search.step_nm, br)
    ts = None if search.tilt_sigma_deg is None else search.tilt_sigma_deg[ii]
    s = _sigma(model, (d, de, curv), colours.n_pixels[ii], th, ts, search, hw)
    alt, alt_d = (_other_orders(model, th, lab, d, (hw, offsets), br) if search.thorough
                  else (np.full(ii.size, np.nan),) * 2)
    return d, s, de, edge, alt, alt_d


def facet_thickness(colours: FacetColours, tilt_deg, model, options: JointOptions, *,
                    tilt_sigma_deg=None, noise_de=1.0, block_noise=(0.0, 64),
                    thorough=True) -> FacetThickness:
    """Thickness per facet from its mean Lab at its tilt, within its interference order.

    The order is the ROI's (the window ±``order_window_fraction`` colour periods about the
    ROI thickness) unless a scan of the table's whole thickness range finds, outside that
    window, a thickness whose colour fits the facet better by more than
    ``options.order_switch_de`` and with at most ``options.order_switch_ratio`` of the ROI
    order's ΔE: a facet of another population than its ROI's majority, in another order,
    takes its own. Within ``order_switch_de`` the orders are not told apart by colour and the
    ROI's is kept. Every ΔE is the facet's against the film at the brightness factor that fits
    it best (module notes; ``options.facet_brightness_min`` 1: at the model's exposure).

    Parameters
    ----------
    colours : FacetColours
        From :meth:`FacetImage.colours`.
    tilt_deg : ndarray, shape (S,)
        Tilt per facet (its plane's, or a stand-in where it has none).
    model : FilmColourModel
        The film colour at the scene's exposure.
    options : JointOptions
    tilt_sigma_deg : ndarray, shape (S,), optional
        Error of ``tilt_deg`` (adds ∂d/∂θ · σ_θ to the error).
    noise_de : float
        Colour noise per Lab component of one pixel.
    block_noise : (float, int)
        JPEG slices: the colour error per Lab component of a block's mean and the pixels
        that share it (:attr:`~.colour_image.ColourImage.block_noise_de`, ``block_px``).
    thorough : bool
        Scan the whole range for another order and the neighbouring orders for
        ``delta_e_other_order``, at ``options.thickness_step_nm``; False (the exposure
        refinement): stay in the ROI's order, at ``options.exposure_thickness_step_nm``.
    Returns
    -------
    FacetThickness
    """
    S = colours.mean_lab.shape[0]
    tilt = np.asarray(tilt_deg, dtype=np.float64)
    has = (colours.n_pixels > 0) & np.isfinite(colours.roi_thickness_nm) & np.isfinite(tilt)
    out = np.full((6, S), np.nan)
    search = _Search(thorough, options.thickness_step_nm if thorough
                     else options.exposure_thickness_step_nm, noise_de,
                     None if tilt_sigma_deg is None else np.asarray(tilt_sigma_deg, np.float64),
                     block_noise,
                     brightness_factors(options.facet_brightness_min,
                                        options.facet_brightness_penalty_de))
    idx = np.flatnonzero(has)

    def chunk(ab):
        ii = idx[ab[0]:ab[1]]
        out[:, ii] = _chunk(model, colours, ii, tilt, options, search)

    thread_map(chunk, chunk_starts(idx.size, _CHUNK))
    return FacetThickness(out[0], out[1], out[2], out[3] == 1.0,
                          colours.n_pixels.astype(np.int64), out[4], out[5])


def refine_exposure_on_facets(image: FacetImage, tilt_deg, model, options: JointOptions, *,
                              seed=0) -> float:
    """Exposure of least median facet ΔE, each facet's thickness re-solved per candidate
    (within ×/÷ 1.5 of the model's) in its own order: its ROI's, or the one the whole-range
    scan of :func:`facet_thickness` gives it at the start (held in the ROI's order, the
    facets of a population in another order pulled a right start up to the bound).

    Facets are homogeneous (one tilt, one thickness), unlike ROIs that span several
    thickness regions, so they pin the exposure down better than the ROI fit did. Facets
    without a tilt (NaN in ``tilt_deg``) are not used; ``options.exposure_facets`` of them at
    random, with at least 4 usable interior pixels.
    """
    S = image.n_facets
    rng = np.random.default_rng(seed)
    cnt = np.bincount(image.labels[image.usable & image.interior], minlength=S)
    cand = np.flatnonzero((cnt >= 4) & np.isfinite(tilt_deg))
    if cand.size < 10:
        return model.exposure
    pick = np.zeros(S, bool)
    pick[rng.choice(cand, min(options.exposure_facets, cand.size), replace=False)] = True
    colours = image.colours(image.usable & pick[image.labels])
    tilt = np.where(pick, tilt_deg, np.nan)
    full = options.replace(facet_brightness_min=1.0)   # the exposure: the film's full light
    start = facet_thickness(colours, tilt, model, full, thorough=True)
    colours = dataclasses.replace(colours, roi_thickness_nm=np.where(
        np.isfinite(start.thickness_nm), start.thickness_nm, colours.roi_thickness_nm))

    def objective(log_e):
        ft = facet_thickness(colours, tilt, model.with_exposure(math.exp(log_e)), full,
                             thorough=False)
        return float(np.nanmedian(ft.delta_e))

    e0 = model.exposure
    opt = optimize.minimize_scalar(objective, bounds=(math.log(e0 / 1.5), math.log(e0 * 1.5)),
                                   method="bounded", options={"xatol": 0.005})
    return float(math.exp(opt.x)) if opt.fun <= objective(math.log(e0)) else e0
