"""The camera's white balance (microfacet.analysis.white_balance): gains from a white
reference, colours corrected for them against the package's own sRGB → CIELAB (an image
made balanced × gains reads as the balanced one), and a scene whose slices carry a white
balance analysed with its white reference like the same scene without one."""

from __future__ import annotations

import dataclasses
import json
import shutil

import numpy as np
import pytest

from microfacet.analysis.white_balance import WhiteBalance, balanced_lab, reference_gains
from microfacet.colour.srgb import srgb_to_lab
from microfacet.colour.transfer import srgb_decode, srgb_encode
from microfacet.core.errors import InputError

GAINS = (1.12, 1.0, 0.9)


def _unbalanced(encoded, gains=GAINS):
    """Encoded sRGB (float, 0-1) whose linear R, G, B were multiplied by ``gains``."""
    lin = srgb_decode(np.asarray(encoded, np.float32)) * np.asarray(gains, np.float32)
    return srgb_encode(lin, dtype=np.float32)


def test_an_unbalanced_image_corrected_reads_as_the_balanced_one():
    rng = np.random.default_rng(0)
    balanced = rng.uniform(0.05, 0.85, size=(32, 32, 3)).astype(np.float32)
    lab = balanced_lab(_unbalanced(balanced), GAINS, illuminant="D65")
    ref = srgb_to_lab(balanced, illuminant="D65")
    np.testing.assert_allclose(lab, ref, atol=2e-3)
    # and gains of 1 change nothing
    np.testing.assert_allclose(balanced_lab(balanced, (1, 1, 1), illuminant="D65"), ref,
                               atol=1e-4)


@pytest.mark.parametrize("level", [0.3, 0.8])
def test_a_white_standard_gives_the_gains(level):
    rng = np.random.default_rng(1)
    white = np.full((40, 50, 3), level, np.float32) * rng.uniform(0.97, 1.03, (40, 50, 1))
    img = _unbalanced(srgb_encode(white, dtype=np.float32))
    np.testing.assert_allclose(reference_gains(img, where="ref"), np.array(GAINS) / GAINS[1],
                               rtol=2e-3)


def test_a_clipped_or_grey_reference_is_refused_naming_it():
    with pytest.raises(InputError, match="ref: the white reference has too few"):
        reference_gains(np.ones((8, 8, 3), np.float32), where="ref")
    with pytest.raises(InputError, match="ref: a white reference must be an RGB image"):
        reference_gains(np.ones((8, 8), np.float32), where="ref")


def test_the_summary_section():
    d = WhiteBalance(gains_rgb=GAINS, source="stack.json").to_dict()
    assert d["gains_rgb"] == list(GAINS) and d["source"] == "stack.json"
    assert d["estimate_rgb"] is None and WhiteBalance().applied is False


@pytest.fixture(scope="module")
def scenes(tmp_path_factory):
    """One synthetic scene, balanced and with R × 1.12, B × 0.90 on its slices, and the
    latter's white reference (a white standard through the same gains)."""
    from microfacet.cli import main
    root = tmp_path_factory.mktemp("wb")
    for name, extra in (("balanced", []), ("unbalanced", ["--variation",
                                                         "white_balance_gains=1.12,1,0.9"])):
        assert main(["synth", "--preset", "nd", "--seed", "3", "--slices", "16",
                     str(root / name), "-q", *extra]) == 0
    from microfacet.io.images import write_image
    white = srgb_encode(np.full((16, 16, 3), 0.7, np.float32) * np.float32(GAINS),
                        dtype=np.uint8)
    write_image(root / "unbalanced" / "white.png", white)
    bare = srgb_encode(np.broadcast_to(0.9 * _bare_titanium_rgb() * np.float32(GAINS),
                                       (16, 16, 3)).astype(np.float32), dtype=np.uint8)
    write_image(root / "unbalanced" / "substrate.png", bare)
    return root


