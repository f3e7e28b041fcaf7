"""The seed's photographic set-up as a Mitsuba 3 scene: a D65 light, a camera given as a
photographer gives it, and an object carrying a BSDF (seed §2.6).

Scene units are metres. The object's centre is at the origin; a plate lies in the xy plane
facing +z; the camera and the light are placed by their distance from the origin, their
elevation above the xy plane and their azimuth from +x. The defaults are a lab photograph of
a titanium plate under a D65 source: a 50 mm lens on a full-frame (36 × 24 mm) sensor at
f/8, 1/15 s, ISO 100, 0.3 m from a 10 cm plate at 45° elevation, a D65 lamp giving 1000 lx at
the plate from 45° on the mirror side, and a D65 room ambient of a tenth of that.

Photometric units (measured: ``tests/render/test_scene.py``)
    Mitsuba's spectral film reports, for a radiance spectrum L(λ) in the scene's units,
    Y = ∫ L(λ) ȳ(λ) dλ (CIE 1931 ȳ, peak 1), and the ``d65`` spectrum at ``scale`` s has
    ∫ s·S(λ) ȳ(λ) dλ = s (Mitsuba divides the CIE table by 10568). The lights here are
    ``d65`` spectra scaled by their illuminance in lux (:class:`Light`), which puts every
    spectrum in units of 1/683 W m⁻² nm⁻¹ (sr⁻¹): one unit of Y in a render is a luminance
    of 1 cd/m². A white Lambertian plate facing a light of E lux renders at Y = E/π
    (:func:`luminance_cd_m2` of the ``rgb`` film; tests/render/test_scene.py checks it within
    Monte Carlo noise).

Exposure (:meth:`Camera.exposure_scale`)
    ISO 12232's saturation-based speed: a sensor saturates at a focal-plane exposure
    H_sat = 78/ISO lx·s; a lens of working f-number N_w passes H = (π/4)·L·t/N_w² of a
    luminance L (vignetting and transmission ignored), so a render times
    π·t·ISO/(312·N_w²) is the sensor value with 1 at saturation. N_w = N·(1 + m) with the
    magnification m = f/(s − f) at the focus distance s (close up, the lens is racked out:
    about 0.5 EV darker at the default 0.3 m); at infinity focus N_w = N. At the defaults a
    white diffuser facing the lamp sits at 0.23 of saturation, room for the film's lobe.

Field of view
    The lens is a thin lens focused at ``focus_distance_m``: the image distance is
    v = f·s/(s − f) and the horizontal field of view 2·atan(w/2v) of the sensor width w
    used (a real lens "breathes" like this when focused close: a 50 mm lens at 0.3 m frames
    18 cm, not the 22 cm 2·atan(18/50) would give). An image whose aspect differs from the
    sensor's is a centred crop of it. ``pinhole=True`` keeps the framing and drops the depth
    of field.

Examples
--------
>>> cam = Camera()
>>> round(cam.fov_x_deg, 2), cam.size_px, round(cam.aperture_radius_m * 1e3, 3)
(33.4, (512, 341), 3.125)
>>> round(Camera(focal_length_mm=50.0, focus_distance_m=1e6).fov_x_deg, 2)   # at infinity
39.6
"""

from __future__ import annotations

import atexit
import hashlib
import math
import os
import shutil
import tempfile
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from ..colour.srgb import SRGB_TO_XYZ
from ..core.errors import InputError
from ..core.lazy import load
from ..core.options import Options, option

mi = load("mitsuba", keep=False)

__all__ = ["MAX_DEPTH", "MESH_TYPES", "OBJECTS", "SCENE_FILE", "Camera", "Light", "Plate",
           "Sheet", "Sphere", "TriangleMesh", "UserMesh", "build_scene", "gonio_scene",
           "luminance_cd_m2", "scene_object", "write_ply"]

#: Path-tracing depth: the camera ray, direct light at the object, one inter-reflection (a
#: bent sheet or a user's concave mesh); a plate or a sphere needs 2.
MAX_DEPTH = 3
#: The scene file :func:`write_scene_xml` writes.
SCENE_FILE = "scene.xml"
#: Objects by name (:func:`scene_object`); anything else is a path to a mesh.
OBJECTS = ("plate", "sheet", "sphere")
#: Mesh files Mitsuba loads, by extension: the shape plugin.
MESH_TYPES = {".obj": "obj", ".ply": "ply", ".serialized": "serialized"}


