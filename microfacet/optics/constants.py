"""Optical constants (complex refractive index n + ik) of the film and substrate sets.

The tables are copied unchanged from the refractiveindex.info database (CC0 1.0); see
``microfacet/data/optical_constants/SOURCES.md`` for the original paper of each set.

The default film and substrate and why: :mod:`microfacet.optics.defaults`.

References
----------
.. [1] N. Nagata, M. Kamei, K. Takahashi, K. Tobitani, T. Akagi, S. Yamamura, "Simulation
   Technology for Titanium Oxide Layer Interference Color", Technical Report (the seed paper),
   §2.4 (the complex refractive index of the film).
.. [2] M. N. Polyanskiy, "Refractiveindex.info database of optical constants", Sci. Data 11
   (2024) 94, doi:10.1038/s41597-023-02898-2 (every set; the paper of each:
   ``microfacet/data/optical_constants/SOURCES.md``).
.. [3] A. Jolivet et al., "Structural, optical, and electrical properties of TiO2 thin films
   deposited by ALD: Impact of the substrate, the deposited thickness and the deposition
   temperature", Appl. Surf. Sci. 608 (2023) 155214, doi:10.1016/j.apsusc.2022.155214 (the
   default film).
.. [4] P. B. Johnson, R. W. Christy, "Optical constants of transition metals: Ti, V, Cr, Mn, Fe,
   Co, Ni, and Pd", Phys. Rev. B 9 (1974) 5056-5070, doi:10.1103/PhysRevB.9.5056 (the default
   substrate).

Examples
--------
>>> from microfacet.optics import optical_constants
>>> n = optical_constants("Ti_JohnsonChristy1974", [550.0])
>>> bool(n.imag[0] > 3)
True
"""

from __future__ import annotations

import functools
from dataclasses import dataclass
from importlib import resources

import numpy as np

from .defaults import DEFAULT_FILM, DEFAULT_SUBSTRATE

__all__ = ["DEFAULT_FILM", "DEFAULT_SUBSTRATE", "OpticalConstantSet", "known_sets", "load_set",
           "optical_constants", "resolve_index", "unknown_set_reason"]


_DATA_PACKAGE = "microfacet.data"
_DATA_DIR = "optical_constants"


@dataclass(frozen=True)
class OpticalConstantSet:
    """One tabulated set of optical constants.

    Attributes
    ----------
    name : str
        File stem, e.g. ``"Ti_JohnsonChristy1974"``.
    wavelength_nm : ndarray, shape (N,)
        Vacuum wavelengths in nm, increasing.
    n, k : ndarray, shape (N,)
        Real and imaginary parts of the refractive index (k >= 0 is absorption).
    """

    name: str
    wavelength_nm: np.ndarray
    n: np.ndarray
    k: np.ndarray

    @property
    def range_nm(self) -> tuple[float, float]:
        """The tabulated wavelength range ``(min, max)`` in nm."""
        return float(self.wavelength_nm[0]), float(self.wavelength_nm[-1])


def _data_root():
    return resources.files(_DATA_PACKAGE).joinpath(_DATA_DIR)


@functools.cache
def known_sets() -> tuple[str, ...]:
    """Names of the bundled optical-constant sets, sorted."""
    return tuple(
        sorted(
            p.name[: -len(".csv")]
            for p in _data_root().iterdir()
            if p.name.endswith(".csv")
        )
    )


def unknown_set_reason(name) -> str | None:
    """Why ``name`` is not a bundled set (None when it is, or when no set is named): the
    check of every option that names one.

    >>> unknown_set_reason(None) is None, unknown_set_reason("nope").startswith("unknown")
    (True, True)
    """
    if name is None:
        return None
    try:
        load_set(name)
    except ValueError as exc:
        return str(exc)
    return None


@functools.cache
def load_set(name: str) -> OpticalConstantSet:
    """Load one bundled set by name.

    Raises
    ------
    ValueError
        If ``name`` is not a bundled set; the message lists the known names.
    """
    if not isinstance(name, str) or name not in known_sets():
        raise ValueError(
            f"unknown optical-constant set {name!r}; known sets: {', '.join(known_sets())}"
        )
    text = _data_root().joinpath(name + ".csv").read_text()
    table = np.loadtxt(text.splitlines(), delimiter=",", skiprows=1, ndmin=2)
    order = np.argsort(table[:, 0], kind="stable")
    table = table[order]
    for arr in (table[:, 0], table[:, 1], table[:, 2]):
        arr.setflags(write=False)
    return OpticalConstantSet(name, table[:, 0].copy(), table[:, 1].copy(), table[:, 2].copy())


def optical_constants(name: str, wavelength_nm) -> np.ndarray:
    """Complex refractive index ``n + ik`` of a bundled set at the given wavelengths.

    n and k are interpolated linearly in wavelength between the tabulated points.

    Parameters
    ----------
    name : str
        A bundled set, see :func:`known_sets` (e.g. ``"TiO2_Jolivet2023_amorphous"``).
    wavelength_nm : array_like, any shape
        Vacuum wavelengths in nm. NaN is passed through as NaN.

    Returns
    -------
    ndarray of complex128, same shape as ``wavelength_nm``

    Raises
    ------
    ValueError
        If ``name`` is unknown (the message lists the known sets) or a wavelength lies
        outside the set's tabulated range (no extrapolation).

    Examples
    --------
    >>> from microfacet.optics import optical_constants
    >>> round(float(optical_constants("TiO2_Jolivet2023_amorphous", 550.0).real), 2)
    2.45
    """
    s = load_set(name)
    wl = np.asarray(wavelength_nm, dtype=np.float64)
    lo, hi = s.range_nm
    finite = wl[np.isfinite(wl)]
    if np.any(np.isinf(wl)) or (finite.size and (finite.min() < lo or finite.max() > hi)):
        bad = wl[~np.isnan(wl)]
        bad = bad[(bad < lo) | (bad > hi)]
        raise ValueError(
            f"wavelength_nm: {bad.flat[0]:g} nm is outside the range of {name!r} "
            f"({lo:g}-{hi:g} nm)"
        )
    n = np.interp(wl, s.wavelength_nm, s.n)
    k = np.interp(wl, s.wavelength_nm, s.k)
    return np.where(np.isnan(wl), np.nan, n + 1j * k)


def resolve_index(value, wavelength_nm) -> np.ndarray:
    """A refractive index given as a set name or as numbers, as a complex array.

    Parameters
    ----------
    value : str or complex or array_like
        A bundled set name (interpolated at ``wavelength_nm``) or index values that
        broadcast against ``wavelength_nm``.
    wavelength_nm : array_like
        Wavelengths in nm, used only when ``value`` is a name.
    """
    if isinstance(value, str):
        return optical_constants(value, wavelength_nm)
    return np.asarray(value, dtype=np.complex128)
