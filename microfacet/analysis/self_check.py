"""The NDF's self-check: inject known facet slopes into the scene's own conditions and recover
them (injection–recovery).

Where the truth is unknown, the analysis measures its own slope transfer on the stack it
analyses. It adds to the scene's own measured surface a piecewise-planar perturbation of known
slopes — the pattern of the scene's own slopes, scaled to 0.5, 1 and 2 times their RMS, the
planes joined at the edges — on *cells* that are a second segmentation of the colour image
re-noised with its own noise (a parametric bootstrap: where the image does not fix the
facets' edges it differs from the analysis' segments as the true facets do). It renders focus
stacks of the surface with and without it through the scene's own all-in-focus image (its
texture, sparse or not), z grid, numerical aperture and slice noise, runs the same
height-from-focus and plane fits on the analysis' segments, and measures two ratios: the gain
of the change of the recovered slopes on the injected ones (the *transfer*: do the heights
flatten or steepen the facets here, for example where a facet has no texture of its own and
its heights are borrowed from a pit or scratch micrometres away), and the RMS slope the NDF
would report, noise removed, over the true per-pixel RMS of the rendered surface (the *width
transfer*, which also pays for segments that are not the cells). Outside
``fits.self_check_range`` the NDF is not identified
(:func:`~.identification.self_check_judgement`). A fifth stack adds domes (rounded facets)
to the 1× injection, rendered with the same noise: the gain of the segments' dome
coefficients (the *dome transfer*) says how much of a facet's curvature the heights show,
and the analysis' planar-facet check is judged over it
(:func:`~.distributions.calibrate_dome_share`). How well it predicts the truth on
randomized scenes: docs/accuracy.md (``python -m pipelines run accuracy-ndf-worlds``).

What it cannot see: a surface unlike the injected one — steps at the facet edges, rounded
facets that the segments straddle (their domes then do not show as domes of the segments;
the injected domes sit on the cells, which are a segmentation of the image, so they do),
brightness that fades with tilt and so selects the flatter facets.

References
----------
.. [1] Nagata et al., "Simulation Technology for Titanium Oxide Layer Interference Color",
   Technical Report (the seed paper), §3.3.3.
.. [2] S. Pertuz, D. Puig, M. A. Garcia, "Analysis of focus measure operators for
   shape-from-focus", Pattern Recognition 46 (2013) 1415–1432,
   doi:10.1016/j.patcog.2012.11.011.
"""

from __future__ import annotations

import math
import warnings
from collections.abc import Sequence
from dataclasses import dataclass, field

import numpy as np

from ..core.lazy import load
from ..core.pixels import pixel_size_yx
from ..focus.height import height_from_focus
from ..focus.options import FocusOptions
from ..focus.uncertainty import height_sigma_with_bias
from .joint import evidence_planes, focus_heights
from .options import JointOptions
from .planes import (
    MAX_SLOPE_SIGMA,
    at_least_px,
    deconvolved_rms_slope,
    dome_coefficients,
    facet_edge_distance,
    fit_facet_planes,
)
from .segmentation import relabel

__all__ = ["Conditions", "RenderedStack", "SelfCheck", "measured_rms_slope",
           "rendered_width_ratio", "self_check_ndf", "slice_noise_sd", "slope_gain"]

cv2 = load("cv2")

#: Largest side (px) of the part of the scene the self-check renders (bounds its time and
#: memory: ~14 blurred copies of this crop).
MAX_SIDE_PX = 512
#: Share of the self-check's height errors its scaled 2σ covers (a margin over the 90 % asked
#: of the analysis' heights, for the difference between the injected and the real scene).
SIGMA_COVERAGE = 0.95

#: Injected lobe widths, as multiples of the scene's own measured RMS slope.
WIDTH_FACTORS = (0.5, 1.0, 2.0)
#: The run (0: the scene's own surface) of the 1× injection, which the domes are added to.
_ONE_X_RUN = 1 + WIDTH_FACTORS.index(1.0)
#: Mean square slope of the domes injected with the 1× planes, over the planes' own (the
#: dome transfer's signal: about what the rounded facets of the generator's worlds add).
DOME_SHARE_INJECTED = 1.0
#: Resamplings of the self-check's facets (with replacement) that give its transfers' standard
#: errors.
BOOTSTRAP_REPLICATES = 200
#: Blur of an in-focus pixel (px) and the blur levels the renderer interpolates between
#: (:func:`_level_index` computes a blur's place among them from this spacing).
_BASE_BLUR_PX = 0.5
_LEVELS_PX = np.array([0.0, 0.5, 1.0, 1.5, 2.0, 3.0, 4.0, 6.0, 8.0, 12.0, 16.0, 24.0, 32.0])


