"""Synthetic stacks (microfacet.forward.synth): truth consistent with the images,
determinism, every preset, defocus, parameters; the bundled fixture against its recorded
parameters. The scene itself: test_scene.py; ``microfacet synth``: tests/cli/test_synth.py."""

import hashlib
import json
from pathlib import Path

import cv2
import numpy as np
import pytest

from microfacet import colour as color
from microfacet.colour.table import direct_xyz
from microfacet.forward.synth import (
    PRESETS,
    defocus_sigma_px,
    generate_stack,
    preset,
    slice_positions_um,
)
from microfacet.forward.synth_params import IMAGING_VARIATIONS, SynthParams
from microfacet.io.stack import read_stack

FIXTURE = Path(__file__).resolve().parents[2] / "fixtures" / "stacks" / "nd-fixture"


def _digest(folder):
    h = hashlib.sha256()
    for p in sorted(folder.rglob("*")):
        if p.is_file():
            h.update(p.relative_to(folder).as_posix().encode())
            h.update(p.read_bytes())
    return h.hexdigest()


@pytest.mark.slow
@pytest.mark.parametrize("name", sorted(PRESETS))
def test_every_preset_generates_a_readable_stack_with_truth(tmp_path, name):
    p = preset(name, seed=5, height_px=64, width_px=80, n_slices=6)
    generate_stack(tmp_path / name, p)
    st = read_stack(tmp_path / name)
    assert st.n_slices == 6 and tuple(st.shape[:2]) == (64, 80)
    assert st.numerical_aperture == pytest.approx(0.8)
    truth = tmp_path / name / "truth"
    for f, dt in [("height_um", np.float32), ("tilt_deg", np.float32),
                  ("azimuth_deg", np.float32), ("thickness_nm", np.float32), ("visible", bool)]:
        a = np.load(truth / f"{f}.npy")
        assert a.shape == (64, 80) and a.dtype == dt, f
    meta = json.loads((truth / "params.json").read_text())
    assert meta["params"]["seed"] == 5 and meta["params"]["preset"] == name
    img = cv2.imread(str(tmp_path / name / "slices" / "000.png"), cv2.IMREAD_UNCHANGED)
    assert img.dtype == (np.uint16 if p.bit_depth == 16 else np.uint8)


@pytest.mark.slow
def test_same_seed_same_bytes_other_seed_other_bytes(tmp_path):
    p = preset("nd", seed=11, height_px=48, width_px=48, n_slices=4)
    generate_stack(tmp_path / "a", p)
    generate_stack(tmp_path / "b", p)
    generate_stack(tmp_path / "c", preset("nd", seed=12, height_px=48, width_px=48, n_slices=4))
    assert _digest(tmp_path / "a") == _digest(tmp_path / "b")
    assert _digest(tmp_path / "a") != _digest(tmp_path / "c")


@pytest.mark.slow
def test_rendered_colour_is_the_thin_film_colour_of_the_truth(tmp_path):
    p = preset("nd", seed=3, height_px=96, width_px=96, n_slices=3, full_well_e=None,
               read_noise=0.0)
    generate_stack(tmp_path / "s", p)
    t = tmp_path / "s" / "truth"
    sharp = cv2.imread(str(t / "all_in_focus.png"))[..., ::-1].astype(int)
    tilt, d = np.load(t / "tilt_deg.npy"), np.load(t / "thickness_nm.npy")
    vis = (np.load(t / "visible.npy") & ~np.load(t / "clipped.npy")
           & (np.load(t / "groove.npy") == 0))
    rng = np.random.default_rng(0)
    idx = rng.choice(np.flatnonzero(vis), 500, replace=False)
    yy, xx = np.unravel_index(idx, vis.shape)
    # Independent route: 1 nm spectral integration, no table.
    xyz = direct_xyz(tilt[yy, xx], d[yy, xx], spectral_step_nm=1.0)
    white = color.spectral_weights(np.arange(380.0, 781.0, 1.0)).sum(axis=0)
    rgb = color.model_xyz_to_linear_srgb(xyz, white=white) * p.exposure
    expected = color.srgb_encode(rgb, dtype=np.uint8).astype(int)
    assert np.abs(sharp[yy, xx] - expected).max() <= 1
    # Dark facets are dark; groove pixels are darker than their facet's colour.
    groove = np.load(t / "groove.npy")
    assert 0.02 < np.mean(groove > 0) < 0.6
    dark = ~np.load(t / "visible.npy")
    if dark.any():
        assert sharp[dark].max() <= color.srgb_encode(np.float32(p.dark_level * p.exposure)) + 1


