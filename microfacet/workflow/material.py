"""``microfacet export-brdf``: a results folder's material as one self-describing file.

The file (:mod:`microfacet.io.material_file`) holds the film average ⟨R⟩(θ_d, λ) of the fitted
thickness mixture, the NDF lobes, the thickness mixture, the optical-constant names and the
format version; the Mitsuba plugin of :mod:`microfacet.render.bsdf` and any other renderer read
it without microfacet.

Its rules are those of every output: it never lies inside the results folder it is made from,
an existing file is replaced only with ``overwrite`` and only when it is a material file, and
it appears whole or not at all (written to a temporary sibling, then renamed).

Examples
--------
>>> import tempfile, pathlib  # doctest: +SKIP
>>> export_material("nd-analysis", "nd-material")  # doctest: +SKIP
ExportOutput(path=PosixPath('nd-material.npz'), ...)
"""

from __future__ import annotations

import os
import time
from dataclasses import dataclass
from pathlib import Path

from ..core.errors import InputError, one_line
from ..forward.material import Material
from ..io.material_file import SUFFIX, read_material_file
from ..io.results import Results

__all__ = ["ExportOutput", "export_material", "material_path"]


@dataclass(frozen=True)
class ExportOutput:
    """What :func:`export_material` wrote.

    Attributes
    ----------
    path : Path
        The material file.
    material : Material
    seconds : float
        Time to tabulate and write.
    """

    path: Path
    material: Material
    seconds: float


def material_path(out) -> Path:
    """``out`` with the material file's extension (``.npz``) added when it has none."""
    p = Path(out)
    return p if p.suffix.lower() == SUFFIX else p.with_name(p.name + SUFFIX)


def check_material_output(out, *, inputs=(), overwrite=False) -> Path:
    """The path to write, checked: not within an input, its folder exists, an existing file
    replaced only with ``overwrite`` and only when it is a material file (InputError naming
    ``out``)."""
    path = material_path(out)
    shown = one_line(os.fspath(path))
    resolved = path.resolve()
    for i in inputs:
        root = Path(i).resolve()
        if resolved == root or root in resolved.parents:
            raise InputError(f"{shown}: is inside the input {one_line(os.fspath(i))}; write the "
                             "material file elsewhere (inputs are never written to)",
                             param="out")
    if not path.parent.is_dir():
        raise InputError(f"{shown}: the folder {one_line(path.parent)} does not exist",
                         param="out")
    if os.path.lexists(path):
        if not overwrite:
            raise InputError(f"{shown}: already exists; `overwrite` replaces a material file",
                             param="out")
        try:
            read_material_file(path)
        except InputError:
            raise InputError(f"{shown}: exists and is not a microfacet material file; it is "
                             "never replaced", param="out") from None
    return path


def export_material(results, out, *, overwrite=False, **grid) -> ExportOutput:
    """Tabulate a results folder's material and write it to ``out`` (``.npz`` added).

    Parameters
    ----------
    results : path-like
        An ``analyze`` results folder with thickness and NDF mixtures.
    out : path-like
        The material file.
    overwrite : bool
        Replace an existing material file.
    **grid
        ``theta_step_deg``, ``wavelength_step_nm``, ``wavelength_range_nm``
        (:meth:`Material.build`).

    Returns
    -------
    ExportOutput
    """
    t0 = time.perf_counter()
    r = Results(results)
    path = check_material_output(out, inputs=[r.path], overwrite=overwrite)
    material = Material.from_results(r, **grid)
    material.write(path)
    return ExportOutput(path, material, time.perf_counter() - t0)
