"""Tests of height from focus (microfacet.focus.height).

Accuracy against ground truth on the Cou & Guennebaud (2023) synthetic stacks copied to
fixtures/focus-stacks/cou2023-synthetic-rough (see its README for units and registration),
and against analytic surfaces rendered with a space-variant defocus blur (the
``render_stack`` fixture, tests/conftest.py). Focus measures: test_measures.py; filling
holes: test_fill.py; slice alignment: test_align.py.
"""

from __future__ import annotations

import tracemalloc
from pathlib import Path

import numpy as np
import pytest

from microfacet.core.errors import InputError
from microfacet.focus.height import height_from_focus, peak_fit
from microfacet.focus.options import FocusOptions
from microfacet.io.stack import read_stack, write_stack

COU = Path(__file__).resolve().parents[2] / "fixtures" / "focus-stacks" / "cou2023-synthetic-rough"
#: Every pixel keeps its height (no reliability cut).
ALL = FocusOptions(min_reliability_db=-np.inf)


def cou_rmse(height, stack_no):
    """RMSE in slices against the GT: reference[i, j] <-> pixel (i+20, j+20), depth = -ref."""
    ref = -np.load(COU / f"stack{stack_no}" / "reference.npy")
    d = height[20:20 + ref.shape[0], 20:20 + ref.shape[1]]
    return float(np.sqrt(np.mean((d - ref) ** 2)))


@pytest.fixture(scope="module")
def cou_stacks():
    return {s: read_stack(COU / f"stack{s}") for s in (1, 2, 3)}


@pytest.mark.slow
@pytest.mark.parametrize("stack_no", [1, 2, 3])
def test_default_method_accuracy_on_ground_truth(cou_stacks, stack_no):
    res = height_from_focus(cou_stacks[stack_no], ALL)
    rmse = cou_rmse(res.height_um, stack_no)
    # issue bar 0.25 slices; the default measured 0.102 / 0.104 / 0.121
    assert rmse <= 0.25
    assert rmse <= 0.14
    # masked by the default reliability cut: few pixels lost, kept ones no worse
    res2 = height_from_focus(cou_stacks[stack_no])
    assert res2.unreliable_fraction < 0.05
    ok = np.isfinite(res2.height_um)
    ref = -np.load(COU / f"stack{stack_no}" / "reference.npy")
    kept = ok[20:379, 20:379]
    e = res2.height_um[20:379, 20:379][kept] - ref[kept]
    assert np.sqrt(np.mean(e ** 2)) <= rmse + 1e-6


@pytest.mark.slow
def test_naive_baseline_is_worse_and_matches_readme(cou_stacks):
    """SML 5x5 box + 3-point Gaussian reproduces the README's naive numbers (0.218 on
    stack 1), which checks the registration; the default beats it by a wide margin."""
    naive = height_from_focus(cou_stacks[1], ALL.replace(
        operator="sml", window="box", window_px=5, interpolation="gauss3"))
    r_naive = cou_rmse(naive.height_um, 1)
    assert abs(r_naive - 0.218) < 0.01
    argmax = height_from_focus(cou_stacks[1], ALL.replace(interpolation="none"))
    assert cou_rmse(argmax.height_um, 1) > 0.3
    best = height_from_focus(cou_stacks[1], ALL)
    assert cou_rmse(best.height_um, 1) < 0.6 * r_naive


# ------------------------------------------------------------------ synthetic surfaces


def test_tilted_plane_uniform_and_unsorted_z(render_stack):
    H, W = 80, 96
    yy, xx = np.mgrid[0:H, 0:W]
    h = (2.0 + 0.06 * xx + 0.03 * yy).astype(np.float32)   # 2 .. 9.1 µm
    z = np.arange(0.0, 11.5, 0.5)
    imgs = render_stack(h, z)
    res = height_from_focus(imgs, ALL, z_um=z)
    inner = (slice(6, -6), slice(6, -6))
    err = res.height_um[inner] - h[inner]
    assert np.sqrt(np.mean(err ** 2)) < 0.08          # 0.16 slices of 0.5 µm
    # shuffling the files (with their z) gives the identical map
    perm = np.random.default_rng(3).permutation(len(z))
    res_p = height_from_focus([imgs[i] for i in perm], ALL, z_um=z[perm])
    np.testing.assert_allclose(res_p.height_um, res.height_um, rtol=0, atol=1e-5)
    np.testing.assert_array_equal(perm[res_p.best_index], res.best_index)


def test_non_uniform_z(render_stack):
    H, W = 64, 64
    yy, xx = np.mgrid[0:H, 0:W]
    h = (3.0 + 4.0 * xx / W).astype(np.float32)
    z = np.cumsum(np.r_[0.0, np.tile([0.35, 0.7], 12)])    # alternating spacing, 0..12.6
    imgs = render_stack(h, z, seed=1)
    res = height_from_focus(imgs, ALL, z_um=z)
    err = res.height_um[6:-6, 6:-6] - h[6:-6, 6:-6]
    assert np.sqrt(np.mean(err ** 2)) < 0.1
    assert abs(np.mean(err)) < 0.03