@pytest.mark.slow
def test_sharpest_slice_is_at_the_true_height(tmp_path):
    p = preset("nd", seed=4, height_px=160, width_px=160, n_slices=24, full_well_e=None,
               read_noise=0.0)
    r = generate_stack(tmp_path / "s", p)
    h = np.load(tmp_path / "s" / "truth" / "height_um.npy")
    # Independent focus measure: local variance of grey level in a 9x9 window.
    fm = []
    for k in range(p.n_slices):
        g = cv2.imread(str(tmp_path / "s" / "slices" / f"{k:03d}.png"),
                       cv2.IMREAD_GRAYSCALE).astype(np.float32)
        m = cv2.blur(g, (9, 9))
        fm.append(cv2.blur(g * g, (9, 9)) - m * m)
    fm = np.array(fm)
    best = fm.argmax(axis=0)
    true_k = np.abs(r.z_um[:, None, None] - h[None]).argmin(axis=0)
    # Where the image has texture (local SD > 4.5 grey levels), the sharpest slice is the
    # one nearest the true height (a height-independent blur would give ~5/24 within 2).
    # The misses are windows that a defocused dark facet nearby bleeds into.
    textured = fm.max(axis=0) > 20
    assert textured.mean() > 0.15
    err = np.abs(best - true_k)[textured]
    assert np.median(err) <= 1 and np.mean(err <= 2) > 0.7


def test_defocus_grows_with_distance_and_has_a_diffraction_floor():
    p = preset("sd")
    s = defocus_sigma_px(np.array([0.0, 0.5, 1.0, 2.0]), p)
    assert np.all(np.diff(s) > 0) and s[0] > 0
    # Large defocus: geometric disc radius |dz| tan(asin NA), sigma about half of it.
    tan_a = np.tan(np.arcsin(p.numerical_aperture))
    assert defocus_sigma_px(10.0, p) == pytest.approx(0.5 * 10 * tan_a / p.pixel_size_um, rel=0.01)


@pytest.mark.parametrize("kw, name", [(dict(n_slices=0), "n_slices"),
                                      (dict(numerical_aperture=1.2), "numerical_aperture"),
                                      (dict(bit_depth=12), "bit_depth")])
def test_bad_parameters(kw, name):
    with pytest.raises(ValueError, match=name):
        preset("nd", **kw)


def test_unknown_preset():
    with pytest.raises(ValueError, match="nd"):
        preset("zz")


# ------------------------------------------------- the bundled fixture (fixtures/stacks/nd-fixture)
#
# These replace a comparison of the fixture's bytes with a regenerated stack: the pixels
# depend on the OpenCV and numpy versions (blur, random streams), so only what does not is
# checked: the recorded parameters, the layout, and the truth against the images.


def _layout(folder):
    """{relative path: (shape, dtype)} of every array and image of a stack folder."""
    out = {}
    for p in sorted(folder.rglob("*")):
        rel = p.relative_to(folder).as_posix()
        if p.suffix == ".npy":
            a = np.load(p)
            out[rel] = (a.shape, a.dtype.str)
        elif p.suffix == ".png":
            a = cv2.imread(str(p), cv2.IMREAD_UNCHANGED)
            out[rel] = (a.shape, a.dtype.str)
        elif p.is_file():
            out[rel] = None
    return out


@pytest.mark.slow
def test_bundled_fixture_is_what_its_recorded_parameters_generate(tmp_path):
    """truth/params.json records a preset, a seed and a size; those alone give back every
    recorded parameter, and generating from them writes the same files, shapes and dtypes
    and the same stack.json (the slice heights follow from each stack's own truth)."""
    meta = json.loads((FIXTURE / "truth" / "params.json").read_text())
    rec = meta["params"]
    p = preset(rec["preset"], seed=rec["seed"], height_px=rec["height_px"],
               width_px=rec["width_px"], n_slices=rec["n_slices"])
    now = json.loads(json.dumps(p.to_json()))
    assert {k: now[k] for k in rec} == rec                # nothing else was changed
    assert set(now) - set(rec) <= set(IMAGING_VARIATIONS)  # added later: the variations, off
    assert p.variations_on() == {}
    generate_stack(tmp_path / "again", p)
    again, bundled = _layout(tmp_path / "again"), _layout(FIXTURE)
    assert {k: again[k] for k in bundled} == bundled
    assert set(again) - set(bundled) == {"truth/facet_id.npy", "truth/feature.npy"}
    bundled = json.loads((FIXTURE / "stack.json").read_text())
    again = json.loads((tmp_path / "again" / "stack.json").read_text())
    z_bundled, z_again = bundled.pop("z_um"), again.pop("z_um")
    assert bundled == again
    for folder, z in ((FIXTURE, z_bundled), (tmp_path / "again", z_again)):
        h = np.load(folder / "truth" / "height_um.npy")
        np.testing.assert_allclose(z, slice_positions_um(p, h), rtol=0, atol=1e-9)
        assert json.loads((folder / "truth" / "params.json").read_text())["z_um"] == z


