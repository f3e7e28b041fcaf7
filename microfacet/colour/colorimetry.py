"""Colorimetry: reflectance spectra to CIE XYZ and CIELAB, and XYZ ↔ Lab.

Conventions
-----------
* Channels are last: colour arrays have shape ``(..., 3)`` and reflectance spectra
  ``(..., N)`` with any leading shape; options are keyword-only.
* CIE XYZ is normalised so that the perfect reflecting diffuser (reflectance 1 at
  every wavelength) under the chosen illuminant has ``Y = 1`` (colour-science uses
  ``Y = 100``; divide its ``sd_to_XYZ`` by 100). CIELAB is on the usual 0-100 scale.
* Functions compute in ``float64`` unless the input is ``float32``, in which case the
  output is ``float32``. NaN (masked pixels) propagates to NaN.
* ``colour`` (colour-science) provides the datasets (CMFs and illuminant spectra); it is
  imported on first use and the tables are cached.

Which white is used where
-------------------------
:func:`spectral_weights` is normalised so that ``R = 1`` gives ``Y = 1`` *on the given
wavelength grid*; :func:`spectrum_to_lab` uses the white of that grid,
``spectral_weights(...).sum(axis=0)``, so a perfect reflector is exactly
``L* = 100, a* = b* = 0`` whatever the grid. :func:`white_xyz` is the same quantity on the
1 nm 360-830 nm grid (the CIE definition); it is the default white of :func:`xyz_to_lab` /
:func:`lab_to_xyz`. The image (sRGB) side and its white: :mod:`microfacet.colour.srgb`.

Examples
--------
>>> import numpy as np
>>> wl = np.arange(360.0, 831.0)
>>> bool(np.abs(spectrum_to_lab(np.ones(wl.size), wl) - [100.0, 0.0, 0.0]).max() < 1e-9)
True
"""

from __future__ import annotations

import functools
import math
from typing import Any

import numpy as np

from ..core.lazy import load
from .arrays import channels, float_array

colour = load("colour")

__all__ = [
    "OBSERVERS",
    "cmfs",
    "illuminant_key",
    "illuminant_sd",
    "known_illuminants",
    "lab_to_xyz",
    "observer_name",
    "spectral_weights",
    "spectrum_to_lab",
    "spectrum_to_xyz",
    "white_xyz",
    "xyz_to_lab",
]

# --------------------------------------------------------------------------------------
# Constants
# --------------------------------------------------------------------------------------

_CIE1931 = "CIE 1931 2 Degree Standard Observer"
_CIE1964 = "CIE 1964 10 Degree Standard Observer"

#: Accepted observer names -> colour-science dataset name.
OBSERVERS: dict[str, str] = {
    "2": _CIE1931,
    _CIE1931: _CIE1931,
    "10": _CIE1964,
    _CIE1964: _CIE1964,
}

#: CIE range of the standard observers tabulated at 1 nm (nm).
_CMF_RANGE = (360.0, 830.0)

#: CIELAB constants (CIE 15:2018, exact rationals).
_EPSILON = 216.0 / 24389.0
_KAPPA = 24389.0 / 27.0

# --------------------------------------------------------------------------------------
# Validation helpers
# --------------------------------------------------------------------------------------


def observer_name(observer: Any) -> str:
    key = str(observer)
    try:
        return OBSERVERS[key]
    except KeyError:
        raise ValueError(
            f"observer must be one of {sorted(set(OBSERVERS))!r}, got {observer!r}"
        ) from None


def _wavelengths(wavelength_nm: Any, *, strict: bool = False) -> np.ndarray:
    w = np.asarray(wavelength_nm, dtype=np.float64)
    if w.ndim != 1 or w.size == 0:
        raise ValueError(f"wavelength_nm must be a non-empty 1-D array, got shape {w.shape}")
    if not np.all(np.isfinite(w)):
        raise ValueError("wavelength_nm must be finite")
    if strict and (w.size < 2 or np.any(np.diff(w) <= 0)):
        raise ValueError("wavelength_nm must be strictly increasing with at least 2 samples")
    return w