@dataclass
class SelfCheck:
    """What the injection–recovery measured.

    Attributes
    ----------
    injected_rms_slope, recovered_rms_slope, ratio : list of float
        Per injected width: the area-weighted RMS of |∇h| of the injected planes; ``ratio``
        the gain of the recovered slope vectors projected on the injected ones (area-weighted
        regression through 0: unbiased by independent slope noise), and
        ``recovered_rms_slope`` = gain × injected.
    transfer : float
        Median ratio (1: slopes recovered without bias). NaN when nothing was measured.
    spread : float
        Half the range of the ratios.
    facets : int
        Facets with a recovered plane.
    width_ratio : list of float
        Per injected width: the RMS slope the NDF would see — the recovered planes' RMS |∇h|
        with their modelled slope noise removed in quadrature, as :func:`measured_rms_slope`
        does — over the true RMS of the injected surface's planes (its own plus the
        injection). It checks the whole width chain, noise model included, where ``ratio``
        checks the slopes' gain only.
    width_transfer : float
        Median ``width_ratio`` (NaN when nothing was measured).
    height_sigma_scale : float
        The factor (≥ 1) by which the focus stage's height σ (with its disagreement term,
        :func:`~microfacet.focus.uncertainty.height_sigma_with_bias`) must grow for 2σ to cover
        :data:`SIGMA_COVERAGE` of the errors of the recovered heights against the rendered
        surfaces: the errors the σ model does not see (a window's borrowed heights, blur
        and sampling of this stack) measured on the stack itself. The analysis reports its
        height σ times this factor.
    height_coverage : float
        The share of those errors within the focus stage's own 2σ.
    transfer_se, width_transfer_se : float
        Standard errors of ``transfer`` and ``width_transfer`` from the facets the self-check
        measured them on: the SD of the two medians over :data:`BOOTSTRAP_REPLICATES`
        resamplings of each injection's facets with replacement. A noisy stack, or one with
        few facets, measures its own transfer only to within this (NaN where nothing was
        measured; 0 for a check built by hand).
    dome_transfer, dome_transfer_se : float
        How much of a facet's curvature its heights show: the gain of the recovered dome
        coefficients (:func:`~.planes.dome_coefficients`) on those of domes injected on
        the cells with the 1× planes (mean square slope :data:`DOME_SHARE_INJECTED` times
        the planes'), per segment, weighted by its area and mean r², and its bootstrap
        standard error. The planar-facet check divides the dome term it measures by its
        square (:func:`~.distributions.calibrate_dome_share`): heights that flatten domes
        cannot show the facets planar. NaN where not measured.
    """

    injected_rms_slope: list
    recovered_rms_slope: list
    ratio: list
    transfer: float
    spread: float
    facets: int
    width_ratio: list = field(default_factory=list)
    width_transfer: float = math.nan
    height_sigma_scale: float = math.nan
    height_coverage: float = math.nan
    transfer_se: float = 0.0
    width_transfer_se: float = 0.0
    dome_transfer: float = math.nan
    dome_transfer_se: float = math.nan

    @classmethod
    def unmeasured(cls) -> SelfCheck:
        """A self-check that measured nothing (fewer than 3 facet planes with measurable
        slopes to inject on): its transfers are NaN, which no range accepts.

        >>> SelfCheck.unmeasured().facets, math.isnan(SelfCheck.unmeasured().transfer)
        (0, True)
        """
        return cls([], [], [], math.nan, math.nan, 0, transfer_se=math.nan,
                   width_transfer_se=math.nan)

    def width_error(self, noise_relative_error) -> float:
        """Relative error of the NDF's width with its systematic part: the noise's
        (``noise_relative_error``, :func:`~.ndf_fit.width_relative_error`), the self-check's
        bias (1 − ``width_transfer``), its spread over the injected widths and the relative
        standard error of the width transfer (what a correction by it carries), in
        quadrature (NaN where the self-check measured nothing).

        >>> SelfCheck([0.1], [0.09], [0.9], 0.9, 0.05, 50, [0.8], 0.8).width_error(0.02)
        0.2071
        >>> SelfCheck([0.1], [0.09], [0.9], 0.9, 0.05, 50, [0.8], 0.8,
        ...           width_transfer_se=0.08).width_error(0.02)
        0.23
        """
        noise = noise_relative_error if noise_relative_error is not None else 0.0
        # the correction's own error, relative (none where there is no width to divide by)
        wt = self.width_transfer
        corr = self.width_transfer_se / wt if wt > 0 else 0.0
        err = math.sqrt(noise ** 2 + (1.0 - wt) ** 2 + self.spread ** 2 + corr ** 2)
        return round(err, 4) if math.isfinite(err) else math.nan

    def to_json(self) -> dict:
        """For ``ndf.self_check`` in summary.json."""
        def num(v):
            return float(v) if math.isfinite(v) else None
        return {"transfer": num(self.transfer), "spread": num(self.spread),
                "width_transfer": num(self.width_transfer), "facets": int(self.facets),
                "transfer_se": num(self.transfer_se),
                "width_transfer_se": num(self.width_transfer_se),
                "dome_transfer": num(self.dome_transfer),
                "dome_transfer_se": num(self.dome_transfer_se),
                "height_sigma_scale": num(self.height_sigma_scale),
                "height_coverage": num(self.height_coverage),
                "width_ratio": [num(v) for v in self.width_ratio],
                "injected_rms_slope": [num(v) for v in self.injected_rms_slope],
                "recovered_rms_slope": [num(v) for v in self.recovered_rms_slope],
                "ratio": [num(v) for v in self.ratio]}


