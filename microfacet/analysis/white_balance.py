"""The camera's white balance: estimated from the film's own colours, or from a reference.

A camera multiplies the linear R, G and B of the scene by gains of its own (its white
balance); an image balanced for another light than the one modelled has every colour moved
the same way. For one film colour a gain and a thickness are interchangeable, but the
film's colours at several thicknesses and tilts lie on one physical curve, and two gains
shared by the whole image are over-determined once the scene holds a few distinct film
colours. :func:`estimate_white_balance` therefore fits the R and B gains (G = 1: the
exposure takes the overall scale) to the image's tiles, each tile at its own thickness and
every pixel at its own tilt, in log chromaticity ``(log R/G, log B/G)``, which the exposure
does not move. The uncertainty counts each tile as one observation of the model's error,
not only of the noise (the least misfit per tile sets the scale, the misfit's curvature the
width; at least the spread over bootstrap resamples of the tiles): a scene of one film
colour leaves a direction of gains a thickness change compensates, and the width says so.
Measured on the generalization sweep (docs/accuracy.md): this σ covers the errors (median
|error|/σ 0.6), and at 256 × 256 px it is 1–15 %, so the gains are rarely determined to 1 %
without a reference. A gain is called determined only where the tiles hold at least two
distinct film colours (:func:`film_colours`): for one colour the misfit's valley, along
which a gain and the thickness trade, is curved, and its narrow width across the best can
pass for a spread below 1 % while the best lies far along it (a 200 nm film over a 5° tilt
spread: B 19 % off at σ 0.85 %, tests/analysis/test_white_balance.py).

A reference wins over the estimate: ``white_balance`` gains in stack.json, a
``white_reference`` image of a white standard (its median linear R, G, B, divided by G, are
the gains), or a ``substrate_reference`` image of the bare metal (the same over the model's
colour of that metal: :func:`substrate_gains`).

Examples
--------
>>> wb = WhiteBalance()
>>> wb.gains_rgb, wb.source
((1.0, 1.0, 1.0), 'none')
"""

from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass

import numpy as np

from ..colour.colorimetry import lab_to_xyz, xyz_to_lab
from ..colour.srgb import (
    image_white_xyz,
    linear_srgb_to_xyz,
    model_xyz_to_linear_srgb,
    xyz_to_linear_srgb,
)
from ..colour.table import direct_xyz
from ..colour.transfer import srgb_decode
from ..core.errors import InputError
from ..core.lazy import load
from .search import parabola

ndimage = load("scipy.ndimage")

__all__ = ["WhiteBalance", "balanced_lab", "estimate_white_balance", "film_colours",
           "rebalanced_lab",
           "reference_gains", "substrate_colour_rgb", "substrate_gain_sigma",
           "substrate_gains"]

#: The gains searched: log gain in ±LOG_RANGE (about 0.82-1.22), a coarse grid then a fine
#: one about its best.
LOG_RANGE = 0.2
COARSE_STEPS = 9
FINE_STEP = 0.01
#: Tiles of the estimate (px; a tile mostly lies in one thickness region), pixels per tile,
#: the most tiles used, and the per-pixel thickness freedom inside a tile (nm).
TILE_PX = 32
TILE_SAMPLE_PX = 24
MAX_TILES = 64
PIXEL_FREEDOM_NM = 3.0
#: Bootstrap resamples of the tiles, and the spread (1σ of the log gain) below which the
#: gains are determined.
BOOTSTRAP = 64
DETERMINED_LOG_SD = 0.01
#: Distinct film colours a determined gain needs: the tiles' best thicknesses at the
#: estimate, in groups split where sorted neighbours lie more than COLOUR_GAP_NM apart
#: (~2 ΔE00 per nm: a distinct colour), each of at least MIN_COLOUR_TILES tiles.
MIN_FILM_COLOURS = 2
COLOUR_GAP_NM = 10.0
MIN_COLOUR_TILES = 4
#: 1σ of a reference's log gains (a white standard's or stack.json's): the neutrality of the
#: standard and the light's drift between it and the stack, taken as 1 % (not measured here).
REFERENCE_LOG_SD = 0.01


