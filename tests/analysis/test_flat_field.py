"""The flat field (microfacet.analysis.flat_field): a smooth illumination field estimated
from the facets' brightness, only where the data ask for it, and the colours divided by it.

References are analytic: facet images rendered by 1 nm spectral integration at a known
thickness and tilt per facet (:func:`~microfacet.colour.table.direct_xyz`, not the table the
estimate uses), multiplied by a known field; and a synthetic stack whose vignetting the
generator records.
"""

from __future__ import annotations

import json
import types
from pathlib import Path

import numpy as np
import pytest

from microfacet import colour as color
from microfacet.analysis import AnalysisOptions, analyse_stack
from microfacet.analysis.colour_image import measure_colour
from microfacet.analysis.flat_field import FlatField, estimate_flat_field, flat_fielded
from microfacet.analysis.options import FitOptions, MaskOptions
from microfacet.colour.model import FilmColourModel
from microfacet.colour.srgb import image_white_xyz
from microfacet.colour.table import build_colour_table, direct_xyz
from microfacet.colour.transfer import srgb_encode
from microfacet.forward.synth import generate_stack, preset

SIDE, ROWS = 12, 16           # 16 × 16 facets of 12 px: a 192 px image
MADS = FitOptions().unexplained_mads
ND_FIXTURE = Path(__file__).resolve().parents[2] / "fixtures" / "stacks" / "nd-fixture"


@pytest.fixture(scope="module")
def model():
    return FilmColourModel(build_colour_table(thickness_range_nm=(0.0, 400.0),
                                              theta_range_deg=(0.0, 27.0)))


