"""Colour mask: the seed's saturation test, dark, clipped, shadowed and NaN pixels."""

import numpy as np
import pytest

from microfacet.analysis.mask import colour_mask
from microfacet.analysis.options import MaskOptions


def test_each_reason_is_detected_and_named():
    img = np.full((20, 20, 3), [0.6, 0.3, 0.8], np.float32)  # saturated purple
    img[0, 0] = [0.5, 0.5, 0.52]      # grey: saturation (0.02/0.52*255 = 9.8) < 15
    img[0, 1] = [0.05, 0.02, 0.06]    # dark: value 15 < 20
    img[0, 2] = [1.0, 1.0, 0.3]       # clipped red and green channels
    img[0, 3] = [np.nan, 0.1, 0.1]    # invalid
    img[10, 10] = img[10, 10] * 0.5   # a shadowed pixel: same hue, half the value
    img[5, 5] = [1.0, 0.4, 0.6]       # one clipped channel: analysed, not masked
    m = colour_mask(img)
    assert m.low_saturation[0, 0] and m.dark[0, 1] and m.clipped[0, 2] and m.invalid[0, 3]
    assert m.shadow[10, 10] and not m.low_saturation[10, 10]
    assert m.mask.sum() == 5
    assert m.fraction == pytest.approx(5 / 400)
    assert set(m.fractions()) == {"low_saturation", "dark", "clipped", "invalid", "shadow",
                                   "steep", "dark_feature", "any", "grey_film", "clipped_one"}
    assert np.argwhere(m.clipped_one).tolist() == [[5, 5]] and m.clip_analysed
    assert not m.coloured[5, 5] and m.coloured[6, 6]     # not for the white balance


def test_one_clipped_channel_is_analysed_unless_told_or_divided_by_a_field():
    img = np.full((16, 16, 3), [0.6, 0.3, 0.8], np.float32)
    img[2:6, 2:6, 2] = 1.0                     # blue clipped
    img[8:10, 8:10, :2] = 1.0                  # red and green clipped
    img[12, 12] = [1.0, 0.97, 0.98]            # one channel clipped, but grey: low saturation
    o = MaskOptions(shadow_ratio=0, steep_ratio=0)
    m = colour_mask(img, o)
    assert m.clipped_one.sum() == 16 and not m.mask[2:6, 2:6].any()
    assert m.clipped[8:10, 8:10].all() and m.mask[8:10, 8:10].all()
    assert m.mask[12, 12] and m.clipped[12, 12] and m.low_saturation[12, 12]
    off = colour_mask(img, MaskOptions(shadow_ratio=0, steep_ratio=0, clipped_one_channel=False))
    assert off.clipped_one is None and not off.clip_analysed
    np.testing.assert_array_equal(off.clipped, np.any(img >= 1.0, axis=-1))
    again = m.clipped_masked()          # a flat field divided out: the clip level varies
    np.testing.assert_array_equal(again.mask, off.mask)
    np.testing.assert_array_equal(again.clipped, off.clipped)
    assert again.clipped_one is None and off.clipped_masked() is off


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
    m = colour_mask(img, bit_depth=16)
    assert not m.clipped[0, 0] and m.clipped_one is None
    img[0, 0, 0] = 1.0
    assert colour_mask(img, bit_depth=16).clipped_one[0, 0]
    img[0, 0, 1] = 1.0
    assert colour_mask(img, bit_depth=16).clipped[0, 0]


def test_bad_image_shape():
    with pytest.raises(ValueError, match="image"):
        colour_mask(np.zeros((4, 4)))


def _film_linear_rgb(thickness_nm, film="TiO2_Jolivet2023_amorphous",
                     substrate="Ti_JohnsonChristy1974"):
    """Linear sRGB (D65-balanced) of the film at normal incidence, one row per thickness."""
    from microfacet.colour.srgb import colours_from_spectra, srgb_decode
    from microfacet.optics.thinfilm import reflectance

    wl = np.arange(380.0, 781.0, 5.0)
    r = reflectance(wl[None, :], 0.0, np.asarray(thickness_nm, float)[:, None], film,
                    substrate)
    return srgb_decode(colours_from_spectra(r, wl, exposure=0.6)[2] / 255.0)


@pytest.mark.parametrize("film", ["TiO2_Jolivet2023_amorphous", "TiO2_Siefke2016_ALD"])
@pytest.mark.parametrize("substrate", ["Ti_JohnsonChristy1974", "Ti_Palm2018"])
def test_no_film_colour_is_darker_than_the_steep_core(film, substrate):
    # Airy's formula over 20-400 nm: the darkest film (29-37 nm) against the median film
    # colour stays well above the core threshold (1.5x on Palm's Ti, 2.6x on Johnson &
    # Christy's), so a few % of pixel noise does not take a film for a steep facet; it is
    # below the rim's threshold, which is why that one alone would
    top = _film_linear_rgb(np.arange(20.0, 401.0, 1.0), film, substrate).max(axis=-1)
    darkest = float(top.min() / np.median(top))
    assert 1.4 * MaskOptions().steep_core_ratio < darkest < MaskOptions().steep_ratio