def _placement(distance_m: float, elevation_deg: float, azimuth_deg: float) -> np.ndarray:
    el, az = math.radians(elevation_deg), math.radians(azimuth_deg)
    return distance_m * np.array([math.cos(el) * math.cos(az), math.cos(el) * math.sin(az),
                                  math.sin(el)])


def _transform():
    """Mitsuba's ScalarTransform4f of the variant set (an InputError when none is)."""
    if mi.variant() is None:
        raise InputError("set a Mitsuba variant first: mitsuba.set_variant(v) with v from "
                         "microfacet.render.variants.choose_variant()", param="variant")
    return mi.ScalarTransform4f


@dataclass(frozen=True)
class Camera(Options):
    """The camera as the photograph was taken: lens, sensor, exposure, placement, image.

    Constructing one validates it (an InputError names the field). Geometry: see the module
    notes (thin lens focused at ``focus_distance_m``, centred crop of the sensor).
    """

    CLI_PREFIX = "camera-"
    focal_length_mm: float = option(50.0, help="lens focal length", unit="mm", low=0,
                                    low_exclusive=True, cli=True)
    sensor_width_mm: float = option(36.0, help="sensor width", unit="mm", low=0,
                                    low_exclusive=True, cli=True)
    sensor_height_mm: float = option(24.0, help="sensor height", unit="mm", low=0,
                                     low_exclusive=True, cli=True)
    f_number: float = option(8.0, help="aperture f-number N (depth of field and exposure)",
                             low=0.5, cli=True)
    pinhole: bool = option(False, help="no depth of field (f_number still sets the exposure)",
                           cli=True)
    focus_distance_m: float | None = option(
        None, kind=float, help="focused distance from the lens (default: distance_m)",
        unit="m", low=0, low_exclusive=True, cli=True)
    shutter_s: float = option(1 / 15, help="exposure time", unit="s", low=0,
                              low_exclusive=True, cli=True)
    iso: float = option(100.0, help="ISO speed (ISO 12232 saturation-based)", low=0,
                        low_exclusive=True, cli=True)
    distance_m: float = option(0.3, help="lens to the object's centre", unit="m", low=0,
                               low_exclusive=True, cli=True)
    elevation_deg: float = option(45.0, help="camera elevation above the plate's plane",
                                  unit="deg", low=-90.0, high=90.0, cli=True)
    azimuth_deg: float = option(0.0, help="camera azimuth from +x", unit="deg", low=-360.0,
                                high=360.0, cli=True)
    width_px: int = option(512, help="image width", unit="px", low=1, high=16384, cli=True)
    height_px: int | None = option(None, kind=int, help="image height (default: the "
                                   "sensor's aspect)", unit="px", low=1, high=16384, cli=True)

    def __post_init__(self):
        super().__post_init__()
        f_m = self.focal_length_mm / 1e3
        if self.focus_m <= f_m:
            param = "focus_distance_m" if self.focus_distance_m is not None else "distance_m"
            raise InputError(f"must be more than the focal length ({f_m:g} m) to focus, got "
                             f"{self.focus_m!r}", param=param)

    @property
    def size_px(self) -> tuple[int, int]:
        """(width, height) of the image, px."""
        h = self.height_px or round(self.width_px * self.sensor_height_mm /
                                    self.sensor_width_mm)
        return int(self.width_px), max(int(h), 1)

    @property
    def crop_mm(self) -> tuple[float, float]:
        """(width, height) of the sensor area the image covers (a centred crop), mm."""
        w, h = self.size_px
        if w / h >= self.sensor_width_mm / self.sensor_height_mm:
            return self.sensor_width_mm, self.sensor_width_mm * h / w
        return self.sensor_height_mm * w / h, self.sensor_height_mm

    @property
    def focus_m(self) -> float:
        """Focused distance from the lens, m."""
        return float(self.focus_distance_m if self.focus_distance_m is not None
                     else self.distance_m)

    @property
    def magnification(self) -> float:
        """m = f/(s − f) at the focus distance s."""
        f = self.focal_length_mm
        return f / (self.focus_m * 1e3 - f)

    @property
    def image_distance_mm(self) -> float:
        """Lens to sensor, v = f(1 + m), mm."""
        return self.focal_length_mm * (1.0 + self.magnification)

    @property
    def fov_x_deg(self) -> float:
        """Horizontal field of view of the image, deg."""
        return math.degrees(2.0 * math.atan(self.crop_mm[0] / (2.0 * self.image_distance_mm)))

    @property
    def aperture_radius_m(self) -> float:
        """Entrance-pupil radius f/(2N), m."""
        return self.focal_length_mm / (2.0 * self.f_number) / 1e3

    @property
    def working_f_number(self) -> float:
        """N·(1 + m): the f-number the sensor sees at the focus distance."""
        return self.f_number * (1.0 + self.magnification)

    def exposure_scale(self) -> float:
        """The factor from a render (Y in cd/m², see the module notes) to sensor values with
        1.0 at saturation (ISO 12232): π·t·ISO / (312·N_w²), per cd/m².

        >>> cam = Camera(shutter_s=1 / 125, iso=100.0, f_number=8.0, focus_distance_m=1e6)
        >>> round(1.0 / cam.exposure_scale())    # the luminance that saturates, cd/m²
        7945
        """
        return math.pi * self.shutter_s * self.iso / (312.0 * self.working_f_number ** 2)

    @property
    def position_m(self) -> np.ndarray:
        """Lens centre (3,), m."""
        return _placement(self.distance_m, self.elevation_deg, self.azimuth_deg)

    def sensor(self, *, spp: int = 64) -> dict:
        """Mitsuba's sensor: ``thinlens`` (``perspective`` for a pinhole) looking at the
        origin, image up towards the far side of the plate, an ``hdrfilm`` (linear sRGB,
        float32) with a box pixel filter — a sensor pixel integrates the light on its area,
        so neighbouring pixels stay independent and edges are not widened (the default
        Gaussian would blur both) — and an independent sampler of ``spp`` samples."""
        el, az = math.radians(self.elevation_deg), math.radians(self.azimuth_deg)
        up = [-math.sin(el) * math.cos(az), -math.sin(el) * math.sin(az), math.cos(el)]
        w, h = self.size_px
        d = {"type": "perspective" if self.pinhole else "thinlens",
             "fov": self.fov_x_deg, "fov_axis": "x",
             "to_world": _transform()().look_at(origin=self.position_m.tolist(),
                                                target=[0.0, 0.0, 0.0], up=up),
             "film": {"type": "hdrfilm", "width": w, "height": h, "pixel_format": "rgb",
                      "component_format": "float32", "rfilter": {"type": "box"}},
             "sampler": {"type": "independent", "sample_count": int(spp)}}
        if not self.pinhole:
            d.update(aperture_radius=self.aperture_radius_m, focus_distance=self.focus_m)
        return d