@pytest.mark.slow
def test_bundled_fixture_truth_agrees_with_its_images():
    """The fixture's truth describes its pixels: the sharp image is the thin-film colour of
    the true tilt and thickness (1 nm spectral integration, within one code value), dark
    where the facet is steeper than the objective accepts, and the recorded regions and
    fractions are those of the truth maps."""
    t = FIXTURE / "truth"
    meta = json.loads((t / "params.json").read_text())
    rec = meta["params"]
    p = preset(rec["preset"], seed=rec["seed"], height_px=rec["height_px"],
               width_px=rec["width_px"], n_slices=rec["n_slices"])
    sharp = cv2.imread(str(t / "all_in_focus.png"))[..., ::-1].astype(int)
    tilt, d = np.load(t / "tilt_deg.npy"), np.load(t / "thickness_nm.npy")
    visible, clipped = np.load(t / "visible.npy"), np.load(t / "clipped.npy")
    groove, region = np.load(t / "groove.npy"), np.load(t / "region_id.npy")
    ok = visible & ~clipped & (groove == 0)
    assert ok.mean() > 0.5
    yy, xx = np.nonzero(ok)
    xyz = direct_xyz(tilt[yy, xx], d[yy, xx], spectral_step_nm=1.0)
    white = color.spectral_weights(np.arange(380.0, 781.0, 1.0)).sum(axis=0)
    rgb = color.model_xyz_to_linear_srgb(xyz, white=white) * p.exposure
    expected = color.srgb_encode(rgb, dtype=np.uint8).astype(int)
    assert np.abs(sharp[yy, xx] - expected).max() <= 1
    # visible exactly where the facet is within the acceptance angle; dark elsewhere
    np.testing.assert_array_equal(visible, tilt <= p.max_tilt_deg)
    dark_code = int(color.srgb_encode(np.float32(p.dark_level * p.exposure)))
    assert (~visible).any() and sharp[~visible].max() <= dark_code + 1
    # clipped pixels are at full scale in some channel
    assert (sharp[clipped].max(axis=-1) == 255).all()
    assert meta["visible_fraction"] == pytest.approx(visible.mean(), abs=1e-12)
    assert meta["clipped_fraction"] == pytest.approx(clipped.mean(), abs=1e-12)
    # each region's thickness is the recorded one plus the fine variation (SD 0.3 nm)
    regions = np.array([r["thickness_nm"] for r in meta["regions"]])
    assert region.max() + 1 == regions.size
    for r in np.unique(region):
        assert abs(np.median(d[region == r]) - regions[r]) < 1.0, r


@pytest.mark.slow
def test_default_variations_regenerate_the_bundled_fixture_truth(tmp_path):
    """With every variation off, the generator reproduces the fixture's truth (arrays to
    float rounding, regions and components exactly, the sharp image within one code)."""
    rec = json.loads((FIXTURE / "truth" / "params.json").read_text())["params"]
    p = preset(rec["preset"], seed=rec["seed"], height_px=rec["height_px"],
               width_px=rec["width_px"], n_slices=2)
    generate_stack(tmp_path / "s", p)
    t, f = tmp_path / "s" / "truth", FIXTURE / "truth"
    for name in ("region_id", "visible", "clipped"):
        np.testing.assert_array_equal(np.load(t / f"{name}.npy"), np.load(f / f"{name}.npy"))
    for name in ("height_um", "tilt_deg", "azimuth_deg", "thickness_nm", "groove"):
        np.testing.assert_allclose(np.load(t / f"{name}.npy"), np.load(f / f"{name}.npy"),
                                   rtol=0, atol=1e-4, err_msg=name)
    a = cv2.imread(str(t / "all_in_focus.png")).astype(int)
    b = cv2.imread(str(f / "all_in_focus.png")).astype(int)
    assert np.abs(a - b).max() <= 1