def _bare_titanium_rgb(oxide_nm=3.0):
    """Linear sRGB of titanium (Johnson & Christy) with ``oxide_nm`` of amorphous TiO2 (its
    native oxide) at normal incidence under D65, from tmm's reflectance through
    colour-science's colorimetry: independent of the package's film model and tables."""
    import colour
    import tmm

    from microfacet.optics.constants import resolve_index
    wl = np.arange(380.0, 781.0, 5.0)
    n_film = resolve_index("TiO2_Jolivet2023_amorphous", wl)
    n_ti = resolve_index("Ti_JohnsonChristy1974", wl)
    R = [tmm.coh_tmm("s", [1.0, a, b], [np.inf, oxide_nm, np.inf], 0.0, w)["R"]
         for a, b, w in zip(n_film, n_ti, wl)]
    sd = colour.SpectralDistribution(dict(zip(wl, R)))
    shape = colour.SpectralShape(380, 780, 5)
    cmfs = colour.MSDS_CMFS["CIE 1931 2 Degree Standard Observer"].copy().align(shape)
    d65 = colour.SDS_ILLUMINANTS["D65"].copy().align(shape)
    xyz = colour.sd_to_XYZ(sd, cmfs=cmfs, illuminant=d65, method="Integration") / 100.0
    return np.asarray(colour.XYZ_to_sRGB(xyz, apply_cctf_encoding=False), np.float32)


def _thickness(path, **optics):
    from microfacet.analysis.options import AnalysisOptions
    from microfacet.analysis.pipeline import analyse_stack
    from microfacet.io.stack import read_stack
    opts = AnalysisOptions().replace(optics=optics) if optics else AnalysisOptions()
    r = analyse_stack(read_stack(path), options=opts)
    return r.pixels.thickness_nm, r.white_balance


@pytest.mark.slow
def test_a_white_reference_makes_the_unbalanced_scene_read_as_the_balanced_one(scenes):
    """The reference given as the option and as stack.json's white_reference: the per-pixel
    thickness of the unbalanced scene equals the balanced scene's (median |Δ| < 0.3 nm),
    where without the reference it does not."""
    t_bal, _ = _thickness(scenes / "balanced")
    t_raw, wb_raw = _thickness(scenes / "unbalanced")
    t_ref, wb_ref = _thickness(scenes / "unbalanced",
                               white_reference=str(scenes / "unbalanced" / "white.png"))
    ok = np.isfinite(t_bal) & np.isfinite(t_raw) & np.isfinite(t_ref)
    assert wb_raw.source == "none" and wb_ref.source == "white reference white.png"
    np.testing.assert_allclose(wb_ref.gains_rgb, GAINS, rtol=0.01)
    err_ref = float(np.median(np.abs(t_ref[ok] - t_bal[ok])))
    err_raw = float(np.median(np.abs(t_raw[ok] - t_bal[ok])))
    assert err_ref < 0.3 < err_raw, (err_ref, err_raw)
    # the same through stack.json
    _, t_key, wb_key = _through_stack_json(scenes, "white_reference", "white.png")
    assert wb_key.source == "white reference white.png"
    np.testing.assert_array_equal(t_key, t_ref)


def _through_stack_json(scenes, key, file):
    """The unbalanced scene copied with stack.json's ``key`` naming ``file``, analysed:
    ``(folder, thickness, white balance)``."""
    meta = json.loads((scenes / "unbalanced" / "stack.json").read_text())
    copy = scenes / f"with-{key}"
    shutil.copytree(scenes / "unbalanced", copy)
    (copy / "stack.json").write_text(json.dumps({**meta, key: file}))
    return (copy, *_thickness(copy))


def test_stack_json_gains_are_checked_and_used(tmp_path):
    from microfacet.analysis.options import OpticsOptions
    from microfacet.analysis.white_balance import choose_white_balance
    from microfacet.io.stack import read_stack
    shutil.copytree("fixtures/stacks/nd-fixture", tmp_path / "s",
                    ignore=shutil.ignore_patterns("truth"))
    meta = json.loads((tmp_path / "s" / "stack.json").read_text())
    (tmp_path / "s" / "stack.json").write_text(json.dumps({**meta,
                                                           "white_balance": [2.24, 2.0, 1.8]}))
    st = read_stack(tmp_path / "s")
    wb = choose_white_balance(st, None, None, None, None, OpticsOptions(white_balance="off"),
                              illuminant="D65")
    assert wb.source == "stack.json" and wb.gains_rgb == pytest.approx(GAINS)
    (tmp_path / "s" / "stack.json").write_text(json.dumps({**meta, "white_balance": [1, 0]}))
    with pytest.raises(InputError, match="key 'white_balance': must be a list of 3 numbers"):
        read_stack(tmp_path / "s")