@dataclass(frozen=True)
class WhiteBalance:
    """The white balance the colours were corrected for, and the scene's own estimate.

    Attributes
    ----------
    gains_rgb : tuple of 3 float
        The camera's gains the image was divided by (G = 1): image = balanced × gains.
    source : str
        ``"none"`` (not corrected), ``"estimated"``, ``"stack.json"`` or ``"white reference
        NAME"``.
    estimate_rgb : tuple of 3 float or None
        The gains the film's colours ask for (None: not estimated).
    estimate_sigma : tuple of 2 float or None
        1σ of the R and B estimates (bootstrap over the image's tiles), relative.
    determined : tuple of 2 bool or None
        Per gain (R, B): the estimate's spread is below 1 %, its best lies inside the
        search, and the tiles hold at least :data:`MIN_FILM_COLOURS` distinct film colours
        (for one colour a gain and the thickness trade along a curved valley of the misfit,
        whose narrow width across the best passes for a small spread: measured 9.75 % off at
        σ 1 % on the sweep, 19 % at σ 0.85 % on a clean one-colour film, docs/accuracy.md).
    misfit_gain : float or None
        How much the tiles' misfit (mean squared log chromaticity) improves at the
        estimate, against gains 1.
    tiles : int
        Tiles the estimate used.
    film_colours : int or None
        Distinct film colours among the tiles at the estimate (:func:`film_colours`).
    withdrawn : str or None
        Why the analysis no longer calls the estimate determined, where it did before
        (:meth:`withdraw`).
    reference_sigma : tuple of 2 float or None
        1σ of a reference's log R and B gains where it knows its own (a bare-substrate
        reference: :func:`substrate_gain_sigma`); None: :data:`REFERENCE_LOG_SD`.
    """

    gains_rgb: tuple = (1.0, 1.0, 1.0)
    source: str = "none"
    estimate_rgb: tuple | None = None
    estimate_sigma: tuple | None = None
    determined: tuple | None = None
    misfit_gain: float | None = None
    tiles: int = 0
    film_colours: int | None = None
    withdrawn: str | None = None
    reference_sigma: tuple | None = None

    @property
    def applied(self) -> bool:
        return self.source != "none"

    @property
    def from_reference(self) -> bool:
        """The gains come from a reference (stack.json's, a white or substrate image), not
        from the scene's own estimate."""
        return self.source not in ("none", "estimated")

    def withdraw(self, reason: str) -> WhiteBalance:
        """The same estimate, no gain called determined, and why: the gains the film's
        colours ask for are those of the thicknesses they were read at, so where the
        analysis finds the thickness not identified it cannot vouch for them either.

        >>> wb = WhiteBalance(estimate_rgb=(1.05, 1.0, 1.09), determined=(True, True))
        >>> w = wb.withdraw("the thickness is not identified")
        >>> w.determined, w.estimate_rgb, w.to_dict()["determined_withdrawn"]
        ((False, False), (1.05, 1.0, 1.09), 'the thickness is not identified')
        >>> WhiteBalance(determined=(False, False)).withdraw("x").withdrawn is None
        True
        """
        if not self.determined or not any(self.determined):
            return self
        return dataclasses.replace(self, determined=(False, False), withdrawn=reason)

    def at_search_edge(self) -> tuple:
        """Per gain (R, B), whether the estimate's best lies at the edge of the log gains
        searched (within :data:`FINE_STEP` of ±:data:`LOG_RANGE`): the misfit still falls
        there, and the gain is not bracketed. ``(False, False)`` without an estimate.

        >>> WhiteBalance(estimate_rgb=(0.818, 1.0, 1.05)).at_search_edge()
        (True, False)
        """
        logs = self.estimate_log_rb()
        return (False, False) if logs is None else tuple(_at_edge(v) for v in logs)

    def estimate_log_rb(self) -> tuple | None:
        """The estimate's log R and B gains (None without an estimate).

        >>> [round(v, 4) for v in WhiteBalance(estimate_rgb=(1.1, 1.0, 0.9)).estimate_log_rb()]
        [0.0953, -0.1054]
        """
        if self.estimate_rgb is None:
            return None
        return (math.log(self.estimate_rgb[0]), math.log(self.estimate_rgb[2]))

    def log_gain_sigma(self) -> tuple | None:
        """1σ of the log R and B gains the colours were corrected with, as far as the
        scene tells: a reference's (``reference_sigma``, else :data:`REFERENCE_LOG_SD`); a
        gain taken from the estimate, the estimate's spread σ; a gain left at the image's
        own (1, the image taken as balanced), the RMS distance of the truth from it given
        the estimate, √(ln² g + σ²) (with σ = :data:`LOG_RANGE` where the estimate's is not
        finite).
        None without an estimate (``white_balance = "off"``, or too few tiles for one).

        >>> wb = WhiteBalance(estimate_rgb=(1.03, 1.0, 0.96), estimate_sigma=(0.04, 0.01),
        ...                   determined=(False, True))
        >>> [round(v, 4) for v in wb.log_gain_sigma()]
        [0.0497, 0.042]
        >>> WhiteBalance(source="stack.json").log_gain_sigma()
        (0.01, 0.01)
        """
        if self.from_reference:
            return self.reference_sigma or (REFERENCE_LOG_SD, REFERENCE_LOG_SD)
        if self.estimate_rgb is None:
            return None
        out = []
        for g, sd, used in zip((self.estimate_rgb[0], self.estimate_rgb[2]),
                               self.estimate_sigma or (None, None),
                               (self.gains_rgb[0], self.gains_rgb[2])):
            sd = sd if sd is not None and math.isfinite(sd) else LOG_RANGE
            taken = self.source == "estimated" and used != 1.0     # withdraw() keeps them
            out.append(float(sd if taken else math.hypot(math.log(g), sd)))
        return tuple(out)

    def to_dict(self) -> dict:
        """summary.json's ``white_balance``."""
        return {"gains_rgb": [float(g) for g in self.gains_rgb], "source": self.source,
             "estimate_rgb": None if self.estimate_rgb is None
             else [float(g) for g in self.estimate_rgb],
             "estimate_sigma_rb": None if self.estimate_sigma is None
             else [float(s) for s in self.estimate_sigma],
             "determined_rb": None if self.determined is None
             else [bool(v) for v in self.determined],
             "misfit_gain": self.misfit_gain,
             "tiles": int(self.tiles), "film_colours": self.film_colours,
             "determined_withdrawn": self.withdrawn,
             "reference_sigma_rb": None if self.reference_sigma is None
             else [float(v) for v in self.reference_sigma]}


