"""``microfacet render``: the measured material on an object, photographed as in seed §2.6.

A results folder (or an exported material file) becomes a picture: the thin-film microfacet
BSDF (:mod:`microfacet.render.bsdf`) on a plate, a bent sheet, a sphere or the user's mesh,
under a D65 lamp or sun with a D65 ambient, seen by a camera given as focal length, sensor,
f-number, shutter and ISO (:mod:`microfacet.render.scene`), rendered by Mitsuba 3 in the
fastest spectral variant that works here (:mod:`microfacet.render.variants`).

The output folder (written whole or not at all, :mod:`microfacet.io.outdir`):

==================  ==========================================================
``render.exr``      float32 linear sRGB (D65 white), scene-referred: Y in cd/m²
``render.png``      8-bit sRGB as the camera exposed it (1 = sensor saturation, clipped)
``render.json``     ``microfacet-render/1``: inputs, options, variant, timings, exposure
``scene.xml``       the Mitsuba scene, with ``material.npz`` (and ``meshes/``) beside it:
                    re-render or edit it in Mitsuba after ``microfacet.render.register()``
==================  ==========================================================

The samples are rendered in :data:`PASSES` passes with their own seeds and averaged, so the
progress bar moves; what the passes cost is in docs/rendering.md (``speed-render``).
"""

from __future__ import annotations

import json
import os
import shutil
import time
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from .. import __version__
from ..core.errors import InputError
from ..core.lazy import load
from ..core.options import Options, option
from ..forward.material import Material
from ..io.material_file import read_material_file
from ..io.outdir import OutputFolder
from ..render import bsdf
from ..render.scene import Camera, Light, UserMesh, build_scene, luminance_cd_m2, scene_object
from ..render.scene_xml import write_scene_xml
from ..render.variants import choose_variant

mi = load("mitsuba", keep=False)

__all__ = ["PASSES", "RenderOptions", "RenderOutput", "render_to_folder"]

#: Passes the samples are split into (fewer when spp is smaller).
PASSES = 8
FORMAT = "microfacet-render/1"
MATERIAL_FILE = "material.npz"


@dataclass(frozen=True)
class RenderOptions(Options):
    """How to render: the object, the camera, the light, the samples and the variant."""

    scene: str = option("sphere", help="plate, sheet, sphere, or a mesh file (.obj, .ply, "
                        ".serialized)", cli=True, flag="--scene", metavar="OBJECT")
    spp: int = option(64, help="samples per pixel", low=1, high=1 << 20, cli=True,
                      flag="--spp")
    seed: int = option(0, help="random seed of the first pass", low=0, cli=True, flag="--seed")
    variant: str | None = option(None, kind=str, help="Mitsuba variant (default: the fastest "
                                 "spectral one that works here)", cli=True, flag="--variant")
    camera: Camera = option(Camera(), help="the camera")
    light: Light = option(Light(), help="the light")


@dataclass(frozen=True)
class RenderOutput:
    """What :func:`render_to_folder` wrote.

    Attributes
    ----------
    path : Path
        The output folder.
    variant : str
    note : str or None
        A one-line note when only a slow variant works.
    shape : (int, int)
        Image height and width, px.
    seconds : float
        Rendering time (all passes).
    saturated_fraction : float
        Pixels at or above sensor saturation in the exposed image.
    source : dict
        Where the material came from; ``ndf_identified`` False when the analysis did not
        identify the NDF it renders (``ndf_reason`` says why).
    """

    path: Path
    variant: str
    note: str | None
    shape: tuple
    seconds: float
    saturated_fraction: float
    source: dict


def passes(spp: int) -> list[int]:
    """Samples per pixel of each pass (:data:`PASSES` of them, fewer when ``spp`` is smaller).

    >>> passes(20), passes(3)
    ([3, 3, 3, 3, 2, 2, 2, 2], [1, 1, 1])
    """
    n = min(spp, PASSES)
    base, extra = divmod(spp, n)
    return [base + (k < extra) for k in range(n)]


def _material_into(folder: Path, *, results, material) -> dict:
    """Write the material file into ``folder``; returns where it came from (and whether the
    analysis identified its NDF)."""
    target = folder / MATERIAL_FILE
    if results is not None:
        m = Material.from_results(results)
        m.write(target)
        return dict(m.metadata.get("source", {}))
    _, meta = read_material_file(material)  # checked before it is copied
    shutil.copyfile(material, target)
    return {**meta.get("source", {}), "material": str(Path(material).resolve())}


