"""The exported material file: a fitted thin-film microfacet BRDF readable without microfacet.

``microfacet export-brdf`` writes one ``.npz`` file: a plain ZIP archive (numpy's ``.npz``
layout) holding three ``.npy`` arrays and one JSON member::

    film_average.npy   float32 (T, N)  ⟨R⟩(θ_d, λ): the film reflectance averaged over the
                                       thickness distribution, at facet incidence θ_d
    theta_d_deg.npy    float64 (T,)    uniform grid of θ_d, degrees, from 0
    wavelength_nm.npy  float64 (N,)    uniform grid of λ, nm
    metadata.json      UTF-8 JSON      format, NDF lobes, thickness mixture, film,
                                       substrate, ambient index, provenance

The BRDF it describes (Walter et al. 2007 with the mixture's own height-correlated Smith
term; :mod:`microfacet.forward.brdf`) is

    f_r(l, v; λ) = ⟨R⟩(θ_d, λ) · D(h) · G₂(l, v) / (4 cos θ_l cos θ_v),
    D(h) = Σ_i w_i exp(−tan²θ_h / α_i²) / (π α_i² cos⁴θ_h),  α_i = √2 tan(sd_deg_i),
    G₂ = 1 / (1 + Λ(l) + Λ(v)),  Λ(ω) = Σ_i w_i Λ_i(ω),
    Λ_i(ω) = (erf(a) − 1)/2 + exp(−a²)/(2 a √π),  a = 1/(α_i tan θ_ω),

with ``θ_d`` half the angle between l and v and ⟨R⟩ interpolated linearly in θ_d and λ (and
held at the ends of the grids). ``metadata.json`` carries ``"brdf"`` with exactly these
formulas as text, and ``"ndf"`` / ``"thickness"`` in the same JSON form as ``summary.json``.

Why ``.npz`` + JSON: numpy alone reads it (``np.load(f)["film_average"]``, and
``json.loads(np.load(f)["metadata.json"])``: numpy returns a non-``.npy`` member as bytes),
any language with a ZIP reader and an ``.npy`` parser reads it (``.npy`` is a 10-line header
and raw little-endian data), it needs no HDF5 or OpenEXR library, and it is one file.

Examples
--------
>>> import tempfile, pathlib
>>> f = pathlib.Path(tempfile.mkdtemp()) / "m.npz"
>>> arrays = {"film_average": np.full((3, 2), 0.5, np.float32),
...           "theta_d_deg": np.array([0.0, 45.0, 90.0]),
...           "wavelength_nm": np.array([400.0, 700.0])}
>>> write_material_file(f, arrays, {"ndf": {}})
>>> a, meta = read_material_file(f)
>>> a["film_average"].shape, meta["format"]
((3, 2), 'microfacet-brdf/1')
"""

from __future__ import annotations

import io
import json
import os
import zipfile
from pathlib import Path

import numpy as np

from ..core.errors import InputError, one_line
from .jsonfile import parse_json
from .limits import check_file_size

__all__ = ["FORMAT", "SUFFIX", "read_material_file", "write_material_file"]

#: The format name and version written into ``metadata.json``.
FORMAT = "microfacet-brdf/1"
#: The file's extension (added by ``export-brdf`` when missing).
SUFFIX = ".npz"
#: The arrays of the file, their dimensions and dtypes.
ARRAYS = {"film_average": (2, np.float32), "theta_d_deg": (1, np.float64),
          "wavelength_nm": (1, np.float64)}
#: Largest file read (bytes): a 0.05° × 0.5 nm table is ~13 MB.
MAX_BYTES = 256 << 20


def _npy_bytes(a: np.ndarray) -> bytes:
    buf = io.BytesIO()
    np.save(buf, a, allow_pickle=False)
    return buf.getvalue()