def measured_rms_slope(joint, max_tilt_deg) -> float | None:
    """Area-weighted RMS |∇h| of the scene's facet planes below the acceptance, their slope
    noise removed in quadrature (None with fewer than 3 planes)."""
    pl = joint.slope_planes
    ok = (pl.fitted & np.isfinite(pl.tilt_deg) & (pl.tilt_deg < max_tilt_deg)
          & (pl.slope_sigma < MAX_SLOPE_SIGMA))
    if ok.sum() < 3:
        return None
    return deconvolved_rms_slope(pl, ok, joint.area_px[ok])


def slice_noise_sd(stack, focus) -> float:
    """Pixel noise SD of the stack's most defocused slice (grey, [0, 1]): the robust SD of its
    Laplacian over √20 (the Laplacian's gain on white noise); defocus leaves noise only."""
    z = np.asarray(stack.z_um, np.float64)
    h = np.asarray(focus.height_fit_um, np.float64)
    mid = float(np.median(h[np.isfinite(h)])) if np.isfinite(h).any() else float(np.median(z))
    img = np.asarray(stack.read_slice(int(np.argmax(np.abs(z - mid)))), np.float32)
    if img.ndim == 3:
        img = img[..., :3] @ np.array([0.2126, 0.7152, 0.0722], np.float32)
    lap = (4 * img[1:-1, 1:-1] - img[:-2, 1:-1] - img[2:, 1:-1] - img[1:-1, :-2]
           - img[1:-1, 2:])
    return float(1.4826 * np.median(np.abs(lap - np.median(lap))) / math.sqrt(20.0))


class RenderedStack(Sequence):
    """A focus stack of a surface ``height_um`` textured by ``texture`` (grey, [0, 1]) at
    heights ``z_um``, each slice rendered when it is read: Gaussian defocus
    σ = 0.5 px + ``blur_px_per_um`` · |z − h| per pixel (interpolated between precomputed blur
    levels), plus white noise of SD ``noise_sd`` drawn from ``np.random.default_rng([*seed,
    i])`` for slice ``i`` (the same slice whenever it is read). Height from focus reads the
    slices once each, so the stack never holds more than one: its memory is the blur levels'
    (13 copies of the texture), not the slices'. Stacks of one texture share them: pass an
    earlier stack's :attr:`levels` as ``levels``.

    >>> tex = np.random.default_rng(0).random((8, 8)).astype(np.float32)
    >>> st = RenderedStack(tex, np.zeros((8, 8)), [-1.0, 0.0, 1.0], blur_px_per_um=2.0,
    ...                    noise_sd=0.01, seed=(7,))
    >>> len(st), st[1].shape, bool(np.array_equal(st[2], st[2]))
    (3, (8, 8), True)
    """

    def __init__(self, texture, height_um, z_um, *, blur_px_per_um, noise_sd, seed=(0,),
                 levels=None):
        tex = np.asarray(texture, np.float32)
        self.levels = _blur_levels(tex) if levels is None else levels
        self._pixels = np.arange(tex.size, dtype=np.intp).reshape(tex.shape)
        self._height = np.asarray(height_um, np.float64)
        self._z = np.asarray(z_um, dtype=np.float64).ravel()
        self._blur, self._noise_sd, self._seed = float(blur_px_per_um), float(noise_sd), seed

    def __len__(self) -> int:
        return self._z.size

    def __getitem__(self, i):
        i = int(i) + (len(self) if int(i) < 0 else 0)
        if not 0 <= i < len(self):
            raise IndexError(i)
        rng = np.random.default_rng([*self._seed, i])
        return self.render(self._z[i], rng)

    def render(self, z, rng):
        """The slice at height ``z`` (µm), its noise drawn from ``rng``: float32 (H, W)."""
        n = self._pixels.size
        f = _level_index(_BASE_BLUR_PX + self._blur * np.abs(z - self._height))
        lo = np.minimum(f.astype(np.int32), _LEVELS_PX.size - 2)
        t = f - lo
        k = lo * n + self._pixels
        flat = self.levels.reshape(-1)
        img = (1 - t) * flat[k] + t * flat[k + n]
        return (img + rng.normal(0.0, self._noise_sd, img.shape)).astype(np.float32)


def _blur_levels(texture):
    """``texture`` (grey, float32, (H, W)) blurred to each of :data:`_LEVELS_PX`: (13, H·W)."""
    return np.stack([texture if s == 0 else cv2.GaussianBlur(texture, (0, 0), float(s))
                     for s in _LEVELS_PX]).reshape(_LEVELS_PX.size, -1)


