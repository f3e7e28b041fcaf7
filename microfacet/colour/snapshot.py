"""colour-science's tables and integration weights, stored with the package.

Importing colour-science loads every one of its subpackages: 0.78 s (docs/colour-benchmarks.md,
"Not importing colour-science") and ~80 MB of resident memory (scratch: the resident size
before and after ``import colour``), more than the colour stage of a 1 MP analysis takes.
The analysis needs only colour-science's data — the CIE standard observers, its illuminant
spectra and names — and its "Integration" weights on the wavelength grids the colour table
and the image white use. Those are stored in ``data/colour_science.npz``, written by
:func:`write_snapshot` (``python -m pipelines.colour_snapshot``) with the colour-science
version it records (summary.json's ``versions`` names it). Whatever the file does not hold
(another grid, illuminant or observer for the weights) is computed by colour-science itself,
as before: the numbers are colour-science's either way, and tests/colour/test_snapshot.py
checks the stored ones against the installed colour-science.

Examples
--------
>>> tables = stored()
>>> tables is None or "D65" in tables.illuminant_names
True
"""

from __future__ import annotations

import functools
import json
import logging
import math
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from ..core.defaults import DEFAULT_ILLUMINANT
from ..core.lazy import load

colour = load("colour")
log = logging.getLogger("microfacet.colour")

__all__ = ["CMF_RANGE_NM", "OBSERVER_NAMES", "SNAPSHOT_PATH", "WEIGHT_GRIDS", "Snapshot",
           "colour_cmf_table", "colour_illuminant_names", "colour_illuminant_table",
           "colour_impulse_xyz", "grid_key", "stored", "write_snapshot"]

#: colour-science's names of the CIE 1931 2° and CIE 1964 10° standard observers.
OBSERVER_NAMES = ("CIE 1931 2 Degree Standard Observer", "CIE 1964 10 Degree Standard Observer")
#: CIE range of the standard observers tabulated at 1 nm (nm).
CMF_RANGE_NM = (360.0, 830.0)
#: Unit-impulse spectra integrated per colour-science call (bounds its (k, N) temporaries).
_BLOCK = 512

#: Where the stored tables are.
SNAPSHOT_PATH = Path(__file__).resolve().parents[1] / "data" / "colour_science.npz"
#: (first, step, last) nm of the grids whose weights are stored: the colour table's
#: wavelength steps (:mod:`microfacet.colour.table`) and the image white's grids.
WEIGHT_GRIDS = ((380.0, 1.0, 780.0), (380.0, 5.0, 780.0), (380.0, 10.0, 780.0),
                (380.0, 20.0, 780.0), (360.0, 1.0, 830.0))
#: Illuminants whose weights are stored (the analysis' default), for both observers.
WEIGHT_ILLUMINANTS = (DEFAULT_ILLUMINANT,)


def grid_key(w: np.ndarray, illuminant: str, observer: str) -> str | None:
    """The key of the weights of the uniform grid ``w`` (nm; within 1e-9 of a step of the
    grid from its first to its last sample, as colour-science's ``SpectralShape`` holds it),
    or None for a non-uniform grid.

    >>> grid_key(np.arange(380.0, 781.0, 5.0), "D65", "CIE 1931 2 Degree Standard Observer")
    'CIE 1931 2 Degree Standard Observer|D65|380|5|780'
    """
    step = _uniform_step(w)
    if step is None:
        return None
    return f"{observer}|{illuminant}|{w[0]:.12g}|{step:.12g}|{w[-1]:.12g}"


def _uniform_step(w: np.ndarray) -> float | None:
    """The step of the grid ``w`` if every step is within 1e-9 of it, else None."""
    if w.size < 2:
        return None
    step = (w[-1] - w[0]) / (w.size - 1)
    return None if np.abs(np.diff(w) - step).max() > 1e-9 * step else float(step)


@dataclass(frozen=True)
class Snapshot:
    """The stored tables (arrays read-only)."""

    colour_version: str
    illuminant_names: tuple
    cmf: dict          # observer name -> (wavelengths (N,), values (N, 3))
    illuminant: dict   # illuminant name -> (wavelengths (N,), values (N,))
    weights: dict      # grid_key -> (N, 3) colour-science "Integration" XYZ of unit impulses


def _frozen(a) -> np.ndarray:
    out = np.array(a, dtype=np.float64)
    out.flags.writeable = False
    return out


@functools.cache
def stored(path: Path = SNAPSHOT_PATH) -> Snapshot | None:
    """The tables stored at ``path``; None if the file is missing or unreadable (logged: the
    numbers then come from colour-science itself, as they would without the file)."""
    if not path.is_file():
        return None
    try:
        return _read(path)
    except (OSError, ValueError, KeyError, TypeError) as exc:
        log.warning("%s: unreadable (%s); colour-science computes its tables instead",
                    path, " ".join(str(exc).split()))
        return None