def _check_range(w: np.ndarray, lo: float, hi: float, what: str) -> None:
    if w.min() < lo or w.max() > hi:
        raise ValueError(
            f"wavelength_nm must lie within [{lo:g}, {hi:g}] nm for {what}, "
            f"got [{w.min():g}, {w.max():g}]"
        )


# --------------------------------------------------------------------------------------
# Datasets (lazy colour-science import, cached)
# --------------------------------------------------------------------------------------


@functools.cache
def _cmf_table(observer_name: str) -> tuple[np.ndarray, np.ndarray]:
    msds = colour.MSDS_CMFS[observer_name]
    wl = np.array(msds.wavelengths, dtype=np.float64)
    values = np.array(msds.values, dtype=np.float64)
    wl.flags.writeable = False
    values.flags.writeable = False
    return wl, values


@functools.cache
def _illuminant_names() -> tuple[str, ...]:
    return tuple(colour.SDS_ILLUMINANTS.keys())


def known_illuminants() -> tuple[str, ...]:
    """Names accepted by ``illuminant=`` (those of ``colour.SDS_ILLUMINANTS``).

    Returns
    -------
    tuple of str

    Examples
    --------
    >>> "D65" in known_illuminants() and "A" in known_illuminants()
    True
    """
    return _illuminant_names()


def illuminant_key(illuminant: Any) -> str:
    names = _illuminant_names()
    if isinstance(illuminant, str):
        if illuminant in names:
            return illuminant
        folded = {n.casefold(): n for n in names}
        if illuminant.casefold() in folded:
            return folded[illuminant.casefold()]
    examples = ", ".join(n for n in ("D65", "D50", "A", "E", "FL2", "F11") if n in names)
    raise ValueError(
        f"illuminant {illuminant!r} is unknown; use a name of colour.SDS_ILLUMINANTS, "
        f"e.g. {examples} ({len(names)} known, see known_illuminants())"
    )


@functools.cache
def _illuminant_table(name: str) -> tuple[np.ndarray, np.ndarray]:
    """SPD aligned to 1 nm over the union of its range and 360-830 nm.

    Uses colour-science's own ``SpectralDistribution.align`` (CIE 167 interpolation,
    Sprague for uniform data, constant extrapolation) -- exactly what
    ``colour.sd_to_XYZ`` does when it aligns an illuminant to the 1 nm CMFs.
    """
    sd = colour.SDS_ILLUMINANTS[name]
    lo = math.floor(min(sd.shape.start, _CMF_RANGE[0]))
    hi = math.ceil(max(sd.shape.end, _CMF_RANGE[1]))
    aligned = sd.copy().align(colour.SpectralShape(lo, hi, 1))
    wl = np.array(aligned.wavelengths, dtype=np.float64)
    values = np.array(aligned.values, dtype=np.float64)
    wl.flags.writeable = False
    values.flags.writeable = False
    return wl, values


# --------------------------------------------------------------------------------------
# Spectra -> XYZ
# --------------------------------------------------------------------------------------


def cmfs(wavelength_nm: Any, *, observer: str = "2") -> np.ndarray:
    """CIE colour matching functions at the given wavelengths.

    Parameters
    ----------
    wavelength_nm : array_like, shape (N,)
        Wavelengths in nm, within 360-830 nm.
    observer : {"2", "10"} or full CIE name, optional
        CIE 1931 2 degree (default) or CIE 1964 10 degree standard observer.

    Returns
    -------
    numpy.ndarray, shape (N, 3), float64
        x-bar, y-bar, z-bar, linearly interpolated from the 1 nm CIE tables shipped
        with colour-science.

    Raises
    ------
    ValueError
        If ``wavelength_nm`` is not 1-D or leaves 360-830 nm, or ``observer`` is unknown.

    Examples
    --------
    >>> float(cmfs([555.0])[0, 1].round(4))
    1.0
    """
    name = observer_name(observer)
    w = _wavelengths(wavelength_nm)
    _check_range(w, *_CMF_RANGE, f"the {name}")
    wl, values = _cmf_table(name)
    out = np.empty((w.size, 3))
    for j in range(3):
        out[:, j] = np.interp(w, wl, values[:, j])
    return out