def _render_passes(scene, shape, plan, seed, progress):
    """The mean of the passes' images (float64, H × W × 3)."""
    acc = np.zeros((*shape, 3))
    done = 0
    for k, spp in enumerate(plan):
        img = np.asarray(mi.render(scene, spp=spp, seed=seed + k), dtype=np.float64)
        acc += img[..., :3] * spp
        done += spp
        progress(k + 1, len(plan))
    return acc / done


def _write_images(folder: Path, linear, exposure_scale: float) -> float:
    """render.exr (scene-referred) and render.png (exposed, sRGB); the saturated fraction."""
    mi.Bitmap(np.ascontiguousarray(linear, dtype=np.float32),
              pixel_format=mi.Bitmap.PixelFormat.RGB).write(str(folder / "render.exr"))
    exposed = linear * exposure_scale
    png = mi.Bitmap(np.ascontiguousarray(np.clip(exposed, 0.0, 1.0), dtype=np.float32),
                    pixel_format=mi.Bitmap.PixelFormat.RGB)
    png.convert(mi.Bitmap.PixelFormat.RGB, mi.Struct.Type.UInt8,
                srgb_gamma=True).write(str(folder / "render.png"))
    return float(np.mean(np.max(exposed, axis=-1) >= 1.0))


def _check_sources(results, material, scene) -> list:
    if (results is None) == (material is None):
        raise InputError("give a results folder or a material file (one of them)",
                         param="results")
    inputs = [results if results is not None else material]
    obj = scene_object(scene)          # a user's mesh is checked (exists, known type) here
    if isinstance(obj, UserMesh):
        inputs.append(obj.path)
    return inputs


def render_to_folder(out, *, results=None, material=None, options: RenderOptions | None = None,
                     overwrite: bool = False, progress=None) -> RenderOutput:
    """Render the material and write the output folder ``out`` (module notes).

    Parameters
    ----------
    out : path-like
        The output folder (replaced only with ``overwrite`` and only if it is a render).
    results, material : path-like
        An ``analyze`` results folder, or a material file of ``export-brdf`` (one of them).
    options : RenderOptions, optional
    overwrite : bool
    progress : callable, optional
        ``progress(done, total)`` after each pass.

    Returns
    -------
    RenderOutput
    """
    options = options or RenderOptions()
    step = progress or (lambda done, total: None)
    inputs = _check_sources(results, material, options.scene)
    variant, note = choose_variant(options.variant)
    mi.set_variant(variant)
    bsdf.register()
    cam = options.camera
    h, w = cam.size_px[1], cam.size_px[0]
    with OutputFolder(out, kind="render", inputs=inputs, overwrite=overwrite,
                      expected_bytes=h * w * 16 + (8 << 20)) as claim, claim.writing() as tmp:
        source = _material_into(tmp, results=results, material=material)
        scene = build_scene(obj=options.scene, bsdf={"type": bsdf.PLUGIN, "filename": str(
            tmp / MATERIAL_FILE)}, camera=cam, light=options.light, spp=options.spp,
            mesh_folder=tmp / "meshes")
        write_scene_xml(scene, tmp)
        t0 = time.perf_counter()
        linear = _render_passes(mi.load_dict(scene), (h, w), passes(options.spp),
                                options.seed, step)
        seconds = time.perf_counter() - t0
        saturated = _write_images(tmp, linear, cam.exposure_scale())
        record = {"format": FORMAT, "microfacet_version": __version__, "source": source,
                  "options": options.to_dict(), "variant": variant, "note": note,
                  "seconds": seconds, "shape": [h, w],
                  "exposure_scale": cam.exposure_scale(),
                  "mean_luminance_cd_m2": float(np.mean(luminance_cd_m2(linear))),
                  "saturated_fraction": saturated,
                  "render_exr": "linear sRGB (D65 white), Y in cd/m² (scene-referred)",
                  "render_png": "sRGB, sensor value x exposure_scale, 1 = saturation"}
        (tmp / "render.json").write_text(json.dumps(record, indent=1), encoding="utf-8")
    return RenderOutput(Path(os.fspath(out)), variant, note, (h, w), seconds, saturated,
                        source)
