"""Colour noise of an image (microfacet.analysis.colour_image): from neighbouring pixels,
and the quantisation floor of 8- and 16-bit code values."""

import numpy as np
import pytest

from microfacet.analysis.colour_image import estimate_colour_noise, quantization_noise_de

KW = {"illuminant": "D65", "delta_e_method": "CIEDE2000"}
KW_LAB = {"illuminant": "D65"}


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


def test_measure_colour_is_the_mask_lab_and_noise_of_the_encoded_image():
    """The stage on an image given linear: encoded once, masked with the section's
    thresholds, converted to Lab under the illuminant, its noise never below the
    quantization floor (a noise-free image has exactly the floor)."""
    from microfacet.analysis.colour_image import measure_colour
    from microfacet.analysis.mask import colour_mask
    from microfacet.analysis.options import MaskOptions
    from microfacet.colour.srgb import srgb_decode, srgb_encode, srgb_to_lab

    rng = np.random.default_rng(4)
    enc = np.clip(np.full((64, 64, 3), [0.7, 0.4, 0.2]) + rng.normal(0, 0.01, (64, 64, 3)), 0, 1)
    enc[:4, :4] = 0.5                                         # grey: masked
    lin = srgb_decode(enc.astype(np.float32))
    opts = MaskOptions(saturation_min=20.0)
    c = measure_colour(lin, opts, color_space="linear-sRGB", bit_depth=8, **KW)
    np.testing.assert_allclose(c.encoded, srgb_encode(lin, dtype=np.float32), atol=1e-6)
    np.testing.assert_array_equal(c.mask.mask, colour_mask(c.encoded, opts).mask)
    assert c.mask.mask[:4, :4].all() and c.mask.fraction < 0.01
    np.testing.assert_allclose(c.lab, srgb_to_lab(c.encoded, illuminant="D65"), atol=1e-4)
    noisy = estimate_colour_noise(c.lab, c.mask.mask, delta_e_method="CIEDE2000")
    floor = quantization_noise_de(c.encoded, c.mask.mask, bit_depth=8, **KW)
    assert c.noise_de == pytest.approx(max(noisy, floor)) and noisy > floor
    flat = measure_colour(np.full((32, 32, 3), [0.7, 0.4, 0.2], np.float32), opts,
                          color_space="sRGB", bit_depth=8, **KW)
    q = quantization_noise_de(flat.encoded, flat.mask.mask, bit_depth=8, **KW)
    assert q > 0 and flat.noise_de == pytest.approx(q)
    assert flat.bit_depth == 8


def test_compression_noise_is_the_block_mean_error_a_real_jpeg_leaves(tmp_path):
    """A real encoder (libjpeg through Pillow, 4:4:4) on an image of 8 × 8 blocks of random
    colours with pixel noise of 3 code values: the ΔE00 between each block's mean before and
    after (the AC terms sum to zero over a block: only the DC rounding moves it) is the
    error :func:`compression_noise_de` predicts from the file's DC steps (median/1.54 per
    component), and it scales with the step."""
    from PIL import Image

    from microfacet.analysis.colour_image import compression_noise_de
    from microfacet.colour.difference import delta_e
    from microfacet.colour.srgb import srgb_to_lab
    from microfacet.io.images import image_info

    rng = np.random.default_rng(4)
    blocks = rng.integers(60, 200, (24, 24, 3)).astype(np.float64)
    img = np.clip(np.repeat(np.repeat(blocks, 8, 0), 8, 1) + rng.normal(0, 3, (192, 192, 3)),
                  0, 255).round().astype(np.uint8)
    before = img.reshape(24, 8, 24, 8, 3).mean(axis=(1, 3)) / 255.0
    got = {}
    for q in (30, 60):
        p = tmp_path / f"{q}.jpg"
        Image.fromarray(img).save(p, quality=q, subsampling=0)
        with Image.open(p) as im:
            dec = np.asarray(im.convert("RGB"), np.float64)
        after = dec.reshape(24, 8, 24, 8, 3).mean(axis=(1, 3)) / 255.0
        de = delta_e(srgb_to_lab(before, **KW_LAB), srgb_to_lab(after, **KW_LAB),
                     method="CIEDE2000")
        jpeg = image_info(p, "x").jpeg
        predicted = compression_noise_de(img / 255.0, np.zeros(img.shape[:2], bool), jpeg,
                                         **KW)
        assert predicted == pytest.approx(float(np.median(de) / 1.54), rel=0.25)
        got[q] = (predicted, jpeg.dc_steps[0])
    assert got[30][0] / got[60][0] == pytest.approx(got[30][1] / got[60][1], rel=0.2)
