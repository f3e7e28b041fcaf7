"""microfacet.render.scene: the photographic set-up, checked on renders.

The field of view follows the focal length, the sensor and the focus distance (a plate of
known width covers the predicted number of pixels); a thin lens blurs an out-of-focus plate
by the predicted circle of confusion and leaves an in-focus one sharp; a white Lambertian
plate under a light of E lux renders at luminance E/π cd/m² and at D65's chromaticity; the
exposure follows ISO 12232; the bent sheet's normals are the cylinder's; the scene written as
XML renders the image the dictionary renders.
"""

from __future__ import annotations

import math

import numpy as np
import pytest

mi = pytest.importorskip("mitsuba")
dr = pytest.importorskip("drjit")

from microfacet.colour.srgb import SRGB_TO_XYZ  # noqa: E402
from microfacet.core.errors import InputError  # noqa: E402
from microfacet.render.scene import (  # noqa: E402
    Camera,
    Light,
    Plate,
    Sheet,
    build_scene,
    luminance_cd_m2,
    scene_object,
    write_ply,
)

WHITE = {"type": "diffuse", "reflectance": 1.0}
#: D65's chromaticity (CIE 015:2018, 2° observer).
D65_XY = (0.31272, 0.32903)
#: A light at the zenith with no ambient: the plate is lit uniformly.
ZENITH_SUN = Light(kind="sun", illuminance_lux=1000.0, elevation_deg=90.0, sky_fraction=0.0)


def render(scene: dict, *, spp: int, seed: int = 0) -> np.ndarray:
    return np.array(mi.render(mi.load_dict(scene), spp=spp, seed=seed), dtype=np.float64)


def top_view(**kw) -> Camera:
    """A camera straight above the plate (the plate faces it)."""
    return Camera(**{"elevation_deg": 90.0, "distance_m": 0.5, "pinhole": True, **kw})


@pytest.mark.parametrize("focal_length_mm", [35.0, 85.0])
def test_a_plate_covers_the_image_fraction_the_lens_and_sensor_predict(variant,
                                                                       focal_length_mm):
    cam = top_view(focal_length_mm=focal_length_mm, width_px=96, height_px=64)
    img = render(build_scene(obj=Plate(size_m=0.1), bsdf=WHITE, camera=cam,
                             light=ZENITH_SUN), spp=8)
    cover = luminance_cd_m2(img) / (1000.0 / math.pi)        # 1 on the plate, 0 off it
    # thin lens focused on the plate: image size = object size × f / (d − f)
    m = focal_length_mm / (500.0 - focal_length_mm)
    expect_w = 100.0 * m / 36.0 * 96                          # sensor 36 mm over 96 px
    expect_h = 100.0 * m / 24.0 * 64                          # 3:2 image: the whole sensor
    rows, cols = cover[28:36].sum(axis=1), cover[:, 44:52].sum(axis=0)
    assert rows.mean() == pytest.approx(expect_w, abs=0.25)
    assert cols.mean() == pytest.approx(expect_h, abs=0.25)
    # the pinhole's 2·atan(w/2f) framing would give a plate 1 + f/(d − f) times smaller
    assert abs(rows.mean() - expect_w / (1 + m)) > 1.0


def _disc_edge(t, radius):
    """Fraction of a uniform disc of ``radius`` (px) left of the line x = t."""
    if radius == 0:
        return (t > 0).astype(float)
    t = np.clip(t / radius, -1.0, 1.0)
    return 0.5 + (t * np.sqrt(1 - t * t) + np.arcsin(t)) / math.pi


def _blurred_plate_profile(x0, x1, radius, n_px):
    """Pixel averages of a plate spanning [x0, x1] px blurred by a disc of ``radius`` px."""
    x = (np.arange(n_px * 50) + 0.5) / 50.0
    f = _disc_edge(x - x0, radius) - _disc_edge(x - x1, radius)
    return f.reshape(n_px, 50).mean(axis=1)


@pytest.mark.parametrize("focus_distance_m", [0.5, 0.3])
def test_a_thin_lens_blurs_by_the_circle_of_confusion(variant, focus_distance_m):
    d, s, f_mm, n = 0.5, focus_distance_m, 50.0, 2.0
    cam = top_view(focal_length_mm=f_mm, f_number=n, pinhole=False, focus_distance_m=s,
                   width_px=96, height_px=64)
    img = render(build_scene(obj=Plate(size_m=0.1), bsdf=WHITE, camera=cam,
                             light=ZENITH_SUN), spp=64)
    profile = (luminance_cd_m2(img) / (1000.0 / math.pi))[24:40].mean(axis=0)
    v_mm = f_mm * s / (s - f_mm / 1e3)                         # image distance
    px_mm = 36.0 / 96
    width_px = 100.0 * v_mm / (d * 1e3) / px_mm               # the plate through the lens centre
    coc_px = (f_mm / n) * v_mm * abs(s - d) / (d * s) / 1e3 / px_mm
    x0, x1 = 48 - width_px / 2, 48 + width_px / 2
    expect = _blurred_plate_profile(x0, x1, coc_px / 2, 96)
    sharp = _blurred_plate_profile(x0, x1, 0.0, 96)
    assert np.abs(profile - expect).max() < 0.05
    if s == d:
        assert coc_px == 0.0
    else:
        assert coc_px > 4.0 and np.abs(profile - sharp).max() > 0.25


