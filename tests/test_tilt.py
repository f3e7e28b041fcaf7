"""Per-pixel tilt inversion: exact on noise-free model colours, uncertainty, prior."""

import numpy as np
import pytest

from microfacet import colour as color
from microfacet.colour.table import build_colour_table
from microfacet.analysis.colour_image import estimate_colour_noise, quantization_noise_de
from microfacet.analysis.tilt import invert_tilt, model_lab_rows


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
    lab = lab.astype(np.float32) + np.random.default_rng(1).normal(0, 2.0, (n, 3)).astype(np.float32)
    grid = np.arange(0, 26.6, 0.5)
    rows = model_lab_rows(table, [140.0], grid, exposure=1.0)
    inv = invert_tilt(lab, rows, np.zeros(n, int), grid, table=table, thickness_px=d,
                      exposure=1.0, noise_de=2.0, prior_deg=np.full(n, 12.0),
                      prior_sigma_deg=np.full(n, 1.0))
    assert np.median(np.abs(inv.tilt_deg - 12.0)) < 1.5
    assert np.median(inv.colour_weight) < 0.5
    assert np.all(inv.tilt_sigma_deg <= 1.0 + 1e-6)


def test_noise_estimate_from_neighbours():
    rng = np.random.default_rng(2)
    lab = np.zeros((200, 200, 3), np.float32) + [60, 20, -30]
    lab += rng.normal(0, 1.0, lab.shape).astype(np.float32)
    est = estimate_colour_noise(lab, np.zeros((200, 200), bool))
    assert 0.5 < est < 1.5  # ΔE00 compresses chroma differences a little
    assert np.isnan(estimate_colour_noise(lab, np.ones((200, 200), bool)))


def test_quantization_noise_floor_scales_with_the_lsb():
    """ΔE is linear for tiny colour changes, so the 8- and 16-bit floors differ by the ratio
    of their LSBs (65535/255 = 257); a masked pixel does not count."""
    from microfacet.analysis.colour_image import estimate_colour_noise, quantization_noise_de

    rng = np.random.default_rng(3)
    img = rng.uniform(0.1, 0.9, (64, 64, 3)).astype(np.float32)
    mask = np.zeros((64, 64), bool)
    q8 = quantization_noise_de(img, mask, bit_depth=8)
    q16 = quantization_noise_de(img, mask, bit_depth=16)
    assert 0.02 < q8 < 0.3
    assert q8 / q16 == pytest.approx(257.0, rel=0.15)
    assert np.isnan(quantization_noise_de(img, np.ones((64, 64), bool), bit_depth=8))
