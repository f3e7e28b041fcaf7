"""Focus measures (microfacet.focus.measures): sharper is larger, flat is zero, RGB is its
grey."""

import cv2
import numpy as np
import pytest

from microfacet.focus.measures import focus_measure


@pytest.mark.parametrize("op", ["tenengrad", "sml", "glv"])
def test_focus_measure_decreases_with_blur(op):
    rng = np.random.default_rng(0)
    tex = rng.random((64, 64)).astype(np.float32)
    vals = [focus_measure(cv2.GaussianBlur(tex, (0, 0), s), operator=op)[8:-8, 8:-8].mean()
            for s in (0.5, 1.0, 2.0, 4.0)]
    assert all(a > b for a, b in zip(vals, vals[1:]))
    assert focus_measure(np.full((16, 16), 0.3, np.float32), operator=op).max() < 1e-6
    rgb = np.repeat(tex[..., None], 3, axis=2)
    np.testing.assert_allclose(focus_measure(rgb, operator=op), focus_measure(tex, operator=op),
                               rtol=1e-4, atol=1e-7)