@pytest.mark.slow
def test_variations_at_their_off_values_give_the_same_bytes(tmp_path):
    """Every variation set explicitly to its default (off) value: the same stack, byte for
    byte; and a zero-strength variation is the same as off."""
    kw = dict(seed=7, height_px=48, width_px=56, n_slices=3)
    defaults = {f.name: f.default for f in SynthParams.__dataclass_fields__.values()
                if f.name in IMAGING_VARIATIONS}
    generate_stack(tmp_path / "a", preset("nd", **kw))
    generate_stack(tmp_path / "b", preset("nd", **kw, **defaults))
    generate_stack(tmp_path / "c", preset("nd", **kw, pit_radius_um=3.0, scratch_wall_deg=70.0,
                                          dust_radius_um=2.0, terrace_size_um=9.0,
                                          rolling_direction_deg=33.0))
    assert _digest(tmp_path / "a") == _digest(tmp_path / "b")
    # strengths of features that are off change nothing but the recorded parameters
    for name in ("slices/000.png", "slices/002.png", "truth/height_um.npy",
                 "truth/all_in_focus.png"):
        assert (tmp_path / "a" / name).read_bytes() == (tmp_path / "c" / name).read_bytes()


@pytest.mark.slow
def test_truth_records_populations_regions_lobes_and_limit(tmp_path):
    p = preset("nd", seed=5, height_px=128, width_px=128, n_slices=3)
    generate_stack(tmp_path / "s", p)
    t = tmp_path / "s" / "truth"
    meta = json.loads((t / "params.json").read_text())
    region, d = np.load(t / "region_id.npy"), np.load(t / "thickness_nm.npy")
    facet = np.load(t / "facet_id.npy")
    assert facet.dtype == np.int32 and facet.shape == (128, 128) and facet.min() == 0
    assert np.load(t / "feature.npy").dtype == np.uint8
    regs = meta["regions"]
    assert [r["id"] for r in regs] == list(range(region.max() + 1))
    for r in regs:
        assert r["mean_thickness_nm"] == pytest.approx(d[region == r["id"]].mean(), abs=1e-3)
        assert r["area_fraction"] == pytest.approx(np.mean(region == r["id"]))
    pops = meta["populations"]
    assert sum(q["area_fraction"] for q in pops) == pytest.approx(1.0)
    present = {r["component"] for r in regs}
    assert {q["component"] for q in pops} == present
    for q in pops:
        assert q["n_regions"] == sum(r["component"] == q["component"] for r in regs)
        assert q["mean_nm"] == p.thickness[q["component"]].mean_nm
    assert meta["lobes"] == [{"weight": lb.weight, "sd_deg": lb.sd_deg} for lb in p.tilt_lobes]
    assert meta["visibility_limit_deg"] == pytest.approx(p.max_tilt_deg)
    assert meta["drift_px"] == [[0.0, 0.0]] * 3 and meta["slice_format"] == "png"
    assert meta["variations"] == {}


@pytest.mark.slow
def test_truth_image_has_no_noise(tmp_path):
    kw = dict(seed=2, height_px=64, width_px=64, n_slices=3, vignetting_corner_loss=0.3,
              white_balance_gains=(1.1, 1.0, 0.9), dust_density_per_mm2=3000.0)
    generate_stack(tmp_path / "noisy", preset("noisy", **kw))
    generate_stack(tmp_path / "clean", preset("noisy", **kw, full_well_e=None, read_noise=0.0))
    a, b = tmp_path / "noisy", tmp_path / "clean"
    aif = "truth/all_in_focus.png"
    assert (a / aif).read_bytes() == (b / aif).read_bytes()
    assert (a / "slices/001.png").read_bytes() != (b / "slices/001.png").read_bytes()


@pytest.mark.slow
def test_jpeg_slices_decode_close_to_the_png_ones(tmp_path):
    kw = dict(seed=3, height_px=96, width_px=96, n_slices=3, full_well_e=None, read_noise=0.0)
    generate_stack(tmp_path / "png", preset("nd", **kw))
    generate_stack(tmp_path / "jpg", preset("nd", **kw, jpeg_quality=90))
    st = read_stack(tmp_path / "jpg")
    assert st.n_slices == 3
    meta = json.loads((tmp_path / "jpg" / "stack.json").read_text())
    assert all(s.endswith(".jpg") for s in meta["slices"])
    assert (tmp_path / "jpg/truth/all_in_focus.png").read_bytes() == \
        (tmp_path / "png/truth/all_in_focus.png").read_bytes()
    for k in range(3):
        a = cv2.imread(str(tmp_path / f"png/slices/{k:03d}.png")).astype(float)
        b = cv2.imread(str(tmp_path / f"jpg/slices/{k:03d}.jpg")).astype(float)
        err = np.abs(a - b)
        assert 0 < err.mean() < 2.0 and np.percentile(err, 99) < 12
    with pytest.raises(ValueError, match="jpeg_quality"):
        preset("nd", jpeg_quality=90, bit_depth=16)