@pytest.mark.parametrize("wb, expected", [
    # a reference's gains: its assumed 1 %
    (WhiteBalance(gains_rgb=GAINS, source="stack.json"), (0.01, 0.01)),
    (WhiteBalance(gains_rgb=GAINS, source="white reference w.png",
                  estimate_rgb=(1.3, 1.0, 0.7), estimate_sigma=(0.2, 0.2)), (0.01, 0.01)),
    # not applied: the truth's RMS distance from gains of 1, given the estimate
    (WhiteBalance(estimate_rgb=(1.1, 1.0, 0.95), estimate_sigma=(0.02, 0.03),
                  determined=(False, False)),
     (float(np.hypot(np.log(1.1), 0.02)), float(np.hypot(np.log(0.95), 0.03)))),
    # applied where determined: its spread; the other gain left at 1
    (WhiteBalance(gains_rgb=(1.1, 1.0, 1.0), source="estimated", estimate_rgb=(1.1, 1.0, 0.95),
                  estimate_sigma=(0.005, 0.03), determined=(True, False)),
     (0.005, float(np.hypot(np.log(0.95), 0.03)))),
    # ... and still so once withdrawn (the thickness not identified): the gain was applied
    (WhiteBalance(gains_rgb=(1.1, 1.0, 1.0), source="estimated", estimate_rgb=(1.1, 1.0, 0.95),
                  estimate_sigma=(0.005, 0.03), determined=(True, False)).withdraw("x"),
     (0.005, float(np.hypot(np.log(0.95), 0.03)))),
    # an estimate without a finite spread: the search's half-range stands in
    (WhiteBalance(estimate_rgb=(1.0, 1.0, 1.0), estimate_sigma=(float("inf"), 0.01),
                  determined=(False, False)), (0.2, 0.01)),
    (WhiteBalance(), None),                                   # white_balance = "off"
])
def test_the_gains_uncertainty_the_thickness_means_carry(wb, expected):
    got = wb.log_gain_sigma()
    assert got == (None if expected is None else pytest.approx(expected, abs=1e-12))


def test_rebalanced_colours_are_those_balanced_with_the_larger_gains():
    """rebalanced_lab moves Lab the way balancing the encoded image with gains larger by
    exp(δ) does, for colours across the gamut and both signs of δ."""
    from microfacet.analysis.white_balance import rebalanced_lab

    rng = np.random.default_rng(3)
    img = rng.uniform(0.05, 0.9, size=(200, 3)).astype(np.float32)
    for d_r, d_b in ((0.05, 0.0), (0.0, -0.08), (-0.1, 0.12)):
        want = balanced_lab(img, (np.exp(d_r), 1.0, np.exp(d_b)), illuminant="D65")
        got = rebalanced_lab(balanced_lab(img, (1.0, 1.0, 1.0), illuminant="D65"),
                             (d_r, d_b), illuminant="D65")
        np.testing.assert_allclose(got, want, atol=2e-3)
        moved = np.abs(got - balanced_lab(img, (1.0, 1.0, 1.0), illuminant="D65")).max()
        assert moved > 0.5                                    # the gains do move the colours


def _model():
    from microfacet.colour.model import FilmColourModel
    from microfacet.colour.table import build_colour_table
    return FilmColourModel(build_colour_table(thickness_range_nm=(0.0, 50.0),
                                              theta_range_deg=(0.0, 10.0)))


def _bare_image(oxide_nm=3.0, seed=5):
    rng = np.random.default_rng(seed)
    lin = 0.8 * _bare_titanium_rgb(oxide_nm) * np.float32(GAINS)
    return srgb_encode(np.clip(lin + rng.normal(0, 0.01, (32, 32, 3)), 0, 1).astype(np.float32),
                       dtype=np.uint8).astype(np.float32) / 255.0


def test_a_bare_substrate_image_gives_the_gains():
    """substrate_gains divides the metal's own colour out: an image of titanium with its
    native 3 nm of oxide through a camera's (1.12, 1, 0.90), 8-bit and noisy, gives those
    gains to 1 %, where taking it for a white standard would be 8-10 % off (titanium is a
    warm grey)."""
    from microfacet.analysis.white_balance import substrate_gains

    model, img = _model(), _bare_image()
    got = substrate_gains(img, model, where="substrate_reference")
    np.testing.assert_allclose(got, GAINS, rtol=0.01)
    as_white = reference_gains(img, where="white_reference")
    assert abs(as_white[0] / GAINS[0] - 1.0) > 0.05 and abs(as_white[2] / GAINS[2] - 1.0) > 0.05
    with pytest.raises(InputError, match="substrate_reference: the substrate reference has too "
                                         "few pixels"):
        substrate_gains(np.zeros((8, 8, 3), np.float32), model, where="substrate_reference")


