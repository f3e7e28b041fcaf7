"""The film-colour model (microfacet.colour.model.FilmColourModel): its CIELAB against the
table's XYZ converted here (and by colour-science), its colour differences against
microfacet.colour.difference for each method, the colour period against the thin-film
period, the refraction term against the equal-phase condition."""

from __future__ import annotations

import math

import numpy as np
import pytest

from microfacet.colour.colorimetry import xyz_to_lab
from microfacet.colour.difference import METHODS, delta_e
from microfacet.colour.model import COLOUR_PERIOD_WAVELENGTH_NM, FilmColourModel
from microfacet.colour.table import build_colour_table
from microfacet.optics.constants import optical_constants
from microfacet.optics.thinfilm import reflectance_period_nm


@pytest.fixture(scope="module")
def table():
    return build_colour_table(thickness_range_nm=(20.0, 300.0), theta_range_deg=(0.0, 27.0))


@pytest.fixture(scope="module")
def points():
    rng = np.random.default_rng(0)
    return rng.uniform(0.0, 27.0, 500), rng.uniform(20.0, 300.0, 500)


@pytest.mark.slow
@pytest.mark.parametrize("exposure", [0.4, 1.0, 1.7])
def test_lab_is_the_tables_xyz_at_the_exposure_in_cielab(table, points, exposure):
    """Inside the sRGB gamut (the rest: the recorded colour, the tests below)."""
    theta, d = points
    model = FilmColourModel(table, exposure=exposure)
    lab = model.lab(theta, d)
    assert lab.dtype == np.float32 and lab.shape == (500, 3)
    xyz = table.xyz_at(theta, d) * exposure
    inside = _in_gamut(table, xyz)
    assert 0.8 < inside.mean() < 1.0           # cyan films (~150-180 nm) are outside
    white = table.white_xyz.astype(np.float32)
    np.testing.assert_allclose(lab[inside], xyz_to_lab(xyz.astype(np.float32),
                                                       white=white)[inside], rtol=0, atol=1e-5)
    # float64 all through: the model's float32 is within its rounding
    np.testing.assert_allclose(lab[inside], xyz_to_lab(xyz, white=table.white_xyz)[inside],
                               rtol=0, atol=5e-3)


def _in_gamut(table, xyz):
    from microfacet.colour.srgb import model_xyz_to_linear_srgb

    return np.all(model_xyz_to_linear_srgb(xyz, white=table.white_xyz) >= 0.0, axis=-1)


def test_lab_against_colour_science(table, points, colour_science):
    theta, d = points
    model = FilmColourModel(table, exposure=0.8)
    w = table.white_xyz
    ref = colour_science.XYZ_to_Lab(table.xyz_at(theta, d) * 0.8, w[:2] / w.sum())
    # colour-science's white is Y = 1: the table's white has Y = 1 too
    assert w[1] == pytest.approx(1.0)
    inside = _in_gamut(table, table.xyz_at(theta, d))
    np.testing.assert_allclose(model.lab(theta, d)[inside], ref[inside], rtol=0, atol=5e-3)


def test_lab_broadcasts_and_exposure_is_the_only_change(table):
    model = FilmColourModel(table)
    grid = model.lab(np.linspace(0, 27, 7)[:, None], np.linspace(20, 300, 11)[None, :])
    assert grid.shape == (7, 11, 3)
    assert model.lab(10.0, 100.0).shape == (3,)
    np.testing.assert_array_equal(grid[3, 5], model.lab(np.linspace(0, 27, 7)[3],
                                                        np.linspace(20, 300, 11)[5]))
    darker = model.with_exposure(0.5)
    assert darker.table is model.table and darker.delta_e_method == model.delta_e_method
    assert darker.exposure == 0.5 and model.exposure == 1.0
    # a lower exposure: lower L*, the same hue angle (XYZ scaled together)
    a, b = model.lab(10.0, 100.0), darker.lab(10.0, 100.0)
    assert b[0] < a[0]
    # lab_from_xyz of the cached xyz at another exposure is lab at that exposure
    np.testing.assert_array_equal(darker.lab_from_xyz(model.xyz(10.0, 100.0)), b)


def test_outside_the_table_is_nan(table):
    model = FilmColourModel(table)
    assert model.theta_range_deg == (0.0, 27.0) and model.thickness_range_nm == (20.0, 300.0)
    assert np.isnan(model.lab(40.0, 100.0)).all()
    assert np.isnan(model.lab(10.0, 350.0)).all()