def illuminant_sd(wavelength_nm: Any, *, illuminant: str = "D65") -> np.ndarray:
    """Relative spectral power of a named CIE / colour-science illuminant.

    The tabulated SPD (5 nm for the CIE illuminants) is first aligned to 1 nm exactly
    as colour-science aligns it inside ``sd_to_XYZ`` (Sprague interpolation, constant
    extrapolation out to 360-830 nm), then linearly interpolated to ``wavelength_nm``.

    Parameters
    ----------
    wavelength_nm : array_like, shape (N,)
        Wavelengths in nm, within the tabulated range extended to 360-830 nm.
    illuminant : str, optional
        A key of ``colour.SDS_ILLUMINANTS`` (case-insensitive), default ``"D65"``.

    Returns
    -------
    numpy.ndarray, shape (N,), float64
        Relative spectral power (the dataset's own scale, e.g. D65 = 100 at 560 nm).

    Raises
    ------
    ValueError
        Unknown ``illuminant`` (the message lists a few known ones) or
        ``wavelength_nm`` out of range.

    Examples
    --------
    >>> float(illuminant_sd([560.0])[0])
    100.0
    """
    key = illuminant_key(illuminant)
    w = _wavelengths(wavelength_nm)
    wl, values = _illuminant_table(key)
    _check_range(w, wl[0], wl[-1], f"illuminant {key}")
    return np.interp(w, wl, values)


def _delta_lambda(w: np.ndarray) -> np.ndarray:
    """Trapezoid weights: half the distance between each sample's neighbours."""
    d = np.empty_like(w)
    d[1:-1] = 0.5 * (w[2:] - w[:-2])
    d[0] = 0.5 * (w[1] - w[0])
    d[-1] = 0.5 * (w[-1] - w[-2])
    return d


@functools.cache
def _weights_cached(wl: tuple[float, ...], illuminant: str, observer: str) -> np.ndarray:
    w = np.array(wl)
    cmf = cmfs(w, observer=observer)
    spd = illuminant_sd(w, illuminant=illuminant)
    weights = cmf * (spd * _delta_lambda(w))[:, None]
    y_white = weights[:, 1].sum()
    if not y_white > 0:
        raise ValueError(
            f"illuminant {illuminant!r} has no power on wavelength_nm "
            f"[{w[0]:g}, {w[-1]:g}] nm (white Y = 0)"
        )
    weights /= y_white
    weights.flags.writeable = False
    return weights


def spectral_weights(
    wavelength_nm: Any, *, illuminant: str = "D65", observer: str = "2"
) -> np.ndarray:
    """Weights ``W`` such that ``XYZ = R @ W`` for reflectance spectra ``R``.

    ``W[i] = cmf(λ_i) S(λ_i) Δλ_i / Σ_k ȳ(λ_k) S(λ_k) Δλ_k`` with trapezoid
    ``Δλ_i`` (half the distance between neighbouring samples), so uniform and
    non-uniform grids are both handled and a perfect reflector (``R ≡ 1``) gives
    exactly ``Y = 1``. ``W.sum(axis=0)`` is the white of this grid.

    Parameters
    ----------
    wavelength_nm : array_like, shape (N,)
        Strictly increasing wavelengths in nm within 360-830 nm.
    illuminant : str, optional
        Illuminant name (see :func:`illuminant_sd`), default ``"D65"``.
    observer : {"2", "10"}, optional
        Standard observer, default ``"2"``.

    Returns
    -------
    numpy.ndarray, shape (N, 3), float64
        Read-only (cached by wavelengths, illuminant and observer).

    Examples
    --------
    >>> W = spectral_weights(np.arange(380.0, 781.0, 5.0))
    >>> round(float(W[:, 1].sum()), 12)
    1.0
    """
    w = _wavelengths(wavelength_nm, strict=True)
    _check_range(w, *_CMF_RANGE, "the CIE colour matching functions")
    return _weights_cached(
        tuple(w.tolist()), illuminant_key(illuminant), observer_name(observer)
    )