@pytest.mark.parametrize("oxide_nm", [1.5, 4.5])
def test_a_native_oxide_off_the_assumed_is_inside_the_gains_sigma(oxide_nm):
    """A reference whose native oxide is 1.5 nm off the assumed 3 nm gives gains off by
    about the σ substrate_gain_sigma reports (within 2σ, and more than 0.4σ: the σ is not
    idle), and ``substrate_oxide_nm`` set to the truth takes the error away."""
    from microfacet.analysis.white_balance import substrate_gain_sigma, substrate_gains

    model, img = _model(), _bare_image(oxide_nm)
    sig = substrate_gain_sigma(model)
    got = substrate_gains(img, model, where="substrate_reference")
    err = np.abs(np.log(np.array([got[0], got[2]]) / np.array([GAINS[0], GAINS[2]])))
    assert np.all(err <= 2.0 * np.array(sig)) and np.all(err > 0.4 * np.array(sig)), (err, sig)
    right = substrate_gains(img, model, where="substrate_reference", oxide_nm=oxide_nm)
    np.testing.assert_allclose(right, GAINS, rtol=0.01)


@pytest.mark.slow
def test_a_substrate_reference_makes_the_unbalanced_scene_read_as_the_balanced_one(scenes):
    """A bare-titanium field through the same camera, as the option and as stack.json's
    substrate_reference: the unbalanced scene's thickness is the balanced one's (median
    |Δ| < 0.3 nm); a white reference given too wins over it."""
    t_bal, _ = _thickness(scenes / "balanced")
    ref = str(scenes / "unbalanced" / "substrate.png")
    t_sub, wb_sub = _thickness(scenes / "unbalanced", substrate_reference=ref)
    ok = np.isfinite(t_bal) & np.isfinite(t_sub)
    assert wb_sub.source == "substrate reference substrate.png"
    np.testing.assert_allclose(wb_sub.gains_rgb, GAINS, rtol=0.01)
    assert float(np.median(np.abs(t_sub[ok] - t_bal[ok]))) < 0.3
    copy, t_key, wb_key = _through_stack_json(scenes, "substrate_reference", "substrate.png")
    assert wb_key.source == "substrate reference substrate.png"
    np.testing.assert_array_equal(t_key, t_sub)
    _, wb_both = _thickness(copy, white_reference=str(copy / "white.png"))
    assert wb_both.source == "white reference white.png"


def _film_image(model, thickness_nm, tilt_deg, rng):
    """Encoded sRGB of the film at ``thickness_nm`` and ``tilt_deg`` per pixel, exposure
    0.8, through :data:`GAINS` (:func:`_unbalanced`), with white noise of 0.01."""
    from microfacet.colour.srgb import model_xyz_to_linear_srgb
    lin = model_xyz_to_linear_srgb(model.xyz(tilt_deg, thickness_nm), white=model.white,
                                   illuminant="D65") * 0.8
    enc = _unbalanced(srgb_encode(np.clip(lin, 0.0, 1.0), dtype=np.float32))
    return np.clip(enc + rng.normal(0.0, 0.01, enc.shape), 0.0, 1.0).astype(np.float32)


@pytest.mark.slow
def test_one_film_colour_leaves_the_gains_free_four_fix_them():
    """A gain and a thickness trade off for one film colour: the estimate's spread is
    unbounded and the order check is told so (:func:`gains_unconstrained`), and no gain is
    called determined; four film colours over-determine the two gains: found within 3 %
    (σ ~2 %), not free, and counted as three (:func:`film_colours`: the 180 nm film is a
    cyan whose red is recorded at 0, which pins no gain)."""
    from microfacet.analysis.identification import gains_unconstrained
    from microfacet.analysis.white_balance import estimate_white_balance
    from microfacet.colour.model import FilmColourModel
    from microfacet.colour.table import build_colour_table

    model = FilmColourModel(build_colour_table(thickness_range_nm=(0.0, 400.0),
                                               theta_range_deg=(0.0, 30.0)))
    rng = np.random.default_rng(1)
    tilt = np.abs(rng.normal(0.0, 5.0, (256, 256)))
    four = np.kron(np.array([[60.0, 120.0], [180.0, 240.0]]), np.ones((128, 128)))
    found = {}
    for name, d in (("one", np.full((256, 256), 85.0)), ("four", four)):
        img = _film_image(model, d, tilt, rng)
        found[name] = estimate_white_balance(img, tilt, np.ones(d.shape, bool), model,
                                             illuminant="D65")
    assert gains_unconstrained(found["one"])
    assert not all(np.isfinite(found["one"].estimate_sigma))
    assert not any(found["one"].determined)
    four = found["four"]
    assert four.film_colours == 3
    assert not gains_unconstrained(four)
    assert abs(four.estimate_rgb[0] / GAINS[0] - 1) < 0.03
    assert abs(four.estimate_rgb[2] / GAINS[2] - 1) < 0.03
    # a reference gives the gains: never free, whatever the estimate's spread
    assert not gains_unconstrained(dataclasses.replace(found["one"], source="stack.json"))


