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

What is colour-science's and what is ours
-----------------------------------------
The spectral integration is colour-science's (``colour.msds_to_XYZ``, method
"Integration", CIE 15 summation): :func:`spectral_weights` are the tristimulus values it
gives unit-impulse spectra, and :func:`white_xyz` is its ``sd_to_XYZ`` of the perfect
reflector; the datasets are its too (:mod:`microfacet.colour.datasets`). Kept, with the
measurements in ``docs/colour-benchmarks.md`` (``python -m pipelines run speed-colour``):
applying the weights (:func:`spectrum_to_xyz`, one matrix product) and XYZ ↔ Lab
(:func:`xyz_to_lab`, :func:`lab_to_xyz`), which colour-science computes in float64 only.

Which white is used where
-------------------------
:func:`spectral_weights` is normalised so that ``R = 1`` gives ``Y = 1`` *on the given
wavelength grid*; :func:`spectrum_to_lab` uses the white of that grid,
``spectral_weights(...).sum(axis=0)``, so a perfect reflector is exactly
``L* = 100, a* = b* = 0`` whatever the grid. :func:`white_xyz` is the same quantity on the
1 nm 360-830 nm grid (the CIE definition); it is the default white of :func:`xyz_to_lab` /
:func:`lab_to_xyz`. The image (sRGB) side and its white: :mod:`microfacet.colour.srgb`.

References
----------
.. [1] N. Nagata, M. Kamei, K. Takahashi, K. Tobitani, T. Akagi, S. Yamamura, "Simulation
   Technology for Titanium Oxide Layer Interference Color", Technical Report (the seed paper),
   §2.4 (spectral reflectance to colour).
.. [2] CIE 015:2018, *Colorimetry*, 4th ed., CIE, Vienna (2018), doi:10.25039/TR.015.2018.

Examples
--------
>>> import numpy as np
>>> wl = np.arange(360.0, 831.0)
>>> bool(np.abs(spectrum_to_lab(np.ones(wl.size), wl) - [100.0, 0.0, 0.0]).max() < 1e-9)
True
"""

from __future__ import annotations

import functools
from typing import Any

import numpy as np

from ..core.defaults import DEFAULT_ILLUMINANT, DEFAULT_OBSERVER
from .arrays import channels, float_array
from .datasets import (  # re-exported: their import path here is public
    CMF_RANGE_NM,
    OBSERVERS,
    check_range,
    check_wavelengths,
    cmfs,
    illuminant_key,
    illuminant_sd,
    known_illuminants,
    observer_name,
)
from .snapshot import colour_impulse_xyz, grid_key, stored

__all__ = ["OBSERVERS", "known_illuminants", "lab_to_xyz", "spectral_weights", "spectrum_to_lab",
           "spectrum_to_xyz", "white_xyz", "xyz_to_lab"]

#: CIELAB constants (CIE 15:2018, exact rationals).
_EPSILON = 216.0 / 24389.0
_KAPPA = 24389.0 / 27.0

# --------------------------------------------------------------------------------------
# Spectra -> XYZ
# --------------------------------------------------------------------------------------


def _impulse_xyz(w: np.ndarray, illuminant: str, observer: str) -> np.ndarray | None:
    """colour-science's "Integration" XYZ (Y = 100 white) of the unit-impulse spectra on
    ``w`` — stored with the package (:mod:`~microfacet.colour.snapshot`) for the analysis'
    grids, else computed — or None where colour-science cannot hold the grid exactly."""
    tables = stored()
    key = grid_key(w, illuminant, observer)
    if tables is not None and key in tables.weights:
        return np.array(tables.weights[key])
    return colour_impulse_xyz(w, illuminant, observer)


def _cell_widths(w: np.ndarray) -> np.ndarray:
    """Δλ of CIE 15 summation on any grid: half the distance between each sample's
    neighbours, and the full neighbour distance at the two ends, so that on a uniform grid
    every sample has the same Δλ, as in colour-science's "Integration"."""
    d = np.empty_like(w)
    d[1:-1] = 0.5 * (w[2:] - w[:-2])
    d[0] = w[1] - w[0]
    d[-1] = w[-1] - w[-2]
    return d


@functools.cache
def _weights_cached(wl: tuple[float, ...], illuminant: str, observer: str) -> np.ndarray:
    w = np.array(wl)
    weights = _impulse_xyz(w, illuminant, observer)
    if weights is None:  # colour-science integrates uniform grids only: its sum, this grid
        spd = illuminant_sd(w, illuminant=illuminant)
        weights = cmfs(w, observer=observer) * (spd * _cell_widths(w))[:, None]
    y_white = weights[:, 1].sum()
    if not y_white > 0:
        raise ValueError(
            f"illuminant {illuminant!r} has no power on wavelength_nm "
            f"[{w[0]:g}, {w[-1]:g}] nm (white Y = 0)"
        )
    weights /= y_white
    weights.flags.writeable = False
    return weights