def spectrum_to_xyz(
    reflectance: Any,
    wavelength_nm: Any,
    *,
    illuminant: str = "D65",
    observer: str = "2",
) -> np.ndarray:
    """CIE XYZ of reflectance spectra (perfect reflector ``Y = 1``).

    Parameters
    ----------
    reflectance : array_like, shape (..., N)
        Reflectance factors (0-1) sampled at ``wavelength_nm``. NaN propagates.
    wavelength_nm : array_like, shape (N,)
        Strictly increasing wavelengths in nm within 360-830 nm.
    illuminant, observer : str, optional
        See :func:`spectral_weights`.

    Returns
    -------
    numpy.ndarray, shape (..., 3)
        float32 if ``reflectance`` is float32, else float64.

    Raises
    ------
    ValueError
        If the last axis of ``reflectance`` does not match ``wavelength_nm``.

    Examples
    --------
    >>> wl = np.arange(360.0, 831.0)
    >>> spectrum_to_xyz(np.ones(wl.size), wl).round(4).tolist()
    [0.9505, 1.0, 1.0888]
    """
    weights = spectral_weights(wavelength_nm, illuminant=illuminant, observer=observer)
    r = float_array(reflectance, "reflectance")
    if r.ndim == 0 or r.shape[-1] != weights.shape[0]:
        raise ValueError(
            f"reflectance must have shape (..., {weights.shape[0]}) to match "
            f"wavelength_nm, got {r.shape}"
        )
    return r @ weights.astype(r.dtype, copy=False)


def white_xyz(*, illuminant: str = "D65", observer: str = "2") -> np.ndarray:
    """XYZ of the perfect reflecting diffuser (``Y = 1``), CIE 1 nm, 360-830 nm.

    This is the default reference white of :func:`xyz_to_lab` / :func:`lab_to_xyz`.
    For a white consistent with another wavelength grid use
    ``spectral_weights(wl, ...).sum(axis=0)`` (what :func:`spectrum_to_lab` uses).

    Parameters
    ----------
    illuminant, observer : str, optional
        See :func:`spectral_weights`.

    Returns
    -------
    numpy.ndarray, shape (3,), float64

    Examples
    --------
    >>> white_xyz().round(5).tolist()
    [0.95047, 1.0, 1.08883]
    """
    grid = np.arange(_CMF_RANGE[0], _CMF_RANGE[1] + 1.0)
    return spectral_weights(grid, illuminant=illuminant, observer=observer).sum(axis=0)


# --------------------------------------------------------------------------------------
# XYZ <-> Lab
# --------------------------------------------------------------------------------------


def _white_arg(white: Any, illuminant: str, observer: str, dtype: np.dtype) -> np.ndarray:
    if white is None:
        wt = white_xyz(illuminant=illuminant, observer=observer)
    else:
        wt = channels(white, "white")
        if np.any(~(wt > 0)):
            raise ValueError("white must be positive XYZ, shape (..., 3)")
    return wt.astype(dtype, copy=False)