@dataclass(frozen=True)
class Light(Options):
    """A D65 light: a point lamp or the sun, and a uniform D65 ambient (sky or room).

    ``illuminance_lux`` is what the lamp or the sun gives at the object's centre on a surface
    facing it; the ambient is a constant environment whose illuminance on a horizontal
    (+z-facing) surface is ``sky_fraction`` × that. Spectra in 1/683 W m⁻² nm⁻¹ (module
    notes): a point lamp has intensity E·d² (cd), the ambient radiance f·E/π (cd/m²).
    """

    CLI_PREFIX = "light-"
    kind: str = option("point", help="a lamp at distance_m or the sun (parallel light)",
                       choices=("point", "sun"), cli=True)
    illuminance_lux: float = option(1000.0, help="illuminance at the object's centre, facing "
                                    "the light", unit="lx", low=0.0, cli=True)
    elevation_deg: float = option(45.0, help="light elevation above the plate's plane",
                                  unit="deg", low=-90.0, high=90.0, cli=True)
    azimuth_deg: float = option(180.0, help="light azimuth from +x (180: the mirror side of "
                                "a camera at 0)", unit="deg", low=-360.0, high=360.0, cli=True)
    distance_m: float = option(0.5, help="lamp to the object's centre (point light)",
                               unit="m", low=0.0, low_exclusive=True, cli=True)
    sky_fraction: float = option(0.1, help="ambient illuminance on a horizontal surface / "
                                 "illuminance_lux", low=0.0, cli=True)

    @property
    def direction(self) -> np.ndarray:
        """Unit vector (3,) from the object's centre towards the light."""
        return _placement(1.0, self.elevation_deg, self.azimuth_deg)

    def emitters(self) -> dict:
        """``{"light": …, "sky": …}`` Mitsuba emitters (no sky when ``sky_fraction`` is 0)."""
        e = float(self.illuminance_lux)
        if self.kind == "sun":
            out = {"light": {"type": "directional", "direction": (-self.direction).tolist(),
                             "irradiance": {"type": "d65", "scale": e}}}
        else:
            out = {"light": {"type": "point",
                             "position": (self.distance_m * self.direction).tolist(),
                             "intensity": {"type": "d65", "scale": e * self.distance_m ** 2}}}
        if self.sky_fraction > 0:
            out["sky"] = {"type": "constant",
                          "radiance": {"type": "d65", "scale": self.sky_fraction * e / math.pi}}
        return out