def _chroma(model, thickness_nm, tilt_deg):
    """The film's log chromaticity (log R/G, log B/G) at each thickness and tilt, as a
    camera records it (a channel below 0, outside the sRGB gamut, at the estimate's floor)."""
    from microfacet.colour.srgb import model_xyz_to_linear_srgb
    rgb = model_xyz_to_linear_srgb(model.xyz(np.asarray(tilt_deg, float),
                                             np.asarray(thickness_nm, float)),
                                   white=model.white, illuminant="D65")
    rgb = np.maximum(rgb, 1e-4)
    return np.log(rgb[..., [0, 2]] / rgb[..., 1:2])


@pytest.mark.parametrize(("thickness_nm", "expected"), [
    ([150.0] * 20, 1),                                    # one colour
    ([150.0] * 16 + [190.0] * 4, 2),                      # a second of the fewest tiles
    ([150.0] * 17 + [190.0] * 3, 1),                      # too few tiles for a colour
    ([60.0] * 5 + [120.0] * 5 + [180.0] * 5, 3),
    ([150.0] * 10 + [140.0] * 10, 2),                     # 10 nm apart: another colour
    ([], 0),
])
def test_distinct_film_colours_are_groups_of_tiles_apart_in_chromaticity(thickness_nm,
                                                                         expected):
    """Tiles of one film over tilts of 0-15° are one colour, films 10 nm or more apart are
    distinct ones; a gain shared by all tiles changes nothing."""
    from microfacet.analysis.white_balance import film_colours
    from microfacet.colour.model import FilmColourModel
    from microfacet.colour.table import build_colour_table

    model = FilmColourModel(build_colour_table(thickness_range_nm=(0.0, 400.0),
                                               theta_range_deg=(0.0, 30.0)))
    rng = np.random.default_rng(0)
    d = rng.permutation(np.asarray(thickness_nm, float))
    u = _chroma(model, d, rng.uniform(0.0, 15.0, d.size)).reshape(d.size, 2)
    assert film_colours(u) == expected
    assert film_colours(u + np.log([1.12, 0.9])) == expected


@pytest.mark.slow
def test_one_film_colour_with_a_narrow_spread_is_not_called_determined():
    """One film colour (200 nm) over a tilt spread of 5°: the misfit's valley, along which
    a gain and the thickness trade, is curved, and its width across the best is narrow,
    while the best may lie far along it. One colour is counted, its spread is unbounded,
    and no gain is called determined."""
    from microfacet.analysis.white_balance import estimate_white_balance
    from microfacet.colour.model import FilmColourModel
    from microfacet.colour.table import build_colour_table

    model = FilmColourModel(build_colour_table(thickness_range_nm=(0.0, 400.0),
                                               theta_range_deg=(0.0, 40.0)))
    rng = np.random.default_rng(1)
    tilt = np.clip(np.abs(rng.normal(0.0, 5.0, (256, 256))), 0.0, 40.0)
    img = _film_image(model, np.full((256, 256), 200.0), tilt, rng)
    wb = estimate_white_balance(img, tilt, np.ones(tilt.shape, bool), model,
                                illuminant="D65")
    assert wb.film_colours == 1 and wb.determined == (False, False)
    assert not any(np.isfinite(wb.estimate_sigma))


