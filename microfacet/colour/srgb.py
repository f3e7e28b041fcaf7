"""sRGB images and XYZ: encoding, RGB ↔ XYZ, chromatic adaptation, image ↔ CIELAB.

Images are white-balanced to the illuminant: RGB ``(1, 1, 1)`` is the illuminant's white.
The sRGB matrix of IEC 61966-2-1 (4 decimals) has the white
``W_sRGB = M @ (1, 1, 1) = (0.9505, 1.0000, 1.0890)``. For D65 with the 2 degree observer
(what sRGB is defined for) no adaptation is applied and Lab is taken relative to
``W_sRGB``; for any other illuminant or observer, XYZ is Bradford-adapted from ``W_sRGB``
to :func:`~microfacet.colour.colorimetry.white_xyz` of that illuminant and observer, and
Lab is taken relative to that white. Either way RGB white maps to exactly
``L* = 100, a* = b* = 0``; :func:`image_white_xyz` returns the white used (the model side
is described in :mod:`microfacet.colour.colorimetry`).

Image conversions return ``float32``; NaN (masked pixels) propagates, except into integer
sRGB output, where it becomes 0.

Examples
--------
>>> import numpy as np
>>> srgb_to_lab(np.array([255, 255, 255], dtype=np.uint8)).round(4).tolist()
[100.0, 0.0, 0.0]
"""

from __future__ import annotations

import functools
from typing import Any

import numpy as np

from .arrays import channels, float_array
from .colorimetry import (illuminant_key, lab_to_xyz, observer_name, spectral_weights,
                          white_xyz, xyz_to_lab)

__all__ = [
    "BRADFORD",
    "SRGB_TO_XYZ",
    "SRGB_WHITE_XYZ",
    "XYZ_TO_SRGB",
    "bradford_matrix",
    "image_white_xyz",
    "lab_to_srgb",
    "linear_srgb_to_xyz",
    "model_xyz_to_linear_srgb",
    "srgb_decode",
    "srgb_encode",
    "srgb_to_lab",
    "xyz_to_linear_srgb",
]

#: sRGB (IEC 61966-2-1:1999) linear RGB -> XYZ (D65, Y = 1 for RGB white).
SRGB_TO_XYZ = np.array(
    [
        [0.4124, 0.3576, 0.1805],
        [0.2126, 0.7152, 0.0722],
        [0.0193, 0.1192, 0.9505],
    ]
)
SRGB_TO_XYZ.flags.writeable = False
#: Exact inverse of :data:`SRGB_TO_XYZ` (so that round trips are exact to rounding).
XYZ_TO_SRGB = np.linalg.inv(SRGB_TO_XYZ)
XYZ_TO_SRGB.flags.writeable = False
#: White of the sRGB matrix path, ``SRGB_TO_XYZ @ (1, 1, 1)`` = (0.9505, 1.0, 1.089).
SRGB_WHITE_XYZ = SRGB_TO_XYZ.sum(axis=1)
SRGB_WHITE_XYZ.flags.writeable = False

#: Bradford cone-response matrix (Lam 1985).
BRADFORD = np.array(
    [
        [0.8951, 0.2664, -0.1614],
        [-0.7502, 1.7135, 0.0367],
        [0.0389, -0.0685, 1.0296],
    ]
)
BRADFORD.flags.writeable = False


# --------------------------------------------------------------------------------------
# Chromatic adaptation and sRGB
# --------------------------------------------------------------------------------------


