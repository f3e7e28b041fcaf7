"""microfacet.colour.transfer: the sRGB transfer functions (kept ours).

Reference: IEC 61966-2-1:1999 §5.2 (decoding) and §5.3 (encoding): linear segment
12.92 below 0.04045 / 0.0031308, ((V + 0.055) / 1.055)^2.4 above.
"""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from hypothesis.extra.numpy import arrays

from microfacet.colour.transfer import srgb_decode, srgb_encode


def iec_decode(v):
    v = np.asarray(v, dtype=np.float64)
    return np.where(v <= 0.04045, v / 12.92, ((np.maximum(v, 0.04045) + 0.055) / 1.055) ** 2.4)


def test_published_values():
    np.testing.assert_allclose(srgb_decode(np.array([0.0, 0.04045, 0.5, 1.0])),
                               [0.0, 0.0031308, 0.2140411, 1.0], rtol=0, atol=1e-7)
    np.testing.assert_allclose(srgb_encode(np.array([0.0031308, 0.18, 0.2140411]),
                                           dtype=np.float32),
                               [0.04045, 0.4613561, 0.5], rtol=0, atol=1e-6)
    # 8-bit: code 128 is 0.2158605 linear; mid-grey 0.18 encodes to 118
    assert srgb_decode(np.array([128], np.uint8))[0] == pytest.approx(0.2158605, abs=1e-7)
    assert srgb_encode(np.array([0.18])).tolist() == [118]


@pytest.mark.parametrize("dtype, scale", [(np.uint8, 255), (np.uint16, 65535)])
def test_integer_decode_is_the_iec_formula(dtype, scale):
    codes = np.arange(scale + 1, dtype=dtype)
    out = srgb_decode(codes)
    assert out.dtype == np.float32 and out.shape == codes.shape
    np.testing.assert_allclose(out, iec_decode(codes / scale), rtol=1e-6, atol=1e-9)


def test_float_decode_is_the_iec_formula_and_unclipped():
    v = np.linspace(-0.2, 1.2, 1401)
    np.testing.assert_allclose(srgb_decode(v), iec_decode(v), rtol=1e-6, atol=1e-9)
    assert srgb_decode(v).dtype == np.float32
    assert srgb_decode(np.array([1.2]))[0] > 1.0  # not clipped


def test_integer_round_trips_are_exact():
    u8 = np.arange(256, dtype=np.uint8)
    assert np.array_equal(srgb_encode(srgb_decode(u8)), u8)
    u16 = np.arange(65536, dtype=np.uint16)
    assert np.array_equal(srgb_encode(srgb_decode(u16), dtype=np.uint16), u16)


@pytest.mark.slow
@settings(max_examples=200, deadline=None)
@given(arrays(np.float64, (5,), elements=st.floats(0, 1)))
def test_decode_encode_round_trip(x):
    np.testing.assert_allclose(srgb_decode(srgb_encode(x, dtype=np.float32)), x,
                               rtol=1e-5, atol=1e-7)


def test_encode_is_continuous_and_monotonic():
    x = np.linspace(0, 1, 100001)
    enc = srgb_encode(x, dtype=np.float32).astype(np.float64)
    assert np.all(np.diff(enc) >= 0)
    knee = srgb_encode(np.array([0.0031308 - 1e-9, 0.0031308 + 1e-9]), dtype=np.float32)
    assert abs(float(knee[1]) - float(knee[0])) < 1e-6


def test_encode_clips_rounds_and_handles_nan():
    lin = np.array([[np.nan, -0.5, 0.5, 2.0]])
    assert srgb_encode(lin).tolist() == [[0, 0, 188, 255]]
    assert srgb_encode(lin, dtype=np.uint16)[0, 3] == 65535
    f = srgb_encode(lin, dtype=np.float32)
    assert f.dtype == np.float32 and np.isnan(f[0, 0]) and f[0, 1] == 0 and f[0, 3] == 1
    dec = srgb_decode(np.array([np.nan, 0.5]))
    assert dec.dtype == np.float32 and np.isnan(dec[0]) and not np.isnan(dec[1])


def test_float32_in_float32_out_shape_kept():
    img = np.random.default_rng(0).uniform(0, 1, (4, 5, 3)).astype(np.float32)
    assert srgb_decode(img).dtype == np.float32 and srgb_decode(img).shape == img.shape
    assert srgb_encode(img).shape == img.shape


def test_bad_input():
    with pytest.raises(ValueError, match="image"):
        srgb_decode(np.zeros(3, np.int32))
    with pytest.raises(ValueError, match="image"):
        srgb_decode(np.zeros(3, bool))
    with pytest.raises(ValueError, match="dtype"):
        srgb_encode(np.zeros(3), dtype=np.int16)
    with pytest.raises(ValueError, match="linear"):
        srgb_encode(np.array(["x"]))