def test_rgb_stack_and_all_in_focus(render_stack):
    H, W = 48, 64
    yy, xx = np.mgrid[0:H, 0:W]
    h = (1.0 + 6.0 * xx / W).astype(np.float32)
    z = np.arange(0.0, 9.0, 1.0)
    imgs = render_stack(h, z, rgb=True, seed=2)
    sharp = render_stack(np.zeros_like(h), [-0.0], rgb=True, seed=2, blur_per_um=0.0)[0]
    res = height_from_focus(imgs, ALL, z_um=z)
    assert res.all_in_focus.shape == (H, W, 3)
    # every pixel's composite comes from its sharpest slice, which is near its true height
    assert np.all(np.abs(z[res.best_index][4:-4, 4:-4] - h[4:-4, 4:-4]) <= 1.0)
    # composite is much closer to the sharp texture than any single slice
    e_aif = np.abs(res.all_in_focus - sharp)[4:-4, 4:-4].mean()
    e_best_single = min(np.abs(im - sharp)[4:-4, 4:-4].mean() for im in imgs)
    assert e_aif < 0.5 * e_best_single


def test_reliability_rejects_textureless_region(render_stack):
    H, W = 96, 96
    flat = np.zeros((H, W), bool)
    flat[:, W // 2:] = True
    h = np.full((H, W), 5.0, np.float32)
    z = np.arange(0.0, 11.0, 1.0)
    imgs = render_stack(h, z, noise=0.01, flat_mask=flat, seed=4)
    for op in ("tenengrad", "sml", "glv"):
        res = height_from_focus(imgs, FocusOptions(operator=op), z_um=z)
        thr = FocusOptions(operator=op).reliability_cut_db
        # the coarse 15-px window reaches ~2.5 σ = 11 px into the flat half (there it
        # legitimately carries the height of the textured neighbours)
        rel_tex = res.reliability_db[8:-8, 8:W // 2 - 8]
        rel_flat = res.reliability_db[8:-8, W // 2 + 12:-8]
        assert np.mean(rel_tex >= thr) > 0.98, op
        assert np.mean(rel_flat < thr) > 0.98, op
        assert np.isnan(res.height_um[8:-8, W // 2 + 12:-8]).mean() > 0.98
        filled = height_from_focus(imgs, FocusOptions(operator=op, fill="smooth"), z_um=z)
        assert np.isfinite(filled.height_um).all()
        ok = res.reliable
        np.testing.assert_array_equal(filled.height_um[ok], res.height_um[ok])


def test_stack_input_equals_array_input(tmp_path, render_stack):
    h = np.add.outer(np.linspace(1, 4, 32), np.zeros(40)).astype(np.float32)
    z = np.array([0.0, 1.0, 2.0, 3.0, 4.0, 5.0])
    imgs = render_stack(h, z, seed=5)
    u8 = [np.round(im * 255).astype(np.uint8) for im in imgs]
    write_stack(tmp_path / "s", u8, z_um=z, pixel_size_um=1.0)
    a = height_from_focus(read_stack(tmp_path / "s"))
    b = height_from_focus(u8, z_um=z)
    # equal up to float32 rounding (SIMD paths may differ by an ulp)
    np.testing.assert_allclose(a.height_fit_um, b.height_fit_um, rtol=0, atol=1e-5)
    np.testing.assert_array_equal(a.best_index, b.best_index)
    c = height_from_focus(read_stack(tmp_path / "s"), prefetch=False)
    np.testing.assert_allclose(a.height_fit_um, c.height_fit_um, rtol=0, atol=1e-5)


# ------------------------------------------------------------------ components


@pytest.mark.parametrize("weighted", [True, False])
def test_peak_fit_exact_on_gaussian(weighted):
    rng = np.random.default_rng(0)
    mu = rng.uniform(-0.5, 0.5, 200)
    sig = rng.uniform(0.8, 3.0, 200)
    x = np.sort(rng.uniform(-3, 3, (5, 200)), axis=0)        # non-uniform positions
    v = 7.0 * np.exp(-0.5 * ((x - mu) / sig) ** 2)
    off, coef, ok = peak_fit(v, x, weighted=weighted)
    assert ok.all()
    np.testing.assert_allclose(off, np.clip(mu, x.min(0), x.max(0)), atol=1e-8)
    np.testing.assert_allclose(coef[0], -0.5 / sig ** 2, rtol=1e-8)


def test_peak_fit_missing_and_degenerate():
    x = np.array([[np.nan], [-1.0], [0.0], [1.0], [2.0]])
    v = np.exp(-0.5 * (x - 0.3) ** 2)
    off, _, ok = peak_fit(v, x)
    assert ok[0] and abs(off[0] - 0.3) < 1e-9
    off, _, ok = peak_fit(np.ones((3, 1)), np.array([[-1.0], [0.0], [1.0]]))
    assert not ok[0] and off[0] == 0.0               # flat curve: no maximum, no shift


def test_bad_options():
    """Options are validated when constructed (naming the field); the images and their
    heights by height_from_focus."""
    imgs = [np.zeros((8, 8), np.float32)] * 4
    z = [0, 1, 2, 3]
    with pytest.raises(InputError, match="^operator: "):
        FocusOptions(operator="laplace")
    with pytest.raises(InputError, match="^window_px: "):
        FocusOptions(window_px=4)
    with pytest.raises(InputError, match="^interpolation: "):
        FocusOptions(interpolation="cubic")
    with pytest.raises(TypeError, match="FocusOptions"):
        height_from_focus(imgs, {"operator": "sml"}, z_um=z)
    with pytest.raises(ValueError, match="z_um"):
        height_from_focus(imgs, z_um=[0, 1, 2])
    with pytest.raises(ValueError, match="duplicate"):
        height_from_focus(imgs, z_um=[0, 1, 1, 2])
    with pytest.raises(InputError, match="at least 3"):
        height_from_focus(imgs[:2], z_um=[0, 1])


def test_default_options_and_params(render_stack):
    """No options means FocusOptions(); ``params`` records the options in use."""
    h = np.add.outer(np.linspace(1, 4, 32), np.zeros(40)).astype(np.float32)
    z = np.arange(6.0)
    imgs = render_stack(h, z, seed=6)
    a = height_from_focus(imgs, z_um=z)
    b = height_from_focus(imgs, FocusOptions(), z_um=z)
    np.testing.assert_array_equal(a.height_fit_um, b.height_fit_um)
    assert a.params == b.params
    assert a.params["windows_px"] == [7, 15] and a.params["min_reliability_db"] == 4.0
    c = height_from_focus(imgs, FocusOptions(interpolation="gauss3", coarse_window_px=0,
                                             fine_window_px=3, fill="nearest"), z_um=z)
    assert c.params["windows_px"] == [3, 7] and c.params["fit_radius"] is None
    assert c.params["fill"] == "nearest" and np.isfinite(c.height_um).all()


def test_memory_does_not_grow_with_slices(tmp_path):
    """Peak traced memory of the whole height step: 40 slices ~ 10 slices."""
    rng = np.random.default_rng(0)
    img = rng.integers(0, 256, (128, 160)).astype(np.uint8)
    peaks = {}
    for n in (10, 40):
        write_stack(tmp_path / f"s{n}", (img for _ in range(n)), z_step_um=1.0, pixel_size_um=1.0)
        st = read_stack(tmp_path / f"s{n}")
        tracemalloc.start()
        height_from_focus(st)
        peaks[n] = tracemalloc.get_traced_memory()[1]
        tracemalloc.stop()
    assert peaks[40] < 1.1 * peaks[10]


def test_evidence_heights_come_from_the_pixel_itself(render_stack):
    """Two tilted textured strips with a textureless gap at a different height between them:
    the combined height lends the gap's edge the strips' heights (windows of 7-15 px); the
    evidence window (3 px) gives the gap no height and the strips their own, so a plane
    through the evidence heights of a strip has the strip's slope. Switched off, there are
    no evidence maps and the combined height is unchanged."""
    H, W = 64, 96
    flat = np.zeros((H, W), bool)
    flat[:, 32:64] = True
    yy, xx = np.mgrid[0:H, 0:W].astype(np.float32)
    h = np.where(flat, 8.0, 2.0 + 0.05 * xx).astype(np.float32)
    z = np.arange(0.0, 12.0, 1.0)
    imgs = render_stack(h, z, noise=0.01, flat_mask=flat, seed=7)
    res = height_from_focus(imgs, z_um=z)
    ev, sig = res.evidence_height_um, res.evidence_sigma_um
    assert ev is not None and ev.dtype == np.float32 and res.params["evidence_window_px"] == 3
    assert np.isnan(ev[:, 36:60]).mean() > 0.95                    # no evidence, no height
    assert np.isfinite(res.height_fit_um[:, 33:36]).all()            # borrowed there
    assert np.all(np.isfinite(sig) == np.isfinite(ev))
    strip = (slice(4, -4), slice(4, 28))
    ok = np.isfinite(ev[strip])
    assert ok.mean() > 0.9
    slope = np.polyfit(xx[strip][ok], ev[strip][ok], 1)[0]
    assert slope == pytest.approx(0.05, rel=0.1)
    err = (ev[strip] - h[strip])[ok]
    assert np.mean(np.abs(err) <= 2 * sig[strip][ok]) > 0.85       # σ covers the errors
    off = height_from_focus(imgs, FocusOptions(evidence_window_px=0), z_um=z)
    assert off.evidence_height_um is None
    np.testing.assert_array_equal(off.height_fit_um, res.height_fit_um)
