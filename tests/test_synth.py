"""Synthetic stacks: truth consistent with the images, determinism, every preset."""

import hashlib
import json

import cv2
import numpy as np
import pytest

from microfacet import colour as color
from microfacet.colour.table import _wavelengths, _white, direct_xyz
from microfacet.io.stack import read_stack
from microfacet.forward.synth import PRESETS, defocus_sigma_px, generate_stack, preset


def _digest(folder):
    h = hashlib.sha256()
    for p in sorted(folder.rglob("*")):
        if p.is_file():
            h.update(p.relative_to(folder).as_posix().encode())
            h.update(p.read_bytes())
    return h.hexdigest()


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


def test_same_seed_same_bytes_other_seed_other_bytes(tmp_path):
    p = preset("nd", seed=11, height_px=48, width_px=48, n_slices=4)
    generate_stack(tmp_path / "a", p)
    generate_stack(tmp_path / "b", p)
    generate_stack(tmp_path / "c", preset("nd", seed=12, height_px=48, width_px=48, n_slices=4))
    assert _digest(tmp_path / "a") == _digest(tmp_path / "b")
    assert _digest(tmp_path / "a") != _digest(tmp_path / "c")


def test_thickness_regions_follow_the_mixture_and_tilts_the_lobes():
    from microfacet.forward.synth import render_scene

    p = preset("nd", seed=2, height_px=512, width_px=512)
    s = render_scene(p)
    means = np.array([c.mean_nm for c in p.thickness])
    comp_of_region = s.region_component
    # Each region's thickness lies within 4 SD of its component mean.
    sd = np.array([c.sd_nm for c in p.thickness])[comp_of_region]
    assert np.all(np.abs(s.region_thickness_nm - means[comp_of_region]) < 4 * sd + 1e-9)
    # The steepest visible facets are below the NA limit; beyond it pixels are marked dark.
    assert s.tilt_deg[s.visible].max() <= p.max_tilt_deg
    assert not s.visible[s.tilt_deg > p.max_tilt_deg].any()


def test_rendered_colour_is_the_thin_film_colour_of_the_truth(tmp_path):
    p = preset("nd", seed=3, height_px=96, width_px=96, n_slices=3, full_well_e=None,
               read_noise=0.0)
    generate_stack(tmp_path / "s", p)
    t = tmp_path / "s" / "truth"
    sharp = cv2.imread(str(t / "all_in_focus.png"))[..., ::-1].astype(int)
    tilt, d = np.load(t / "tilt_deg.npy"), np.load(t / "thickness_nm.npy")
    vis = np.load(t / "visible.npy") & ~np.load(t / "clipped.npy") & (np.load(t / "groove.npy") == 0)
    rng = np.random.default_rng(0)
    idx = rng.choice(np.flatnonzero(vis), 500, replace=False)
    yy, xx = np.unravel_index(idx, vis.shape)
    # Independent route: 1 nm spectral integration, no table.
    xyz = direct_xyz(tilt[yy, xx], d[yy, xx], spectral_step_nm=1.0)
    white = _white(_wavelengths(1.0), "D65", "2")
    rgb = color.model_xyz_to_linear_srgb(xyz, white=white) * p.exposure
    expected = color.srgb_encode(rgb, dtype=np.uint8).astype(int)
    assert np.abs(sharp[yy, xx] - expected).max() <= 1
    # Dark facets are dark; groove pixels are darker than their facet's colour.
    groove = np.load(t / "groove.npy")
    assert 0.02 < np.mean(groove > 0) < 0.6
    dark = ~np.load(t / "visible.npy")
    if dark.any():
        assert sharp[dark].max() <= color.srgb_encode(np.float32(p.dark_level * p.exposure)) + 1


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


def test_cli_synth(tmp_path):
    from microfacet.cli import main

    assert main(["synth", str(tmp_path / "x"), "--preset", "thin", "--seed", "1", "--size",
                 "40x50", "--slices", "3", "-q"]) == 0
    assert read_stack(tmp_path / "x").n_slices == 3
    assert main(["synth", str(tmp_path / "x"), "--preset", "thin", "-q"]) == 2


def test_generator_rebuilds_the_bundled_fixture_exactly(tmp_path):
    from pathlib import Path

    fixture = Path(__file__).resolve().parent.parent / "fixtures" / "stacks" / "nd-fixture"
    meta = json.loads((fixture / "truth" / "params.json").read_text())["params"]
    p = preset(meta["preset"], seed=meta["seed"], height_px=meta["height_px"],
               width_px=meta["width_px"], n_slices=meta["n_slices"])
    generate_stack(tmp_path / "again", p)
    for k in range(p.n_slices):
        a = cv2.imread(str(fixture / "slices" / f"{k:03d}.png"), cv2.IMREAD_UNCHANGED)
        b = cv2.imread(str(tmp_path / "again" / "slices" / f"{k:03d}.png"), cv2.IMREAD_UNCHANGED)
        np.testing.assert_array_equal(a, b)
    for f in ("height_um", "tilt_deg", "azimuth_deg", "thickness_nm", "visible"):
        np.testing.assert_array_equal(np.load(fixture / "truth" / f"{f}.npy"),
                                      np.load(tmp_path / "again" / "truth" / f"{f}.npy"))
    assert json.loads((fixture / "stack.json").read_text()) == json.loads(
        (tmp_path / "again" / "stack.json").read_text())
