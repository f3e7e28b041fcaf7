"""Half-vector model: geometry (seed eq. 5) and colours."""

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from microfacet import colour as color
from microfacet.forward.angular import simulate_map
from microfacet.forward.halfvector import (
    half_angle_deg,
    half_angle_from_vectors,
    half_vector,
    in_plane_directions,
    spectra,
)
from microfacet.optics.thinfilm import reflectance

angle = st.floats(-89.0, 89.0)


@settings(max_examples=200, deadline=None)
@given(tl=angle, tv=angle)
def test_in_plane_half_angle_equals_half_the_angle_between_the_vectors(tl, tv):
    light, view = in_plane_directions(tl, tv)
    assert half_angle_from_vectors(light, view) == pytest.approx(half_angle_deg(tl, tv), abs=1e-9)
    # The half vector is tilted by (view - light)/2 in the plane.
    h = half_vector(light, view)
    tilt = np.rad2deg(np.arctan2(h[0], h[2]))
    assert tilt == pytest.approx((tv - tl) / 2, abs=1e-9)


def test_eq5_specular_and_retro():
    assert half_angle_deg(30.0, 30.0) == 30.0  # specular: the facet is the macro surface
    assert half_angle_deg(30.0, -30.0) == 0.0  # retro-reflection: normal incidence
    assert half_angle_deg(10.0, 45.0) == 27.5


@settings(max_examples=100, deadline=None)
@given(st.lists(st.floats(-1, 1), min_size=6, max_size=6))
def test_3d_half_angle_is_symmetric_and_matches_the_dot_product(v):
    l, w = np.array(v[:3]), np.array(v[3:])
    if np.linalg.norm(l) < 1e-3 or np.linalg.norm(w) < 1e-3:
        return
    cosang = np.dot(l, w) / np.linalg.norm(l) / np.linalg.norm(w)
    expected = np.rad2deg(np.arccos(np.clip(cosang, -1, 1))) / 2
    assert half_angle_from_vectors(l, w) == pytest.approx(expected, abs=1e-6)
    assert half_angle_from_vectors(w, l) == pytest.approx(half_angle_from_vectors(l, w), abs=1e-12)


def test_spectra_use_the_half_angle():
    wl, R = spectra(10.0, 50.0, 80.0, wavelength_nm=[450.0, 550.0, 650.0])
    ref = reflectance(wl, 30.0, 80.0, "TiO2_Jolivet2023_amorphous", "Ti_JohnsonChristy1974")
    np.testing.assert_allclose(R, ref, rtol=1e-14)


def test_half_vector_map_is_constant_along_the_antidiagonal_and_blue_at_51nm():
    m = simulate_map(model="half-vector", thickness=51.0,
                     theta_light_deg=np.arange(0, 61, 10.0),
                     theta_view_deg=np.arange(0, 61, 10.0))
    assert m.lab.shape == (7, 7, 3) and m.srgb.dtype == np.uint8
    # Cells with equal theta_light + theta_view see the film at the same angle.
    np.testing.assert_allclose(m.lab[1, 3], m.lab[3, 1], atol=1e-5)
    np.testing.assert_allclose(m.lab[0, 4], m.lab[2, 2], atol=1e-5)
    hue = np.rad2deg(np.arctan2(m.lab[0, 0, 2], m.lab[0, 0, 1])) % 360
    assert 220 < hue < 300  # blue


def test_angular_map_cell_equals_colour_science_on_the_tmm_spectrum():
    colour = pytest.importorskip("colour")
    tmm = pytest.importorskip("tmm")
    from microfacet.optics import optical_constants

    wl = np.arange(380.0, 781.0, 1.0)
    m = simulate_map(model="half-vector", thickness=120.0, theta_light_deg=[10.0],
                     theta_view_deg=[40.0], wavelength_nm=wl)
    n1 = optical_constants("TiO2_Jolivet2023_amorphous", wl)
    n2 = optical_constants("Ti_JohnsonChristy1974", wl)
    R = [np.mean([tmm.coh_tmm(p, [1, a, b], [np.inf, 120.0, np.inf], np.deg2rad(25.0), w)["R"]
                  for p in "sp"]) for w, a, b in zip(wl, n1, n2)]
    shape = colour.SpectralShape(380, 780, 1)
    cmfs = colour.MSDS_CMFS["CIE 1931 2 Degree Standard Observer"].copy().align(shape)
    ill = colour.SDS_ILLUMINANTS["D65"].copy().align(shape)
    xyz = colour.sd_to_XYZ(colour.SpectralDistribution(dict(zip(wl, R))), cmfs, ill,
                           method="Integration") / 100
    white = colour.sd_to_XYZ(colour.SpectralDistribution(dict(zip(wl, np.ones(wl.size)))),
                             cmfs, ill, method="Integration") / 100
    ref = colour.XYZ_to_Lab(xyz, colour.XYZ_to_xy(white))
    assert color.delta_e_2000(m.lab[0, 0].astype(float), ref) < 0.1


def test_map_png_written(tmp_path):
    import cv2

    from microfacet.io.angular_map import save_png

    m = simulate_map(model="half-vector", thickness=120.0, theta_light_deg=[0, 20],
                     theta_view_deg=[0, 20, 40])
    save_png(tmp_path / "m.png", m, scale=2)
    img = cv2.imread(str(tmp_path / "m.png"))
    assert img.shape == (4, 6, 3)


@pytest.mark.parametrize("args, name", [
    ((95.0, 0.0), "theta_light_deg"), ((0.0, np.inf), "theta_view_deg")])
def test_bad_angles(args, name):
    with pytest.raises(ValueError, match=name):
        half_angle_deg(*args)


def test_zero_vector_refused():
    with pytest.raises(ValueError, match="light"):
        half_angle_from_vectors([0, 0, 0], [0, 0, 1])