def balanced_lab(encoded, gains_rgb, *, illuminant, linear=False) -> np.ndarray:
    """CIELAB (float32) of encoded sRGB in [0, 1] (``linear``: values already linear, e.g.
    divided by a flat field) after dividing its linear R, G, B by the camera's ``gains_rgb``
    (no clipping: a balanced channel may exceed 1).

    >>> from microfacet.colour.transfer import srgb_encode
    >>> grey = srgb_encode(np.array([[0.5 * 1.1, 0.5, 0.5 * 0.9]]), dtype=np.float32)
    >>> [round(float(v), 2) + 0.0 for v in balanced_lab(grey, (1.1, 1.0, 0.9),
    ...                                                  illuminant="D65")[0]]
    [76.07, 0.0, 0.0]
    """
    a = np.asarray(encoded, dtype=np.float32)
    lin = (a if linear else srgb_decode(a)) / np.asarray(gains_rgb, np.float32)
    xyz = linear_srgb_to_xyz(lin, illuminant=illuminant)
    return xyz_to_lab(xyz, white=image_white_xyz(illuminant=illuminant)).astype(np.float32)


def rebalanced_lab(lab, log_gain_rb, *, illuminant) -> np.ndarray:
    """CIELAB of colours balanced with R and B gains larger by ``exp(log_gain_rb)``:
    ``lab`` (shape (..., 3), as :func:`balanced_lab` gives it) back to linear sRGB, R and B
    divided by those factors, and to Lab again.

    >>> lab = balanced_lab(np.array([[0.6, 0.5, 0.4]]), (1.0, 1.0, 1.0), illuminant="D65")
    >>> twice = balanced_lab(np.array([[0.6, 0.5, 0.4]]), (1.1, 1.0, 0.9), illuminant="D65")
    >>> bool(np.allclose(rebalanced_lab(lab, (np.log(1.1), np.log(0.9)), illuminant="D65"),
    ...                  twice, atol=1e-3))
    True
    """
    white = image_white_xyz(illuminant=illuminant)
    rgb = xyz_to_linear_srgb(lab_to_xyz(np.asarray(lab, np.float64), white=white),
                             illuminant=illuminant)
    rgb = rgb * np.exp(-np.array([log_gain_rb[0], 0.0, log_gain_rb[1]]))
    return xyz_to_lab(linear_srgb_to_xyz(rgb, illuminant=illuminant), white=white)