def _scene(field, *, seed=0, side=SIDE, rows=ROWS):
    """``rows`` × ``rows`` facets of ``side`` px of random thickness (60-250 nm) and tilt
    (0-15°), rendered by direct spectral integration and multiplied by ``field(u, v)``; the
    joint result a fit would give (true thickness and tilt per facet) and the Lab image."""
    rng = np.random.default_rng(seed)
    n = rows * rows
    yy, xx = np.mgrid[0:rows * side, 0:rows * side]
    labels = ((yy // side) * rows + xx // side).astype(np.int32)
    d, t = rng.uniform(60.0, 250.0, n), rng.uniform(0.0, 15.0, n)
    h = w = rows * side
    r = np.hypot((h - 1) / 2.0, (w - 1) / 2.0)
    light = field((xx - (w - 1) / 2.0) / r, (yy - (h - 1) / 2.0) / r)
    xyz = direct_xyz(t[labels], d[labels], spectral_step_nm=1.0) * light[..., None]
    white = color.spectral_weights(np.arange(380.0, 781.0, 1.0)).sum(axis=0)
    rgb = np.maximum(color.model_xyz_to_linear_srgb(xyz, white=white), 0.0)  # as sRGB holds it
    lab = color.xyz_to_lab(color.linear_srgb_to_xyz(rgb), white=image_white_xyz())
    lab = lab.astype(np.float32)
    thick = types.SimpleNamespace(thickness_nm=d, delta_e=np.full(n, 0.5))
    joint = types.SimpleNamespace(facets=labels, usable=np.ones(labels.shape, bool),
                                  censored=np.zeros(labels.shape, bool), prior_deg=t,
                                  thickness=thick)
    return joint, lab, light


def test_the_field_is_one_at_the_centre_and_its_corners_say_their_loss():
    ff = FlatField(coefficients=(0.0, 0.0, -0.5, 0.0, -0.5))
    v = ff.map((9, 9))
    assert v[4, 4] == pytest.approx(1.0)
    assert v[0, 0] == pytest.approx(np.exp(-0.5), rel=1e-6)       # u = v = -1/√2
    assert np.allclose(v, v[::-1, ::-1]) and np.allclose(v, v.T)
    assert ff.corner_loss((9, 9)) == pytest.approx(1.0 - np.exp(-0.5), rel=1e-6)
    assert FlatField().corner_loss((9, 9)) is None
    assert np.all(FlatField().map((3, 4)) == 1.0)


@pytest.mark.slow
@pytest.mark.parametrize("field", [
    lambda u, v: 0.6 ** (2.0 * (u * u + v * v)),                            # the generator's
    lambda u, v: np.exp(-0.3 * (u - 0.2) ** 2 - 0.6 * v * v + 0.1 * u),     # off-centre
    lambda u, v: 1.0 / (1.0 + 0.8 * (u * u + v * v)) ** 2,                  # not of the form
], ids=["radial", "off-centre", "rational"])
def test_a_vignetted_image_gives_back_its_field(model, field):
    joint, lab, light = _scene(field)
    ff = estimate_flat_field(joint, lab, model, unexplained_mads=MADS)
    assert ff.reason == ""
    h, w = light.shape
    centre = field(np.array(0.0), np.array(0.0))          # both maps are 1 at the centre
    err = ff.log_map(light.shape) - np.log(light / centre)
    assert np.abs(err).max() < 0.03, (np.abs(err).max(), h, w)


@pytest.mark.slow
def test_even_light_asks_for_no_field(model):
    joint, lab, _ = _scene(lambda u, v: np.ones_like(u))
    rng = np.random.default_rng(1)
    lab = lab + rng.normal(0.0, 0.5, lab.shape).astype(np.float32)
    ff = estimate_flat_field(joint, lab, model, unexplained_mads=MADS)
    assert "BIC" in ff.reason and not ff.applied
    assert abs(ff.corner_loss(lab.shape[:2])) < 0.02


@pytest.mark.slow
def test_a_field_within_the_facets_brightness_scatter_is_not_used(model):
    """1.5 % lost at the corners under 2304 facets whose brightness scatters by 6 %: BIC
    asks for the field (it is real), but it moves no facet by more than the scatter, so it
    is not used; at 20 % it is."""
    rng = np.random.default_rng(7)
    scatter = np.exp(rng.normal(0.0, 0.06, 48 * 48))
    white = np.array([1.0, 1.0, 1.0])
    for loss, used in ((0.015, False), (0.2, True)):
        joint, lab, _ = _scene(lambda u, v: (1 - loss) ** (2.0 * (u * u + v * v)), seed=6,
                               side=4, rows=48)
        xyz = color.lab_to_xyz(lab, white=white) * scatter[joint.facets][..., None]
        lab = color.xyz_to_lab(xyz, white=white).astype(np.float32)
        ff = estimate_flat_field(joint, lab, model, unexplained_mads=MADS)
        assert ff.bic_gain > 0 and (ff.reason == "") == used, ff.reason
        assert ff.misfit_sd == pytest.approx(0.06, rel=0.2)
        if not used:
            assert "scatter" in ff.reason


@pytest.mark.slow
def test_dark_facets_that_are_not_the_light_do_not_pull_the_field(model):
    joint, lab, light = _scene(lambda u, v: 0.7 ** (2.0 * (u * u + v * v)), seed=2)
    rng = np.random.default_rng(3)
    stained = rng.random(ROWS * ROWS) < 0.1            # a tenth of the facets at half light
    xyz = color.lab_to_xyz(lab, white=np.array([1.0, 1.0, 1.0]))
    xyz = np.where(stained[joint.facets][..., None], 0.5 * xyz, xyz)
    lab = color.xyz_to_lab(xyz, white=np.array([1.0, 1.0, 1.0])).astype(np.float32)
    ff = estimate_flat_field(joint, lab, model, unexplained_mads=MADS)
    assert ff.reason == ""
    err = ff.log_map(light.shape) - np.log(light)          # 1 at the centre
    assert np.abs(err).max() < 0.05


def test_too_few_facets_give_no_field(model):
    joint, lab, _ = _scene(lambda u, v: np.ones_like(u))
    joint.usable = np.zeros(joint.facets.shape, bool)
    ff = estimate_flat_field(joint, lab, model, unexplained_mads=MADS)
    assert ff.coefficients is None and "fewer than" in ff.reason


def test_flat_fielded_colours_are_those_of_even_light():
    rng = np.random.default_rng(4)
    lin = np.broadcast_to(np.array([0.45, 0.30, 0.12], np.float32), (40, 60, 3)).copy()
    lin *= rng.uniform(0.9, 1.1, (40, 60, 1)).astype(np.float32)
    lin[36:, 56:] *= 0.2      # a dark film in the corner: darker than any film only when dimmed
    ff = FlatField(coefficients=(0.0, 0.0, -1.5, 0.0, -1.5))
    v = ff.map((40, 60))
    opts = MaskOptions()
    kw = dict(color_space="sRGB", bit_depth=16, illuminant="D65", delta_e_method="CIEDE2000")
    even = measure_colour(srgb_encode(lin, dtype=np.float32), opts, **kw)
    dim = measure_colour(srgb_encode(lin * v[..., None], dtype=np.float32), opts, **kw)
    fixed = flat_fielded(dim, v, illuminant="D65", mask_options=opts)
    assert np.abs(fixed.lab - even.lab).max() < 0.05
    assert dim.mask.steep.sum() > even.mask.steep.sum()        # the corners read as dark
    assert np.array_equal(fixed.mask.steep, even.mask.steep)
    assert np.array_equal(fixed.mask.mask, even.mask.mask)
    # with the camera's gains: the colours of the balanced, even image
    gains = (1.1, 1.0, 0.9)
    biased = measure_colour(srgb_encode(lin * v[..., None] * np.float32(gains),
                                        dtype=np.float32), opts, **kw)
    both = flat_fielded(biased, v, gains_rgb=gains, illuminant="D65",
                        mask_options=opts)
    assert np.abs(both.lab - even.lab).max() < 0.05


def test_clipped_pixels_analysed_are_masked_once_a_field_is_divided_out():
    """Divided by a field, a pixel clipped at the camera's top code reads above or below it
    by where it lies: the clip level varies, and the model cannot be clipped alike."""
    lin = np.broadcast_to(np.array([0.45, 0.30, 0.12], np.float32), (30, 40, 3)).copy()
    lin[5:15, 5:15, 0] = 1.0                                   # red clipped
    opts = MaskOptions(shadow_ratio=0)
    c = measure_colour(srgb_encode(lin, dtype=np.float32), opts, color_space="sRGB",
                       bit_depth=8, illuminant="D65", delta_e_method="CIEDE2000")
    assert c.mask.clipped_one.sum() == 100 and c.clip_rgb == (1.0, 1.0, 1.0)
    fixed = flat_fielded(c, FlatField(coefficients=(0.0, 0.0, -0.3, 0.0, -0.3)).map((30, 40)),
                         illuminant="D65", mask_options=opts)
    assert fixed.clip_rgb is None and fixed.mask.clipped_one is None
    assert fixed.mask.clipped[5:15, 5:15].all() and fixed.mask.mask[5:15, 5:15].all()
    assert not fixed.mask.mask[20:, 20:].any()


def test_too_little_light_is_masked_not_amplified():
    lin = np.broadcast_to(np.array([0.45, 0.30, 0.12], np.float32), (30, 30, 3)).copy()
    v = np.ones((30, 30), np.float32)
    v[:, :3] = 0.05                                       # a field stop's edge
    opts = MaskOptions()
    kw = dict(color_space="sRGB", bit_depth=16, illuminant="D65", delta_e_method="CIEDE2000")
    img = measure_colour(srgb_encode(lin * v[..., None], dtype=np.float32), opts, **kw)
    fixed = flat_fielded(img, v, illuminant="D65", mask_options=opts)
    assert fixed.mask.mask[:, :3].all() and not fixed.mask.mask[:, 3:].any()


@pytest.mark.slow
def test_the_analysis_divides_a_vignetted_stack_by_its_field(tmp_path):
    p = preset("nd", height_px=160, width_px=160, n_slices=12, seed=5,
               vignetting_corner_loss=0.4)
    generate_stack(tmp_path / "s", p)
    truth = np.load(tmp_path / "s" / "truth" / "thickness_nm.npy")
    runs = {}
    for mode in ("estimate", "off"):
        opts = AnalysisOptions(mode="joint").replace(joint={"flat_field": mode})
        runs[mode] = analyse_stack(tmp_path / "s", opts)
    ff = runs["estimate"].flat_field
    assert ff.applied and ff.median_delta_e[1] < ff.median_delta_e[0]
    assert ff.corner_loss((160, 160)) == pytest.approx(0.4, abs=0.1)
    assert runs["off"].flat_field.reason == "joint.flat_field is off"
    err = {m: np.nanmedian(np.abs(r.pixels.thickness_nm - truth)) for m, r in runs.items()}
    assert err["estimate"] < err["off"]
    params = json.loads((tmp_path / "s" / "truth" / "params.json").read_text())["params"]
    assert params["vignetting_corner_loss"] == 0.4


@pytest.fixture(scope="module")
def vignetted(tmp_path_factory):
    """One synthetic scene with even light and the same with 40 % lost at the corners, and
    the latter's flat reference: an even grey target through the generator's vignetting,
    8-bit, with noise and a dust speck."""
    from microfacet.forward.imaging import vignetting_factor
    from microfacet.io.images import write_image

    root = tmp_path_factory.mktemp("ff")
    for name, loss in (("even", 0.0), ("vignetted", 0.4)):
        generate_stack(root / name, preset("nd", height_px=128, width_px=128, n_slices=12,
                                           seed=5, vignetting_corner_loss=loss))
    rng = np.random.default_rng(0)
    lin = 0.6 * vignetting_factor((128, 128), corner_loss=0.4)
    lin = lin * rng.normal(1.0, 0.02, lin.shape)
    lin[40:44, 70:74] *= 0.3                                    # dust on the target
    write_image(root / "vignetted" / "flat.png",
                srgb_encode(np.repeat(lin[..., None], 3, axis=-1).astype(np.float32),
                            dtype=np.uint8))
    return root


def _analyse(path, **optics):
    opts = AnalysisOptions(mode="joint")
    if optics:
        opts = opts.replace(optics=optics)
    return analyse_stack(path, opts)


@pytest.mark.slow
def test_a_flat_reference_makes_the_vignetted_scene_read_as_the_even_one(vignetted):
    """The reference given as the option and as stack.json's flat_reference: the per-pixel
    thickness of the vignetted scene is the even scene's (median |Δ| < 0.3 nm) and its
    exposure the even scene's (2 %), where without any flat field it is not."""
    import shutil

    even = _analyse(vignetted / "even")
    raw = analyse_stack(vignetted / "vignetted",
                        AnalysisOptions(mode="joint").replace(joint={"flat_field": "off"}))
    ref = _analyse(vignetted / "vignetted", flat_reference=str(vignetted / "vignetted" /
                                                                "flat.png"))
    assert ref.flat_field.source == "flat reference flat.png" and ref.flat_field.applied
    assert ref.flat_field.corner_loss((128, 128)) == pytest.approx(0.4, abs=0.03)
    t0, t_raw, t_ref = (r.pixels.thickness_nm for r in (even, raw, ref))
    ok = np.isfinite(t0) & np.isfinite(t_raw) & np.isfinite(t_ref)
    err_ref = float(np.median(np.abs(t_ref[ok] - t0[ok])))
    err_raw = float(np.median(np.abs(t_raw[ok] - t0[ok])))
    assert err_ref < 0.3 < err_raw, (err_ref, err_raw)
    assert ref.exposure == pytest.approx(even.exposure, rel=0.02)
    assert abs(raw.exposure / even.exposure - 1.0) > 0.03
    copy = vignetted / "with-key"
    shutil.copytree(vignetted / "vignetted", copy)
    meta = json.loads((copy / "stack.json").read_text())
    (copy / "stack.json").write_text(json.dumps({**meta, "flat_reference": "flat.png"}))
    key = _analyse(copy)
    assert key.flat_field.source == "flat reference flat.png"
    np.testing.assert_array_equal(key.pixels.thickness_nm, t_ref)
    seed = analyse_stack(copy, AnalysisOptions(mode="seed"))   # the seed mode takes it too
    assert seed.flat_field.source == "flat reference flat.png"
    assert seed.exposure == pytest.approx(even.exposure, rel=0.05)


def test_a_flat_reference_of_another_size_or_clipped_is_refused(tmp_path):
    from microfacet.analysis.flat_field import reference_flat_field
    from microfacet.core.errors import InputError
    from microfacet.io.images import write_image
    from microfacet.io.stack import read_stack

    stack = read_stack(ND_FIXTURE)
    h, w = stack.shape
    write_image(tmp_path / "small.png", np.full((h // 2, w, 3), 128, np.uint8))
    write_image(tmp_path / "white.png", np.full((h, w, 3), 255, np.uint8))
    write_image(tmp_path / "grey.png", np.full((h, w, 3), 150, np.uint8))
    with pytest.raises(InputError, match=r"flat_reference \(small.png\).*stack's size"):
        reference_flat_field(stack, str(tmp_path / "small.png"), (h, w),
                             where_given="flat_reference")
    with pytest.raises(InputError, match="white.png.*clipped"):
        reference_flat_field(stack, str(tmp_path / "white.png"), (h, w),
                             where_given="flat_reference")
    with pytest.raises(InputError, match="missing.png not found"):
        reference_flat_field(stack, str(tmp_path / "missing.png"), (h, w),
                             where_given="flat_reference")
    even = reference_flat_field(stack, str(tmp_path / "grey.png"), (h, w),
                                where_given="flat_reference")
    assert np.allclose(even.map((h, w)), 1.0) and even.corner_loss((h, w)) == pytest.approx(0)
    # a grey (one-channel) reference with dust on it: the dust does not enter
    yy, xx = np.mgrid[0:h, 0:w]
    r2 = ((yy - (h - 1) / 2) ** 2 + (xx - (w - 1) / 2) ** 2) / ((h - 1) ** 2 / 4 + (w - 1) ** 2 / 4)
    lin = 0.5 * 0.7 ** r2
    lin[h // 2 - 3:h // 2 + 3, w // 2 - 3:w // 2 + 3] *= 0.3          # dust at the centre
    lin[20:26, 40:46] *= 0.3                                           # and elsewhere
    write_image(tmp_path / "dusty.png", srgb_encode(lin.astype(np.float32), dtype=np.uint8))
    dusty = reference_flat_field(stack, str(tmp_path / "dusty.png"), (h, w),
                                 where_given="flat_reference")
    assert np.abs(np.log(dusty.map((h, w)) / 0.7 ** r2)).max() < 0.03
    assert reference_flat_field(stack, None, (h, w), where_given="flat_reference") is None
