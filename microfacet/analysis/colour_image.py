"""The colour stage: the all-in-focus image as CIELAB, the mask of pixels without colour
information, and the image's colour noise (seed §3.3.3 step 2, first half).

References
----------
.. [1] N. Nagata, M. Kamei, K. Takahashi, K. Tobitani, T. Akagi, S. Yamamura, "Simulation
   Technology for Titanium Oxide Layer Interference Color", Technical Report (the seed paper),
   §3.3.3 (2) (the microscope image as Lab).
.. [2] G. Sharma, W. Wu, E. N. Dalal, "The CIEDE2000 color-difference formula: implementation
   notes, supplementary test data, and mathematical observations", Color Res. Appl. 30 (2005)
   21-30, doi:10.1002/col.20070.
"""

from __future__ import annotations

import logging
from dataclasses import dataclass

import numpy as np

from ..colour.difference import delta_e
from ..colour.srgb import srgb_encode, srgb_to_lab
from .mask import MASK_REASONS, ColourMask, colour_mask
from .options import MaskOptions

__all__ = ["ColourImage", "compression_noise_de", "estimate_colour_noise",
           "mean_colour_noise", "measure_colour"]

log = logging.getLogger(__name__)


@dataclass
class ColourImage:
    """The image the colour analysis uses.

    Attributes
    ----------
    encoded : ndarray of float32 (H, W, 3)
        sRGB-encoded values in [0, 1].
    lab : ndarray of float32 (H, W, 3)
        CIELAB relative to the illuminant white.
    mask : ColourMask
        Pixels without colour information, by reason.
    noise_de : float
        Colour noise per Lab component (ΔE00 units), at least the quantization floor.
    bit_depth : int
        8 or 16.
    block_noise_de : float
        JPEG slices: the colour error per Lab component (ΔE00 units) that the quantization of
        each block's mean (the DC coefficient) leaves, shared by the block's pixels, so a
        mean over a region does not average it below one block's worth
        (:func:`compression_noise_de`); 0 for lossless slices.
    block_px : int
        Pixels that share that error (the chroma block: 64, or 256 with 4:2:0 subsampling).
    clip_rgb : tuple of 3 float or None
        Where pixels with a clipped channel are analysed (``mask.clipped_one``): the linear
        level of each channel in ``lab``'s values at which the camera clipped them (1; ``1/g``
        once divided by gains ``g``), the film model's ``clip_rgb``. None: none analysed.
    """

    encoded: np.ndarray
    lab: np.ndarray
    mask: ColourMask
    noise_de: float
    bit_depth: int
    block_noise_de: float = 0.0
    block_px: int = 64
    clip_rgb: tuple | None = None


def mean_colour_noise(noise_de, block_noise, n_px):
    """Colour error per Lab component of the mean of ``n_px`` pixels: the pixel noise
    ``noise_de`` averaged over them, and the JPEG block error ``block_noise = (ΔE, pixels
    per block)`` averaged over the blocks they span (not below one block's).

    >>> mean_colour_noise(1.0, (0.5, 64), np.array([1, 256])).round(4).tolist()
    [1.118, 0.2577]
    """
    n = np.maximum(np.asarray(n_px, dtype=np.float64), 1.0)
    b_de, b_px = block_noise
    return np.sqrt(noise_de ** 2 / n + b_de ** 2 * np.minimum(1.0, b_px / n))


def measure_colour(all_in_focus, options: MaskOptions, *, color_space, bit_depth, illuminant,
                   delta_e_method, jpeg=None) -> ColourImage:
    """CIELAB, the colour mask and the colour noise of a composite image.

    Parameters
    ----------
    all_in_focus : ndarray (H, W) or (H, W, 3)
        In [0, 1], encoded per ``color_space`` (``"sRGB"`` or ``"linear-sRGB"``).
    options : MaskOptions
        The mask's thresholds (:func:`~microfacet.analysis.mask.colour_mask`): saturation and
        value (0-255 HSV scale, seed: saturation 15), shadows, and pixels far darker than the
        film (facets tilted past the acceptance,
        :func:`~microfacet.analysis.mask.steep_facet_mask`).
    color_space : {"sRGB", "linear-sRGB"}
    bit_depth : {8, 16}
        Of the source images (sets the quantization floor of the noise).
    illuminant : str
    delta_e_method : str
        The colour difference of the noise estimate.
    jpeg : JpegTables, optional
        The slices' JPEG quantization (:attr:`microfacet.io.stack.Stack.jpeg`): the block
        error of the noise model (:func:`compression_noise_de`).
    """
    aif = np.asarray(all_in_focus)
    if aif.ndim == 2:
        aif = np.repeat(aif[..., None], 3, axis=-1)
    enc = (srgb_encode(aif, dtype=np.float32) if color_space == "linear-sRGB"
           else aif.astype(np.float32, copy=False).view())
    enc.flags.writeable = False      # may be the composite itself (12 bytes a pixel not copied)
    cm = colour_mask(enc, options, bit_depth=bit_depth)
    lab = srgb_to_lab(enc, illuminant=illuminant).astype(np.float32)
    # the noise of unclipped film: a clipped channel has none
    quiet = cm.mask | cm.clipped_one if cm.clip_analysed else cm.mask
    noise = estimate_colour_noise(lab, quiet, delta_e_method=delta_e_method)
    floor = quantization_noise_de(enc, quiet, bit_depth=bit_depth, illuminant=illuminant,
                                  delta_e_method=delta_e_method)
    if np.isfinite(floor) and not noise >= floor:
        log.info("colour noise %.4g below the quantization floor; using %.4g ΔE00", noise, floor)
        noise = floor
    block = (0.0 if jpeg is None else
             compression_noise_de(enc, quiet, jpeg, illuminant=illuminant,
                                  delta_e_method=delta_e_method))
    return ColourImage(enc, lab, cm, noise, bit_depth, block if np.isfinite(block) else 0.0,
                       64 if jpeg is None else jpeg.chroma_block_px,
                       (1.0, 1.0, 1.0) if cm.clip_analysed else None)