@pytest.mark.parametrize("method", METHODS)
def test_delta_e_is_the_methods_difference_from_the_model_colour(table, points, method):
    """``delta_e(lab, θ, d)`` is ``colour.difference.delta_e`` between the model's colour at
    (θ, d) — the reference — and the image's."""
    theta, d = points
    rng = np.random.default_rng(1)
    model = FilmColourModel(table, exposure=0.9, delta_e_method=method)
    ref = model.lab(theta, d)
    lab = (ref + rng.normal(0, 3.0, ref.shape)).astype(np.float32)
    got = model.delta_e(lab, theta, d)
    np.testing.assert_allclose(got, delta_e(ref, lab, method=method), rtol=1e-6, atol=1e-6)
    np.testing.assert_allclose(model.difference(ref, lab), delta_e(ref, lab, method=method),
                               rtol=1e-6, atol=1e-6)
    assert np.all(model.delta_e(ref, theta, d) < 1e-4)          # the model's own colours
    if method == "CIE94":   # asymmetric: the model is the reference, not the pixel
        assert not np.allclose(got, delta_e(lab, ref, method=method), rtol=1e-3)
    others = [m for m in METHODS if m != method]
    assert all(not np.allclose(got, delta_e(ref, lab, method=m), rtol=1e-3) for m in others)


def test_period_is_the_thin_film_period_at_560_nm(table):
    model = FilmColourModel(table)
    n = float(np.real(np.ravel(optical_constants(table.film, np.array([560.0])))[0]))
    assert COLOUR_PERIOD_WAVELENGTH_NM == 560.0
    assert model.film_index == pytest.approx(n, rel=1e-12)
    assert model.period_nm == pytest.approx(float(reflectance_period_nm(560.0, 0.0, n)),
                                            rel=1e-12)
    assert model.period_nm == pytest.approx(560.0 / (2.0 * n), rel=1e-12)   # λ / (2n)


def test_thickness_per_tilt_keeps_the_phase(table):
    """Equal colour: the film's phase d·n·cos θ₁ stays, so d(θ) = d₀ cos θ₁(0) / cos θ₁(θ)
    with sin θ₁ = sin θ / n; its derivative, by finite differences, is the model's."""
    model = FilmColourModel(table)
    n = model.film_index
    d0 = 120.0

    def d_of(theta_deg):
        s1 = np.sin(np.radians(theta_deg)) / n
        return d0 / np.sqrt(1.0 - s1 ** 2)

    for theta in (0.0, 5.0, 15.0, 25.0):
        h = 1e-4
        fd = (d_of(theta + h) - d_of(theta - h)) / math.radians(2 * h)
        assert model.thickness_per_tilt(theta, d_of(theta)) == pytest.approx(fd, rel=1e-6,
                                                                              abs=1e-9)


@pytest.mark.parametrize("exposure", [1.4, 1.8])
def test_a_clipped_model_is_the_colour_an_over_exposed_camera_records(table, exposure):
    """An over-exposed film as an 8-bit camera records it (the thin-film spectra integrated
    here on their own grid, encoded and clipped to [0, 255]): the model clipped at 1 matches
    it to the quantization, cyan films outside the gamut included; the model not clipped at
    1 does not, where a channel clipped there."""
    from microfacet.colour.srgb import colours_from_spectra, srgb_to_lab
    from microfacet.optics.thinfilm import reflectance

    wl = np.arange(380.0, 781.0, 5.0)
    d = np.arange(40.0, 290.0, 3.0)
    r = reflectance(wl[None, :], 0.0, d[:, None], table.film, table.substrate)
    rgb8 = colours_from_spectra(r, wl, exposure=exposure)[2]
    recorded = srgb_to_lab(rgb8)
    clipped = (rgb8 == 255).any(axis=-1)
    assert 10 <= clipped.sum() <= d.size - 5           # both cases are there
    m = FilmColourModel(table, exposure=exposure)
    camera = m.with_clip((1.0, 1.0, 1.0))
    assert np.max(camera.delta_e(recorded, 0.0, d)) < 1.0
    unclipped = m.delta_e(recorded[clipped], 0.0, d[clipped])
    assert np.median(unclipped) > 1.0 and np.max(unclipped) > 3.0
    np.testing.assert_array_equal(camera.lab(0.0, d[~clipped]), m.lab(0.0, d[~clipped]))


@pytest.mark.parametrize("film, thickness_nm", [("TiO2_Jolivet2023_amorphous", 170.0),
                                                ("TiO2_Jolivet2023_amorphous", 175.0),
                                                ("TiO2_Devore1951_rutile_o", 160.0)])