def xyz_to_lab(
    xyz: Any,
    *,
    white: Any = None,
    illuminant: str = "D65",
    observer: str = "2",
) -> np.ndarray:
    """CIE 1976 L*a*b* from XYZ (exact CIE piecewise function).

    Parameters
    ----------
    xyz : array_like, shape (..., 3)
        Tristimulus values with the reference white at ``Y = 1``.
    white : array_like, shape (3,), optional
        Reference white XYZ. Default: :func:`white_xyz` of ``illuminant`` and
        ``observer`` (CMF-integrated, 1 nm).
    illuminant, observer : str, optional
        Used only when ``white`` is None.

    Returns
    -------
    numpy.ndarray, shape (..., 3)
        L* (0-100), a*, b*. float32 if ``xyz`` is float32, else float64.

    Examples
    --------
    >>> xyz_to_lab(white_xyz()).round(6).tolist()
    [100.0, 0.0, 0.0]
    """
    x = channels(xyz, "xyz")
    wt = _white_arg(white, illuminant, observer, x.dtype)
    t = x / wt
    f = np.cbrt(t)
    lin = t <= _EPSILON  # NaN compares False and stays NaN in the cbrt branch
    if lin.any():
        f[lin] = (_KAPPA * t[lin] + 16.0) / 116.0
    out = np.empty_like(f)
    fx, fy, fz = f[..., 0], f[..., 1], f[..., 2]
    out[..., 0] = 116.0 * fy - 16.0
    out[..., 1] = 500.0 * (fx - fy)
    out[..., 2] = 200.0 * (fy - fz)
    return out


def lab_to_xyz(
    lab: Any,
    *,
    white: Any = None,
    illuminant: str = "D65",
    observer: str = "2",
) -> np.ndarray:
    """XYZ from CIE 1976 L*a*b* (inverse of :func:`xyz_to_lab`).

    Parameters
    ----------
    lab : array_like, shape (..., 3)
        L* (0-100), a*, b*.
    white, illuminant, observer
        As in :func:`xyz_to_lab`.

    Returns
    -------
    numpy.ndarray, shape (..., 3)
        XYZ with the white at ``Y = 1``; float32 if ``lab`` is float32, else float64.

    Examples
    --------
    >>> lab_to_xyz([100.0, 0.0, 0.0]).round(5).tolist()
    [0.95047, 1.0, 1.08883]
    """
    lab_a = channels(lab, "lab")
    wt = _white_arg(white, illuminant, observer, lab_a.dtype)
    f = np.empty_like(lab_a)
    fy = (lab_a[..., 0] + 16.0) / 116.0
    f[..., 0] = fy + lab_a[..., 1] / 500.0
    f[..., 1] = fy
    f[..., 2] = fy - lab_a[..., 2] / 200.0
    t = f * f * f
    lin = t <= _EPSILON
    if lin.any():
        t[lin] = (116.0 * f[lin] - 16.0) / _KAPPA
    return t * wt


def spectrum_to_lab(
    reflectance: Any,
    wavelength_nm: Any,
    *,
    illuminant: str = "D65",
    observer: str = "2",
) -> np.ndarray:
    """CIELAB of reflectance spectra relative to the white of the same grid.

    The white is ``spectral_weights(wavelength_nm, ...).sum(axis=0)`` so the perfect
    reflector is exactly ``L* = 100, a* = b* = 0`` on any grid.

    Parameters
    ----------
    reflectance : array_like, shape (..., N)
    wavelength_nm : array_like, shape (N,)
    illuminant, observer : str, optional

    Returns
    -------
    numpy.ndarray, shape (..., 3)

    Examples
    --------
    >>> wl = np.arange(400.0, 701.0, 10.0)
    >>> bool(np.abs(spectrum_to_lab(np.ones(wl.size), wl) - [100, 0, 0]).max() < 1e-9)
    True
    """
    weights = spectral_weights(wavelength_nm, illuminant=illuminant, observer=observer)
    xyz = spectrum_to_xyz(
        reflectance, wavelength_nm, illuminant=illuminant, observer=observer
    )
    return xyz_to_lab(xyz, white=weights.sum(axis=0))