def no_colour_message(stack, mask: ColourMask, what: str, options: MaskOptions) -> str:
    """One-line InputError text for a stack without usable colour, with the mask reasons."""
    key = "tiff" if stack.tiff_path is not None else "slices" if stack.has_slices else "image"
    f = mask.fractions()
    reasons = ", ".join(f"{name.replace('_', ' ')} {100 * f[name]:.0f}%"
                        for name in MASK_REASONS)
    return (f"{stack.path / 'stack.json'}: key {key!r}: no colour information to analyse, "
            f"{what} ({reasons}; `mask.saturation_min` {options.saturation_min:g}, "
            f"`mask.value_min` {options.value_min:g} on the 0-255 scale)")


def estimate_colour_noise(lab, mask, *, delta_e_method):
    """Per-component colour noise σ_n in ΔE00 units from neighbouring pixels.

    The ΔE00 between horizontally adjacent unmasked pixels is, for noise alone, the norm of
    a 3-D Gaussian of per-component SD σ√2, whose median is 2.18 σ. Texture inflates the
    estimate, so it is an upper bound (conservative uncertainties).
    """
    lab = np.asarray(lab, dtype=np.float32)
    m = ~np.asarray(mask, bool)
    ok = m[:, 1:] & m[:, :-1]
    if ok.sum() < 10:
        return float("nan")
    de = delta_e(lab[:, 1:][ok], lab[:, :-1][ok], method=delta_e_method)
    return float(np.median(de) / 2.18)


def compression_noise_de(encoded_srgb, mask, jpeg, *, illuminant, delta_e_method,
                         n_sample=4096, seed=0):
    """Colour error per Lab component (ΔE00 units, as :func:`estimate_colour_noise`) that a
    JPEG's quantization of each 8 × 8 block's mean leaves.

    The DC coefficient is 8 × the block's mean (the orthonormal DCT), rounded to a step
    ``Q`` (``jpeg.dc_steps``, luma and chroma): the block mean is off by up to ±Q/16 code
    values, uniformly, SD Q / (8√12), the same for all its pixels. Luma and chroma errors are
    taken to the RGB values (ITU-R BT.601 full range, as JPEG/JFIF) of up to ``n_sample``
    unmasked pixels and measured in ΔE00. At quality 90 (Q = 3) this is about 0.1 code
    value; at 70 (Q = 10) 0.36: beside a sensor noise of a few code values it is nothing
    per pixel, but it does not average out over a facet's pixels within one block.

    Parameters
    ----------
    encoded_srgb, mask
        As :func:`quantization_noise_de`.
    jpeg : JpegTables
    """
    steps = np.asarray(jpeg.dc_steps, dtype=np.float64) / (8.0 * 255.0)   # full ranges

    def block_error(img, rng):
        y, cb, cr = (rng.uniform(-0.5, 0.5, img.shape[0]) * q for q in steps[[0, 1, 1]])
        return np.stack([y + 1.402 * cr, y - 0.344136 * cb - 0.714136 * cr,
                         y + 1.772 * cb], -1).astype(np.float32)

    return _moved_de(encoded_srgb, mask, block_error, illuminant=illuminant,
                     delta_e_method=delta_e_method, n_sample=n_sample, seed=seed)


def _moved_de(encoded_srgb, mask, error, *, illuminant, delta_e_method, n_sample, seed):
    """ΔE00 per Lab component (median / 1.54: the norm of a 3-D error of per-component SD σ
    has median ~1.54 σ) between up to ``n_sample`` unmasked pixels and themselves moved by
    ``error(pixels, rng)``; NaN without unmasked pixels."""
    img = np.asarray(encoded_srgb, dtype=np.float32)[~np.asarray(mask, bool)]
    if img.shape[0] == 0:
        return float("nan")
    rng = np.random.default_rng(seed)
    if img.shape[0] > n_sample:
        img = img[rng.choice(img.shape[0], n_sample, replace=False)]
    moved = np.clip(img + error(img, rng), 0, 1)
    de = delta_e(srgb_to_lab(img, illuminant=illuminant),
                 srgb_to_lab(moved, illuminant=illuminant), method=delta_e_method)
    return float(np.median(de) / 1.54)


def quantization_noise_de(encoded_srgb, mask, *, bit_depth, illuminant, delta_e_method,
                          n_sample=4096, seed=0):
    """Colour noise (ΔE00 per component, as :func:`estimate_colour_noise`) that the image's
    quantization alone implies: the floor of the colour noise.

    An image without visible noise (a synthetic composite, a denoised export) has a
    neighbour-difference noise of 0, which would make colour look infinitely precise; its
    code values are still rounded to ±½ LSB. Measured on up to ``n_sample`` unmasked pixels
    by re-rounding them by uniform ±½ LSB: about 0.08 ΔE00 for 8-bit images, 0.0003 for
    16-bit.

    Parameters
    ----------
    encoded_srgb : ndarray, shape (H, W, 3)
        The encoded image in [0, 1].
    mask : ndarray of bool, shape (H, W)
        True where a pixel is not used.
    bit_depth : {8, 16}
    """
    lsb = np.float32(1.0 / (2 ** bit_depth - 1))
    return _moved_de(encoded_srgb, mask,
                     lambda img, rng: rng.uniform(-0.5, 0.5, img.shape).astype(np.float32) * lsb,
                     illuminant=illuminant, delta_e_method=delta_e_method, n_sample=n_sample,
                     seed=seed)


