"""Colour mask: the seed's saturation test, dark, clipped, shadowed and NaN pixels."""

import numpy as np
import pytest

from microfacet.analysis.mask import colour_mask
from microfacet.analysis.options import MaskOptions


def test_each_reason_is_detected_and_named():
    img = np.full((20, 20, 3), [0.6, 0.3, 0.8], np.float32)  # saturated purple
    img[0, 0] = [0.5, 0.5, 0.52]      # grey: saturation (0.02/0.52*255 = 9.8) < 15
    img[0, 1] = [0.05, 0.02, 0.06]    # dark: value 15 < 20
    img[0, 2] = [1.0, 0.4, 0.3]       # clipped red channel
    img[0, 3] = [np.nan, 0.1, 0.1]    # invalid
    img[10, 10] = img[10, 10] * 0.5   # a shadowed pixel: same hue, half the value
    m = colour_mask(img)
    assert m.low_saturation[0, 0] and m.dark[0, 1] and m.clipped[0, 2] and m.invalid[0, 3]
    assert m.shadow[10, 10] and not m.low_saturation[10, 10]
    assert m.mask.sum() == 5
    assert m.fraction == pytest.approx(5 / 400)
    assert set(m.fractions()) == {"low_saturation", "dark", "clipped", "invalid", "shadow",
                                   "steep", "any"}


def test_saturation_threshold_is_on_the_0_255_scale():
    # S = (max - min) / max * 255; exactly at 15 is kept, just below is masked.
    v = 0.8
    keep = np.array([[[v, v * (1 - 15.5 / 255), v]]], np.float32)
    drop = np.array([[[v, v * (1 - 14.5 / 255), v]]], np.float32)
    assert not colour_mask(keep, MaskOptions(shadow_ratio=0)).mask[0, 0]
    assert colour_mask(drop, MaskOptions(shadow_ratio=0)).mask[0, 0]


def test_sixteen_bit_clip_level():
    img = np.full((4, 4, 3), [0.9, 0.5, 0.2], np.float32)
    img[0, 0, 0] = 65534.0 / 65535
    assert not colour_mask(img, bit_depth=16).clipped[0, 0]
    img[0, 0, 0] = 1.0
    assert colour_mask(img, bit_depth=16).clipped[0, 0]


def test_bad_image_shape():
    with pytest.raises(ValueError, match="image"):
        colour_mask(np.zeros((4, 4)))