def bradford_matrix(source_white: Any, target_white: Any) -> np.ndarray:
    """Bradford (linear, von Kries in sharpened cone space) adaptation matrix.

    Parameters
    ----------
    source_white, target_white : array_like, shape (3,)
        XYZ of the source and target whites.

    Returns
    -------
    numpy.ndarray, shape (3, 3), float64
        ``A`` with ``xyz_target = xyz_source @ A.T`` and ``A @ source_white ==
        target_white``.

    Examples
    --------
    >>> A = bradford_matrix(SRGB_WHITE_XYZ, white_xyz(illuminant="A"))
    >>> np.allclose(A @ SRGB_WHITE_XYZ, white_xyz(illuminant="A"))
    True
    """
    src = np.asarray(source_white, dtype=np.float64)
    dst = np.asarray(target_white, dtype=np.float64)
    if src.shape != (3,):
        raise ValueError(f"source_white must have shape (3,), got {src.shape}")
    if dst.shape != (3,):
        raise ValueError(f"target_white must have shape (3,), got {dst.shape}")
    gain = (BRADFORD @ dst) / (BRADFORD @ src)
    return np.linalg.solve(BRADFORD, gain[:, None] * BRADFORD)


def _is_srgb_native(illuminant: str, observer: str) -> bool:
    return illuminant_key(illuminant) == "D65" and observer_name(observer) == observer_name("2")


def image_white_xyz(*, illuminant: str = "D65", observer: str = "2") -> np.ndarray:
    """Reference white of the image (sRGB) path, i.e. the XYZ of RGB ``(1, 1, 1)``.

    :data:`SRGB_WHITE_XYZ` (0.9505, 1, 1.089) for D65 and the 2 degree observer,
    otherwise :func:`white_xyz` of the illuminant and observer.

    Returns
    -------
    numpy.ndarray, shape (3,), float64

    Examples
    --------
    >>> image_white_xyz().tolist()
    [0.9505, 1.0, 1.089]
    """
    if _is_srgb_native(illuminant, observer):
        return SRGB_WHITE_XYZ.copy()
    return white_xyz(illuminant=illuminant, observer=observer)


@functools.cache
def _rgb_to_xyz_matrix(illuminant: str, observer: str) -> np.ndarray:
    if _is_srgb_native(illuminant, observer):
        m = np.array(SRGB_TO_XYZ)
    else:
        adapt = bradford_matrix(
            SRGB_WHITE_XYZ, white_xyz(illuminant=illuminant, observer=observer)
        )
        m = adapt @ SRGB_TO_XYZ
    m.flags.writeable = False
    return m


@functools.cache
def _xyz_to_rgb_matrix(illuminant: str, observer: str) -> np.ndarray:
    m = np.linalg.inv(_rgb_to_xyz_matrix(illuminant, observer))
    m.flags.writeable = False
    return m


def _srgb_eotf(c: np.ndarray) -> np.ndarray:
    """Encoded -> linear, in the dtype of ``c`` (float)."""
    hi = np.maximum(c, 0.04045)  # NaN propagates through maximum
    hi += 0.055
    hi /= 1.055
    np.power(hi, 2.4, out=hi)
    return np.where(c <= 0.04045, c / 12.92, hi).astype(c.dtype, copy=False)


@functools.cache
def _decode_lut(bits: int) -> np.ndarray:
    n = (1 << bits) - 1
    lut = _srgb_eotf(np.arange(n + 1, dtype=np.float64) / n).astype(np.float32)
    lut.flags.writeable = False
    return lut


def srgb_decode(image: Any) -> np.ndarray:
    """Decode sRGB (IEC 61966-2-1) to linear RGB.

    Parameters
    ----------
    image : array_like, shape (...)
        Encoded sRGB: uint8 (0-255), uint16 (0-65535) or float (0-1; values
        outside are decoded with the same piecewise function, not clipped).

    Returns
    -------
    numpy.ndarray, same shape, float32
        Linear RGB (1 = illuminant white). NaN propagates.

    Raises
    ------
    ValueError
        For other dtypes (e.g. int32, bool).

    Examples
    --------
    >>> srgb_decode(np.array([0, 255], dtype=np.uint8)).tolist()
    [0.0, 1.0]
    """
    a = np.asarray(image)
    if a.dtype == np.uint8:
        return _decode_lut(8)[a]
    if a.dtype == np.uint16:
        return _decode_lut(16)[a]
    if a.dtype.kind == "f":
        return _srgb_eotf(a.astype(np.float64 if a.dtype == np.float64 else np.float32)).astype(
            np.float32, copy=False
        )
    raise ValueError(f"image must be uint8, uint16 or float sRGB, got dtype {a.dtype}")


