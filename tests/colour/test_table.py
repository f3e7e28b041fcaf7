"""microfacet.colour.table: the colour table against direct and independent evaluation.

The independent reference is the thin-film reflectance (microfacet.optics.thinfilm)
integrated by colour-science's ``sd_to_XYZ`` and converted to linear sRGB by
colour-science's Bradford adaptation and the IEC 61966-2-1 matrix, none of which goes
through the table's own code.
"""

from __future__ import annotations

import numpy as np
import pytest

from microfacet.colour.colorimetry import spectral_weights, xyz_to_lab
from microfacet.colour.difference import delta_e_2000
from microfacet.colour.table import (
    _wavelengths,
    build_colour_table,
    choose_spectral_step,
    direct_xyz,
)
from microfacet.optics.thinfilm import reflectance

IEC_SRGB_TO_XYZ = np.array([[0.4124, 0.3576, 0.1805],
                            [0.2126, 0.7152, 0.0722],
                            [0.0193, 0.1192, 0.9505]])


@pytest.fixture(scope="module")
def table():
    return build_colour_table(thickness_range_nm=(0.0, 400.0), theta_range_deg=(0.0, 30.0))


def _independent_linear_rgb(colour, theta, d, table):
    """Reflectance -> colour.sd_to_XYZ -> Bradford to the sRGB white -> IEC matrix."""
    step = table.spectral_step_nm
    shape = colour.SpectralShape(380, 780, step)
    wl = np.asarray(shape.wavelengths)
    R = reflectance(wl, theta, d, table.film, table.substrate)
    cmfs = colour.MSDS_CMFS["CIE 1931 2 Degree Standard Observer"].copy().align(shape)
    ill = colour.SDS_ILLUMINANTS["D65"].copy().align(shape)
    xyz = colour.sd_to_XYZ(colour.SpectralDistribution(R, wl), cmfs, ill,
                           method="Integration") / 100
    white = colour.sd_to_XYZ(colour.sd_ones(shape), cmfs, ill, method="Integration") / 100
    adapted = colour.adaptation.chromatic_adaptation_VonKries(
        xyz, white, IEC_SRGB_TO_XYZ.sum(axis=1), transform="Bradford")
    return np.linalg.solve(IEC_SRGB_TO_XYZ, adapted)


@pytest.mark.slow
def test_linear_rgb_at_grid_nodes_matches_an_independent_computation(table, colour_science):
    assert table.illuminant == "D65" and table.observer == "2"
    for i, j in ((0, 0), (3, 17), (table.theta_deg.size - 1, table.thickness_nm.size - 1)):
        th, d = table.theta_deg[i], table.thickness_nm[j]
        got = table.linear_rgb_at(th, d)
        assert got.dtype == np.float32 and got.shape == (3,)
        np.testing.assert_allclose(got, _independent_linear_rgb(colour_science, th, d, table),
                                   rtol=0, atol=2e-6)


def test_linear_rgb_between_nodes_is_within_the_interpolation_error(table, colour_science):
    rng = np.random.default_rng(4)
    th, d = rng.uniform(0, 30, 20), rng.uniform(0, 400, 20)
    got = table.linear_rgb_at(th, d)
    ref = np.array([_independent_linear_rgb(colour_science, a, b, table) for a, b in zip(th, d)])
    # the table's interpolation error (<= 0.05 dE00) is ~2e-4 in linear RGB here
    np.testing.assert_allclose(got, ref, rtol=0, atol=1e-3)


def test_first_order_blue_and_bare_metal_grey(table):
    rgb = table.linear_rgb_at(0.0, 51.0)
    assert rgb[2] > rgb[0]  # the first-order interference blue of ~50 nm TiO2
    lab = table.lab_at(0.0, 0.0)  # bare titanium: a grey metal
    assert 75 < lab[0] < 90 and np.hypot(lab[1], lab[2]) < 6


def test_direct_xyz_is_the_reflectance_integrated_by_colour_science(colour_science):
    colour = colour_science
    shape = colour.SpectralShape(380, 780, 1)
    wl = np.asarray(shape.wavelengths)
    R = reflectance(wl, 20.0, 130.0, "TiO2_Jolivet2023_amorphous", "Ti_JohnsonChristy1974")
    cmfs = colour.MSDS_CMFS["CIE 1931 2 Degree Standard Observer"].copy().align(shape)
    ill = colour.SDS_ILLUMINANTS["D65"].copy().align(shape)
    ref = colour.sd_to_XYZ(colour.SpectralDistribution(R, wl), cmfs, ill,
                           method="Integration") / 100
    got = direct_xyz(20.0, 130.0, spectral_step_nm=1.0, film="TiO2_Jolivet2023_amorphous",
                     substrate="Ti_JohnsonChristy1974")
    np.testing.assert_allclose(got, ref, rtol=0, atol=1e-9)