@pytest.mark.slow
def test_the_tiles_average_the_pixel_noise_and_the_sigma_counts_film_colours():
    """Pixel noise of 0.05 in encoded sRGB (several times what a 10 % gain does to a dark
    film's pixel) averages out in the tiles' summed colours: the gains within 3 %, the truth
    within 2σ of the estimate, which counts film colours (at least three of the four: the
    darkest film's noisy tiles may fail the one-film test), not the tiles."""
    from microfacet.analysis.white_balance import estimate_white_balance
    from microfacet.colour.model import FilmColourModel
    from microfacet.colour.table import build_colour_table

    model = FilmColourModel(build_colour_table(thickness_range_nm=(0.0, 400.0),
                                               theta_range_deg=(0.0, 30.0)))
    rng = np.random.default_rng(2)
    tilt = np.abs(rng.normal(0.0, 5.0, (256, 256)))
    four = np.kron(np.array([[60.0, 120.0], [180.0, 240.0]]), np.ones((128, 128)))
    clean = _film_image(model, four, tilt, rng)
    noisy = np.clip(clean + rng.normal(0.0, 0.05, clean.shape), 0.0, 1.0).astype(np.float32)
    wb = estimate_white_balance(noisy, tilt, np.ones(four.shape, bool), model,
                                illuminant="D65")
    assert wb.film_colours >= 3 and wb.tiles > 100
    err = np.log([wb.estimate_rgb[0] / GAINS[0], wb.estimate_rgb[2] / GAINS[2]])
    assert np.all(np.abs(err) < 0.03)
    assert np.all(np.abs(err) <= 2.0 * np.asarray(wb.estimate_sigma))


def _two_films(thickness_nm, *, seed, tilt_sd_deg):
    """A film model (0-400 nm, 0-30°), tilts |N(0, ``tilt_sd_deg``)| over 256² px, and the
    image (:func:`_film_image`) of two films side by side, ``thickness_nm`` (left, right)."""
    from microfacet.colour.model import FilmColourModel
    from microfacet.colour.table import build_colour_table

    model = FilmColourModel(build_colour_table(thickness_range_nm=(0.0, 400.0),
                                               theta_range_deg=(0.0, 30.0)))
    rng = np.random.default_rng(seed)
    tilt = np.abs(rng.normal(0.0, tilt_sd_deg, (256, 256)))
    two = np.kron(np.array([list(thickness_nm)]), np.ones((256, 128)))
    return model, tilt, _film_image(model, two, tilt, rng)


@pytest.mark.slow
def test_a_film_at_the_chromaticity_floor_is_kept_but_pins_no_gain():
    """TiO2 near 172 nm is a cyan of negative linear red, recorded at 0: its tiles are
    kept (their red read as the floor, not as noise about 0, which failed the one-film test
    and dropped them), but beside a 120 nm film it is no second colour: its red says nothing
    of the R gain, so the two films pin one combination of the gains, and the estimate
    leaves them free (counted, the gains read 18 % and 15 % off at a σ below 1 %)."""
    from microfacet.analysis.white_balance import TILE_PX, estimate_white_balance

    model, tilt, img = _two_films((120.0, 172.0), seed=3, tilt_sd_deg=5.0)
    assert np.mean(img[:, 128:, 0] == 0.0) > 0.3            # the cyan's red is clipped
    wb = estimate_white_balance(img, tilt, np.ones(tilt.shape, bool), model,
                                illuminant="D65")
    assert wb.tiles == (256 // TILE_PX) ** 2
    assert wb.film_colours == 1 and not any(np.isfinite(wb.estimate_sigma))


@pytest.mark.slow
def test_the_sigma_covers_tilts_the_height_map_inflated():
    """Two film colours (60 and 250 nm) rendered at tilts of |N(0, 8°)|, estimated with a
    tilt map 2.5 times those (the heights' noise inflates tilts): the model colours are
    taken at the wrong tilts and the R gain reads ~14 % off. The σ's tilt term (the same
    fit at half the tilts) covers it within 2σ; the noise and misfit terms alone are ~2 %."""
    from microfacet.analysis.white_balance import estimate_white_balance

    model, tilt, img = _two_films((60.0, 250.0), seed=2, tilt_sd_deg=8.0)
    ones = np.ones(tilt.shape, bool)
    right = estimate_white_balance(img, tilt, ones, model, illuminant="D65")
    wrong = estimate_white_balance(img, 2.5 * tilt, ones, model, illuminant="D65")
    err = np.log([wrong.estimate_rgb[0] / GAINS[0], wrong.estimate_rgb[2] / GAINS[2]])
    assert abs(err[0]) > 0.05 and wrong.film_colours == 2
    assert np.all(np.abs(err) <= 2.0 * np.asarray(wrong.estimate_sigma))
    assert np.all(np.asarray(right.estimate_sigma) < 0.05)