def _reference_rgb(encoded, *, where: str, linear: bool, what: str) -> np.ndarray:
    """The median linear R, G, B of a reference image's pixels that are neither dark nor
    clipped (encoded sRGB in [0, 1], (H, W, 3); ``linear``: linear sRGB)."""
    a = np.asarray(encoded, dtype=np.float32)
    if a.ndim != 3 or a.shape[-1] != 3:
        raise InputError(f"{where}: a {what} must be an RGB image, got shape {a.shape}")
    lin = (a if linear else srgb_decode(a)).reshape(-1, 3)
    ok = np.all((lin > 0.02) & (a.reshape(-1, 3) < 0.995), axis=1)
    if ok.sum() < 16:
        raise InputError(f"{where}: the {what} has too few pixels that are neither dark nor "
                         f"clipped ({int(ok.sum())})")
    return np.median(lin[ok], axis=0)


def reference_gains(encoded, *, where: str, linear: bool = False) -> tuple:
    """The gains of a white-standard image (encoded sRGB in [0, 1], (H, W, 3); ``linear``:
    linear sRGB, as a ``linear-sRGB`` stack's): the median linear R, G, B over its unclipped
    pixels, divided by G."""
    m = _reference_rgb(encoded, where=where, linear=linear, what="white reference")
    return tuple(float(v) for v in m / m[1])


#: The native oxide of a bare-substrate reference: titanium in air grows a few nm of TiO2
#: (2.6 ± 0.3 nm on evaporated films after a day in room air, ellipsometry and resistivity;
#: thicker with time and handling), and each nm moves the metal's R/G by ~0.5 % and B/G by
#: ~1 % (:func:`substrate_colour_rgb`): the reference's colour is taken at this thickness,
#: and the spread adds to its gains' σ (:func:`substrate_gain_sigma`).
NATIVE_OXIDE_NM = 3.0
NATIVE_OXIDE_SD_NM = 1.5


def substrate_colour_rgb(model, *, oxide_nm=NATIVE_OXIDE_NM) -> np.ndarray:
    """Linear sRGB (relative) of ``model``'s substrate metal with ``oxide_nm`` of the model's
    film on it (its native oxide), at normal incidence: what a white-balanced camera records
    of bare metal."""
    t = model.table
    xyz = direct_xyz(0.0, float(oxide_nm), spectral_step_nm=t.spectral_step_nm, film=t.film,
                     substrate=t.substrate, illuminant=t.illuminant, observer=t.observer)
    return np.asarray(model_xyz_to_linear_srgb(xyz, white=model.white, illuminant=t.illuminant,
                                               observer=t.observer), dtype=np.float64)


def substrate_gains(encoded, model, *, where: str, linear: bool = False,
                    oxide_nm=NATIVE_OXIDE_NM) -> tuple:
    """The gains of an image of the bare substrate (the metal without its film, a flat area
    facing the objective, taken with the stack's camera settings and light): its median
    linear R, G, B over the model's colour of that metal with its native oxide
    (:func:`substrate_colour_rgb`), divided by G. Unlike a white standard the metal is not
    neutral (titanium is a warm grey), so its own colour is divided out; its optical
    constants are the model's (``optics.substrate``).
    """
    m = _reference_rgb(encoded, where=where, linear=linear, what="substrate reference")
    g = m / substrate_colour_rgb(model, oxide_nm=oxide_nm)
    return tuple(float(v) for v in g / g[1])


def substrate_gain_sigma(model, *, oxide_nm=NATIVE_OXIDE_NM,
                         oxide_sd_nm=NATIVE_OXIDE_SD_NM) -> tuple:
    """1σ of the log R and B gains from a bare-substrate reference: the native oxide's
    spread (half the change of the metal's log R/G and B/G between ``oxide_nm`` ± its SD),
    and :data:`REFERENCE_LOG_SD`, in quadrature."""
    lo, hi = (substrate_colour_rgb(model, oxide_nm=max(0.0, oxide_nm + s * oxide_sd_nm))
              for s in (-1.0, 1.0))
    half = 0.5 * np.abs(np.log((hi / hi[1]) / (lo / lo[1])))
    return tuple(float(math.hypot(h, REFERENCE_LOG_SD)) for h in (half[0], half[2]))