def _positive(value, name: str) -> float:
    v = float(value)
    if not (math.isfinite(v) and v > 0):
        raise InputError(f"must be finite and > 0, got {value!r}", param=name)
    return v


@dataclass(frozen=True)
class TriangleMesh:
    """A triangle mesh: ``positions_m`` (V, 3), unit ``normals`` (V, 3), ``texcoords``
    (V, 2) in [0, 1], ``faces`` (F, 3) vertex indices, counter-clockwise seen from the side
    the normals point to."""

    positions_m: np.ndarray
    normals: np.ndarray
    texcoords: np.ndarray
    faces: np.ndarray


def write_ply(path, mesh: TriangleMesh) -> Path:
    """Write ``mesh`` as a binary little-endian PLY (x y z nx ny nz u v; faces as lists);
    written to a temporary name and renamed, so a reader never sees half a file."""
    path = Path(path)
    n_v, n_f = len(mesh.positions_m), len(mesh.faces)
    header = "\n".join([
        "ply", "format binary_little_endian 1.0", f"element vertex {n_v}",
        *[f"property float {c}" for c in ("x", "y", "z", "nx", "ny", "nz", "u", "v")],
        f"element face {n_f}", "property list uchar int vertex_indices", "end_header", ""])
    vertices = np.concatenate([mesh.positions_m, mesh.normals, mesh.texcoords],
                              axis=1).astype("<f4")
    faces = np.empty(n_f, dtype=[("n", "u1"), ("i", "<i4", (3,))])
    faces["n"], faces["i"] = 3, mesh.faces
    tmp = path.with_name(path.name + ".tmp")
    tmp.write_bytes(header.encode("ascii") + vertices.tobytes() + faces.tobytes())
    os.replace(tmp, path)
    return path


@dataclass(frozen=True)
class Plate:
    """A flat square plate of side ``size_m`` (m) in the xy plane, facing +z."""

    size_m: float = 0.1

    def __post_init__(self):
        _positive(self.size_m, "size_m")

    def shape(self, bsdf: dict, *, mesh_folder=None) -> dict:
        """The Mitsuba shape (``rectangle``) carrying ``bsdf``."""
        h = self.size_m / 2.0
        return {"type": "rectangle", "to_world": _transform()().scale([h, h, 1.0]),
                "bsdf": bsdf}


@dataclass(frozen=True)
class Sphere:
    """A sphere of radius ``radius_m`` (m) at the origin."""

    radius_m: float = 0.04

    def __post_init__(self):
        _positive(self.radius_m, "radius_m")

    def shape(self, bsdf: dict, *, mesh_folder=None) -> dict:
        """The Mitsuba shape (``sphere``) carrying ``bsdf``."""
        return {"type": "sphere", "center": [0.0, 0.0, 0.0], "radius": float(self.radius_m),
                "bsdf": bsdf}


