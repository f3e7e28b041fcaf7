"""The simulation folder (format ``microfacet-simulate/2``) of ``microfacet simulate``: the one
module that writes and reads it.

=====================  ===========================================================
file                   content
=====================  ===========================================================
``spectra.npy``        reflectance factor, float32 (L, V, N)
``wavelength_nm.npy``  the N wavelengths, nm
``angular_lab.npy``    CIELAB, float32 (L, V, 3)
``angular_xyz.npy``    CIE XYZ (perfect reflector Y = 1), float32 (L, V, 3)
``theta_light_deg.npy`` the L light zenith angles (rows), degrees
``theta_view_deg.npy`` the V view zenith angles (columns, positive on the mirror side)
``angular_map.npz``    the same map as ``microfacet-angular/1`` (:mod:`.angular_map`)
``angular_map.png``    its picture, 4 × 4 pixels per cell, light angle down
``delta_e.npy``        CIEDE2000 to the measured map, float32 (L, V); with a comparison
``simulate.json``      what was simulated (model, exposure, mixtures, grids, optics, fits,
                       comparison, versions, timings); written last
=====================  ===========================================================

The command adds its figure (``figure.pdf``) through the ``extra`` hook of
:func:`save_simulation`, inside the same atomic step. docs/forward-simulation.md describes
the keys of ``simulate.json``.

Examples
--------
>>> import tempfile, pathlib
>>> from microfacet.forward.angular import simulate_map
>>> m = simulate_map(model="half-vector", thickness=51.0, theta_light_deg=[0, 30],
...                  theta_view_deg=[0, 30, 60])
>>> out = pathlib.Path(tempfile.mkdtemp()) / "sim"
>>> _ = save_simulation(out, Simulation(m, {"model": "half-vector"}))
>>> back = read_simulation(out)
>>> back.meta["format"], back.map.lab.shape, back.delta_e is None
('microfacet-simulate/2', (2, 3, 3), True)
"""

from __future__ import annotations

import json
import math
import time
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from ..core.angular import AngularMap
from ..core.defaults import DEFAULT_ILLUMINANT, DEFAULT_OBSERVER
from ..core.errors import InputError, one_line
from .angular_map import MAX_ANGLES, MAX_WAVELENGTHS, save_map, save_png
from .jsonfile import json_safe, read_json
from .outdir import atomic_output_dir

__all__ = ["FILES", "FORMAT", "Simulation", "read_simulation", "save_simulation",
           "write_simulation"]

FORMAT = "microfacet-simulate/2"
#: The files of a simulation folder: name -> file (``figure.pdf`` comes from the command).
FILES = {
    "spectra": "spectra.npy",
    "wavelength_nm": "wavelength_nm.npy",
    "lab": "angular_lab.npy",
    "xyz": "angular_xyz.npy",
    "theta_light_deg": "theta_light_deg.npy",
    "theta_view_deg": "theta_view_deg.npy",
    "map": "angular_map.npz",
    "png": "angular_map.png",
    "delta_e": "delta_e.npy",
    "meta": "simulate.json",
}
#: Cells per side of the picture of one map cell.
PNG_SCALE = 4


@dataclass
class Simulation:
    """What a simulation folder holds.

    Attributes
    ----------
    map : AngularMap
        The simulated map, with its spectra, XYZ and Lab.
    meta : dict
        ``simulate.json`` (its ``format`` is set on writing).
    delta_e : ndarray (L, V) or None
        CIEDE2000 to a measured map.
    """

    map: AngularMap
    meta: dict = field(default_factory=dict)
    delta_e: np.ndarray | None = None


def write_simulation(folder, sim: Simulation, *, extra: Callable | None = None,
                     started: float | None = None) -> None:
    """Write the files of ``sim`` into the existing ``folder`` (normally the temporary folder
    of an :class:`~microfacet.io.outdir.OutputFolder`); ``simulate.json`` last.

    Parameters
    ----------
    folder : path-like
    sim : Simulation
    extra : callable, optional
        ``extra(folder)`` writes more files (the command's figure) before ``simulate.json``.
    started : float, optional
        ``time.perf_counter()`` when the work started: ``timings_s.total`` is recorded.
    """
    folder, m = Path(folder), sim.map
    np.save(folder / FILES["spectra"], np.asarray(m.spectra).astype(np.float32))
    np.save(folder / FILES["wavelength_nm"], m.wavelength_nm)
    np.save(folder / FILES["lab"], m.lab)
    np.save(folder / FILES["xyz"], np.asarray(m.xyz).astype(np.float32))
    np.save(folder / FILES["theta_light_deg"], m.theta_light_deg)
    np.save(folder / FILES["theta_view_deg"], m.theta_view_deg)
    save_map(folder / FILES["map"], m)
    save_png(folder / FILES["png"], m, scale=PNG_SCALE)
    if extra is not None:
        extra(folder)
    if sim.delta_e is not None:
        np.save(folder / FILES["delta_e"], np.asarray(sim.delta_e).astype(np.float32))
    meta = {"format": FORMAT, **{k: v for k, v in sim.meta.items() if k != "format"}}
    if started is not None:
        meta["timings_s"] = {**meta.get("timings_s", {}), "total": time.perf_counter() - started}
    (folder / FILES["meta"]).write_text(json.dumps(json_safe(meta), indent=2, allow_nan=False),
                                        encoding="utf-8")


