"""The camera's white balance: estimated from the film's own colours, or from a reference.

A camera multiplies the linear R, G and B of the scene by gains of its own (its white
balance); an image balanced for another light than the one modelled has every colour moved
the same way. For one film colour a gain and a thickness are interchangeable, but the
film's colours at several thicknesses and tilts lie on one physical curve, and two gains
shared by the whole image are over-determined once the scene holds a few distinct film
colours. :func:`estimate_white_balance` therefore fits the R and B gains (G = 1: the
exposure takes the overall scale) to the image's tiles, each tile at its own thickness, in
log chromaticity ``(log R/G, log B/G)``, which the exposure does not move. A tile is 16 px
and holds one film (its pixels within 0.1 of its median log chromaticity); its colour is
the log chromaticity of its pixels' summed linear R, G and B (the pixel noise averages out
before the logarithm) and its model colour the film's averaged over its pixels' tilts. A
chromaticity below :data:`CHROMA_FLOOR` is read as that floor, in the image and in the
model alike: a film outside the sRGB gamut is recorded at 0 in a channel, and that
channel says only that the film's is at or below it. Its thickness is free: what pins the
gains is that one pair of gains must put every tile's colour on the film's curve. Each
distinct film colour pins one combination of the gains (two chromaticities less its
thickness; one at the floor, none), so the gains need two colours with neither
chromaticity at the floor (:func:`film_colours`), and the uncertainty counts each such
colour as one observation of the model's error (the tiles of one colour share it: one
trade of a gain for a thickness, one set of scene effects), not each tile: the least
misfit sets the scale, the misfit's curvature the width; at least the spread over
bootstrap resamples of the tiles; and, in quadrature, how far the estimate moves when
the tilts are halved (:data:`TILT_SCALE`: the height map's tilts, inflated by its noise,
put the model's colours at the wrong tilts). Fewer than two colours leave a direction of
gains a thickness change compensates: the σ is then unbounded. Measured on the
generalization sweep (docs/accuracy.md, "A white-balance estimate from tile colours"):
on its seeds 0-11 (360 scenes) the median |error| is 0.030 (R) and 0.043 (B) in log
gain (0.051 and 0.067 with the per-pixel estimate before it), and 2σ covers 93 % and 89 %
of the errors where the σ is finite (165 scenes; 70 % and 65 % of 305 before). A gain is
called determined only where the σ is below 1 % and the tiles hold at least two such
colours: for one colour the misfit's valley, along which a gain and the thickness trade,
is curved, and its narrow width across the best can pass for a spread below 1 % while the
best lies far along it.

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

hierarchy = load("scipy.cluster.hierarchy")

__all__ = ["WhiteBalance", "balanced_lab", "colour_groups", "estimate_white_balance",
           "film_colours",
           "rebalanced_lab",
           "reference_gains", "substrate_colour_rgb", "substrate_gain_sigma",
           "substrate_gains"]

#: The gains searched: log gain in ±LOG_RANGE (about 0.82-1.22), a coarse grid then a fine
#: one about its best.
LOG_RANGE = 0.2
COARSE_STEPS = 41
FINE_STEP = 0.002
#: Tiles of the estimate (px), the most tiles used, the film colours a tile may hold (the
#: pixels within TILE_CHROMA_RANGE of the tile's median log chromaticity in R/G and B/G: one
#: film, not the edge of two), the fewest such pixels a tile needs, and the tilt quantiles
#: its model colour is averaged over (at the colour table's thickness nodes).
TILE_PX = 16
MAX_TILES = 256
TILE_CHROMA_RANGE = 0.1
MIN_TILE_PIXELS = 16
TILT_QUANTILES = 8
#: The tilts' own error is measured by fitting again with the tilts scaled by this: the
#: height map's tilts are inflated by its noise and flattened by its smoothing (the NDF's
#: self-check reads 0.5-0.9 of planted slopes, docs/accuracy.md), and the change of the
#: estimate between the two is a systematic part of its σ.
TILT_SCALE = 0.5
#: A channel below this share of the green is read as at most it (a bound, not a value):
#: a film outside the sRGB gamut (TiO2 near 172 nm is a cyan of negative linear red) is
#: recorded at 0 in that channel, whose log chromaticity is then the noise's, not the
#: film's. The image's and the model's are floored alike, the model's after the gains.
CHROMA_FLOOR = 0.05
#: Bootstrap resamples of the tiles, and the spread (1σ of the log gain) below which the
#: gains are determined.
BOOTSTRAP = 64
DETERMINED_LOG_SD = 0.01
#: Distinct film colours a determined gain needs: the tiles' log chromaticities in groups
#: joined within COLOUR_GAP_LOG (10 nm of thickness moves a film's by 0.23 or more, its 5th
#: percentile over 10-300 nm; 8° of tilt by 0.02, its 95th percentile 0.13), each of at least
#: MIN_COLOUR_TILES tiles and MIN_COLOUR_SHARE of them (a few tiles of dust or a defect
#: are no colour of the scene).
MIN_FILM_COLOURS = 2
COLOUR_GAP_LOG = 0.1
#: ... and whose best thicknesses at the estimate lie more than COLOUR_GAP_NM apart
#: (~2 ΔE00 per nm: a distinct colour).
COLOUR_GAP_NM = 10.0
MIN_COLOUR_TILES = 4
MIN_COLOUR_SHARE = 0.05
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
        1σ of the R and B estimates, relative (each distinct film colour one observation of
        the model's error; at least the bootstrap spread over the tiles; with the change
        when the tilts are halved in quadrature; inf with fewer than two colours with
        neither chromaticity at the floor: module notes).
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
        Distinct film colours among the tiles with neither chromaticity at
        :data:`CHROMA_FLOOR`, in colour and in the thickness each reads at the estimate
        (:func:`film_colours`): the colours that pin the gains.
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
@dataclass(frozen=True)
class _Tiles:
    """Per tile: its film's log chromaticity ``u`` (T, 2), from the sums of its pixels'
    linear R, G and B (the exposure and any shading cancel, and the noise averages before
    the logarithm), and the tilts its model colour is averaged over (T, TILT_QUANTILES)."""

    u: np.ndarray
    tilt: np.ndarray


def _blocks(a, t) -> np.ndarray:
    """The whole ``t`` × ``t`` tiles of ``a`` (H, W, ...), row by row: (tiles, t·t, ...).

    >>> _blocks(np.arange(16).reshape(4, 4), 2)[1].tolist()
    [2, 3, 6, 7]
    """
    hh, ww = a.shape[0] // t * t, a.shape[1] // t * t
    return a[:hh, :ww].reshape(hh // t, t, ww // t, t, *a.shape[2:]).swapaxes(1, 2).reshape(
        (hh // t) * (ww // t), t * t, *a.shape[2:])


def _tiles(encoded, tilt, usable, rng) -> _Tiles:
    """Up to :data:`MAX_TILES` tiles of :data:`TILE_PX` whose usable pixels hold one film:
    of each tile the pixels within :data:`TILE_CHROMA_RANGE` of its median log chromaticity,
    at least :data:`MIN_TILE_PIXELS` of them."""
    t = TILE_PX
    ok = _blocks(np.asarray(usable, bool), t)
    keep = np.flatnonzero(ok.sum(axis=1) >= max(MIN_TILE_PIXELS, t * t // 4))
    if keep.size > MAX_TILES:
        keep = np.sort(rng.choice(keep, MAX_TILES, replace=False))
    ok = ok[keep]
    lin = np.maximum(srgb_decode(_blocks(np.asarray(encoded, np.float32), t)[keep]), 1e-4)
    ch = _floored_log_chroma(lin)                                               # (T, n, 2)
    med = np.nanmedian(np.where(ok[..., None], ch, np.nan), axis=1)             # (T, 2)
    sel = ok & np.all(np.abs(ch - med[:, None, :]) < TILE_CHROMA_RANGE, axis=2)
    good = sel.sum(axis=1) >= MIN_TILE_PIXELS
    sel, lin, tl = sel[good], lin[good], _blocks(tilt, t)[keep][good]
    sums = np.einsum("tn,tnc->tc", sel.astype(np.float64), lin.astype(np.float64))
    u = _floored_log_chroma(sums)
    q = np.linspace(0.05, 0.95, TILT_QUANTILES)
    tq = np.nanquantile(np.where(sel, tl, np.nan), q, axis=1).T                 # (T, Q)
    return _Tiles(u, tq)


def _floored_log_chroma(rgb) -> np.ndarray:
    """``(log R/G, log B/G)`` of linear ``rgb`` (..., 3), each at least
    ``log CHROMA_FLOOR`` (:data:`CHROMA_FLOOR`).

    >>> np.round(_floored_log_chroma(np.array([[0.0, 0.5, 0.25]])), 3).tolist()
    [[-2.996, -0.693]]
    """
    rgb = np.asarray(rgb)
    g = np.maximum(rgb[..., 1:2], 1e-12)
    return np.log(np.maximum(rgb[..., [0, 2]], CHROMA_FLOOR * g) / g)


class _Scorer:
    """Per-tile misfit of the film model at candidate gains, in log chromaticity.

    A tile's ``(log R/G, log B/G)`` (its pixels' linear sums) does not depend on the
    exposure, and the gains shift the model's by ``(log g_R, log g_B)``: the misfit of a tile
    at gains g and thickness d is ``|u − max(M(d) + log g, F)|²`` (clipped at :data:`CLIP`
    so that a tile the film does not explain counts as one outlier), M the log chromaticity
    of the model's linear colour averaged over the tile's tilts, F = log
    :data:`CHROMA_FLOOR` (the image's ``u`` is floored alike: a channel the camera records
    at 0 is matched by any model colour at or below the floor). Only the thicknesses whose
    colour lies within the gains searched (and the clip) of a tile's can be its best: those
    are kept.
    """

    CLIP = 0.01
    FLOOR = math.log(CHROMA_FLOOR)

    def __init__(self, tiles: _Tiles, model, illuminant):
        self.n_tiles = tiles.u.shape[0]
        # the film's linear colour at the table's nodes, and each tile's mean over its tilts
        # as the table interpolates them (linearly in tilt at a thickness node)
        theta, self.grid = model.table.theta_deg, model.table.thickness_nm
        nodes = model_xyz_to_linear_srgb(model.xyz(theta[:, None], self.grid[None, :]),
                                         white=model.white, illuminant=illuminant)
        rgb = np.maximum(np.einsum("tk,kdc->tdc", _tilt_weights(tiles.tilt, theta),
                                   nodes.astype(np.float64)), 1e-6)               # (T, D, 3)
        m = np.log(rgb[..., [0, 2]] / rgb[..., 1:2])                               # (T, D, 2)
        u = np.broadcast_to(tiles.u[:, None, :], m.shape)
        # a gain moves max(M + log g, F) by at most |log g| <= LOG_RANGE
        resid = u - np.maximum(m, self.FLOOR)
        near = np.all(np.abs(resid) <= LOG_RANGE + math.sqrt(self.CLIP), axis=2)
        self.tile, self.node = np.nonzero(near)
        self.u = u[self.tile, self.node].astype(np.float64)                       # (P, 2)
        self.m = m[self.tile, self.node].astype(np.float64)                       # (P, 2)

    def _axis_misfit(self, c, log_gains) -> np.ndarray:
        """Squared misfit (P, g) of chromaticity ``c`` (0: R/G, 1: B/G) of the kept (tile,
        thickness) pairs at each of the log gains (g,) of that channel: the misfit is the
        sum of the two, each of one gain."""
        e = self.u[:, c:c + 1] - np.maximum(self.m[:, c:c + 1] + np.asarray(log_gains)[None],
                                            self.FLOOR)
        return e * e

    def per_thickness(self, log_r, log_b) -> np.ndarray:
        """Misfit (T, D) per tile and thickness of the grid at gains (e^log_r, 1, e^log_b)
        (the clip where a thickness was not kept)."""
        out = np.full((self.n_tiles, self.grid.size), self.CLIP)
        e = self._axis_misfit(0, [log_r])[:, 0] + self._axis_misfit(1, [log_b])[:, 0]
        out[self.tile, self.node] = np.minimum(e, self.CLIP)
        return out

    def per_tile(self, log_r, log_b) -> np.ndarray:
        """Misfit per tile at gains (e^log_r, 1, e^log_b), each tile at its best
        thickness."""
        return self.on_grid(np.atleast_1d(log_r), np.atleast_1d(log_b))[0, 0]

    def on_grid(self, ax_r, ax_b) -> np.ndarray:
        """:meth:`per_tile` at every pair of ``ax_r`` × ``ax_b``: shape (R, B, T); one R
        gain at a time (bounded memory), the two chromaticities' misfits computed once per
        gain of their own and added."""
        out = np.full((len(ax_r), len(ax_b), self.n_tiles), self.CLIP)
        if self.tile.size:
            # self.tile is sorted (np.nonzero): each tile's kept thicknesses are one run
            has, start = np.unique(self.tile, return_index=True)
            mr, mb = self._axis_misfit(0, ax_r), self._axis_misfit(1, ax_b)     # (P, R), (P, B)
            for i in range(len(ax_r)):
                e = np.minimum.reduceat(mr[:, i:i + 1] + mb, start, axis=0)       # (T', B)
                out[i][:, has] = np.minimum(e, self.CLIP).T
        return out


def _tilt_weights(tilt_deg, theta_deg) -> np.ndarray:
    """Weights (T, K) of the tilt nodes ``theta_deg`` (K, increasing) that average the
    linear interpolation at each row's tilts (T, Q) (clipped to the nodes' range).

    >>> _tilt_weights(np.array([[0.0, 1.5]]), np.array([0.0, 1.0, 2.0])).tolist()
    [[0.5, 0.25, 0.25]]
    """
    t = np.clip(tilt_deg, theta_deg[0], theta_deg[-1])
    k = theta_deg.size
    if k == 1:
        return np.ones(t.shape[:1] + (1,))
    i = np.clip(np.searchsorted(theta_deg, t, side="right") - 1, 0, k - 2)
    f = (t - theta_deg[i]) / (theta_deg[i + 1] - theta_deg[i])
    w = np.zeros((t.shape[0], k))
    rows = np.repeat(np.arange(t.shape[0]), t.shape[1])
    np.add.at(w, (rows, i.ravel()), (1.0 - f).ravel())
    np.add.at(w, (rows, i.ravel() + 1), f.ravel())
    return w / t.shape[1]


def _at_edge(log_gain) -> bool:
    """A log gain within :data:`FINE_STEP` of the edge of the search (±:data:`LOG_RANGE`)."""
    return bool(abs(log_gain) >= LOG_RANGE - FINE_STEP)


def film_colours(log_chroma, *, gap=COLOUR_GAP_LOG, min_tiles=MIN_COLOUR_TILES) -> int:
    """How many distinct film colours the tiles hold (:func:`colour_groups`).

    >>> film_colours([[0.1, -0.2], [0.11, -0.2], [0.1, -0.21], [0.12, -0.19],
    ...               [0.4, 0.1], [0.41, 0.1], [0.4, 0.11], [0.42, 0.12], [0.9, 0.9]])
    2
    """
    return int(colour_groups(log_chroma, gap=gap, min_tiles=min_tiles).max(initial=-1) + 1)


def colour_groups(log_chroma, *, gap=COLOUR_GAP_LOG, min_tiles=MIN_COLOUR_TILES
                  ) -> np.ndarray:
    """The film colour of each tile (0, 1, …; -1: a tile of a group of fewer than
    ``min_tiles``): the tiles' log chromaticities ``(log R/G, log B/G)`` (shape (T, 2))
    joined into groups wherever two lie within ``gap`` of each other (single linkage, the
    largest of the two differences). Gains shift every tile alike, so the groups do not
    depend on them; a film's spread of tilt moves its colour by far less than the gap, a
    thickness 10 nm away by more.

    >>> colour_groups([[0, 0], [0.3, 0], [0.02, 0], [0.9, 0.9], [0.01, 0.01], [0.31, 0]],
    ...               min_tiles=2).tolist()
    [0, 1, 0, -1, 0, 1]
    """
    u = np.asarray(log_chroma, np.float64)
    out = np.full(u.shape[0], -1, np.int64)
    if u.shape[0] == 0:
        return out
    u = u.reshape(u.shape[0], -1)
    if u.shape[0] == 1:
        run = np.zeros(1, np.int64)
    else:
        link = hierarchy.linkage(u, method="single", metric="chebyshev")
        run = hierarchy.fcluster(link, t=gap, criterion="distance") - 1
    size = np.bincount(run)
    big = np.flatnonzero(size >= min_tiles)
    label = np.full(size.size, -1, np.int64)
    # numbered in order of their first tile
    first = np.array([np.flatnonzero(run == g)[0] for g in big], np.int64)
    label[big[np.argsort(first)]] = np.arange(big.size)
    out[:] = label[run]
    return out


def _distinct_colours(log_chroma, thickness_nm) -> int:
    """Film colours distinct in colour (whatever the gains: :func:`film_colours`) and in
    the thickness each tile reads at the estimate (:func:`_thickness_groups`): a population
    whose colour changes fast with thickness spreads over several groups of colour, one of
    thickness. Groups of at least :data:`MIN_COLOUR_TILES` tiles and
    :data:`MIN_COLOUR_SHARE` of them. Only tiles with neither channel at
    :data:`CHROMA_FLOOR` count: a colour pins the two gains by its two chromaticities less
    its thickness, one constraint, and one at the floor by none (its other chromaticity is
    its thickness'), so two such colours leave a gain free (measured: a 120 nm film beside a
    172 nm cyan, gains R 1.12, B 0.90, read 18 % and 15 % off at a σ below 1 % when the cyan
    counted).

    >>> u = np.array([[0.4, -2.2]] * 8 + [[math.log(CHROMA_FLOOR), 0.3]] * 8)
    >>> _distinct_colours(u, np.array([120.0] * 8 + [172.0] * 8))
    1
    """
    least = max(MIN_COLOUR_TILES, math.ceil(MIN_COLOUR_SHARE * len(thickness_nm)))
    free = np.all(np.asarray(log_chroma) > math.log(CHROMA_FLOOR) + 1e-9, axis=1)
    return min(film_colours(np.asarray(log_chroma)[free], min_tiles=least),
               _thickness_groups(np.asarray(thickness_nm)[free], min_tiles=least))


def _thickness_groups(thickness_nm, *, min_tiles) -> int:
    """How many groups of at least ``min_tiles`` tiles their best thicknesses form, split
    where sorted neighbours lie more than :data:`COLOUR_GAP_NM` apart.

    >>> _thickness_groups([100, 102, 104, 101, 180, 182, 181, 183, 300], min_tiles=4)
    2
    """
    d = np.sort(np.asarray(thickness_nm, np.float64))
    if d.size == 0:
        return 0
    sizes = np.diff(np.flatnonzero(np.diff(d, prepend=-np.inf, append=np.inf) > COLOUR_GAP_NM))
    return int(np.count_nonzero(sizes >= min_tiles))


def _argmin_2d(scores, ax_r, ax_b):
    """The (log_r, log_b) of least score on a grid, refined by a parabola per axis
    (:func:`~.search.parabola`)."""
    i, j = np.unravel_index(int(np.argmin(scores)), scores.shape)
    n = scores.shape[0]
    di = float(parabola(*scores[i - 1:i + 2, j])[0]) if 0 < i < n - 1 else 0.0
    dj = float(parabola(*scores[i, j - 1:j + 2])[0]) if 0 < j < n - 1 else 0.0
    return ax_r[i] + di * (ax_r[1] - ax_r[0]), ax_b[j] + dj * (ax_b[1] - ax_b[0])


def _systematic_sd(scores, ax_r, ax_b, n_obs):
    """1σ of the log gains when the tiles' misfit holds ``n_obs`` independent observations
    of the model's error (not only of the noise; the caller passes its film colours): a
    quadratic fitted to the mean misfit on the fine grid, and the region where it rises by
    its least value / ``n_obs`` (a χ² of one per observation, with the least misfit as the
    variance)."""
    rr, bb = np.meshgrid(ax_r - ax_r.mean(), ax_b - ax_b.mean(), indexing="ij")
    a = np.stack([np.ones(rr.size), rr.ravel(), bb.ravel(), rr.ravel() ** 2,
                  rr.ravel() * bb.ravel(), bb.ravel() ** 2], axis=1)
    c = np.linalg.lstsq(a, scores.ravel(), rcond=None)[0]
    h = np.array([[2 * c[3], c[4]], [c[4], 2 * c[5]]])
    f0 = float(scores.min())
    try:
        cov = 2.0 * (f0 / max(n_obs, 1)) * np.linalg.inv(h)
    except np.linalg.LinAlgError:
        return np.array([np.inf, np.inf])
    if np.any(np.linalg.eigvalsh(h) <= 0):
        return np.array([np.inf, np.inf])
    return np.sqrt(np.maximum(np.diag(cov), 0.0))


def _least_misfit(sc):
    """The log gains (R, B) of least mean misfit of :class:`_Scorer` ``sc`` (a coarse grid
    over ±:data:`LOG_RANGE`, then a fine one about its best), the fine grid's per-tile
    misfit (7, 7, T) and its two axes."""
    coarse = np.linspace(-LOG_RANGE, LOG_RANGE, COARSE_STEPS)
    r0, b0 = _argmin_2d(sc.on_grid(coarse, coarse).mean(axis=2), coarse, coarse)
    fine_r = np.arange(-3, 4) * FINE_STEP + r0
    fine_b = np.arange(-3, 4) * FINE_STEP + b0
    fine = sc.on_grid(fine_r, fine_b)                                           # (7, 7, T)
    lr, lb = _argmin_2d(fine.mean(axis=2), fine_r, fine_b)
    return lr, lb, fine, fine_r, fine_b


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
    tiles = _tiles(encoded, tilt, ok, rng)
    if tiles.u.shape[0] < 4:
        return WhiteBalance(determined=(False, False), tiles=int(tiles.u.shape[0]))
    sc = _Scorer(tiles, model, illuminant)
    lr, lb, fine, fine_r, fine_b = _least_misfit(sc)
    # the tilts' own error: the same fit with the tilts halved (module notes)
    half = _least_misfit(_Scorer(dataclasses.replace(tiles, tilt=np.maximum(
        tiles.tilt * TILT_SCALE, t_lo)), model, illuminant))
    tilt_sd = np.abs(np.array([lr - half[0], lb - half[1]]))
    boot = []
    for _ in range(BOOTSTRAP):
        pick = rng.integers(0, sc.n_tiles, sc.n_tiles)
        boot.append(_argmin_2d(fine[:, :, pick].mean(axis=2), fine_r, fine_b))
    at_one = float(sc.per_tile(0.0, 0.0).mean())
    per = sc.per_thickness(lr, lb)                                              # (T, D)
    best = float(per.min(axis=1).mean())
    edge_r = _at_edge(lr) or fine_r[0] >= lr or lr >= fine_r[-1]
    edge_b = _at_edge(lb) or fine_b[0] >= lb or lb >= fine_b[-1]
    colours = _distinct_colours(tiles.u, sc.grid[per.argmin(axis=1)])
    several = colours >= MIN_FILM_COLOURS
    # the tiles of one film colour share its model error (one trade of gain for thickness,
    # one set of scene effects): each colour is one observation of it, not each tile; one
    # colour leaves a direction of gains that its thickness compensates (the misfit's
    # valley is curved, and its width across the best says nothing of how far along it)
    sd = (np.hypot(np.maximum(np.std(np.array(boot), axis=0),
                              _systematic_sd(fine.mean(axis=2), fine_r, fine_b, colours)),
                   tilt_sd)
          if several else np.full(2, np.inf))
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