@pytest.mark.parametrize("light, factor", [
    (ZENITH_SUN, 1.0),
    (ZENITH_SUN.replace(elevation_deg=30.0), 0.5),                    # cos 60° incidence
    (ZENITH_SUN.replace(kind="point", distance_m=0.4), 1.0),          # lamp above the centre
    (ZENITH_SUN.replace(elevation_deg=-90.0, sky_fraction=0.5), 0.5),  # ambient only
])
def test_a_white_plate_renders_at_illuminance_over_pi(variant, light, factor):
    cam = top_view(width_px=16, height_px=16)
    img = render(build_scene(obj=Plate(size_m=0.3), bsdf=WHITE, camera=cam, light=light),
                 spp=256)                        # 4 wavelengths a sample: colour noise
    centre = img[4:12, 4:12].reshape(-1, 3)
    falloff = 1.0
    if light.kind == "point":     # (d/√(d² + r²))³ at the pixels' footprints on the plate
        px_m = 0.5 * 24.0 / (50.0 * 500.0 / 450.0) / 16       # square crop: 24 mm wide
        xy = (np.arange(4, 12) + 0.5 - 8) * px_m
        r2 = xy[:, None] ** 2 + xy[None, :] ** 2
        falloff = np.mean((light.distance_m ** 2 / (light.distance_m ** 2 + r2)) ** 1.5)
    lum = luminance_cd_m2(centre).mean()
    assert lum == pytest.approx(factor * falloff * 1000.0 / math.pi, rel=0.01)
    xyz = centre.mean(axis=0) @ SRGB_TO_XYZ.T
    assert xyz[:2] / xyz.sum() == pytest.approx(D65_XY, abs=0.002)


def test_exposure_follows_iso_12232(variant):
    far = top_view(width_px=16, height_px=16, shutter_s=1 / 125, iso=100.0, f_number=8.0,
                   focus_distance_m=1e4)
    img = render(build_scene(obj=Plate(size_m=0.3), bsdf=WHITE, camera=far,
                             light=ZENITH_SUN), spp=16)
    value = far.exposure_scale() * luminance_cd_m2(img[6:10, 6:10]).mean()
    # H = (π/4)(E/π) t / N², saturation at H = 78/ISO lx·s
    assert value == pytest.approx(1000.0 * (1 / 125) * 100.0 / (312.0 * 64.0), rel=0.01)
    # focused at 2f the lens is racked out to 2f: a quarter of the light (N_w = 2N)
    near = far.replace(focus_distance_m=0.1)
    assert near.exposure_scale() / far.exposure_scale() == pytest.approx(0.25, rel=1e-4)


def test_the_sheet_has_the_cylinders_normals_and_outward_faces(tmp_path, variant):
    sheet = Sheet(width_m=0.05, arc_length_m=0.1, bend_radius_m=0.06, segments=24)
    m = sheet.mesh()
    n = m.normals
    assert np.allclose(np.linalg.norm(n, axis=1), 1.0, atol=1e-12)
    assert np.allclose(n[:, 1], 0.0)                      # perpendicular to the axis (y)
    axis_z = m.positions_m[:, 2] - 0.06 * n[:, 2]          # p − R·n is on the axis
    assert np.allclose(m.positions_m[:, 0] - 0.06 * n[:, 0], 0.0, atol=1e-12)
    assert np.ptp(axis_z) < 1e-12
    box = np.stack([m.positions_m.min(0), m.positions_m.max(0)])
    assert np.allclose(box.mean(axis=0), 0.0, atol=1e-12)  # centred on the origin
    a, b, c = (m.positions_m[m.faces[:, k]] for k in range(3))
    face_n = np.cross(b - a, c - a)
    assert np.all(np.einsum("ij,ij->i", face_n, n[m.faces].mean(axis=1)) > 0)
    # the PLY Mitsuba reads back holds the same vertices and normals
    shape = mi.load_dict({"type": "ply", "filename": str(write_ply(tmp_path / "s.ply", m)),
                          "face_normals": False})
    params = mi.traverse(shape)
    assert np.allclose(np.array(params["vertex_normals"]).reshape(-1, 3), n, atol=1e-6)
    assert np.allclose(np.array(params["vertex_positions"]).reshape(-1, 3), m.positions_m,
                       atol=1e-7)


def test_bad_objects_and_cameras_are_refused_naming_the_parameter(tmp_path):
    with pytest.raises(InputError) as e:
        scene_object(tmp_path / "missing.ply")
    assert e.value.param == "scene" and "missing.ply" in str(e.value)
    (tmp_path / "mesh.stl").write_text("solid x\n")
    with pytest.raises(InputError) as e:
        scene_object(tmp_path / "mesh.stl")
    assert e.value.param == "scene" and "mesh.stl" in str(e.value)
    with pytest.raises(InputError) as e:
        Camera(focal_length_mm=50.0, distance_m=0.04)
    assert e.value.param == "distance_m"
    with pytest.raises(InputError) as e:
        Light(kind="laser")
    assert e.value.param == "kind"