def test_a_dark_film_is_not_steep_but_a_dark_facet_and_its_rim_are():
    from microfacet.colour.srgb import srgb_encode

    thin, thick = _film_linear_rgb([37.0, 200.0])
    rng = np.random.default_rng(3)
    lin = np.broadcast_to(thick, (40, 60, 3)).copy()
    lin[:, 40:] = thin                               # a third of the field: 37 nm film
    ref = float(np.median(lin.max(axis=-1)))
    lin *= rng.uniform(0.97, 1.03, lin.shape[:2])[..., None]
    lin[10:16, 10:16] = 0.05 * ref * np.array([1.0, 0.9, 0.8])     # a steep facet (dark core)
    lin[9, 10:16] = 0.2 * ref * thick / thick.max()                # its blurred rim
    lin[20, 50] = 0.04 * ref                                        # a pit in the dark film
    lin[30:32, 2:30] = 0.2 * ref * thick / thick.max()              # a scratch as dark, 2 px
    m = colour_mask(srgb_encode(lin, dtype=np.float32), MaskOptions(shadow_ratio=0))
    assert m.steep[10:16, 10:16].all() and m.steep[9, 10:16].all()
    assert m.steep[20, 50]
    assert not m.steep[:, 40:][np.hypot(*np.mgrid[-20:20, -10:10]) > 2.5].any()
    assert m.steep.sum() == 36 + 6 + 21       # the facet, its rim, the pit and its rim
    # the scratch is dark but thin: masked, not steep; the dark film is neither
    assert m.dark_feature[30:32, 2:30].all() and not m.steep[30:32, 2:30].any()
    assert m.dark_feature.sum() == 56 and not m.mask[:, 40:][
        np.hypot(*np.mgrid[-20:20, -10:10]) > 2.5].any()
    # one threshold (the core at 0.3) masks the whole dark film as steep
    one = colour_mask(srgb_encode(lin, dtype=np.float32),
                      MaskOptions(shadow_ratio=0, steep_core_ratio=0.3))
    assert one.steep[:, 40:].mean() > 0.9


def test_a_nan_pixel_is_no_steep_core():
    # invalid (NaN) pixels are masked as invalid; the dim pixels beside one are not a rim
    img = np.full((20, 20, 3), [0.6, 0.3, 0.8], np.float32)
    img[5:8, 5:8] *= 0.5                       # linear ~0.2 of the film: dim, no dark core
    img[6, 6] = np.nan
    m = colour_mask(img, MaskOptions(shadow_ratio=0, dark_film_min_px=1))
    assert m.invalid[6, 6] and not m.steep.any()
    assert not m.dark_feature.any()            # 3 px is a film at dark_film_min_px 1


def test_a_wide_grey_film_is_analysed_but_a_grey_rim_and_a_grey_image_are_masked():
    from microfacet.colour.srgb import srgb_encode

    # Airy's formula: rutile near 51 nm on Werner's Ti is grey (a population of a sweep
    # scene that the seed's saturation test masked whole)
    grey, blue = _film_linear_rgb([51.0, 158.0], "TiO2_Devore1951_rutile_e",
                                  "Ti_Werner2009_REELS")
    enc = srgb_encode(np.stack([grey, blue]), dtype=np.float32)
    sat = (enc.max(axis=-1) - enc.min(axis=-1)) / enc.max(axis=-1) * 255
    assert sat[0] < 15 < sat[1]                              # the premise
    rng = np.random.default_rng(5)
    lin = np.broadcast_to(blue, (60, 90, 3)).copy()
    lin[:, 60:] = grey                                       # a third of the field: grey film
    lin[20, 5:50] = grey                                     # a grey rim, 1 px wide
    lin[40:45, 10:15] = grey                                 # a grey glint, 5 px
    lin *= rng.normal(1.0, 0.01, lin.shape)                  # noise: the grey film speckles
    img = srgb_encode(np.clip(lin, 0, 1), dtype=np.float32)
    m = colour_mask(img, MaskOptions(shadow_ratio=0))
    low = colour_mask(img, MaskOptions(shadow_ratio=0, grey_film_min_px=0)).low_saturation
    assert low[:, 60:].mean() > 0.5                          # the seed's test masks most of it
    assert not m.mask[:, 62:].any() and m.grey_film[:, 62:].all()
    assert m.low_saturation[20, 5:50].all() and m.low_saturation[40:45, 10:15].all()
    # the grey film reported: the seed's low-saturation pixels that are no longer masked
    assert m.fractions()["grey_film"] == pytest.approx(np.mean(low & ~m.mask))
    # every pixel grey (a monochrome camera, a bare sample): nothing is film of colour
    allgrey = srgb_encode(np.broadcast_to(grey, (60, 90, 3)).copy(), dtype=np.float32)
    assert colour_mask(allgrey, MaskOptions(shadow_ratio=0)).mask.all()