@dataclass(frozen=True)
class Sheet:
    """A bent sheet: a section of a cylinder of radius ``bend_radius_m`` whose axis is y,
    ``width_m`` along the axis and ``arc_length_m`` around it, convex towards +z (its normals
    sweep the xz plane, the plane of the default camera and light), centred on the origin,
    with ``segments`` facets around the bend."""

    width_m: float = 0.1
    arc_length_m: float = 0.1
    bend_radius_m: float = 0.08
    segments: int = 96

    def __post_init__(self):
        for name in ("width_m", "arc_length_m", "bend_radius_m"):
            _positive(getattr(self, name), name)
        if self.arc_length_m / self.bend_radius_m >= math.pi:
            raise InputError("must be less than π × `bend_radius_m` (half a cylinder), got "
                             f"{self.arc_length_m!r}", param="arc_length_m")
        if int(self.segments) != self.segments or self.segments < 1:
            raise InputError(f"must be a whole number >= 1, got {self.segments!r}",
                             param="segments")

    def mesh(self) -> TriangleMesh:
        """The sheet's triangles with the cylinder's normals at the vertices."""
        r, n = self.bend_radius_m, int(self.segments)
        phi = np.linspace(-0.5, 0.5, n + 1) * (self.arc_length_m / r)
        y = np.array([-0.5, 0.5]) * self.width_m
        z0 = r * (1.0 + math.cos(phi[-1])) / 2.0          # bounding box centre on the origin
        P, Y = np.meshgrid(phi, y, indexing="ij")          # (n + 1, 2)
        normals = np.stack([np.sin(P), np.zeros_like(P), np.cos(P)], -1).reshape(-1, 3)
        positions = np.stack([r * np.sin(P), Y, r * np.cos(P) - z0], -1).reshape(-1, 3)
        uv = np.stack([(P - phi[0]) / (phi[-1] - phi[0]), (Y - y[0]) / self.width_m],
                      -1).reshape(-1, 2)
        i = np.arange(n)[:, None]
        a, b, c, d = 2 * i, 2 * i + 2, 2 * i + 3, 2 * i + 1   # (φ, y): (i,0) (i+1,0) (i+1,1) (i,1)
        faces = np.concatenate([np.hstack([a, b, c]), np.hstack([a, c, d])]).astype(np.int32)
        return TriangleMesh(positions, normals, uv, faces)

    def shape(self, bsdf: dict, *, mesh_folder=None) -> dict:
        """The Mitsuba shape (``ply``, vertex normals) carrying ``bsdf``; the PLY is written
        to ``mesh_folder`` (default: a temporary folder of this process)."""
        folder = Path(mesh_folder) if mesh_folder is not None else _temp_folder()
        folder.mkdir(parents=True, exist_ok=True)
        key = hashlib.sha1(repr(self).encode()).hexdigest()[:10]
        path = folder / f"sheet-{key}.ply"
        if not path.is_file():
            write_ply(path, self.mesh())
        return {"type": "ply", "filename": str(path), "face_normals": False, "bsdf": bsdf}


@dataclass(frozen=True)
class UserMesh:
    """A mesh file (``.obj``, ``.ply``, ``.serialized``) scaled by ``scale_m`` (metres per
    mesh unit) and moved so that its bounding box is centred on the origin; z is up."""

    path: Path
    scale_m: float = 1.0

    def __post_init__(self):
        p = Path(self.path).expanduser()
        object.__setattr__(self, "path", p)
        if p.suffix.lower() not in MESH_TYPES:
            raise InputError(f"{p}: not a mesh Mitsuba reads (expected "
                             f"{', '.join(MESH_TYPES)}) nor one of {', '.join(OBJECTS)}",
                             param="scene")
        if not p.is_file():
            raise InputError(f"{p}: no such mesh file", param="scene")
        _positive(self.scale_m, "scale_m")

    def shape(self, bsdf: dict, *, mesh_folder=None) -> dict:
        """The Mitsuba shape carrying ``bsdf`` (the file is read once for its bounds)."""
        T = _transform()
        kind = MESH_TYPES[self.path.suffix.lower()]
        box = mi.load_dict({"type": kind, "filename": str(self.path)}).bbox()
        centre = [-0.5 * (float(box.min[k]) + float(box.max[k])) for k in range(3)]
        return {"type": kind, "filename": str(self.path),
                "to_world": T().scale(float(self.scale_m)).translate(centre), "bsdf": bsdf}


def scene_object(spec) -> Plate | Sheet | Sphere | UserMesh:
    """The object named by ``spec``: ``"plate"``, ``"sheet"``, ``"sphere"`` (defaults), a mesh
    path, or an object itself (returned as is).

    >>> scene_object("plate")
    Plate(size_m=0.1)
    """
    if isinstance(spec, (Plate, Sheet, Sphere, UserMesh)):
        return spec
    if isinstance(spec, str) and spec in OBJECTS:
        return {"plate": Plate, "sheet": Sheet, "sphere": Sphere}[spec]()
    if isinstance(spec, (str, os.PathLike)):
        return UserMesh(Path(spec))
    raise InputError(f"expected one of {', '.join(OBJECTS)} or a mesh path, got {spec!r}",
                     param="scene")


_TEMP: list[Path] = []


def _temp_folder() -> Path:
    if not _TEMP:
        path = Path(tempfile.mkdtemp(prefix="microfacet-render-"))
        atexit.register(shutil.rmtree, path, True)
        _TEMP.append(path)
    return _TEMP[0]