# ----------------------------------------------------------------------------- estimate
def _tiles(usable, rng):
    """Up to :data:`MAX_TILES` tiles of :data:`TILE_PX` with enough usable pixels: a sample
    of :data:`TILE_SAMPLE_PX` pixel coordinates each."""
    h, w = usable.shape
    out = []
    for r0 in range(0, h - TILE_PX + 1, TILE_PX):
        for c0 in range(0, w - TILE_PX + 1, TILE_PX):
            yy, xx = np.nonzero(usable[r0:r0 + TILE_PX, c0:c0 + TILE_PX])
            if yy.size >= 2 * TILE_SAMPLE_PX:
                pick = rng.choice(yy.size, TILE_SAMPLE_PX, replace=False)
                out.append((yy[pick] + r0, xx[pick] + c0))
    if len(out) > MAX_TILES:
        out = [out[i] for i in np.sort(rng.choice(len(out), MAX_TILES, replace=False))]
    return out


class _Scorer:
    """Per-tile misfit of the film model at candidate gains, in log chromaticity.

    A pixel's ``(log R/G, log B/G)`` (linear) does not depend on the exposure, and the
    gains shift it by ``(log g_R, log g_B)``: the misfit of a pixel at gains g and thickness
    d is ``|u − log g − M(d, tilt)|²`` (clipped at :data:`CLIP` so that a defect pixel
    counts as one outlier), M the model's log chromaticity.
    """

    CLIP = 0.04

    def __init__(self, encoded, tilt, tiles, model, illuminant):
        ys = np.concatenate([t[0] for t in tiles])
        xs = np.concatenate([t[1] for t in tiles])
        self.n_tiles = len(tiles)
        lin = np.maximum(srgb_decode(np.asarray(encoded, np.float32)[ys, xs]), 1e-4)
        self.u = np.log(lin[:, [0, 2]] / lin[:, 1:2]).astype(np.float32)          # (T·n, 2)
        d_lo, d_hi = model.thickness_range_nm
        self.grid = np.arange(d_lo, d_hi + 1e-9, 2.0)
        rgb = model_xyz_to_linear_srgb(model.xyz(tilt[ys, xs][:, None], self.grid[None, :]),
                                       white=model.white, illuminant=illuminant)
        rgb = np.maximum(rgb, 1e-4)
        self.m = np.log(rgb[..., [0, 2]] / rgb[..., 1:2]).astype(np.float32)       # (T·n, D, 2)
        self.resid = self.u[:, None, :] - self.m                                   # (T·n, D, 2)
        self.k = max(1, int(round(PIXEL_FREEDOM_NM / 2.0)))

    def per_thickness(self, log_r, log_b) -> np.ndarray:
        """Mean misfit (T, D) per tile and thickness of the grid at gains
        (e^log_r, 1, e^log_b), each pixel free by ±PIXEL_FREEDOM_NM about the thickness."""
        e = self.resid - np.array([log_r, log_b], np.float32)
        e = np.minimum(np.einsum("ndc,ndc->nd", e, e), self.CLIP)                  # (T·n, D)
        e = ndimage.minimum_filter1d(e, size=2 * self.k + 1, axis=1, mode="nearest")
        return e.reshape(self.n_tiles, -1, e.shape[-1]).mean(axis=1)                # (T, D)

    def per_tile(self, log_r, log_b) -> np.ndarray:
        """Mean misfit per tile at gains (e^log_r, 1, e^log_b), each tile at its best
        thickness (:meth:`per_thickness`)."""
        return self.per_thickness(log_r, log_b).min(axis=1)



def _at_edge(log_gain) -> bool:
    """A log gain within :data:`FINE_STEP` of the edge of the search (±:data:`LOG_RANGE`)."""
    return bool(abs(log_gain) >= LOG_RANGE - FINE_STEP)