def srgb_encode(linear: Any, *, dtype: Any = np.uint8) -> np.ndarray:
    """Encode linear RGB to sRGB (IEC 61966-2-1), clipping to [0, 1].

    Parameters
    ----------
    linear : array_like, shape (...)
        Linear RGB, 1 = white.
    dtype : {numpy.uint8, numpy.uint16, numpy.float32}, keyword-only
        Output type. Integer outputs are rounded to nearest (0-255 / 0-65535);
        NaN becomes 0 there (an integer cannot hold NaN). float32 keeps NaN.

    Returns
    -------
    numpy.ndarray, same shape, ``dtype``

    Examples
    --------
    >>> srgb_encode(np.array([0.0, 0.2159, 1.0, 2.0])).tolist()
    [0, 128, 255, 255]
    """
    dt = np.dtype(dtype)
    if dt not in (np.dtype(np.uint8), np.dtype(np.uint16), np.dtype(np.float32)):
        raise ValueError(f"dtype must be numpy.uint8, numpy.uint16 or numpy.float32, got {dt}")
    x = float_array(linear, "linear")
    x = np.clip(x, 0.0, 1.0)
    lo = x * 12.92
    hi = np.power(np.maximum(x, 0.0031308), 1.0 / 2.4, out=None)
    hi *= 1.055
    hi -= 0.055
    enc = np.where(x <= 0.0031308, lo, hi)
    if dt == np.float32:
        return enc.astype(np.float32, copy=False)
    scale = 255.0 if dt == np.uint8 else 65535.0
    enc *= scale
    np.rint(enc, out=enc)
    enc[np.isnan(enc)] = 0.0
    return enc.astype(dt)


def linear_srgb_to_xyz(rgb: Any, *, illuminant: str = "D65", observer: str = "2") -> np.ndarray:
    """Linear sRGB -> XYZ, white-balanced images (RGB 1 = illuminant white).

    Parameters
    ----------
    rgb : array_like, shape (..., 3)
        Linear sRGB.
    illuminant, observer : str, optional
        The stack's illuminant. For D65 / 2 degree this is the IEC matrix (white
        :data:`SRGB_WHITE_XYZ`); otherwise the result is Bradford-adapted from
        :data:`SRGB_WHITE_XYZ` to :func:`white_xyz` (see :func:`image_white_xyz`).

    Returns
    -------
    numpy.ndarray, shape (..., 3), float32
        XYZ with ``Y = 1`` for RGB white.

    Examples
    --------
    >>> linear_srgb_to_xyz(np.ones(3)).astype(float).round(4).tolist()
    [0.9505, 1.0, 1.089]
    """
    a = channels(rgb, "rgb")
    m = _rgb_to_xyz_matrix(illuminant_key(illuminant), observer_name(observer))
    return (a @ m.T.astype(a.dtype, copy=False)).astype(np.float32, copy=False)


def xyz_to_linear_srgb(xyz: Any, *, illuminant: str = "D65", observer: str = "2") -> np.ndarray:
    """XYZ -> linear sRGB, the inverse of :func:`linear_srgb_to_xyz` (unclipped).

    Parameters
    ----------
    xyz : array_like, shape (..., 3)
        XYZ relative to :func:`image_white_xyz` of ``illuminant``/``observer``.
    illuminant, observer : str, optional

    Returns
    -------
    numpy.ndarray, shape (..., 3), float32

    Examples
    --------
    >>> xyz_to_linear_srgb(image_white_xyz()).round(6).tolist()
    [1.0, 1.0, 1.0]
    """
    a = channels(xyz, "xyz")
    m = _xyz_to_rgb_matrix(illuminant_key(illuminant), observer_name(observer))
    return (a @ m.T.astype(a.dtype, copy=False)).astype(np.float32, copy=False)


