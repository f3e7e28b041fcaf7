"""Colour noise of an image (microfacet.analysis.colour_image): from neighbouring pixels,
and the quantisation floor of 8- and 16-bit code values."""

import numpy as np
import pytest

from microfacet.analysis.colour_image import estimate_colour_noise, quantization_noise_de

KW = {"illuminant": "D65", "delta_e_method": "CIEDE2000"}


def test_noise_estimate_from_neighbours():
    rng = np.random.default_rng(2)
    lab = np.zeros((200, 200, 3), np.float32) + [60, 20, -30]
    lab += rng.normal(0, 1.0, lab.shape).astype(np.float32)
    est = estimate_colour_noise(lab, np.zeros((200, 200), bool), delta_e_method="CIEDE2000")
    assert 0.5 < est < 1.5  # ΔE00 compresses chroma differences a little
    assert np.isnan(estimate_colour_noise(lab, np.ones((200, 200), bool),
                                         delta_e_method="CIEDE2000"))


def test_quantization_noise_floor_scales_with_the_lsb():
    """ΔE is linear for tiny colour changes, so the 8- and 16-bit floors differ by the ratio
    of their LSBs (65535/255 = 257); a masked pixel does not count."""
    rng = np.random.default_rng(3)
    img = rng.uniform(0.1, 0.9, (64, 64, 3)).astype(np.float32)
    mask = np.zeros((64, 64), bool)
    q8 = quantization_noise_de(img, mask, bit_depth=8, **KW)
    q16 = quantization_noise_de(img, mask, bit_depth=16, **KW)
    assert 0.02 < q8 < 0.3
    assert q8 / q16 == pytest.approx(257.0, rel=0.15)
    assert np.isnan(quantization_noise_de(img, np.ones((64, 64), bool), bit_depth=8, **KW))