def spectral_weights(wavelength_nm: Any, *, illuminant: str = DEFAULT_ILLUMINANT,
                     observer: str = DEFAULT_OBSERVER) -> np.ndarray:
    """Weights ``W`` such that ``XYZ = R @ W`` for reflectance spectra ``R``.

    ``W[i] = cmf(λ_i) S(λ_i) Δλ / Σ_k ȳ(λ_k) S(λ_k) Δλ``, CIE 15 summation: on a uniform
    grid these are colour-science's (``colour.msds_to_XYZ(..., method="Integration")`` of
    the unit-impulse spectra, CMFs and illuminant aligned to the grid by colour-science,
    divided by 100). colour-science integrates uniform grids only; on a non-uniform grid
    (or one colour-science cannot hold exactly, e.g. 0.1 nm steps) the same sum is taken
    here with ``Δλ_i`` half the distance between sample ``i``'s neighbours (the full
    distance to its one neighbour at the ends, which makes every ``Δλ_i`` equal on a
    uniform grid) and the CMFs / illuminant of :func:`cmfs` / :func:`illuminant_sd`.
    Either way a perfect reflector (``R ≡ 1``) gives ``Y = 1`` and ``W.sum(axis=0)`` is
    the white of this grid. Not a hot path (cached), so it is delegated
    (docs/colour-benchmarks.md, which also gives the change from the trapezoid sum used
    before: up to 5e-5 in XYZ, 0.006 ΔE00, on a 5 nm grid).

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

    Raises
    ------
    ValueError
        ``wavelength_nm`` not strictly increasing or outside 360-830 nm, an unknown
        ``illuminant`` / ``observer``, or an illuminant with no power on the grid.

    Examples
    --------
    >>> W = spectral_weights(np.arange(380.0, 781.0, 5.0))
    >>> round(float(W[:, 1].sum()), 12)
    1.0
    """
    w = check_wavelengths(wavelength_nm, strict=True)
    check_range(w, *CMF_RANGE_NM, "the CIE colour matching functions")
    return _weights_cached(tuple(w.tolist()), illuminant_key(illuminant),
                           observer_name(observer))


def spectrum_to_xyz(reflectance: Any, wavelength_nm: Any, *, illuminant: str = DEFAULT_ILLUMINANT,
                    observer: str = DEFAULT_OBSERVER) -> np.ndarray:
    """CIE XYZ of reflectance spectra (perfect reflector ``Y = 1``): ``R @ W``.

    The weights ``W`` are colour-science's integration (:func:`spectral_weights`); applying
    them is kept ours, one matrix product in the input's precision: 4.2× (float64) and
    11× (float32) faster than ``colour.msds_to_XYZ(..., method="Integration")`` on
    (1e5, 81) spectra, with 28× / 110× less memory (it forms ``R * S`` in float64);
    results equal to 2e-15 (float64); docs/colour-benchmarks.md.

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


def white_xyz(*, illuminant: str = DEFAULT_ILLUMINANT,
              observer: str = DEFAULT_OBSERVER) -> np.ndarray:
    """XYZ of the perfect reflecting diffuser (``Y = 1``), CIE 1 nm, 360-830 nm.

    colour-science's ``sd_to_XYZ(sd_ones, cmfs, illuminant, method="Integration") / 100``
    on the CMFs' own 1 nm grid (via :func:`spectral_weights`). This is the default
    reference white of :func:`xyz_to_lab` / :func:`lab_to_xyz`. For a white consistent with
    another wavelength grid use ``spectral_weights(wl, ...).sum(axis=0)`` (what
    :func:`spectrum_to_lab` uses).

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
    grid = np.arange(CMF_RANGE_NM[0], CMF_RANGE_NM[1] + 1.0)
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


def xyz_to_lab(xyz: Any, *, white: Any = None, illuminant: str = DEFAULT_ILLUMINANT,
               observer: str = DEFAULT_OBSERVER) -> np.ndarray:
    """CIE 1976 L*a*b* from XYZ (exact CIE piecewise function).

    Kept ours (colour-science has ``colour.XYZ_to_Lab``): it computes in float32 when
    given float32, which colour-science cannot; on a 12 MP float32 image it is 3.3× faster
    and needs 2.6× less memory (538 MB vs 1373 MB peak), on float64 1.9× / 1.4×; on
    float64 model tables (1e5-1e6 colours) 1.4-1.6× faster; agreement 2e-13 (float64),
    1e-4 (float32); docs/colour-benchmarks.md.

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


def lab_to_xyz(lab: Any, *, white: Any = None, illuminant: str = DEFAULT_ILLUMINANT,
               observer: str = DEFAULT_OBSERVER) -> np.ndarray:
    """XYZ from CIE 1976 L*a*b* (inverse of :func:`xyz_to_lab`).

    Kept ours (colour-science has ``colour.Lab_to_XYZ``) for the float32 image path of
    :func:`~microfacet.colour.srgb.lab_to_srgb`: on a 12 MP float32 image 2.6× faster and
    2.8× less memory (492 MB vs 1373 MB peak); on float64 within 1.2-1.4× (agreement
    1e-15); docs/colour-benchmarks.md.

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


def spectrum_to_lab(reflectance: Any, wavelength_nm: Any, *, illuminant: str = DEFAULT_ILLUMINANT,
                    observer: str = DEFAULT_OBSERVER) -> np.ndarray:
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
    xyz = spectrum_to_xyz(reflectance, wavelength_nm, illuminant=illuminant, observer=observer)
    return xyz_to_lab(xyz, white=weights.sum(axis=0))