def save_simulation(out, sim: Simulation, *, overwrite: bool = False, inputs=(),
                    extra: Callable | None = None, started: float | None = None) -> Path:
    """Write ``sim`` as the simulation folder ``out``, whole or not at all: into a temporary
    sibling renamed into place when complete (:func:`~microfacet.io.outdir.atomic_output_dir`;
    its rules: never an input, one writer, only a simulation folder replaced and only with
    ``overwrite``). ``extra`` and ``started`` as :func:`write_simulation`.

    Returns
    -------
    pathlib.Path
        ``out``.

    Raises
    ------
    InputError
        With ``param="out"``: ``out`` may not be written.
    """
    with atomic_output_dir(out, kind="simulate", overwrite=overwrite, inputs=inputs) as tmp:
        write_simulation(tmp, sim, extra=extra, started=started)
    return Path(out)


def read_simulation(folder) -> Simulation:
    """The simulation folder ``folder``, read and checked.

    Raises
    ------
    InputError
        Naming the file: ``simulate.json`` missing or of another format, an array missing,
        unreadable, too large or of a shape that does not fit the angles and wavelengths.
    """
    folder = Path(folder)
    f = folder / FILES["meta"]
    if not f.is_file():
        raise InputError(f"{one_line(f)}: missing (not a simulation folder)")
    meta = read_json(f)
    fmt = meta.get("format") if isinstance(meta, dict) else None
    if not (isinstance(fmt, str) and fmt.startswith("microfacet-simulate/")):
        raise InputError(f"{one_line(f)}: key 'format': {fmt!r} is not {FORMAT!r}")
    tl = _array(folder, "theta_light_deg", 1, MAX_ANGLES)
    tv = _array(folder, "theta_view_deg", 1, MAX_ANGLES)
    wl = _array(folder, "wavelength_nm", 1, MAX_WAVELENGTHS)
    cells = (tl.size, tv.size)
    lab = _array(folder, "lab", 3, shape=cells + (3,))
    xyz = _array(folder, "xyz", 3, shape=cells + (3,))
    spectra = _array(folder, "spectra", 3, shape=cells + (wl.size,))
    de = _array(folder, "delta_e", 2, shape=cells, required=False)
    m = AngularMap(tl, tv, lab, xyz, None, spectra, wl,
                   str(meta.get("illuminant") or DEFAULT_ILLUMINANT),
                   str(meta.get("observer") or DEFAULT_OBSERVER), dict(meta))
    return Simulation(m, meta, de)


def _array(folder: Path, name: str, ndim: int, most: int | None = None, *, shape=None,
           required: bool = True):
    """The array ``name`` of :data:`FILES`, its size and shape checked from the header first."""
    f = folder / FILES[name]
    if not f.is_file():
        if required:
            raise InputError(f"{one_line(f)}: missing")
        return None
    try:
        a = np.load(f, mmap_mode="r", allow_pickle=False)
    except (OSError, ValueError) as exc:
        raise InputError(f"{one_line(f)}: cannot read ({one_line(exc)})") from None
    if a.ndim != ndim or not np.issubdtype(a.dtype, np.number):
        raise InputError(f"{one_line(f)}: expected a {ndim}-D array of numbers, got "
                         f"{a.dtype} of shape {a.shape}")
    if most is not None and math.prod(a.shape) > most:
        raise InputError(f"{one_line(f)}: {math.prod(a.shape):,} values, more than {most:,}")
    if shape is not None and tuple(a.shape) != tuple(shape):
        raise InputError(f"{one_line(f)}: shape {a.shape}, expected {tuple(shape)}")
    return np.array(a)