def _level_index(sigma):
    """``np.interp(sigma, _LEVELS_PX, arange)`` as float32, bit for bit, for ``sigma`` ≥ 0.5 px
    (the renderer's blur is never less), in arithmetic instead of a search: the levels are
    0.5 px apart up to 2 px, then 2^k, 1.5 · 2^k, 2^(k+1), …, each step 2^(k-1) wide, so the
    index is 2σ below 2 px and 2e − 2 + 4f above, with σ = f · 2^e and 0.5 ≤ f < 1
    (``np.frexp``). Each is one rounding of the value np.interp rounds once; half its time.
    (tests/analysis/test_self_check.py checks it against np.interp.)"""
    mant, expo = np.frexp(sigma)
    f = np.where(sigma < 2.0, 2.0 * sigma, 2.0 * expo - 2.0 + 4.0 * mant)
    return np.minimum(f, _LEVELS_PX.size - 1.0).astype(np.float32)


def _crop(shape):
    h, w = shape
    r0, c0 = max(0, (h - MAX_SIDE_PX) // 2), max(0, (w - MAX_SIDE_PX) // 2)
    return slice(r0, r0 + min(h, MAX_SIDE_PX)), slice(c0, c0 + min(w, MAX_SIDE_PX))


def _flat(pattern) -> bool:
    """Whether the slopes ``pattern`` (∂h/∂x, ∂h/∂y per facet) are all but zero."""
    return float(np.mean(pattern[0] ** 2 + pattern[1] ** 2)) < 1e-12


def _planes(labels, rms_slope, pixel_yx, rng, pattern=None):
    """Heights of planes joined at the facets' edges, with the slopes ``pattern`` (∂h/∂x,
    ∂h/∂y per facet, rows down) scaled to the RMS |∇h| ``rms_slope`` — or, where the pattern
    is flat or not given, slopes N(0, s²) per axis with 2 s² = ``rms_slope``²; returns the
    height map and the slopes per facet."""
    S = int(labels.max()) + 1
    dy, dx = _from_centroids(labels, pixel_yx)
    if pattern is None or _flat(pattern):
        s = rms_slope / math.sqrt(2.0)
        a, b = rng.normal(0, s, S), rng.normal(0, s, S)
    else:
        a, b = pattern
        k = rms_slope / math.sqrt(float(np.mean(a * a + b * b)))
        a, b = k * a, k * b
    plane = a[labels] * dx + b[labels] * dy
    offset = _joined_offsets(labels, plane)
    return offset[labels] + plane, a, b


def _from_centroids(labels, pixel_yx):
    """Each pixel's offset (µm; y, x, (H, W) each) from the centroid of its label's pixels."""
    S = int(labels.max()) + 1
    yy, xx = np.indices(labels.shape, dtype=np.float64)
    y_um, x_um = yy * pixel_yx[0], xx * pixel_yx[1]
    n = np.maximum(np.bincount(labels.ravel(), minlength=S), 1)
    cy = np.bincount(labels.ravel(), y_um.ravel(), S) / n
    cx = np.bincount(labels.ravel(), x_um.ravel(), S) / n
    return y_um - cy[labels], x_um - cx[labels]


def _joined_offsets(labels, plane, *, pull=1e-3):
    """Facet offsets that join the planes as well as they can (least squares of the height
    steps across every facet edge, weakly pulled towards 0): a faceted surface, not a field
    of independent steps."""
    sparse, linalg = load("scipy.sparse"), load("scipy.sparse.linalg")
    S = int(labels.max()) + 1
    rows_f, rows_g, resid = [], [], []
    for axis in (0, 1):
        la, lb = (labels[1:], labels[:-1]) if axis == 0 else (labels[:, 1:], labels[:, :-1])
        pa, pb = (plane[1:], plane[:-1]) if axis == 0 else (plane[:, 1:], plane[:, :-1])
        edge = la != lb
        rows_f.append(la[edge])
        rows_g.append(lb[edge])
        resid.append((pa - pb)[edge])
    f, g, r = np.concatenate(rows_f), np.concatenate(rows_g), np.concatenate(resid)
    m = f.size
    eq = np.arange(m)
    A = sparse.csr_matrix((np.r_[np.ones(m), -np.ones(m), np.full(S, pull)],
                           (np.r_[eq, eq, m + np.arange(S)], np.r_[f, g, np.arange(S)])),
                          shape=(m + S, S))
    rhs = np.r_[-r, np.zeros(S)]
    # the normal equations are a graph Laplacian plus pull² I (symmetric positive definite,
    # as sparse as the facets' adjacency): a direct solve, the exact least squares, in
    # milliseconds where LSQR took half a second to converge to it (1e-8 µm apart)
    return linalg.spsolve((A.T @ A).tocsc(), A.T @ rhs)


def slope_gain(got_x, got_y, true_x, true_y, weights) -> float:
    """Area-weighted regression through 0 of slope vectors ``got`` on ``true`` (per facet):
    the part of the truth that came back, unbiased by noise independent of it.

    >>> slope_gain(np.array([0.5, -0.1]), np.array([0.0, 0.2]), np.array([1.0, 0.0]),
    ...            np.array([0.0, 0.4]), np.ones(2))
    0.5
    """
    num = np.sum(weights * (got_x * true_x + got_y * true_y))
    return float(num / np.sum(weights * (true_x * true_x + true_y * true_y)))


def _rms(values, weights):
    return math.sqrt(float(np.sum(weights * values ** 2) / max(float(np.sum(weights)), 1e-30)))


@dataclass
class _Scene:
    """The scene's conditions the injection reuses (one crop)."""

    labels: np.ndarray
    cells: np.ndarray
    texture: np.ndarray
    levels: np.ndarray          # the texture's blur levels, shared by every rendered stack
    base_um: np.ndarray
    z_um: np.ndarray
    pixel_yx: tuple
    blur_px_per_um: float
    noise_sd: float


def _scene(focus, labels, cells, *, z_um, pixel_size_um, numerical_aperture, noise_sd
           ) -> _Scene:
    rs, cs = _crop(labels.shape)
    lab = relabel(labels[rs, cs])
    img = np.asarray(focus.all_in_focus, np.float32)[rs, cs]
    tex = img @ np.array([0.2126, 0.7152, 0.0722], np.float32) if img.ndim == 3 else img
    h = np.asarray(focus.height_fit_um, np.float64)[rs, cs]
    S = int(lab.max()) + 1
    ok = np.isfinite(h)
    med = float(np.median(h[ok])) if ok.any() else float(np.median(z_um))
    cnt = np.bincount(lab[ok], minlength=S)
    centre = np.where(cnt > 0, np.bincount(lab[ok], h[ok], S) / np.maximum(cnt, 1), med)
    z = np.asarray(z_um, np.float64)
    centre = np.clip(centre, z.min(), z.max())
    pyx = pixel_size_yx(pixel_size_um)
    na = min(max(float(numerical_aperture), 0.05), 0.95)
    # Gaussian σ ≈ half the geometric blur radius |Δz|·tan(asin NA)
    blur = 0.5 * na / math.sqrt(1.0 - na * na) / math.sqrt(pyx[0] * pyx[1])
    # the scene's own measured surface (holes: their facet's mean height) carries the
    # injected planes: the relief, its range in z and its creases stay the scene's
    base = np.clip(np.where(ok, h, centre[lab]), z.min(), z.max())
    cell = cells((rs, cs)) if callable(cells) else np.asarray(cells)[rs, cs]
    return _Scene(lab, relabel(cell), tex, _blur_levels(tex), base, z, pyx, blur,
                  float(noise_sd))


@dataclass(frozen=True)
class Conditions:
    """The scene's imaging conditions the injection reuses: slice heights ``z_um`` (µm),
    ``pixel_size_um``, ``numerical_aperture``, the slices' pixel noise ``noise_sd`` (grey,
    [0, 1]) and the random ``seed``."""

    z_um: np.ndarray
    pixel_size_um: object
    numerical_aperture: float
    noise_sd: float
    seed: int = 0


def _recovered_planes(sc, height_um, focus_options, joint, seed, interior, *, domes=False):
    """Render ``height_um`` in the scene's conditions (:class:`RenderedStack`, noise keyed by
    ``seed``); the facet planes of its height from focus, fitted as the analysis fits them
    (through the heights ``interior`` to the segments, :func:`_interior`),
    the errors of the focus stage's reliable heights in units of their σ, and with ``domes``
    the segments' dome coefficients (:func:`~.planes.dome_coefficients`, as the analysis'
    planar-facet check fits them; else None)."""
    slices = RenderedStack(sc.texture, height_um, sc.z_um, blur_px_per_um=sc.blur_px_per_um,
                           noise_sd=sc.noise_sd, seed=seed, levels=sc.levels)
    # the next slice is rendered (numpy, the GIL let go) while this one is measured (OpenCV):
    # each slice's noise is keyed by its index, so the heights are the same either way
    foc = height_from_focus(slices, focus_options, z_um=sc.z_um, prefetch=True)
    sig = height_sigma_with_bias(foc)
    rel = foc.reliable & np.isfinite(sig) & (sig > 0)
    z_scores = np.abs(foc.height_fit_um[rel] - height_um[rel]) / sig[rel]
    got = focus_heights(foc, joint)
    reliable = got.reliable & interior
    fit, unmixed = evidence_planes(sc.labels, got, reliable=interior, pixel_size_um=sc.pixel_yx,
                                   options=joint, surround_um=foc.height_fit_um)
    dome = (dome_coefficients(sc.labels, unmixed, height_sigma_um=got.sigma_um,
                              reliable=reliable, pixel_size_um=sc.pixel_yx,
                              correlation_px=got.correlation_px) if domes else None)
    return fit, z_scores, dome


def _interior(sc, joint):
    """The pixels far enough inside the segments for their planes (``joint.plane_edge_px``),
    the same for every run of one self-check."""
    return at_least_px(facet_edge_distance(sc.labels), joint.plane_edge_px)


def _usable(fit):
    return (fit.fitted & np.isfinite(fit.slope_x) & np.isfinite(fit.slope_y)
            & (fit.slope_sigma < MAX_SLOPE_SIGMA))


def self_check_ndf(focus, labels, *, cells=None, conditions: Conditions, rms_slope,
                   focus_options: FocusOptions, joint: JointOptions) -> SelfCheck:
    """Injection–recovery of facet slopes in the scene's own conditions.

    Parameters
    ----------
    focus : FocusResult
        The scene's height from focus (its all-in-focus image and heights are reused).
    labels : ndarray of int (H, W)
        The scene's facets (the segments whose planes the NDF is made of).
    cells : ndarray of int (H, W) or callable, optional
        The facets the injected planes follow (or ``cells(crop)`` giving them on the crop,
        a pair of slices, that the self-check works on); default ``labels``. The analysis passes a
        second segmentation of the colour image re-noised with its own noise: where the image
        does not fix the facets' edges the two disagree, as the true facets and the segments
        do, and the recovered widths pay for it.
    conditions : Conditions
        The stack's z grid, pixel size, aperture, noise, and the seed.
    rms_slope : float
        The scene's measured RMS facet slope (|∇h|); the injected widths are
        :data:`WIDTH_FACTORS` times it (at least 0.02, at most 0.6).
    focus_options, joint : FocusOptions, JointOptions
        The options the analysis used (alignment is not repeated).

    Returns
    -------
    SelfCheck
    """
    c = conditions
    sc = _scene(focus, labels, labels if cells is None else cells, z_um=c.z_um,
                pixel_size_um=c.pixel_size_um, numerical_aperture=c.numerical_aperture,
                noise_sd=c.noise_sd)
    fo = focus_options.replace(align=None, fill=None)
    everywhere = np.ones(sc.labels.shape, bool)
    own = fit_facet_planes(sc.cells, sc.base_um, height_sigma_um=1.0, reliable=everywhere,
                           pixel_size_um=sc.pixel_yx, min_pixels=3, robust_rounds=0)
    pattern = (np.nan_to_num(own.slope_x), np.nan_to_num(own.slope_y))
    unit = None if _flat(pattern) else _planes(sc.cells, 1.0, sc.pixel_yx, None, pattern=pattern)

    interior = _interior(sc, joint)

    def run(k):
        # run 0: the scene's own surface; run k: the injection of WIDTH_FACTORS[k - 1], each
        # from its own random streams (the runs share nothing). One after the other: OpenCV
        # already spreads each run's filters over the cores (two runs on two threads took as
        # long, 2.9-3.6 s against 3.1 s at 1 MP, and held twice the memory)
        if k == 0:
            return None, _recovered_planes(sc, sc.base_um, fo, joint, (c.seed, 0), interior)
        width = min(max(WIDTH_FACTORS[k - 1] * rms_slope, 0.02), 0.6)
        if unit is not None:          # the pattern's joined planes are linear in its scale
            injected = tuple(width * v for v in unit)
        else:
            injected = _planes(sc.cells, width, sc.pixel_yx,
                               np.random.default_rng([c.seed, k]))
        return injected, _recovered_planes(sc, sc.base_um + injected[0], fo, joint, (c.seed, k),
                                           interior, domes=k == _ONE_X_RUN)

    runs = [run(k) for k in range(len(WIDTH_FACTORS) + 1)]
    dome = _dome_transfer(sc, runs[_ONE_X_RUN], fo, joint, c.seed, interior)
    base = runs[0][1][0]
    area = np.bincount(sc.labels.ravel()).astype(np.float64)
    inj, rec, widths, n_fac, sums = [], [], [], 0, []
    for (delta, a_cell, b_cell), (fit, _, _) in runs[1:]:
        ok = _usable(fit) & _usable(base)
        n_fac = max(n_fac, int(ok.sum()))
        if ok.sum() < 3:
            inj.append(math.nan)
            rec.append(math.nan)
            widths.append(math.nan)
            sums.append(None)
            continue
        # the injection as each segment holds it (its plane through the exact heights)
        seg = fit_facet_planes(sc.labels, delta, height_sigma_um=1.0, reliable=everywhere,
                               pixel_size_um=sc.pixel_yx, min_pixels=3, robust_rounds=0)
        ok &= seg.fitted
        w = area[ok]
        # what the injection changed in the recovered slopes, projected on what was injected:
        # a gain unbiased by slope noise independent of the injection
        a, b = seg.slope_x[ok], seg.slope_y[ok]
        gain = slope_gain(fit.slope_x[ok] - base.slope_x[ok],
                          fit.slope_y[ok] - base.slope_y[ok], a, b, w)
        inj.append(_rms(np.hypot(a, b), w))
        rec.append(gain * inj[-1])
        # the width the NDF would report against the true slopes of the rendered surface,
        # pixel by pixel over the segments it is made of
        px = ok[sc.labels]
        cell = sc.cells[px]
        t2 = (pattern[0][cell] + a_cell[cell]) ** 2 + (pattern[1][cell] + b_cell[cell]) ** 2
        true = _rms(np.sqrt(t2), np.ones(cell.size))
        widths.append(deconvolved_rms_slope(fit, ok, w) / true if true > 0 else math.nan)
        seg_px = sc.labels[px]
        sums.append(_facet_sums(fit, ok, w, a, b, (fit.slope_x[ok] - base.slope_x[ok],
                                                   fit.slope_y[ok] - base.slope_y[ok]),
                                np.bincount(seg_px, t2, ok.size)[ok],
                                np.bincount(seg_px, minlength=ok.size)[ok]))
    ratio = [r / i if i > 0 else math.nan for r, i in zip(rec, inj)]
    good = [v for v in ratio if math.isfinite(v)]
    transfer = float(np.median(good)) if good else math.nan
    spread = 0.5 * (max(good) - min(good)) if good else math.nan
    wgood = [v for v in widths if math.isfinite(v)]
    se = _bootstrap_se(sums, np.random.default_rng([c.seed, 99]))
    return SelfCheck(inj, rec, ratio, transfer, spread, n_fac, widths,
                     float(np.median(wgood)) if wgood else math.nan,
                     *_sigma_scale(np.concatenate([z for _, (_, z, _) in runs[1:]])), *se,
                     *dome)


def rendered_width_ratio(focus, labels, height_um, true_tilt_deg, *, conditions: Conditions,
                         max_tilt_deg, focus_options: FocusOptions, joint: JointOptions) -> float:
    """The width transfer of one given surface in the scene's conditions: ``height_um`` (µm,
    the image's shape) rendered as the self-check renders its injections (the scene's
    all-in-focus image as texture, its z grid, aperture and slice noise; the same crop),
    its facet planes fitted on ``labels`` as the analysis fits the NDF's, and their RMS
    slope below ``max_tilt_deg`` with the slope noise removed
    (:func:`~.planes.deconvolved_rms_slope`) over the RMS slope of ``true_tilt_deg`` (°, the
    surface's own per-pixel tilts, NaN off the facets) below it on the segments with a plane.

    With the true surface of a synthetic stack this is the self-check's renderer and
    plane fits applied to the truth: how much of the width the scene's own geometry lets
    through, where the self-check injects a surface of its own making (docs/accuracy.md,
    "One width for the lobes and the self-check"). NaN where no segment has a plane.
    """
    c = conditions
    sc = _scene(focus, labels, labels, z_um=c.z_um, pixel_size_um=c.pixel_size_um,
                numerical_aperture=c.numerical_aperture, noise_sd=c.noise_sd)
    rs, cs = _crop(np.shape(labels))
    surface = np.asarray(height_um, np.float64)[rs, cs]
    tilt = np.asarray(true_tilt_deg, np.float64)[rs, cs]
    fo = focus_options.replace(align=None, fill=None)
    fit, _, _ = _recovered_planes(sc, surface, fo, joint, (c.seed, 7), _interior(sc, joint))
    ok = _usable(fit) & (fit.tilt_deg < max_tilt_deg)
    px = ok[sc.labels] & np.isfinite(tilt) & (tilt < max_tilt_deg)
    if not ok.any() or not px.any():
        return math.nan
    true = math.sqrt(float(np.mean(np.tan(np.radians(tilt[px])) ** 2)))
    area = np.bincount(sc.labels.ravel(), minlength=ok.size).astype(np.float64)
    return deconvolved_rms_slope(fit, ok, area[ok]) / true if true > 0 else math.nan


def _domes(cells, rms_slope, pixel_yx):
    """Caps ``−κ r²/2`` per cell about its centroid, joined at the edges as well as they can
    be (:func:`_joined_offsets`), κ such that their RMS slope κ·√⟨r²⟩ is ``rms_slope``:
    rounded facets, (H, W) µm."""
    dy, dx = _from_centroids(cells, pixel_yx)
    r2 = dy * dy + dx * dx
    mean_r2 = float(np.mean(r2))
    if not mean_r2 > 0:
        return np.zeros(cells.shape)
    cap = -0.5 * rms_slope / math.sqrt(mean_r2) * r2
    return _joined_offsets(cells, cap)[cells] + cap


def _dome_transfer(sc, planes_run, focus_options, joint, seed, interior
                   ) -> tuple[float, float]:
    """:attr:`SelfCheck.dome_transfer` and its standard error: the 1× injection
    (``planes_run``, its planes and recovered dome coefficients) rendered again with domes
    on the cells, with the same noise; the gain of the segments' recovered dome coefficients'
    change on those of the injected domes (NaN, NaN with fewer than 3 segments measured or
    flat 1× planes). The domes' RMS slope is that of the 1× planes' slopes over the cells
    (cells weighted alike) times √:data:`DOME_SHARE_INJECTED`."""
    (delta, a_cell, b_cell), (_, _, before) = planes_run
    rms = math.sqrt(float(np.mean(a_cell ** 2 + b_cell ** 2)))
    caps = _domes(sc.cells, math.sqrt(DOME_SHARE_INJECTED) * rms, sc.pixel_yx)
    if not np.any(caps):
        return math.nan, math.nan
    _, _, after = _recovered_planes(sc, sc.base_um + delta + caps, focus_options, joint,
                                    (seed, _ONE_X_RUN), interior, domes=True)
    true = dome_coefficients(sc.labels, caps, height_sigma_um=1.0,
                             reliable=np.ones(sc.labels.shape, bool), pixel_size_um=sc.pixel_yx,
                             min_pixels=3)
    ok = before.ok & after.ok & true.ok & (true.area > 0)
    if ok.sum() < 3:
        return math.nan, math.nan
    w = true.area[ok] * true.r2[ok]
    x, y = true.d[ok], after.d[ok] - before.d[ok]
    sums = np.stack([w * x * y, w * x * x])
    gain = float(sums[0].sum() / sums[1].sum())
    boot = _resampled(sums, np.random.default_rng([seed, 98]), BOOTSTRAP_REPLICATES)
    with np.errstate(divide="ignore", invalid="ignore"):
        return gain, float(np.nanstd(boot[0] / boot[1]))


def _facet_sums(fit, ok, weights, true_x, true_y, change, true_sq, n_px) -> np.ndarray:
    """Per facet of ``fit[ok]``, the terms whose sums over the facets give the self-check's two
    ratios (:func:`_ratios`): the slope gain's numerator and denominator (:func:`slope_gain`
    of the recovered ``change`` on the injected ``true_x``, ``true_y``), the noise-removed mean
    square slope's (:func:`~.planes.deconvolved_rms_slope`) and the true mean square's
    (``true_sq`` summed over the facet's ``n_px`` pixels): (6, facets)."""
    keep = fit.slope_sigma[ok] < MAX_SLOPE_SIGMA
    g2 = np.tan(np.radians(fit.tilt_deg[ok])) ** 2 - 2.0 * fit.slope_sigma[ok] ** 2
    return np.stack([weights * (change[0] * true_x + change[1] * true_y),
                     weights * (true_x * true_x + true_y * true_y),
                     np.where(keep, weights * g2, 0.0), np.where(keep, weights, 0.0),
                     np.asarray(true_sq, np.float64), np.asarray(n_px, np.float64)])


def _ratios(s) -> tuple[np.ndarray, np.ndarray]:
    """The slope gain and the width ratio from the facet sums ``s`` (6, …) of
    :func:`_facet_sums`."""
    with np.errstate(divide="ignore", invalid="ignore"):
        width = np.sqrt(np.maximum(s[2] / s[3], 0.0)) / np.sqrt(s[4] / s[5])
        return s[0] / s[1], width


def _bootstrap_se(sums, rng, replicates=BOOTSTRAP_REPLICATES) -> tuple[float, float]:
    """Standard errors of the median slope gain and of the median width ratio over the
    injections, each injection's facets (``sums``: :func:`_facet_sums` per injection, None
    where it measured nothing) resampled with replacement ``replicates`` times (NaN, NaN
    without any measured injection).

    >>> rng = np.random.default_rng(0)
    >>> x = rng.normal(0, 1, 400)
    >>> s = np.stack([x * (0.9 * x + rng.normal(0, 0.1, 400)), x * x, np.ones(400),
    ...               np.ones(400), np.ones(400), np.ones(400)])
    >>> se, _ = _bootstrap_se([s], np.random.default_rng(1))
    >>> 0.002 < se < 0.01                      # the regression's own SE: 0.1 / √400 = 0.005
    True
    """
    gains, widths = [], []
    for s in sums:
        if s is None:
            continue
        g, w = _ratios(_resampled(s, rng, replicates))
        gains.append(g)
        widths.append(w)
    if not gains:
        return math.nan, math.nan
    return _sd_of_median(gains), _sd_of_median(widths)


def _resampled(sums, rng, replicates) -> np.ndarray:
    """Per-facet ``sums`` (k, facets) summed over ``replicates`` resamplings of the facets
    with replacement (multinomial counts from ``rng``): (k, replicates)."""
    n = sums.shape[1]
    counts = rng.multinomial(n, np.full(n, 1.0 / n), size=replicates).astype(np.float64)
    return (counts @ sums.T).T


def _sd_of_median(replicates) -> float:
    """SD over the replicates (columns) of their median over the injections (rows), NaN
    injections left out (NaN where a replicate has none)."""
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", RuntimeWarning)       # all-NaN replicates: NaN
        return float(np.std(np.nanmedian(np.array(replicates), axis=0)))


def _sigma_scale(z) -> tuple[float, float]:
    """The factor (≥ 1) that makes 2σ cover :data:`SIGMA_COVERAGE` of the recovered heights'
    errors ``z`` (in units of their σ), and the 2σ coverage before it (NaN, NaN without
    errors)."""
    z = z[np.isfinite(z)]
    if z.size < 100:
        return math.nan, math.nan
    return (max(1.0, float(np.quantile(z, SIGMA_COVERAGE)) / 2.0),
            float(np.mean(z <= 2.0)))