def write_material_file(path, arrays: dict, metadata: dict) -> None:
    """Write a material file atomically (a temporary sibling renamed into place).

    Parameters
    ----------
    path : path-like
        The ``.npz`` file; its folder must exist.
    arrays : dict
        ``film_average`` (T, N), ``theta_d_deg`` (T,), ``wavelength_nm`` (N,).
    metadata : dict
        JSON-serializable; ``format`` is set to :data:`FORMAT`.
    """
    path = Path(path)
    meta = {"format": FORMAT, **{k: v for k, v in metadata.items() if k != "format"}}
    tmp = path.with_name(f".{path.name}.tmp-{os.getpid()}")
    try:
        with zipfile.ZipFile(tmp, "w", compression=zipfile.ZIP_DEFLATED, compresslevel=6) as zf:
            for name, (ndim, dtype) in ARRAYS.items():
                a = np.ascontiguousarray(arrays[name], dtype=dtype)
                if a.ndim != ndim:
                    raise ValueError(f"{name}: expected {ndim}-D, got shape {a.shape}")
                zf.writestr(f"{name}.npy", _npy_bytes(a))
            zf.writestr("metadata.json", json.dumps(meta, indent=1, allow_nan=False))
        os.replace(tmp, path)
    finally:
        if tmp.exists():
            tmp.unlink()


def read_material_file(path) -> tuple[dict, dict]:
    """The arrays and metadata of a material file, checked.

    Returns
    -------
    arrays : dict
        As :func:`write_material_file` (``film_average`` float32, the grids float64).
    metadata : dict

    Raises
    ------
    InputError
        One line naming the file and what is wrong (not a ZIP, a missing member, another
        format, grids that are not increasing and uniform, shapes that disagree, non-finite
        or negative reflectance).
    """
    path = Path(path)
    shown = one_line(path)
    try:
        check_file_size(path, MAX_BYTES, shown)
        with zipfile.ZipFile(path) as zf:
            names = set(zf.namelist())
            missing = [n for n in (*(f"{a}.npy" for a in ARRAYS), "metadata.json")
                       if n not in names]
            if missing:
                raise InputError(f"{shown}: not a microfacet material file (no "
                                 f"{missing[0]})")
            meta = parse_json(zf.read("metadata.json").decode("utf-8-sig"),
                              f"{shown}: metadata.json")
            arrays = {a: np.load(io.BytesIO(zf.read(f"{a}.npy")), allow_pickle=False)
                      for a in ARRAYS}
    except FileNotFoundError:
        raise InputError(f"{shown}: no such file") from None
    except (OSError, zipfile.BadZipFile, ValueError, UnicodeDecodeError) as exc:
        if isinstance(exc, InputError):
            raise
        raise InputError(f"{shown}: cannot read as a material file ({one_line(exc)})") from None
    if not isinstance(meta, dict) or meta.get("format") != FORMAT:
        got = meta.get("format") if isinstance(meta, dict) else None
        raise InputError(f"{shown}: metadata.json: format {got!r}, expected {FORMAT!r}")
    _check_arrays(arrays, shown)
    return arrays, meta


def _check_arrays(arrays: dict, shown: str) -> None:
    for name, (ndim, dtype) in ARRAYS.items():
        a = arrays[name]
        if a.ndim != ndim or a.dtype != dtype:
            raise InputError(f"{shown}: {name}: expected {ndim}-D {np.dtype(dtype).name}, got "
                             f"{a.ndim}-D {a.dtype}")
    fa, th, wl = arrays["film_average"], arrays["theta_d_deg"], arrays["wavelength_nm"]
    if fa.shape != (th.size, wl.size):
        raise InputError(f"{shown}: film_average has shape {fa.shape}, the grids "
                         f"({th.size}, {wl.size})")
    for name, g in (("theta_d_deg", th), ("wavelength_nm", wl)):
        d = np.diff(g)
        if g.size < 2 or not np.all(np.isfinite(g)) or not np.all(d > 0) or \
                not np.allclose(d, d[0], rtol=1e-6, atol=0):
            raise InputError(f"{shown}: {name}: expected an increasing uniform grid of >= 2 "
                             f"values")
    if th[0] != 0 or th[-1] > 90 or wl[0] <= 0:
        raise InputError(f"{shown}: grids out of range (theta_d_deg must start at 0 and end "
                         f"<= 90, wavelength_nm > 0)")
    if not (np.all(np.isfinite(fa)) and np.all(fa >= 0) and np.all(fa <= 1)):
        raise InputError(f"{shown}: film_average: expected reflectances in [0, 1]")
