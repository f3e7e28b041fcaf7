"""CIE datasets from colour-science: standard observers (CMFs) and illuminant spectra.

The tables are colour-science's own (``colour.MSDS_CMFS``, ``colour.SDS_ILLUMINANTS``), read
from the copy stored with the package (:mod:`~microfacet.colour.snapshot`: importing
colour-science costs ~0.7 s) or, without it, from colour-science on first use; cached
read-only. Names are validated here, with messages that name the argument.
:mod:`microfacet.colour.colorimetry` integrates spectra against them.

Examples
--------
>>> float(cmfs([555.0])[0, 1].round(4)), float(illuminant_sd([560.0])[0])
(1.0, 100.0)
"""

from __future__ import annotations

import functools
from typing import Any

import numpy as np

from ..core.defaults import DEFAULT_ILLUMINANT, DEFAULT_OBSERVER
from .snapshot import (
    CMF_RANGE_NM,
    OBSERVER_NAMES,
    colour_cmf_table,
    colour_illuminant_names,
    colour_illuminant_table,
    stored,
)

__all__ = ["OBSERVERS", "cmfs", "illuminant_key", "illuminant_sd", "known_illuminants"]

_CIE1931, _CIE1964 = OBSERVER_NAMES

#: Accepted observer names -> colour-science dataset name.
OBSERVERS: dict[str, str] = {
    "2": _CIE1931,
    _CIE1931: _CIE1931,
    "10": _CIE1964,
    _CIE1964: _CIE1964,
}


# --------------------------------------------------------------------------------------
# Validation
# --------------------------------------------------------------------------------------


def observer_name(observer: Any) -> str:
    """colour-science's name of a standard observer given as ``"2"``, ``"10"`` or in full.

    Examples
    --------
    >>> observer_name("10")
    'CIE 1964 10 Degree Standard Observer'
    """
    key = str(observer)
    try:
        return OBSERVERS[key]
    except KeyError:
        raise ValueError(
            f"observer must be one of {sorted(set(OBSERVERS))!r}, got {observer!r}"
        ) from None


def check_wavelengths(wavelength_nm: Any, *, strict: bool = False) -> np.ndarray:
    """``wavelength_nm`` as a finite, non-empty 1-D float64 array (strictly increasing with
    at least 2 samples if ``strict``); a ValueError names ``wavelength_nm``."""
    w = np.asarray(wavelength_nm, dtype=np.float64)
    if w.ndim != 1 or w.size == 0:
        raise ValueError(f"wavelength_nm must be a non-empty 1-D array, got shape {w.shape}")
    if not np.all(np.isfinite(w)):
        raise ValueError("wavelength_nm must be finite")
    if strict and (w.size < 2 or np.any(np.diff(w) <= 0)):
        raise ValueError("wavelength_nm must be strictly increasing with at least 2 samples")
    return w


def check_range(w: np.ndarray, lo: float, hi: float, what: str) -> None:
    if w.min() < lo or w.max() > hi:
        raise ValueError(
            f"wavelength_nm must lie within [{lo:g}, {hi:g}] nm for {what}, "
            f"got [{w.min():g}, {w.max():g}]"
        )


@functools.cache
def _illuminant_names() -> tuple[str, ...]:
    tables = stored()
    return tables.illuminant_names if tables is not None else colour_illuminant_names()


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
    """The ``colour.SDS_ILLUMINANTS`` key of ``illuminant`` (matched case-insensitively).

    Examples
    --------
    >>> illuminant_key("d65")
    'D65'
    """
    names = _illuminant_names()
    if isinstance(illuminant, str):
        if illuminant in names:
            return illuminant
        folded = {n.casefold(): n for n in names}
        if illuminant.casefold() in folded:
            return folded[illuminant.casefold()]
    examples = ", ".join(n for n in (DEFAULT_ILLUMINANT, "D50", "A", "E", "FL2", "F11")
                         if n in names)
    raise ValueError(
        f"illuminant {illuminant!r} is unknown; use a name of colour.SDS_ILLUMINANTS, "
        f"e.g. {examples} ({len(names)} known, see known_illuminants())"
    )


# --------------------------------------------------------------------------------------
# Tables (lazy colour-science import, cached read-only)
# --------------------------------------------------------------------------------------


@functools.cache
def _cmf_table(name: str) -> tuple[np.ndarray, np.ndarray]:
    tables = stored()
    if tables is not None and name in tables.cmf:
        return tables.cmf[name]
    return colour_cmf_table(name)


@functools.cache
def _illuminant_table(name: str) -> tuple[np.ndarray, np.ndarray]:
    tables = stored()
    if tables is not None and name in tables.illuminant:
        return tables.illuminant[name]
    return colour_illuminant_table(name)


def cmfs(wavelength_nm: Any, *, observer: str = DEFAULT_OBSERVER) -> np.ndarray:
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
    w = check_wavelengths(wavelength_nm)
    check_range(w, *CMF_RANGE_NM, f"the {name}")
    wl, values = _cmf_table(name)
    out = np.empty((w.size, 3))
    for j in range(3):
        out[:, j] = np.interp(w, wl, values[:, j])
    return out


def illuminant_sd(wavelength_nm: Any, *, illuminant: str = DEFAULT_ILLUMINANT) -> np.ndarray:
    """Relative spectral power of a named CIE / colour-science illuminant.

    The tabulated SPD (5 nm for the CIE illuminants) is first aligned to 1 nm exactly
    as colour-science aligns it inside ``sd_to_XYZ`` (the dataset's interpolator, linear
    for the CIE illuminants; constant extrapolation out to 360-830 nm), then linearly
    interpolated to ``wavelength_nm``.

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
    w = check_wavelengths(wavelength_nm)
    wl, values = _illuminant_table(key)
    check_range(w, wl[0], wl[-1], f"illuminant {key}")
    return np.interp(w, wl, values)
