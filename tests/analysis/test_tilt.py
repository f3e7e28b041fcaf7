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
