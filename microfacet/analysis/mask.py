"""Pixels that carry no colour information (seed §3.3.3 step 2).

The seed masks pixels whose HSV saturation is below 15 (on the 0-255 scale): the specular
highlights and the shadows. We also mask dark pixels (facets tilted past the objective's
acceptance reflect outside it) and pixels with a clipped channel (their colour is not the
film's). A wide grey area in an image of coloured film is a film of a grey colour, and is
analysed (:func:`grey_film`), as a wide dark one is a film of a dark colour.

References
----------
.. [1] N. Nagata, M. Kamei, K. Takahashi, K. Tobitani, T. Akagi, S. Yamamura, "Simulation
   Technology for Titanium Oxide Layer Interference Color", Technical Report (the seed paper),
   §3.3.3 (2) (pixels of saturation below 15 masked: highlights and shadows).
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass

import numpy as np

from ..colour.srgb import srgb_decode
from ..core.lazy import load
from .options import MaskOptions

cv2 = load("cv2")

__all__ = ["ColourMask", "colour_mask", "grey_film"]

#: The mask's reasons, in the order summary.json and the report give them.
MASK_REASONS = ("low_saturation", "dark", "clipped", "invalid", "shadow", "steep",
                "dark_feature")


@dataclass
class ColourMask:
    """Per-pixel mask and its reasons (all bool, H×W; True = masked).

    Attributes
    ----------
    mask : ndarray of bool
        Any reason below.
    low_saturation, dark, clipped, invalid : ndarray of bool
        HSV saturation below the threshold (outside areas of grey film, below); HSV value
        below the threshold; a channel at the clip level; NaN input.
    shadow : ndarray of bool
        HSV value below ``shadow_ratio`` × the median value of the 9×9 neighbourhood:
        partly shadowed pixels (the walls of the steps between facets), whose hue is the
        film's but whose lightness is not — darkening does not lower saturation, so the
        seed's saturation test misses them.
    steep : ndarray of bool
        Far darker than the film (:func:`steep_facet_mask`): tilted past the acceptance
        (all False without ``steep_ratio``). The NDF censors these.
    dark_feature : ndarray of bool
        Darker than ``steep_ratio`` of the film without being steep, in a shape narrower than
        ``dark_film_min_px`` (:func:`steep_facet_mask`): scratches, pit and groove walls and
        rims, stains — masked, not censored. A wider dark area is a film of a dark colour
        and is analysed.
    grey_film : ndarray of bool or None
        Below the saturation threshold but analysed, not masked (by this or another
        reason): a film of a grey colour (:func:`grey_film`). None: not looked for.
    clipped_one : ndarray of bool or None
        One channel at the clip level, analysed, not masked (by this or another reason):
        the film's model colour is clipped alike (``FilmColourModel.clip_rgb``). None: every
        clipped pixel is masked (``clipped``).
    """

    mask: np.ndarray
    low_saturation: np.ndarray
    dark: np.ndarray
    clipped: np.ndarray
    invalid: np.ndarray
    shadow: np.ndarray
    steep: np.ndarray
    dark_feature: np.ndarray
    grey_film: np.ndarray | None = None
    clipped_one: np.ndarray | None = None

    @property
    def clip_analysed(self) -> bool:
        """Whether any clipped pixel is analysed (the model must then be clipped alike)."""
        return self.clipped_one is not None and bool(self.clipped_one.any())

    def clipped_masked(self) -> "ColourMask":
        """The mask with every clipped pixel masked (where the clip level varies across the
        image: a flat field divided out)."""
        if self.clipped_one is None:
            return self
        return dataclasses.replace(self, mask=self.mask | self.clipped_one,
                                   clipped=self.clipped | self.clipped_one, clipped_one=None)

    @property
    def coloured(self) -> np.ndarray:
        """Pixels not masked that are film by their colour, not only by their shape (grey
        film left out): the white balance is estimated from these alone. A grey is what
        fixes the gains most, so a grey area taken for film by its width — a stain, bare
        metal — would set them; on the generalization sweep the grey part of a one-colour
        film (seed 4 g014) passed for a second film colour and let its wrong order be
        called established. Clipped pixels are left out too: a clipped channel is not the
        film's colour, and the gains' estimate does not model the clip."""
        out = ~self.mask
        for extra in (self.grey_film, self.clipped_one):
            if extra is not None:
                out = out & ~extra
        return out

    @property
    def fraction(self) -> float:
        """Fraction of masked pixels."""
        return float(self.mask.mean()) if self.mask.size else 1.0

    def fractions(self) -> dict:
        """Masked fraction per reason (a pixel may have several), all of them (``any``), the
        fraction of grey film analysed though below the saturation threshold (``grey_film``)
        and of pixels analysed with one channel clipped (``clipped_one``; each 0 where none
        was looked for)."""
        grey, one = (0.0 if a is None else float(a.mean())
                     for a in (self.grey_film, self.clipped_one))
        return {k: float(getattr(self, k).mean()) for k in MASK_REASONS} | {
            "any": self.fraction, "grey_film": grey, "clipped_one": one}


def colour_mask(image, options: MaskOptions | None = None, *, bit_depth=8,
                clip_level=None) -> ColourMask:
    """Mask low-saturation, dark, clipped, shadowed, steep and NaN pixels of an encoded RGB
    image.

    Parameters
    ----------
    image : ndarray, shape (H, W, 3)
        Encoded (sRGB) image scaled to [0, 1] (float) — e.g. the all-in-focus composite.
    options : MaskOptions, optional
        ``saturation_min`` (HSV saturation threshold on the 0-255 scale, the seed's 15),
        ``value_min`` (HSV value threshold, 0-255), ``shadow_ratio`` (mask pixels darker
        than this fraction of their 9×9 neighbourhood's median value; 0 disables),
        ``steep_ratio``, ``steep_core_ratio``, ``steep_rim_px`` and ``dark_film_min_px``
        (mask pixels far darker than the median of the other unmasked pixels as steep, or
        as dark features where they are not, :func:`steep_facet_mask`; ``steep_ratio`` 0
        disables), ``clipped_one_channel`` (pixels with one channel at the clip level are
        analysed, ``clipped_one``, not masked).
    bit_depth : int
        Bit depth of the source images, for the default clip level.
    clip_level : float, optional
        A channel at or above this (0-1 scale) is clipped. Default: the top code value of
        ``bit_depth`` minus half a step (255 of 255 for 8-bit, 65535 for 16-bit).

    Returns
    -------
    ColourMask

    Examples
    --------
    >>> import numpy as np
    >>> img = np.array([[[0.5, 0.2, 0.8], [0.5, 0.5, 0.5], [1.0, 1.0, 0.2], [1.0, 0.4, 0.2]]],
    ...                np.float32)
    >>> m = colour_mask(img)
    >>> m.mask.tolist(), m.clipped_one.tolist()     # grey, two clipped; one clipped: analysed
    ([[False, True, True, False]], [[False, False, False, True]])
    """
    o = MaskOptions() if options is None else options
    img = np.asarray(image, dtype=np.float32)
    if img.ndim != 3 or img.shape[-1] != 3:
        raise ValueError(f"image: expected an RGB image (H, W, 3), got shape {img.shape}")
    if clip_level is None:
        top = 2 ** int(bit_depth) - 1
        clip_level = (top - 0.5) / top
    # channel by channel: a reduction over a last axis of 3 costs several times the
    # element-wise maximum of the three planes (the same values)
    invalid = ~(np.isfinite(img[..., 0]) & np.isfinite(img[..., 1]) & np.isfinite(img[..., 2]))
    safe = np.where(invalid[..., None], np.float32(0), img) if invalid.any() else img
    vmax = _channel_max(safe)
    vmin = np.minimum(np.minimum(safe[..., 0], safe[..., 1]), safe[..., 2])
    with np.errstate(invalid="ignore", divide="ignore"):
        sat = np.where(vmax > 0, (vmax - vmin) / vmax, 0.0) * 255.0
    del vmin
    low_sat = sat < o.saturation_min
    dark = vmax * 255.0 < o.value_min
    clipped = vmax >= clip_level
    one = None
    if o.clipped_one_channel and clipped.any():
        n_at = sum((safe[..., c] >= clip_level).astype(np.uint8) for c in range(3))
        one = clipped & (n_at == 1)
    other = dark | clipped | invalid
    grey = grey_film(low_sat & ~other, ~(low_sat | other), o)
    if one is not None:       # analysed: masked only for another reason (not grey film)
        clipped = clipped & ~one
    low_sat &= ~grey
    if o.shadow_ratio > 0:
        v8 = np.clip(np.round(vmax * 255.0), 0, 255).astype(np.uint8)
        local = cv2.medianBlur(v8, 9).astype(np.float32) / 255.0
        shadow = (vmax < o.shadow_ratio * local) & ~invalid
    else:
        shadow = np.zeros(vmax.shape, bool)
    mask = low_sat | dark | clipped | invalid | shadow
    steep = feature = np.zeros(vmax.shape, bool)
    if o.steep_ratio > 0 and (~mask).any():
        steep, feature = dark_classes(_channel_max(safe, decode=True), mask, invalid, o)
        mask = mask | steep | feature
    if one is not None:       # masked for another reason: clipped is one of its reasons
        clipped = clipped | (one & mask)
        one = one & ~mask
    return ColourMask(mask, low_sat & ~invalid, dark & ~invalid, clipped & ~invalid, invalid,
                      shadow, steep, feature, grey & ~mask, one)


#: Least share of the image that must be film of colour (no reason to mask it) before a wide
#: grey area is taken for film too: an image that is grey all over is a monochrome camera's or
#: a sample without an oxide, not a grey film.
GREY_FILM_MIN_COLOURED = 0.05
#: Radius (px) of the closing that joins a grey film's pixels where noise lifts some of them
#: above the saturation threshold (a film of saturation 14-16 against the seed's 15).
GREY_SPECKLE_PX = 2


def grey_film(grey, coloured, options: MaskOptions) -> np.ndarray:
    """The low-saturation pixels that are a film of a grey colour, not a highlight or a rim.

    The seed masks every pixel of HSV saturation below 15 (highlights and shadows). Some
    films are that grey: TiO2 near 50 nm on titanium reads (0.80, 0.81, 0.80) in sRGB with
    Devore's rutile on Werner's Ti, saturation 6 — and a population of them, two thirds of a
    scene of the generalization sweep, was masked and lost (docs/accuracy.md). Under coaxial
    light a highlight is clipped (masked as such) or narrow, a rim or a glint; a film fills
    its regions. So, as for a film of a dark colour (:func:`steep_facet_mask`), a grey area
    at least ``options.grey_film_min_px`` wide (a morphological opening, after a closing
    of :data:`GREY_SPECKLE_PX` that joins a film speckled by noise about the threshold) is
    analysed, where at least :data:`GREY_FILM_MIN_COLOURED` of the image is film of colour
    (``coloured``). The film model then reads it like any other film, and colours it does
    not explain are set aside as they are elsewhere.

    Parameters
    ----------
    grey : ndarray of bool, shape (H, W)
        Below the saturation threshold, neither dark, clipped nor invalid.
    coloured : ndarray of bool, shape (H, W)
        Pixels without any of the seed's reasons to mask them.
    options : MaskOptions
        ``grey_film_min_px`` (0: none, every grey pixel masked as the seed does).

    Examples
    --------
    >>> grey = np.zeros((40, 40), bool)
    >>> grey[5:30, 5:30] = True               # a grey region 25 px wide
    >>> grey[35, :] = True                    # a grey rim 1 px wide
    >>> g = grey_film(grey, ~grey, MaskOptions())
    >>> bool(g[15, 15]), bool(g[35, 20])
    (True, False)
    >>> bool(grey_film(grey, np.zeros((40, 40), bool), MaskOptions()).any())  # all grey
    False
    """
    g = np.asarray(grey, bool)
    if (options.grey_film_min_px <= 0 or not g.any()
            or float(np.mean(coloured)) < GREY_FILM_MIN_COLOURED):
        return np.zeros(g.shape, bool)
    # noise speckles a film whose saturation lies near the threshold: close the speckle
    # first, then keep what is wide
    closed = cv2.morphologyEx(g.astype(np.uint8), cv2.MORPH_CLOSE, _disc(GREY_SPECKLE_PX))
    return _wide(closed, options.grey_film_min_px) & g




def dark_classes(linear_max, masked, invalid, options: MaskOptions):
    """:func:`steep_facet_mask` against the median of the pixels not ``masked`` (the film),
    an ``invalid`` pixel passed as NaN: it is no dark core, so its neighbours are no steep
    rim. Returns ``(steep, dark_feature)``."""
    ref = float(np.median(linear_max[~masked]))
    return steep_facet_mask(np.where(invalid, np.nan, linear_max), ref, options)


def steep_facet_mask(linear_max, reference, options: MaskOptions):
    """Pixels far darker than the film: facets tilted past the objective's acceptance, and
    dark features that are not film.

    Under coaxial light a facet tilted past asin(NA)/2 reflects outside the objective and
    images dark: measured on synthetic scenes, a linear value of ~0.05 of the film's
    median, while the film's colours over a scene's thickness range mostly stay above ~0.4
    of it. The darkest film colour of all (TiO2 on Ti near 29–37 nm, brightest channel at
    normal incidence) is 0.15–0.29 of the median film colour over 20–400 nm, by the bundled
    optical constants (0.26 for the sweep's Jolivet 2023 film on Johnson & Christy's Ti,
    0.15 on Palm 2018's), so a film of that colour beside much brighter ones is dark
    without being steep. Two thresholds tell them apart (hysteresis, as in Canny's edges):
    a pixel below ``steep_core_ratio`` of the film (0.1: two thirds of the darkest film's
    value, twice the steep facets') is darker than any film and steep; one below
    ``steep_ratio`` (0.3) is steep only within ``steep_rim_px``
    of such a core — the blurred rim of the same facet, pit or groove wall. (Every pixel
    below 0.3 was masked before: on the sweep of docs/accuracy.md a population of 37 nm
    film, a third of one scene, was masked as steep and lost.) Their noise can still make
    dark facets look saturated, so the saturation test misses them. Which dark areas are
    whole facets is decided per facet by the joint stage.

    Parameters
    ----------
    linear_max : ndarray, shape (H, W)
        The largest of the three linear (decoded) channels per pixel.
    reference : float
        Median linear value (max channel) of the film's pixels.
    options : MaskOptions
        ``steep_ratio``, ``steep_core_ratio``, ``steep_rim_px`` and ``dark_film_min_px``.

    Returns
    -------
    steep, dark_feature : ndarray of bool, shape (H, W)

    Examples
    --------
    >>> lin = np.full((30, 40), 0.6, np.float32)
    >>> lin[2, 1] = 0.01                    # a steep facet's core: 0.017 of the film
    >>> lin[2, 2] = 0.15                    # its blurred rim: 0.25 of it, beside the core
    >>> lin[:, 20:] = 0.16                  # a dark film, 0.27 of it, nowhere near a core
    >>> lin[10, :12] = 0.15                 # a scratch as dark, one pixel wide
    >>> steep, feature = steep_facet_mask(lin, 0.6, MaskOptions())
    >>> int(steep.sum()), int(feature.sum()), bool(steep[:, 20:].any() | feature[:, 20:].any())
    (2, 12, False)
    """
    o = options
    lin = np.nan_to_num(np.asarray(linear_max, dtype=np.float32), nan=np.inf)
    dark = lin < o.steep_ratio * reference
    core = lin < min(o.steep_core_ratio, o.steep_ratio) * reference
    rest = dark & ~core
    if not rest.any():
        return core, rest
    steep = core.copy()
    if o.steep_rim_px > 0:               # the rim: dark pixels beside a core
        steep |= rest & cv2.dilate(core.astype(np.uint8), _disc(o.steep_rim_px)).astype(bool)
    rest &= ~steep
    return steep, rest & ~_wide(dark, o.dark_film_min_px)


def _wide(mask, min_px) -> np.ndarray:
    """The parts of ``mask`` (H, W) at least ``min_px`` wide: its opening by a disc of that
    diameter (a dark or a grey film, against the narrower features beside it)."""
    return cv2.morphologyEx(np.asarray(mask).astype(np.uint8), cv2.MORPH_OPEN,
                            _disc(0.5 * min_px)).astype(bool)


def _disc(radius_px):
    """A disc of ``radius_px`` (uint8, a structuring element for OpenCV)."""
    r = int(radius_px)
    yy, xx = np.mgrid[-r:r + 1, -r:r + 1]
    return (yy * yy + xx * xx <= radius_px ** 2).astype(np.uint8)


def _channel_max(img, *, decode=False):
    """The largest of the three channels of ``img`` (H, W, 3), decoded from sRGB first if
    ``decode`` (float32, shape (H, W))."""
    f = srgb_decode if decode else np.asarray
    return np.maximum(np.maximum(f(img[..., 0]), f(img[..., 1])), f(img[..., 2]))
