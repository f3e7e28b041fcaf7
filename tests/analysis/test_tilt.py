"""Per-pixel tilt inversion (microfacet.analysis.tilt): exact on noise-free model colours,
uncertainty, prior. The colour noise it is given: test_colour_image.py."""

import numpy as np
import pytest

from microfacet import colour as color
from microfacet.analysis.tilt import invert_tilt, model_lab_rows
from microfacet.colour.table import build_colour_table


@pytest.fixture(scope="module")
def table():
    return build_colour_table(thickness_range_nm=(100, 160), theta_range_deg=(0, 27))


def test_noise_free_colours_give_back_their_tilt(table):
    rng = np.random.default_rng(0)
    n = 2000
    true = rng.uniform(3, 25, n)
    d = np.full(n, 140.0)
    lab = color.xyz_to_lab(table.xyz_at(true, d), white=table.white_xyz).astype(np.float32)
    grid = np.arange(0, 26.6, 0.5)
    rows = model_lab_rows(table, [140.0], grid, exposure=1.0)
    inv = invert_tilt(lab, rows, np.zeros(n, int), grid, table=table, thickness_px=d,
                      exposure=1.0, noise_de=0.5)
    assert np.median(np.abs(inv.tilt_deg - true)) < 0.2
    assert np.all(inv.delta_e < 0.5)
    assert np.all(inv.tilt_sigma_deg > 0) and np.all(inv.colour_weight == 1)
    # Sensitivity grows with tilt (colour changes faster at steeper incidence).
    assert np.median(inv.sensitivity_de_per_deg[true > 20]) > np.median(
        inv.sensitivity_de_per_deg[true < 8])


def test_prior_dominates_when_colour_is_uninformative(table):
    n = 500
    d = np.full(n, 140.0)
    lab = color.xyz_to_lab(table.xyz_at(np.full(n, 12.0), d), white=table.white_xyz)
    noise = np.random.default_rng(1).normal(0, 2.0, (n, 3)).astype(np.float32)
    lab = lab.astype(np.float32) + noise
    grid = np.arange(0, 26.6, 0.5)
    rows = model_lab_rows(table, [140.0], grid, exposure=1.0)
    inv = invert_tilt(lab, rows, np.zeros(n, int), grid, table=table, thickness_px=d,
                      exposure=1.0, noise_de=2.0, prior_deg=np.full(n, 12.0),
                      prior_sigma_deg=np.full(n, 1.0))
    assert np.median(np.abs(inv.tilt_deg - 12.0)) < 1.5
    assert np.median(inv.colour_weight) < 0.5
    assert np.all(inv.tilt_sigma_deg <= 1.0 + 1e-6)




@pytest.mark.parametrize("prior", [False, True])
def test_the_coarse_to_fine_search_finds_the_full_search_minimum(table, prior):
    """Noisy colours at random tilts and thicknesses of several rows, with and without a
    prior: the coarse-to-fine search (every 4th node, then ±4 nodes) returns the full
    search's tilt, error and sensitivity for every pixel."""
    rng = np.random.default_rng(5)
    n = 3000
    d_rows = np.array([105.0, 130.0, 155.0])
    ri = rng.integers(0, 3, n)
    true = rng.uniform(0, 26.5, n)
    lab = color.xyz_to_lab(table.xyz_at(true, d_rows[ri]), white=table.white_xyz)
    lab = (lab + rng.normal(0, 1.5, lab.shape)).astype(np.float32)
    grid = np.linspace(0, 26.5, 54)
    rows = model_lab_rows(table, d_rows, grid, exposure=1.0)
    kw = dict(table=table, thickness_px=d_rows[ri], exposure=1.0, noise_de=1.5)
    if prior:
        kw.update(prior_deg=np.clip(true + rng.normal(0, 3, n), 0, 26.5),
                  prior_sigma_deg=np.full(n, 3.0))
    full = invert_tilt(lab, rows, ri, grid, coarse_stride=1, **kw)
    fast = invert_tilt(lab, rows, ri, grid, coarse_stride=4, **kw)
    np.testing.assert_array_equal(fast.tilt_deg, full.tilt_deg)
    np.testing.assert_array_equal(fast.tilt_sigma_deg, full.tilt_sigma_deg)
    np.testing.assert_array_equal(fast.delta_e, full.delta_e)
    # the same values given per row (by_row) instead of per pixel
    per_row = dict(table=table, thickness_px=d_rows, exposure=1.0,
                   noise_de=np.array([1.5, 1.4, 1.6]), by_row=True)
    per_px = dict(kw, noise_de=per_row["noise_de"][ri])
    if prior:
        p_rows, s_rows = np.array([5.0, 12.0, 20.0]), np.array([2.0, 3.0, 4.0])
        per_row.update(prior_deg=p_rows, prior_sigma_deg=s_rows)
        per_px.update(prior_deg=p_rows[ri], prior_sigma_deg=s_rows[ri])
    a = invert_tilt(lab, rows, ri, grid, **per_row)
    b = invert_tilt(lab, rows, ri, grid, **per_px)
    for f in ("tilt_deg", "tilt_sigma_deg", "delta_e", "colour_weight"):
        np.testing.assert_array_equal(getattr(a, f), getattr(b, f))


@pytest.mark.parametrize("method, formula", [("CIE76", color.delta_e_76),
                                             ("CIE94", color.delta_e_94),
                                             ("CIEDE2000", color.delta_e_2000)])
def test_the_colour_difference_formula_is_the_one_asked_for(table, method, formula):
    """``delta_e_method`` reaches the search and the reported ΔE: the ΔE at the solution is
    that formula's difference between the model colour there and the pixel."""
    rng = np.random.default_rng(2)
    n = 300
    true = rng.uniform(3, 25, n)
    d = np.full(n, 140.0)
    lab = color.xyz_to_lab(table.xyz_at(true, d), white=table.white_xyz).astype(np.float32)
    lab = lab + rng.normal(0, 1.0, lab.shape).astype(np.float32)   # off the model surface
    grid = np.arange(0, 26.6, 0.5)
    rows = model_lab_rows(table, [140.0], grid, exposure=1.0)
    inv = invert_tilt(lab, rows, np.zeros(n, int), grid, table=table, thickness_px=d,
                      exposure=1.0, noise_de=1.0, delta_e_method=method)
    model = color.xyz_to_lab(table.xyz_at(inv.tilt_deg, d).astype(np.float32),
                             white=table.white_xyz.astype(np.float32))
    np.testing.assert_allclose(inv.delta_e, formula(model, lab), rtol=1e-4, atol=1e-4)


def test_an_unknown_formula_is_refused_naming_the_option():
    from microfacet.analysis.options import AnalysisOptions
    from microfacet.core.errors import InputError

    with pytest.raises(InputError) as err:
        AnalysisOptions(delta_e_method="CMC").validate()
    assert err.value.param == "delta_e_method" and "CIEDE2000" in str(err.value)