def film_colours(thickness_nm, *, gap_nm=COLOUR_GAP_NM, min_tiles=MIN_COLOUR_TILES) -> int:
    """How many distinct film colours the tiles hold: their thicknesses sorted and split
    where neighbours lie more than ``gap_nm`` apart, the groups of at least ``min_tiles``
    counted.

    >>> film_colours([100, 102, 104, 101, 180, 182, 181, 183, 300])
    2
    >>> film_colours([100, 102, 104, 101, 106, 110, 114, 118, 122])
    1
    """
    d = np.sort(np.asarray(thickness_nm, np.float64))
    if d.size == 0:
        return 0
    sizes = np.diff(np.flatnonzero(np.diff(d, prepend=-np.inf, append=np.inf) > gap_nm))
    return int(np.count_nonzero(sizes >= min_tiles))


def _argmin_2d(scores, ax_r, ax_b):
    """The (log_r, log_b) of least score on a grid, refined by a parabola per axis
    (:func:`~.search.parabola`)."""
    i, j = np.unravel_index(int(np.argmin(scores)), scores.shape)
    n = scores.shape[0]
    di = float(parabola(*scores[i - 1:i + 2, j])[0]) if 0 < i < n - 1 else 0.0
    dj = float(parabola(*scores[i, j - 1:j + 2])[0]) if 0 < j < n - 1 else 0.0
    return ax_r[i] + di * (ax_r[1] - ax_r[0]), ax_b[j] + dj * (ax_b[1] - ax_b[0])


def _systematic_sd(scores, ax_r, ax_b, n_tiles):
    """1σ of the log gains when each tile's misfit is one observation of the model's error
    (not only of the noise): a quadratic fitted to the mean misfit on the fine grid, and the
    region where it rises by its least value / n_tiles (a χ² of one per tile, with the
    least misfit as the variance). A scene of one film colour leaves a direction of gains
    that a thickness change compensates: the region is long along it."""
    rr, bb = np.meshgrid(ax_r - ax_r.mean(), ax_b - ax_b.mean(), indexing="ij")
    a = np.stack([np.ones(rr.size), rr.ravel(), bb.ravel(), rr.ravel() ** 2,
                  rr.ravel() * bb.ravel(), bb.ravel() ** 2], axis=1)
    c = np.linalg.lstsq(a, scores.ravel(), rcond=None)[0]
    h = np.array([[2 * c[3], c[4]], [c[4], 2 * c[5]]])
    f0 = float(scores.min())
    try:
        cov = 2.0 * (f0 / max(n_tiles, 1)) * np.linalg.inv(h)
    except np.linalg.LinAlgError:
        return np.array([np.inf, np.inf])
    if np.any(np.linalg.eigvalsh(h) <= 0):
        return np.array([np.inf, np.inf])
    return np.sqrt(np.maximum(np.diag(cov), 0.0))