def _read(path: Path) -> Snapshot:
    with np.load(path, allow_pickle=False) as z:
        meta = json.loads(str(z["meta"]))
        cmf = {n: (_frozen(z[f"cmf_w_{i}"]), _frozen(z[f"cmf_v_{i}"]))
               for i, n in enumerate(meta["observers"])}
        ill = {n: (_frozen(z[f"ill_w_{i}"]), _frozen(z[f"ill_v_{i}"]))
               for i, n in enumerate(meta["illuminant_names"])}
        weights = {k: _frozen(z[f"weights_{i}"]) for i, k in enumerate(meta["weights"])}
    return Snapshot(meta["colour_version"], tuple(meta["illuminant_names"]), cmf, ill, weights)


def write_snapshot(path: Path = SNAPSHOT_PATH) -> Snapshot:
    """Compute the tables with colour-science and store them at ``path`` (written under a
    temporary name, then renamed); returns what was stored."""
    names = colour_illuminant_names()
    observers = OBSERVER_NAMES
    arrays, keys = {}, []
    for i, n in enumerate(observers):
        arrays[f"cmf_w_{i}"], arrays[f"cmf_v_{i}"] = colour_cmf_table(n)
    for i, n in enumerate(names):
        arrays[f"ill_w_{i}"], arrays[f"ill_v_{i}"] = colour_illuminant_table(n)
    for obs in observers:
        for ill in WEIGHT_ILLUMINANTS:
            for first, step, last in WEIGHT_GRIDS:
                w = np.linspace(first, last, int(round((last - first) / step)) + 1)
                arrays[f"weights_{len(keys)}"] = colour_impulse_xyz(w, ill, obs)
                keys.append(grid_key(w, ill, obs))
    meta = {"colour_version": colour.__version__, "illuminant_names": list(names),
            "observers": list(observers), "weights": keys}
    path.parent.mkdir(parents=True, exist_ok=True)
    tmp = path.with_name(f".{path.name}.partial")
    with open(tmp, "wb") as f:
        np.savez_compressed(f, meta=np.array(json.dumps(meta)), **arrays)
    tmp.replace(path)
    stored.cache_clear()
    return stored(path)


# ----------------------------------------------------------------- colour-science itself
def colour_illuminant_names() -> tuple[str, ...]:
    """colour-science's illuminant names (imports it)."""
    return tuple(colour.SDS_ILLUMINANTS.keys())


def colour_cmf_table(name: str) -> tuple[np.ndarray, np.ndarray]:
    """colour-science's 1 nm table of the standard observer ``name`` (imports it)."""
    msds = colour.MSDS_CMFS[name]
    return _frozen(msds.wavelengths), _frozen(msds.values)


def colour_illuminant_table(name: str) -> tuple[np.ndarray, np.ndarray]:
    """SPD aligned to 1 nm over the union of its range and 360-830 nm.

    colour-science's own ``SpectralDistribution.align`` (the dataset's interpolator,
    linear for the CIE illuminants as CIE 15 prescribes; constant extrapolation): what
    ``colour.sd_to_XYZ`` does when it aligns an illuminant to the 1 nm CMFs.
    """
    sd = colour.SDS_ILLUMINANTS[name]
    lo = math.floor(min(sd.shape.start, CMF_RANGE_NM[0]))
    hi = math.ceil(max(sd.shape.end, CMF_RANGE_NM[1]))
    aligned = sd.copy().align(colour.SpectralShape(lo, hi, 1))
    return _frozen(aligned.wavelengths), _frozen(aligned.values)


def _spectral_shape(w: np.ndarray):
    """``colour.SpectralShape`` whose wavelengths are ``w`` (to 1e-9 of a step) and which
    colour-science itself sees as uniform (e.g. not a 0.1 nm grid), or None."""
    step = _uniform_step(w)
    if step is None:
        return None
    tol = 1e-9 * step
    shape = colour.SpectralShape(w[0], w[-1], step)
    grid = np.asarray(shape.wavelengths)
    if (grid.shape != w.shape or np.abs(grid - w).max() > tol
            or not colour.utilities.is_uniform(grid)):
        return None
    return shape


def colour_impulse_xyz(w: np.ndarray, illuminant: str, observer: str) -> np.ndarray | None:
    """colour-science's "Integration" XYZ (Y = 100 white) of the unit-impulse spectra on
    ``w`` (imports it), or None where colour-science cannot hold the grid exactly."""
    shape = _spectral_shape(w)
    if shape is None:
        return None
    cmf = colour.colorimetry.reshape_msds(colour.MSDS_CMFS[observer], shape)
    ill = colour.colorimetry.reshape_sd(colour.SDS_ILLUMINANTS[illuminant], shape)
    if cmf.shape != shape or ill.shape != shape:
        return None
    n = w.size
    out = np.empty((n, 3))
    for i in range(0, n, _BLOCK):
        k = min(_BLOCK, n - i)
        impulses = np.zeros((k, n))
        impulses[np.arange(k), i + np.arange(k)] = 1.0
        out[i:i + k] = colour.msds_to_XYZ(impulses, cmf, ill, method="Integration",
                                          shape=shape)
    return out