def model_xyz_to_linear_srgb(xyz: Any, *, white: Any, illuminant: str = "D65",
                             observer: str = "2") -> np.ndarray:
    """Linear sRGB of model XYZ whose perfect reflector is ``white``, which maps to RGB 1.

    Spectra integrated on a wavelength grid have their own white (the perfect reflector on
    that grid), which differs from :func:`image_white_xyz` in the 4th digit; a Bradford
    adaptation from ``white`` to the image white makes the model's perfect reflector
    exactly RGB ``(1, 1, 1)``, as in a white-balanced camera image.

    Parameters
    ----------
    xyz : array_like, shape (..., 3)
        Model XYZ (any scale; ``white`` has the same scale).
    white : array_like, shape (3,)
        XYZ of the perfect reflector on the model's grid.

    Returns
    -------
    numpy.ndarray, shape (..., 3), float32
        Linear sRGB, not clipped.

    Examples
    --------
    >>> w = spectral_weights(np.arange(380.0, 781.0, 10.0)).sum(axis=0)
    >>> np.allclose(model_xyz_to_linear_srgb(w, white=w), 1.0, atol=1e-6)
    True
    """
    xyz = channels(xyz, "xyz")
    w = np.asarray(white, dtype=np.float64)
    if w.shape != (3,) or not np.all(np.isfinite(w)) or w[1] <= 0:
        raise ValueError("white: must be a finite XYZ triple with Y > 0")
    target = image_white_xyz(illuminant=illuminant, observer=observer)
    A = bradford_matrix(w / w[1], target)
    adapted = (np.asarray(xyz, dtype=np.float64) / w[1]) @ A.T
    return xyz_to_linear_srgb(adapted, illuminant=illuminant, observer=observer).astype(
        np.float32)


def srgb_to_lab(image: Any, *, illuminant: str = "D65", observer: str = "2") -> np.ndarray:
    """Encoded sRGB image -> CIELAB relative to the illuminant white.

    decode (:func:`srgb_decode`) -> XYZ (:func:`linear_srgb_to_xyz`, Bradford from
    D65 when the illuminant is not D65) -> Lab relative to :func:`image_white_xyz`.
    RGB white is exactly ``L* = 100, a* = b* = 0`` for every illuminant.

    Parameters
    ----------
    image : array_like, shape (..., 3)
        uint8, uint16 or float (0-1) encoded sRGB, white-balanced to the illuminant.
    illuminant, observer : str, optional

    Returns
    -------
    numpy.ndarray, shape (..., 3), float32

    Examples
    --------
    >>> srgb_to_lab(np.array([[255, 0, 0]], dtype=np.uint8)).astype(float).round(1).tolist()
    [[53.2, 80.1, 67.2]]
    """
    a = np.asarray(image)
    if a.ndim == 0 or a.shape[-1] != 3:
        raise ValueError(f"image must have shape (..., 3), got {a.shape}")
    xyz = linear_srgb_to_xyz(srgb_decode(a), illuminant=illuminant, observer=observer)
    white = image_white_xyz(illuminant=illuminant, observer=observer)
    return xyz_to_lab(xyz, white=white)


def lab_to_srgb(
    lab: Any, *, illuminant: str = "D65", observer: str = "2", dtype: Any = np.uint8
) -> np.ndarray:
    """CIELAB -> encoded sRGB (inverse of :func:`srgb_to_lab`; out-of-gamut clipped).

    Parameters
    ----------
    lab : array_like, shape (..., 3)
    illuminant, observer : str, optional
    dtype : {numpy.uint8, numpy.uint16, numpy.float32}, optional

    Returns
    -------
    numpy.ndarray, shape (..., 3), ``dtype``

    Examples
    --------
    >>> lab_to_srgb(np.array([100.0, 0.0, 0.0])).tolist()
    [255, 255, 255]
    """
    white = image_white_xyz(illuminant=illuminant, observer=observer)
    xyz = lab_to_xyz(lab, white=white)
    rgb = xyz_to_linear_srgb(xyz, illuminant=illuminant, observer=observer)
    return srgb_encode(rgb, dtype=dtype)