def test_a_cyan_film_outside_the_srgb_gamut_is_read_at_its_thickness(film, thickness_nm):
    """A cyan film (negative linear red) as an 8-bit sRGB image holds it (red at 0): the
    thickness of least ΔE00 is its own, the misfit the quantization's; the table's colour
    taken unclipped into Lab, as the model did before, misfits it by more than 2 ΔE00 and
    moves the thickness."""
    from microfacet.colour.srgb import colours_from_spectra, srgb_to_lab
    from microfacet.optics.thinfilm import reflectance

    t = build_colour_table(thickness_range_nm=(100.0, 250.0), theta_range_deg=(0.0, 5.0),
                           film=film)
    wl = np.arange(380.0, 781.0, 5.0)
    r = reflectance(wl, 0.0, thickness_nm, film, t.substrate)
    recorded = srgb_to_lab(colours_from_spectra(r, wl)[2])
    m = FilmColourModel(t)
    grid = np.arange(100.0, 250.0, 0.05)
    de = m.delta_e(recorded, 0.0, grid)
    assert abs(grid[np.argmin(de)] - thickness_nm) < 0.15 and de.min() < 0.25
    raw = delta_e(xyz_to_lab(m.xyz(0.0, grid).astype(np.float32), white=m.white), recorded)
    assert raw.min() > 2.0 and abs(grid[np.argmin(raw)] - thickness_nm) > 0.3


def test_clip_levels_apply_per_channel(table):
    """A level per channel (an image divided by gains g clips at 1/g): only the channel
    over its level is clipped, and a level above every colour changes nothing."""
    from microfacet.colour.srgb import model_xyz_to_linear_srgb

    m = FilmColourModel(table, exposure=1.8)
    d = np.arange(40.0, 290.0, 3.0)
    xyz = m.xyz(0.0, d)
    rgb = model_xyz_to_linear_srgb(xyz * 1.8, white=table.white_xyz)
    top = float(rgb.max()) * 1.01
    np.testing.assert_array_equal(m.with_clip((top, top, top)).lab(0.0, d), m.lab(0.0, d))
    red_only = m.with_clip((1.0, top, top))
    changed = np.any(red_only.lab(0.0, d) != m.lab(0.0, d), axis=-1)
    np.testing.assert_array_equal(changed, rgb[:, 0] > 1.0)
    assert m.with_clip(None) is m and red_only.with_exposure(1.0).clip_rgb == (1.0, top, top)
    assert red_only.with_clip(np.array([1.0, top, top])) is red_only


@pytest.mark.parametrize("kw, match", [({"delta_e_method": "CMC"}, "delta_e_method"),
                                       ({"exposure": 0.0}, "exposure"),
                                       ({"exposure": math.nan}, "exposure"),
                                       ({"exposure": -1.0}, "exposure"),
                                       ({"clip_rgb": (1.0, 1.0)}, "clip_rgb"),
                                       ({"clip_rgb": (1.0, 0.0, 1.0)}, "clip_rgb"),
                                       ({"clip_rgb": (1.0, math.nan, 1.0)}, "clip_rgb")])
def test_bad_arguments_are_refused_naming_them(table, kw, match):
    with pytest.raises(ValueError, match=match):
        FilmColourModel(table, **kw)


@pytest.mark.parametrize("factor", [0.5, 0.72, 0.95, 1.0, 0.004])
@pytest.mark.parametrize("clip", [None, (0.9, 0.9, 0.9)])
def test_a_colour_scaled_in_brightness_is_the_lab_of_its_xyz_scaled(table, points, factor,
                                                                    clip):
    """``lab_scaled`` against ``lab_from_xyz`` of the scaled XYZ over 500 film colours
    (0-27°, 20-300 nm: the cyan films outside the sRGB gamut among them) and a NaN outside
    the table, at exposures that put colours near black (0.02) and, with clip levels, over
    them (1.6): the cube-root scaling, its exact fallback near black and the clipped model's
    exact path agree to 2e-4 in L*, a*, b*; at factor 1 it is the Lab given."""
    theta, d = points
    theta, d = np.append(theta, 0.0), np.append(d, 900.0)              # NaN: outside
    for exposure in (0.02, 1.0, 1.6):
        m = FilmColourModel(table, exposure=exposure, clip_rgb=clip)
        xyz = m.xyz(theta, d)
        lab = m.lab_from_xyz(xyz)
        got, want = m.lab_scaled(lab, xyz, factor), m.lab_from_xyz(xyz * factor)
        np.testing.assert_allclose(got, want, atol=2e-4, rtol=0)   # NaN where NaN
        assert np.isnan(got[-1]).all()
        if factor == 1.0:
            assert got is lab
