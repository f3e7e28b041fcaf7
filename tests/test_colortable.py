"""Colour table: interpolation error and spectral step measured against direct evaluation."""

import numpy as np
import pytest

from microfacet import colour as color
from microfacet.colour.table import (
    _wavelengths,
    build_colour_table,
    choose_spectral_step,
    direct_xyz,
)
from microfacet.optics import DEFAULT_FILM, DEFAULT_SUBSTRATE, optical_constants
from microfacet.optics.thinfilm import reflectance


@pytest.fixture(scope="module")
def table():
    return build_colour_table(thickness_range_nm=(0.0, 400.0), theta_range_deg=(0.0, 30.0))


def test_interpolation_error_is_within_target_on_independent_points(table):
    rng = np.random.default_rng(12345)  # not the seed the builder checked with
    th = rng.uniform(0, 30, 3000)
    d = rng.uniform(0, 400, 3000)
    ref = color.xyz_to_lab(direct_xyz(th, d, spectral_step_nm=table.spectral_step_nm),
                           white=table.white_xyz)
    err = color.delta_e_2000(table.lab_at(th, d).astype(np.float64), ref)
    assert err.max() <= 0.05
    assert table.interp_error_de00 <= 0.05


def test_spectral_step_is_within_target_of_1nm(table):
    rng = np.random.default_rng(7)
    th, d = rng.uniform(0, 30, 500), rng.uniform(0, 400, 500)
    w1 = color.spectral_weights(_wavelengths(1.0))
    ref = color.xyz_to_lab(direct_xyz(th, d, spectral_step_nm=1.0), white=w1.sum(0))
    got = color.xyz_to_lab(direct_xyz(th, d, spectral_step_nm=table.spectral_step_nm),
                           white=table.white_xyz)
    assert color.delta_e_2000(got, ref).max() <= 0.05


def test_thicker_films_need_finer_spectral_steps():
    thin, _, _ = choose_spectral_step(thickness_range_nm=(0, 150))
    thick, _, _ = choose_spectral_step(thickness_range_nm=(0, 800))
    assert thick < thin


def test_direct_xyz_is_reflectance_integrated_against_the_cmfs():
    # Independent route: colour-science's own integration of the same spectrum.
    colour = pytest.importorskip("colour")
    wl = np.arange(380.0, 781.0, 1.0)
    R = reflectance(wl, 20.0, 130.0, optical_constants(DEFAULT_FILM, wl),
                    optical_constants(DEFAULT_SUBSTRATE, wl))
    sd = colour.SpectralDistribution(dict(zip(wl, R)))
    shape = colour.SpectralShape(380, 780, 1)
    cmfs = colour.MSDS_CMFS["CIE 1931 2 Degree Standard Observer"].copy().align(shape)
    ill = colour.SDS_ILLUMINANTS["D65"].copy().align(shape)
    ref = colour.sd_to_XYZ(sd, cmfs, ill, method="Integration") / 100
    np.testing.assert_allclose(direct_xyz(20.0, 130.0, spectral_step_nm=1.0), ref, atol=2e-4)


def test_perfect_reflector_white_and_lab_range(table):
    assert table.white_xyz[1] == pytest.approx(1.0)
    assert table.lab.dtype == np.float32
    L = table.lab[..., 0]
    assert L.min() > 0 and L.max() < 100


def test_outside_the_table_is_nan_and_nan_propagates(table):
    lab = table.lab_at(np.array([10.0, 31.0, np.nan, 10.0]), np.array([100.0, 100.0, 100, 401]))
    assert np.isfinite(lab[0]).all()
    assert np.isnan(lab[1:]).all()


def test_grid_nodes_reproduce_the_tabulated_values(table):
    i, j = 3, 17
    np.testing.assert_allclose(table.xyz_at(table.theta_deg[i], table.thickness_nm[j]),
                               table.xyz[i, j], rtol=1e-12)


def test_linear_rgb_of_the_table_matches_the_colour_module(table):
    rgb = table.linear_rgb_at(0.0, 51.0)
    ref = color.model_xyz_to_linear_srgb(table.xyz_at(0.0, 51.0), white=table.white_xyz)
    np.testing.assert_allclose(rgb, ref, atol=1e-6)
    assert rgb[2] > rgb[0]  # the first-order blue
    # The perfect reflector of the table's own grid is exactly RGB white.
    np.testing.assert_allclose(color.model_xyz_to_linear_srgb(table.white_xyz,
                                                              white=table.white_xyz), 1, atol=1e-6)


@pytest.mark.parametrize("kw, name", [
    (dict(theta_range_deg=(0, 90)), "theta_range_deg"),
    (dict(thickness_range_nm=(50, 10)), "thickness_range_nm"),
    (dict(film="Nope"), "Nope"),
])
def test_bad_arguments(kw, name):
    with pytest.raises(ValueError, match=name):
        build_colour_table(**kw)