def build_scene(*, obj, bsdf: dict, camera: Camera | None = None, light: Light | None = None,
                integrator="path", spp: int = 64, mesh_folder=None) -> dict:
    """The Mitsuba scene dictionary (for ``mitsuba.load_dict``) of the photograph.

    Parameters
    ----------
    obj : str, path or Plate, Sheet, Sphere, UserMesh
        See :func:`scene_object`.
    bsdf : dict
        The object's BSDF as a Mitsuba dict (a registered custom type is fine).
    camera, light : Camera, Light, optional
        Default: the seed's lab set-up (module notes).
    integrator : str or dict
        A Mitsuba integrator type (``max_depth`` :data:`MAX_DEPTH`) or a full dict.
    spp : int
        Samples per pixel of the sampler (``mitsuba.render(spp=…)`` overrides it).
    mesh_folder : path, optional
        Where a generated mesh (the sheet's PLY) is written; default a temporary folder.

    Returns
    -------
    dict
        Keys ``integrator``, ``camera``, ``object``, ``light`` and (ambient) ``sky``. A
        Mitsuba variant must be set (transforms are the variant's).
    """
    camera = Camera() if camera is None else camera
    light = Light() if light is None else light
    if not isinstance(bsdf, dict) or "type" not in bsdf:
        raise InputError(f"expected a Mitsuba BSDF dict with a 'type', got {bsdf!r}",
                         param="bsdf")
    if isinstance(integrator, str):
        integrator = {"type": integrator, "max_depth": MAX_DEPTH}
    return {"type": "scene", "integrator": integrator, "camera": camera.sensor(spp=spp),
            "object": scene_object(obj).shape(bsdf, mesh_folder=mesh_folder),
            **light.emitters()}


def gonio_scene(*, bsdf: dict, theta_light_deg: float, theta_view_deg: float,
                irradiance_lux: float = 1.0, width_px: int = 8, spp: int = 256) -> dict:
    """A gonioreflectometer in Mitsuba: a large flat sample in the xy plane lit by a parallel
    D65 beam and seen by an orthographic camera, both in the xz plane of incidence (the
    angles of ``microfacet simulate``: the view positive on the mirror side), so that every
    pixel sees the same pair of directions.

    Parameters
    ----------
    bsdf : dict
        The sample's BSDF.
    theta_light_deg, theta_view_deg : float
        Zenith angles, degrees, in (−90, 90).
    irradiance_lux : float
        Illuminance of the beam on a surface facing it.
    width_px, spp : int
        Image side and samples per pixel (direct lighting only: ``direct`` integrator).

    Returns
    -------
    dict
        Render it and divide by a white Lambertian sample rendered the same way: the ratio
        is the reflectance factor π f_r of the two directions (``tests/render/test_bsdf.py``).

    Examples
    --------
    >>> import mitsuba as mi
    >>> mi.set_variant("scalar_spectral")
    >>> d = gonio_scene(bsdf={"type": "diffuse"}, theta_light_deg=30, theta_view_deg=20)
    >>> d["light"]["type"], d["camera"]["type"]
    ('directional', 'orthographic')
    """
    tl, tv = math.radians(theta_light_deg), math.radians(theta_view_deg)
    view = [5 * math.sin(tv), 0.0, 5 * math.cos(tv)]
    T = _transform()
    return {
        "type": "scene",
        "integrator": {"type": "direct", "emitter_samples": 1, "bsdf_samples": 0},
        "light": {"type": "directional", "direction": [math.sin(tl), 0.0, -math.cos(tl)],
                  "irradiance": {"type": "d65", "scale": float(irradiance_lux)}},
        "object": {"type": "rectangle", "bsdf": bsdf, "to_world": T().scale([10.0, 10.0, 1.0])},
        "camera": {"type": "orthographic",
                   "to_world": T().look_at(origin=view, target=[0, 0, 0], up=[0, 1, 0])
                   @ T().scale([0.5, 0.5, 1.0]),
                   "film": {"type": "hdrfilm", "width": int(width_px), "height": int(width_px),
                            "rfilter": {"type": "box"}, "pixel_format": "rgb"},
                   "sampler": {"type": "independent", "sample_count": int(spp)}},
    }


def luminance_cd_m2(image) -> np.ndarray:
    """Luminance (cd/m²) of a render of :func:`build_scene` (linear sRGB, H × W × ≥3): the Y
    of the film's RGB (module notes: one unit of Y is 1 cd/m² with these lights)."""
    img = np.asarray(image, dtype=np.float64)
    return img[..., :3] @ SRGB_TO_XYZ[1]
