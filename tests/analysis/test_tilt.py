"""Per-pixel tilt inversion (microfacet.analysis.tilt): exact on noise-free model colours,
uncertainty, prior. The colour noise it is given: test_colour_image.py."""

import numpy as np
import pytest

from microfacet import colour as color
from microfacet.analysis.options import TiltOptions
from microfacet.analysis.tilt import (
    PixelEstimates,
    TiltRows,
    invert_tilt,
    model_lab_rows,
    tilt_grid,
)
from microfacet.colour.model import FilmColourModel
from microfacet.colour.table import build_colour_table


@pytest.fixture(scope="module")
def table():
    return build_colour_table(thickness_range_nm=(100, 160), theta_range_deg=(0, 27))


@pytest.fixture(scope="module")
def model(table):
    return FilmColourModel(table)


def _lab(table, tilt, d):
    """Lab of the table's XYZ at exposure 1, computed here (not through the model)."""
    return color.xyz_to_lab(table.xyz_at(tilt, d), white=table.white_xyz).astype(np.float32)


def test_noise_free_colours_give_back_their_tilt(table, model):
    rng = np.random.default_rng(0)
    n = 2000
    true = rng.uniform(3, 25, n)
    lab = _lab(table, true, np.full(n, 140.0))
    grid = np.arange(0, 26.6, 0.5)
    rows = TiltRows(model_lab_rows(model, [140.0], grid), np.array([140.0]), 0.5)
    inv = invert_tilt(lab, np.zeros(n, int), rows, grid, model, TiltOptions())
    assert np.median(np.abs(inv.tilt_deg - true)) < 0.2
    assert np.all(inv.delta_e < 0.5)
    assert np.all(inv.tilt_sigma_deg > 0) and np.all(inv.colour_weight == 1)
    # Sensitivity grows with tilt (colour changes faster at steeper incidence).
    assert np.median(inv.sensitivity_de_per_deg[true > 20]) > np.median(
        inv.sensitivity_de_per_deg[true < 8])


def test_prior_dominates_when_colour_is_uninformative(table, model):
    n = 500
    lab = _lab(table, np.full(n, 12.0), np.full(n, 140.0))
    lab = lab + np.random.default_rng(1).normal(0, 2.0, (n, 3)).astype(np.float32)
    grid = np.arange(0, 26.6, 0.5)
    rows = TiltRows(model_lab_rows(model, [140.0], grid), np.array([140.0]), 2.0,
                    prior_deg=np.array([12.0]), prior_sigma_deg=np.array([1.0]))
    inv = invert_tilt(lab, np.zeros(n, int), rows, grid, model, TiltOptions())
    assert np.median(np.abs(inv.tilt_deg - 12.0)) < 1.5
    assert np.median(inv.colour_weight) < 0.5
    assert np.all(inv.tilt_sigma_deg <= 1.0 + 1e-6)


def test_model_rows_are_the_model_colour_on_the_grid(table, model):
    """Each row is the film colour of its thickness at every grid tilt, at the model's
    exposure (computed here from the table's XYZ)."""
    grid = tilt_grid(26.5, 0.5)
    d = np.array([101.0, 130.5, 159.0])
    half = model.with_exposure(0.5)
    rows = model_lab_rows(half, d, grid)
    assert rows.shape == (3, grid.size, 3) and rows.dtype == np.float32
    want = color.xyz_to_lab((table.xyz_at(grid[None, :], d[:, None]) * 0.5).astype(np.float32),
                            white=table.white_xyz.astype(np.float32))
    np.testing.assert_allclose(rows, want, atol=1e-4)


@pytest.mark.parametrize("prior", [False, True])
def test_the_coarse_to_fine_search_finds_the_full_search_minimum(table, model, prior):
    """Noisy colours at random tilts and thicknesses of several rows, with and without a
    prior: the coarse-to-fine search (every 4th node, then ±4 nodes) returns the full
    search's tilt, error and sensitivity for every pixel."""
    rng = np.random.default_rng(5)
    n = 3000
    d_rows = np.array([105.0, 130.0, 155.0])
    ri = rng.integers(0, 3, n)
    true = rng.uniform(0, 26.5, n)
    lab = _lab(table, true, d_rows[ri])
    lab = (lab + rng.normal(0, 1.5, lab.shape)).astype(np.float32)
    grid = np.linspace(0, 26.5, 54)
    rows_lab = model_lab_rows(model, d_rows, grid)
    noise = np.array([1.5, 1.4, 1.6])
    prior_kw = {}
    if prior:
        prior_kw = dict(prior_deg=np.array([5.0, 12.0, 20.0]),
                        prior_sigma_deg=np.array([2.0, 3.0, 4.0]))
    rows = TiltRows(rows_lab, d_rows, noise, **prior_kw)
    full = invert_tilt(lab, ri, rows, grid, model, TiltOptions(coarse_stride=1))
    fast = invert_tilt(lab, ri, rows, grid, model, TiltOptions(coarse_stride=4))
    np.testing.assert_array_equal(fast.tilt_deg, full.tilt_deg)
    np.testing.assert_array_equal(fast.tilt_sigma_deg, full.tilt_sigma_deg)
    np.testing.assert_array_equal(fast.delta_e, full.delta_e)
    np.testing.assert_array_equal(fast.sensitivity_de_per_deg, full.sensitivity_de_per_deg)
    # the same values given once per pixel (a row each) instead of shared per row
    per_px = TiltRows(rows_lab[ri], d_rows[ri], noise[ri],
                      **{k: v[ri] for k, v in prior_kw.items()})
    b = invert_tilt(lab, np.arange(n), per_px, grid, model, TiltOptions())
    for f in ("tilt_deg", "tilt_sigma_deg", "delta_e", "colour_weight"):
        np.testing.assert_array_equal(getattr(fast, f), getattr(b, f))