def test_interpolation_error_is_within_target_on_independent_points(table):
    rng = np.random.default_rng(12345)  # not the seed the builder checked with
    th = rng.uniform(0, 30, 3000)
    d = rng.uniform(0, 400, 3000)
    ref = xyz_to_lab(direct_xyz(th, d, spectral_step_nm=table.spectral_step_nm),
                     white=table.white_xyz)
    err = delta_e_2000(table.lab_at(th, d).astype(np.float64), ref)
    assert err.max() <= 0.05
    assert table.interp_error_de00 <= 0.05


def test_spectral_step_is_within_target_of_1nm(table):
    rng = np.random.default_rng(7)
    th, d = rng.uniform(0, 30, 500), rng.uniform(0, 400, 500)
    w1 = spectral_weights(_wavelengths(1.0))
    ref = xyz_to_lab(direct_xyz(th, d, spectral_step_nm=1.0), white=w1.sum(0))
    got = xyz_to_lab(direct_xyz(th, d, spectral_step_nm=table.spectral_step_nm),
                     white=table.white_xyz)
    assert delta_e_2000(got, ref).max() <= 0.05


def test_thicker_films_need_finer_spectral_steps():
    thin, _, _ = choose_spectral_step(thickness_range_nm=(0, 150))
    thick, _, _ = choose_spectral_step(thickness_range_nm=(0, 800))
    assert thick < thin


def test_perfect_reflector_white_and_lab_range(table):
    assert table.white_xyz[1] == pytest.approx(1.0)
    np.testing.assert_allclose(table.white_xyz,
                               spectral_weights(_wavelengths(table.spectral_step_nm)).sum(0))
    assert table.lab.dtype == np.float32
    L = table.lab[..., 0]
    assert L.min() > 0 and L.max() < 100


def test_outside_the_table_is_nan_and_nan_propagates(table):
    lab = table.lab_at(np.array([10.0, 31.0, np.nan, 10.0]), np.array([100.0, 100.0, 100, 401]))
    assert np.isfinite(lab[0]).all()
    assert np.isnan(lab[1:]).all()
    assert np.isnan(table.linear_rgb_at(31.0, 100.0)).all()


def test_grid_nodes_reproduce_the_tabulated_values(table):
    i, j = 3, 17
    np.testing.assert_allclose(table.xyz_at(table.theta_deg[i], table.thickness_nm[j]),
                               table.xyz[i, j], rtol=1e-12)


@pytest.mark.parametrize("kw, name", [
    (dict(theta_range_deg=(0, 90)), "theta_range_deg"),
    (dict(thickness_range_nm=(50, 10)), "thickness_range_nm"),
    (dict(film="Nope"), "Nope"),
])
def test_bad_arguments(kw, name):
    with pytest.raises(ValueError, match=name):
        build_colour_table(**{"thickness_range_nm": (0, 100), **kw})


@pytest.mark.slow
def test_a_float32_input_at_the_tables_edge_is_inside():
    """A float32 tilt map clipped to the table's range (asin(NA)/2, not a float32 number)
    rounds the edge outward: it is still inside, with the edge's colour (the exposure
    reading of the ROI stage read NaN everywhere and stopped at its scan's bound)."""
    edge = float(np.degrees(np.arcsin(0.8))) / 2.0         # NA 0.8
    assert float(np.float32(edge)) > edge                     # the case is really there
    t = build_colour_table(thickness_range_nm=(100.0, 120.0), theta_range_deg=(0.0, edge),
                           spectral_step_nm=10.0, thickness_step_nm=2.0, theta_step_deg=4.0)
    a = t.xyz_at(np.float32(edge), 110.0)
    np.testing.assert_allclose(a, t.xyz_at(edge, 110.0), rtol=1e-6)
    assert np.isnan(t.xyz_at(edge + 1e-3, 110.0)).all()       # past rounding: outside


def test_a_tilt_per_row_and_a_thickness_per_column_give_the_pointwise_values_to_the_bit(table):
    """xyz_at of a tilt per row (n, 1) and a thickness per column (1, D) — the ROI and
    white-balance scans — computes the thickness-only bilinear terms once per table cell
    (ColourTable._xyz_outer); each value equals the one xyz_at gives for that point alone,
    to the bit, NaN and points outside the table (NaN) included, in any chunking."""
    rng = np.random.default_rng(3)
    t_lo, t_hi = table.theta_deg[0], table.theta_deg[-1]
    d_lo, d_hi = table.thickness_nm[0], table.thickness_nm[-1]
    th = rng.uniform(t_lo - 2, t_hi + 2, (300, 1))
    th[:3, 0] = [np.nan, t_lo, t_hi]
    d = np.concatenate([[np.nan, d_lo - 1, d_lo, d_hi], rng.uniform(d_lo, d_hi, 400)])[None, :]
    got = table.xyz_at(th, d)
    assert got.shape == (300, 404, 3)
    pointwise = np.stack([table.xyz_at(np.full(d.shape[1], t), d[0]) for t in th[:, 0]])
    np.testing.assert_array_equal(got, pointwise)
    assert np.isnan(got[0]).all() and np.isnan(got[:, :2]).all()
    assert np.isfinite(got[1:3, 2:]).all()
