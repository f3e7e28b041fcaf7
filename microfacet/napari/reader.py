"""napari readers (npe2 ``readers`` contributions): a stack folder and a results folder as
layers, through the package's own readers (:func:`microfacet.io.stack.read_stack`,
:class:`microfacet.io.results.Results`).

A reader returns napari's *layer data* — ``(data, kwargs, layer_type)`` tuples — so it needs
neither napari nor Qt: ``npe2.read(path)`` works in a plain Python.

- a **stack folder** (``stack.json``) → one image layer, the z-stack ``(Z, Y, X[, RGB])`` in
  increasing z with ``scale = (z_step_um, pixel_y_um, pixel_x_um)`` and the stack's path, z
  positions and optics in the metadata;
- a **results folder** (``summary.json``) → ``all_in_focus`` (when present), ``height_um``,
  ``thickness_nm``, ``tilt_deg`` (images) and ``facets`` (labels, joint mode), each scaled
  in µm by the summary's pixel size; the metadata hold the map's unit and description and
  the thickness and NDF mixtures of ``summary.json`` (``thickness_mixture``,
  ``ndf_mixture``, with whether each was identified).

Examples
--------
>>> import numpy as np, tempfile, pathlib
>>> from microfacet.io.results import write_results_files
>>> d = pathlib.Path(tempfile.mkdtemp())
>>> _ = write_results_files(d, summary={"inputs": {"pixel_size_um": 0.5}},
...                         maps={"height_um": np.zeros((2, 3))}, tool_copies=False)
>>> [(kw["name"], kw["scale"], kind) for _, kw, kind in get_results_reader(str(d))(str(d))]
[('height_um', (0.5, 0.5), 'image')]
>>> get_stack_reader(str(d)) is None
True
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from ..io.results import MAPS, Results, pixel_size_of
from ..io.stack import read_stack

__all__ = ["RESULT_LAYERS", "UNITS", "get_results_reader", "get_stack_reader",
           "results_layers", "stack_layers", "z_step_of"]

#: The result maps shown as layers, bottom to top: map name → (layer type, colormap).
RESULT_LAYERS = {
    "height_um": ("image", "viridis"),
    "thickness_nm": ("image", "turbo"),
    "tilt_deg": ("image", "magma"),
    "facets": ("labels", None),
}
#: The unit of each map's values (what its name's suffix says).
UNITS = {"height_um": "µm", "thickness_nm": "nm", "tilt_deg": "degree", "facets": "label"}
#: napari's spatial unit of the layers (a pint name).
SPACE_UNIT = "micrometer"


def _one_folder(path) -> Path | None:
    if isinstance(path, (list, tuple)):
        if len(path) != 1:
            return None
        path = path[0]
    p = Path(path)
    return p if p.is_dir() else None


def get_stack_reader(path):
    """The reader of ``path`` if it is a stack folder (holds ``stack.json``), else None."""
    p = _one_folder(path)
    return stack_layers if p is not None and (p / "stack.json").is_file() else None


def get_results_reader(path):
    """The reader of ``path`` if it is a results folder (holds ``summary.json``), else
    None."""
    p = _one_folder(path)
    return results_layers if p is not None and (p / "summary.json").is_file() else None


def z_step_of(z_um) -> float:
    """The z step of sorted slice positions ``z_um`` (µm): the median spacing, 1.0 for a
    single slice.

    >>> z_step_of([2.0, 0.0, 1.0, 3.0]), z_step_of([5.0])
    (1.0, 1.0)
    """
    z = np.sort(np.asarray(z_um, dtype=float))
    steps = np.diff(z)
    steps = steps[steps > 0]
    return float(np.median(steps)) if steps.size else 1.0


def stack_layers(path) -> list[tuple]:
    """A stack folder as one image layer: ``[(data, kwargs, "image")]``.

    ``data`` is ``(Z, Y, X)`` (grey) or ``(Z, Y, X, 3)`` (RGB) in the stack's own sample type,
    slices in increasing z; ``kwargs["scale"]`` is ``(z_step_um, pixel_y_um, pixel_x_um)``
    and ``kwargs["translate"]`` starts the z axis at the lowest slice.
    """
    path = _one_folder(path) or Path(path)
    st = read_stack(path)
    order = st.z_order
    data = np.stack([im for _, _, im in st.iter_slices(st.dtype, order="z")])
    z = np.asarray(st.z_um, dtype=float)[order]
    dz = z_step_of(z)
    py, px = st.pixel_size_yx_um
    meta = {"microfacet": "stack", "stack_path": str(st.path), "z_um": z.tolist(),
            "z_step_um": dz, "pixel_size_um": [py, px], "units": {"z": "µm", "y": "µm",
                                                                  "x": "µm"},
            "color_space": st.color_space, "illuminant": st.illuminant,
            "film": st.film, "substrate": st.substrate}
    kwargs = {"name": st.path.name, "scale": (dz, py, px), "translate": (float(z[0]), 0.0, 0.0),
              "rgb": st.channels == 3, "metadata": meta, "units": (SPACE_UNIT,) * 3,
              "axis_labels": ("z", "y", "x")}
    return [(data, kwargs, "image")]


def _mixtures(res: Results) -> dict:
    return {"thickness_mixture": res.get("thickness", "mixture"),
            "thickness_identified": res.get("thickness", "mixture", "identified"),
            "thickness_reason": res.get("thickness", "mixture", "reason"),
            "ndf_mixture": res.get("ndf", "mixture"),
            "ndf_identified": res.get("ndf", "identified"),
            "ndf_reason": res.get("ndf", "reason")}


def _limits(a: np.ndarray) -> tuple[float, float]:
    finite = a[np.isfinite(a)]
    if finite.size == 0:
        return 0.0, 1.0
    lo, hi = (float(v) for v in np.percentile(finite, [1, 99]))
    return (lo, hi) if hi > lo else (lo, lo + 1.0)


def results_layers(path) -> list[tuple]:
    """A results folder as layers: ``all_in_focus`` (RGB, when present), then the maps of
    :data:`RESULT_LAYERS` the folder holds, each ``(data, kwargs, layer_type)`` scaled in µm
    by the pixel size of ``summary.json`` (1 µm when it records none)."""
    path = _one_folder(path) or Path(path)
    res = Results(path)
    scale = pixel_size_of(res.summary) or (1.0, 1.0)
    common = {"results_path": str(res.path), "pixel_size_um": list(scale), **_mixtures(res)}
    layers = []
    aif = res.image("all_in_focus")
    if aif is not None:
        layers.append((aif, {"name": "all_in_focus", "scale": scale, "rgb": aif.ndim == 3,
                             "units": (SPACE_UNIT,) * 2,
                             "metadata": {"microfacet": "results", "map": "all_in_focus",
                                          "unit": None, **common}}, "image"))
    for name, (kind, cmap) in RESULT_LAYERS.items():
        a = res.map(name)
        if a is None:
            continue
        meta = {"microfacet": "results", "map": name, "unit": UNITS[name],
                "description": MAPS[name][1], **common}
        kwargs = {"name": name, "scale": scale, "units": (SPACE_UNIT,) * 2, "metadata": meta}
        if kind == "image":
            kwargs.update(colormap=cmap, contrast_limits=_limits(a), visible=name != "tilt_deg")
        else:
            kwargs.update(opacity=0.4, visible=False)
        layers.append((a, kwargs, kind))
    return layers