@pytest.mark.parametrize("method, formula", [("CIE76", color.delta_e_76),
                                             ("CIE94", color.delta_e_94),
                                             ("CIEDE2000", color.delta_e_2000)])
def test_the_colour_difference_formula_is_the_one_asked_for(table, method, formula):
    """The model's ``delta_e_method`` reaches the search and the reported ΔE: the ΔE at the
    solution is that formula's difference between the model colour there and the pixel."""
    rng = np.random.default_rng(2)
    n = 300
    true = rng.uniform(3, 25, n)
    d = np.full(n, 140.0)
    lab = _lab(table, true, d)
    lab = lab + rng.normal(0, 1.0, lab.shape).astype(np.float32)   # off the model surface
    grid = np.arange(0, 26.6, 0.5)
    model = FilmColourModel(table, delta_e_method=method)
    rows = TiltRows(model_lab_rows(model, [140.0], grid), np.array([140.0]), 1.0)
    inv = invert_tilt(lab, np.zeros(n, int), rows, grid, model, TiltOptions())
    ref = color.xyz_to_lab(table.xyz_at(inv.tilt_deg, d).astype(np.float32),
                           white=table.white_xyz.astype(np.float32))
    np.testing.assert_allclose(inv.delta_e, formula(ref, lab), rtol=1e-4, atol=1e-4)
    # and the search minimised that formula: no grid node is better by it
    on_grid = formula(rows.lab[0][None, :, :], lab[:, None, :]).min(axis=1)
    assert np.all(inv.delta_e <= on_grid + 1e-3)


def test_inverting_into_maps_gives_the_numbers_of_invert_tilt(table, model, monkeypatch):
    """invert_tilt_into (each chunk gathered from the image and stored into the maps) gives,
    bitwise, what invert_tilt of the gathered pixels stored at their places gives, with each pixel's
    row thickness beside it; pixels not asked for keep NaN. Chunks smaller than the pixels, so
    that several chunks (on the threads) are stored."""
    from microfacet.analysis import tilt as tilt_module

    monkeypatch.setattr(tilt_module, "CHUNK_PX", 37)
    rng = np.random.default_rng(4)
    shape = (13, 17)
    flat = np.sort(rng.choice(shape[0] * shape[1], 120, replace=False))
    group = rng.integers(0, 3, shape).astype(np.int32)
    d = np.array([112.0, 131.0, 150.0])
    true = rng.uniform(2, 24, shape)
    lab = _lab(table, true.ravel(), d[group.ravel()]).reshape(shape + (3,))
    lab += rng.normal(0, 0.5, lab.shape).astype(np.float32)
    grid = tilt_grid(26.0, 0.5)
    rows = TiltRows(model_lab_rows(model, d, grid), d, np.array([0.5, 0.7, 0.9]),
                    prior_deg=np.array([5.0, 9.0, 13.0]), prior_sigma_deg=np.full(3, 4.0))
    ref = PixelEstimates.empty(shape)
    ref.thickness_nm.reshape(-1)[flat] = d[group.reshape(-1)[flat]]
    inv = invert_tilt(lab.reshape(-1, 3)[flat], group.reshape(-1)[flat], rows, grid, model,
                      TiltOptions())
    for name in ("tilt_deg", "tilt_sigma_deg", "delta_e", "colour_weight"):
        getattr(ref, name).reshape(-1)[flat] = getattr(inv, name)
    got = PixelEstimates.empty(shape, group=group)
    tilt_module.invert_tilt_into(got, flat, lab, rows, grid, model, TiltOptions())
    for name in ("thickness_nm", "tilt_deg", "tilt_sigma_deg", "delta_e", "colour_weight"):
        np.testing.assert_array_equal(getattr(got, name), getattr(ref, name), err_msg=name)
        assert getattr(got, name).dtype == np.float32
    assert got.thickness_group is group
    assert np.isfinite(got.tilt_deg).sum() == flat.size