def estimate_white_balance(encoded, tilt_deg, usable, model, *, illuminant, seed=0
                           ) -> WhiteBalance:
    """The camera's R and B gains that make the image's colours the film's (module notes).

    Parameters
    ----------
    encoded : ndarray (H, W, 3)
        The image, encoded sRGB in [0, 1].
    tilt_deg : ndarray (H, W)
        Tilt per pixel from the height map (NaN: not used).
    usable : ndarray of bool (H, W)
        Pixels that carry colour.
    model : FilmColourModel
    illuminant : str
    seed : int

    Returns
    -------
    WhiteBalance
        ``source`` is ``"none"``: the caller decides whether to apply the estimate.
    """
    rng = np.random.default_rng(seed)
    t_lo, t_hi = model.theta_range_deg
    tilt = np.clip(np.nan_to_num(np.asarray(tilt_deg, np.float64), nan=t_lo), t_lo, t_hi)
    ok = np.asarray(usable, bool) & np.isfinite(np.asarray(tilt_deg, np.float64))
    tiles = _tiles(ok, rng)
    if len(tiles) < 4:
        return WhiteBalance(determined=(False, False), tiles=len(tiles))
    sc = _Scorer(encoded, tilt, tiles, model, illuminant)
    coarse = np.linspace(-LOG_RANGE, LOG_RANGE, COARSE_STEPS)
    per = np.array([[sc.per_tile(r, b) for b in coarse] for r in coarse])     # (R, B, T)
    r0, b0 = _argmin_2d(per.mean(axis=2), coarse, coarse)
    fine_r = np.arange(-3, 4) * FINE_STEP + r0
    fine_b = np.arange(-3, 4) * FINE_STEP + b0
    fine = np.array([[sc.per_tile(r, b) for b in fine_b] for r in fine_r])     # (7, 7, T)
    lr, lb = _argmin_2d(fine.mean(axis=2), fine_r, fine_b)
    boot = []
    for _ in range(BOOTSTRAP):
        pick = rng.integers(0, sc.n_tiles, sc.n_tiles)
        boot.append(_argmin_2d(fine[:, :, pick].mean(axis=2), fine_r, fine_b))
    sd = np.maximum(np.std(np.array(boot), axis=0), _systematic_sd(fine.mean(axis=2), fine_r,
                                                                    fine_b, sc.n_tiles))
    at_one = float(sc.per_tile(0.0, 0.0).mean())
    per = sc.per_thickness(lr, lb)                                              # (T, D)
    best = float(per.min(axis=1).mean())
    edge_r = _at_edge(lr) or fine_r[0] >= lr or lr >= fine_r[-1]
    edge_b = _at_edge(lb) or fine_b[0] >= lb or lb >= fine_b[-1]
    colours = film_colours(sc.grid[per.argmin(axis=1)])
    several = colours >= MIN_FILM_COLOURS
    determined = (bool(sd[0] < DETERMINED_LOG_SD and not edge_r and several),
                  bool(sd[1] < DETERMINED_LOG_SD and not edge_b and several))
    return WhiteBalance(estimate_rgb=(math.exp(lr), 1.0, math.exp(lb)),
                        estimate_sigma=(float(sd[0]), float(sd[1])), determined=determined,
                        misfit_gain=at_one - best, tiles=sc.n_tiles, film_colours=colours)


# ------------------------------------------------------------------------------ choice
def _given_gains(stack, options, model):
    """The reference's gains, its name and its gains' σ (None: :data:`REFERENCE_LOG_SD`), or
    None: ``white_reference`` (the option, then stack.json's), then ``substrate_reference``
    (likewise), then stack.json's ``white_balance``."""
    linear = stack.color_space == "linear-sRGB"
    ref = stack.read_reference("white_reference", options.white_reference,
                               where_given="white_reference")
    if ref is not None:
        img, name, where = ref
        return (reference_gains(img, where=where, linear=linear), f"white reference {name}",
                None)
    ref = stack.read_reference("substrate_reference", options.substrate_reference,
                               where_given="substrate_reference")
    if ref is not None:
        img, name, where = ref
        ox = options.substrate_oxide_nm
        return (substrate_gains(img, model, where=where, linear=linear, oxide_nm=ox),
                f"substrate reference {name}", substrate_gain_sigma(model, oxide_nm=ox))
    given = stack.meta.get("white_balance")      # 3 numbers > 0: the schema checked it
    if given is None:
        return None
    g = np.asarray(given, dtype=np.float64)
    return tuple(float(v) for v in g / g[1]), "stack.json", None


def choose_white_balance(stack, encoded, tilt_deg, usable, model, options, *, illuminant,
                         seed=0) -> WhiteBalance:
    """The white balance to correct the colours for: a reference when one is given; else,
    with ``white_balance = "apply"``, each gain the estimate calls determined
    (:func:`estimate_white_balance`); else none. The estimate is made with ``"report"`` and
    ``"apply"``.

    ``options`` is the ``optics`` section (``white_balance``, ``white_reference``,
    ``substrate_reference``).
    """
    given = _given_gains(stack, options, model)
    est = (estimate_white_balance(encoded, tilt_deg, usable, model, illuminant=illuminant,
                                  seed=seed)
           if options.white_balance in ("report", "apply") else WhiteBalance())
    if given is not None:
        return dataclasses.replace(est, gains_rgb=given[0], source=given[1],
                                   reference_sigma=given[2])
    if (options.white_balance != "apply" or est.estimate_rgb is None
            or not any(est.determined)):
        return est
    r = est.estimate_rgb[0] if est.determined[0] else 1.0
    b = est.estimate_rgb[2] if est.determined[1] else 1.0
    return dataclasses.replace(est, gains_rgb=(r, 1.0, b), source="estimated")
