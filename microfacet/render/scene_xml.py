"""A Mitsuba scene dictionary written as Mitsuba 3 XML (``scene.xml``), self-contained.

``mitsuba.python.xml.dict_to_xml`` is gone in Mitsuba 3.9 and its replacement
``mi.parser.write_file`` refuses a plugin type it does not know (a custom Python BSDF such as
``microfacet_thinfilm``), so :func:`write_scene_xml` writes the XML itself. The file reloads
with ``mi.load_file`` (after the custom plugins are registered) and renders bit-identical
images to the dictionary with the same seed (``tests/render/test_scene_xml.py``).
"""

from __future__ import annotations

import filecmp
import os
import shutil
import xml.etree.ElementTree as ET
from pathlib import Path

import numpy as np

from ..core.errors import InputError
from .scene import MESH_TYPES, SCENE_FILE

__all__ = ["write_scene_xml"]

_TAGS = {
    "shape": ("rectangle", "sphere", "ply", "obj", "serialized", "disk", "cube", "cylinder",
              "instance", "shapegroup"),
    "emitter": ("directional", "point", "constant", "envmap", "area", "spot", "projector",
                "directionalarea"),
    "sensor": ("perspective", "thinlens", "orthographic", "radiancemeter", "irradiancemeter"),
    "film": ("hdrfilm", "specfilm"),
    "rfilter": ("box", "gaussian", "tent", "lanczos", "mitchell", "catmullrom"),
    "sampler": ("independent", "stratified", "multijitter", "orthogonal", "ldsampler"),
    "integrator": ("path", "direct", "volpath", "volpathmis", "aov", "depth", "moment",
                   "ptracer", "prb", "stokes"),
    "bsdf": ("diffuse", "conductor", "roughconductor", "dielectric", "roughdielectric",
             "thindielectric", "plastic", "roughplastic", "twosided", "blendbsdf", "mask",
             "principled", "principledthin", "bumpmap", "normalmap", "null", "hair",
             "measured", "pplastic"),
    "texture": ("d65", "regular", "irregular", "blackbody", "uniform", "srgb", "bitmap",
                "checkerboard", "mesh_attribute", "volume"),
}
_TAG_OF = {t: tag for tag, types in _TAGS.items() for t in types}
_MESH_EXTS = tuple(MESH_TYPES)


def _num(x) -> str:
    return repr(float(x))


def _tag(kind: str, key: str, parent: str) -> str:
    """The XML tag of a plugin: by its type, else by the key it is under (``bsdf``), else a
    shape's unknown child is its BSDF (a custom plugin)."""
    if kind in _TAG_OF:
        return _TAG_OF[kind]
    if key in _TAGS or key == "medium":
        return key
    if parent == "shape":
        return "bsdf"
    raise InputError(f"cannot tell which kind of Mitsuba object {key!r} (type {kind!r}) is; "
                     f"put it under a key naming it ('bsdf', 'emitter', …)", param="scene")


def _relocate(value: str, folder: Path, copied: dict) -> str:
    """A file named by a ``filename`` parameter, copied into ``folder`` (meshes into
    ``meshes/``) and named relative to it; a name that is not an existing file is kept."""
    src = Path(value)
    if not src.is_file():
        return value
    src = src.resolve()
    if src in copied:
        return copied[src]
    try:
        rel = src.relative_to(folder.resolve()).as_posix()
    except ValueError:
        sub = Path("meshes") if src.suffix.lower() in _MESH_EXTS else Path()
        dest = folder / sub / src.name
        k = 1
        while dest.exists() and not filecmp.cmp(dest, src, shallow=False):
            dest = folder / sub / f"{src.stem}_{k}{src.suffix}"
            k += 1
        dest.parent.mkdir(parents=True, exist_ok=True)
        if not dest.exists():
            shutil.copyfile(src, dest)
        rel = dest.relative_to(folder).as_posix()
    copied[src] = rel
    return rel


def _element(key: str, value, parent: str, folder: Path, copied: dict, top: bool = False):
    """The XML element of one scene-dict entry."""
    if isinstance(value, dict):
        kind = value.get("type")
        if kind == "rgb":
            return ET.Element("rgb", name=key, value=" ".join(map(_num, value["value"])))
        if kind == "spectrum":
            v = value["value"]
            text = (_num(v) if np.isscalar(v) else
                    ", ".join(f"{_num(a)}:{_num(b)}" for a, b in v))
            return ET.Element("spectrum", name=key, value=text)
        if kind == "ref":
            return ET.Element("ref", name=key, id=str(value["id"]))
        tag = _tag(str(kind), key, parent)
        attrs = {"type": str(kind), ("id" if top else "name"): key}
        if "id" in value:
            attrs["id"] = str(value["id"])
        el = ET.Element(tag, attrs)
        for k, v in value.items():
            if k not in ("type", "id"):
                el.append(_element(k, v, tag, folder, copied))
        return el
    if isinstance(value, (bool, np.bool_)):
        return ET.Element("boolean", name=key, value=str(bool(value)).lower())
    if isinstance(value, (int, np.integer)):
        return ET.Element("integer", name=key, value=str(int(value)))
    if isinstance(value, (float, np.floating)):
        return ET.Element("float", name=key, value=_num(value))
    if isinstance(value, (str, os.PathLike)):
        text = _relocate(os.fspath(value), folder, copied) if key == "filename" else str(value)
        return ET.Element("string", name=key, value=text)
    if hasattr(value, "matrix"):
        el = ET.Element("transform", name=key)
        m = np.array(value.matrix, dtype=np.float64).ravel()
        ET.SubElement(el, "matrix", value=" ".join(map(_num, m)))
        return el
    try:
        xyz = [float(c) for c in value]
    except (TypeError, ValueError):
        xyz = []
    if len(xyz) == 3:
        return ET.Element("vector", name=key, x=_num(xyz[0]), y=_num(xyz[1]), z=_num(xyz[2]))
    raise InputError(f"cannot write {key!r} ({type(value).__name__}) in Mitsuba's XML",
                     param="scene")


def write_scene_xml(scene: dict, folder) -> Path:
    """Write a :func:`build_scene` dictionary as ``folder/scene.xml`` (Mitsuba 3 XML), so
    the scene can be re-rendered or edited in Mitsuba directly.

    Files named by ``filename`` parameters (meshes, a material file) are copied into
    ``folder`` (meshes into ``meshes/``) and named relative to it, so the folder is
    self-contained; a ``filename`` that is not an existing file is written as given. A
    custom plugin type is written as such (``<bsdf type="microfacet_thinfilm">``): register
    the plugin before ``mitsuba.load_file``. Top-level objects get their key as ``id``.

    Parameters
    ----------
    scene : dict
        A Mitsuba scene dict (``"type": "scene"``).
    folder : path
        Created if needed.

    Returns
    -------
    Path
        ``folder/scene.xml``.
    """
    folder = Path(folder)
    if not isinstance(scene, dict) or scene.get("type") != "scene":
        raise InputError("expected a Mitsuba scene dict ('type': 'scene')", param="scene")
    folder.mkdir(parents=True, exist_ok=True)
    root = ET.Element("scene", version="3.0.0")
    copied: dict = {}
    for key, value in scene.items():
        if key != "type":
            root.append(_element(key, value, "scene", folder, copied, top=True))
    ET.indent(root)
    path = folder / SCENE_FILE
    tmp = path.with_name(path.name + ".tmp")
    tmp.write_text('<?xml version="1.0" encoding="utf-8"?>\n' + ET.tostring(
        root, encoding="unicode") + "\n", encoding="utf-8")
    os.replace(tmp, path)
    return path
