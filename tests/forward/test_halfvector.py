"""Half-vector model (microfacet.forward.halfvector): geometry (seed eq. 5) and spectra.
Its angular maps: test_angular.py."""

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from microfacet.forward.halfvector import (
    half_angle_deg,
    half_angle_from_vectors,
    half_vector,
    in_plane_directions,
    spectra,
)
from microfacet.optics.thinfilm import reflectance

angle = st.floats(-89.0, 89.0)


@pytest.mark.slow
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


@pytest.mark.slow
@settings(max_examples=100, deadline=None)
@given(st.lists(st.floats(-1, 1), min_size=6, max_size=6))
def test_3d_half_angle_is_symmetric_and_matches_the_dot_product(v):
    a, w = np.array(v[:3]), np.array(v[3:])
    if np.linalg.norm(a) < 1e-3 or np.linalg.norm(w) < 1e-3:
        return
    cosang = np.dot(a, w) / np.linalg.norm(a) / np.linalg.norm(w)
    expected = np.rad2deg(np.arccos(np.clip(cosang, -1, 1))) / 2
    assert half_angle_from_vectors(a, w) == pytest.approx(expected, abs=1e-6)
    assert half_angle_from_vectors(w, a) == pytest.approx(half_angle_from_vectors(a, w), abs=1e-12)


def test_spectra_use_the_half_angle():
    wl, R = spectra(10.0, 50.0, 80.0, wavelength_nm=[450.0, 550.0, 650.0])
    ref = reflectance(wl, 30.0, 80.0, "TiO2_Jolivet2023_amorphous", "Ti_JohnsonChristy1974")
    np.testing.assert_allclose(R, ref, rtol=1e-14)


@pytest.mark.parametrize("args, name", [
    ((95.0, 0.0), "theta_light_deg"), ((0.0, np.inf), "theta_view_deg")])
def test_bad_angles(args, name):
    with pytest.raises(ValueError, match=name):
        half_angle_deg(*args)


def test_zero_vector_refused():
    with pytest.raises(ValueError, match="light"):
        half_angle_from_vectors([0, 0, 0], [0, 0, 1])