@pytest.mark.slow
def test_drift_shifts_each_slice_by_the_recorded_offset(tmp_path):
    """Registration (OpenCV's ECC, independent of the bicubic shift used) of slice k with
    drift onto slice k without finds the offset recorded in truth/params.json."""
    kw = dict(seed=4, height_px=128, width_px=128, n_slices=6, full_well_e=None,
              read_noise=0.0, z_margin_um=0.3)
    generate_stack(tmp_path / "still", preset("nd", **kw))
    generate_stack(tmp_path / "drift", preset("nd", **kw, drift_px_per_slice=0.6))
    off = np.array(json.loads((tmp_path / "drift/truth/params.json").read_text())["drift_px"])
    assert off.shape == (6, 2) and np.allclose(off.mean(axis=0), 0, atol=1e-5)
    assert np.abs(np.diff(off, axis=0)).max() > 0.1
    for k in range(6):
        a = cv2.imread(str(tmp_path / f"still/slices/{k:03d}.png"), 0).astype(np.float32)
        b = cv2.imread(str(tmp_path / f"drift/slices/{k:03d}.png"), 0).astype(np.float32)
        crit = (cv2.TERM_CRITERIA_EPS | cv2.TERM_CRITERIA_COUNT, 200, 1e-6)
        _, w = cv2.findTransformECC(a, b, np.eye(2, 3, dtype=np.float32),
                                    cv2.MOTION_TRANSLATION, crit, None, 1)
        assert np.hypot(w[1, 2] - off[k, 0], w[0, 2] - off[k, 1]) < 0.15, k
    still = np.load(tmp_path / "still/truth/height_um.npy")
    np.testing.assert_array_equal(still, np.load(tmp_path / "drift/truth/height_um.npy"))


@pytest.mark.slow
def test_other_optical_constants_are_named_in_stack_json(tmp_path):
    kw = dict(seed=1, height_px=48, width_px=48, n_slices=2)
    generate_stack(tmp_path / "a", preset("sd", **kw))
    generate_stack(tmp_path / "b", preset("sd", **kw, film="TiO2_Devore1951_rutile_o",
                                          substrate="Ti_Palm2018"))
    st = json.loads((tmp_path / "b" / "stack.json").read_text())
    assert st["film"] == "TiO2_Devore1951_rutile_o" and st["substrate"] == "Ti_Palm2018"
    a = cv2.imread(str(tmp_path / "a/truth/all_in_focus.png")).astype(int)
    b = cv2.imread(str(tmp_path / "b/truth/all_in_focus.png")).astype(int)
    assert np.abs(a - b).mean() > 3
    with pytest.raises(ValueError, match="film"):
        preset("sd", film="TiO2_nonexistent")


@pytest.mark.slow
def test_measured_stained_stack_records_its_relief_by_name(tmp_path):
    from microfacet.io.x3p import write_x3p

    yy, xx = np.mgrid[0:80, 0:90].astype(float)
    write_x3p(tmp_path / "surface.x3p", np.sin(0.2 * yy) + np.cos(0.15 * xx), 0.4)
    p = preset("nd", seed=2, height_px=48, width_px=48, n_slices=3,
               relief_file=str(tmp_path / "surface.x3p"), stain_density_per_mm2=40000.0)
    generate_stack(tmp_path / "s", p)
    t = tmp_path / "s" / "truth"
    meta = json.loads((t / "params.json").read_text())
    assert meta["params"]["relief_file"] == "surface.x3p"
    assert meta["variations"]["relief_file"] == "surface.x3p"
    assert str(tmp_path) not in (t / "params.json").read_text()
    r = meta["relief"]
    assert r["file"] == "surface.x3p" and r["sha256"] == hashlib.sha256(
        (tmp_path / "surface.x3p").read_bytes()).hexdigest()[:16]
    assert {"rot90", "flip_lr", "window_origin_px", "magnification"} <= set(r)
    assert meta["lobes"] == [] and meta["groove_fraction"] == 0.0
    assert meta["feature_codes"]["stain"] == 4
    feature = np.load(t / "feature.npy")
    assert np.mean(feature == 4) > 0
    assert meta["feature_fractions"]["stain"] == pytest.approx(np.mean(feature == 4))
