"""The NDF's self-check (microfacet.analysis.self_check): the renderer's defocus follows
|z − h|; injected slopes come back where the stack has texture in every facet and do not
where facets have no texture of their own; the judgement refuses an NDF outside the range."""

from __future__ import annotations

import math

import numpy as np
import pytest

from microfacet.analysis.identification import Judgement, self_check_judgement
from microfacet.analysis.options import FitOptions, JointOptions
from microfacet.analysis.self_check import (
    Conditions,
    RenderedStack,
    SelfCheck,
    self_check_ndf,
)
from microfacet.focus.options import FocusOptions


def _sharpness(img):
    gy, gx = np.gradient(img.astype(np.float64))
    return float(np.mean(gx * gx + gy * gy))


def test_defocus_grows_with_the_distance_from_the_surface():
    rng = np.random.default_rng(0)
    tex = rng.random((64, 64)).astype(np.float32)
    z = np.linspace(-2.0, 2.0, 9)
    stack = RenderedStack(tex, np.full(tex.shape, 0.5), z, blur_px_per_um=2.0, noise_sd=0.0)
    sl = [stack[i] for i in range(len(stack))]
    s = [_sharpness(x) for x in sl]
    k = int(np.argmin(np.abs(z - 0.5)))
    assert int(np.argmax(s)) == k
    assert all(s[i] > s[i - 1] for i in range(1, k)) and all(
        s[i] < s[i - 1] for i in range(k + 1, len(s)))
    # |z − h| alone sets the blur: 0.5 ± 1 µm give the same image
    np.testing.assert_allclose(sl[k - 2], sl[k + 2], atol=1e-6)


def _voronoi(shape, n, rng):
    pts = rng.uniform(0, 1, (n, 2)) * np.array(shape)
    yy, xx = np.indices(shape)
    d = (yy[..., None] - pts[:, 0]) ** 2 + (xx[..., None] - pts[:, 1]) ** 2
    return np.argmin(d, axis=-1).astype(np.int32)


def _check(focus_result, texture, labels, cells=None):
    cond = Conditions(np.linspace(-4, 4, 21), 0.25, 0.5, 0.002)
    focus = focus_result(np.zeros(labels.shape), texture)
    return self_check_ndf(focus, labels, cells=cells, conditions=cond, rms_slope=0.2,
                          focus_options=FocusOptions(), joint=JointOptions())


@pytest.mark.slow
def test_slopes_come_back_where_every_facet_has_texture_and_not_where_none_has(focus_result):
    rng = np.random.default_rng(3)
    labels = _voronoi((160, 160), 15, np.random.default_rng(4))      # facets of ~40 px
    rich = rng.random(labels.shape).astype(np.float32)
    good = _check(focus_result, rich, labels)
    assert 0.8 <= good.transfer <= 1.25, good.to_json()
    # smaller facets (~20 px) whose only texture is sparse dark pits (0.5 % of the pixels):
    # most facets have no focus evidence of their own, and their heights are borrowed (the
    # transfer 0.59-0.72 over six noise seeds; at 1 % of the pixels it is 0.73-0.85, astride
    # the range's edge)
    small = _voronoi((160, 160), 60, rng)
    sparse = np.full(small.shape, 0.6, np.float32)
    sparse[rng.random(small.shape) < 0.005] = 0.1
    bad = _check(focus_result, sparse, small)
    assert not (0.8 <= bad.transfer <= 1.25), bad.to_json()


@pytest.mark.slow
def test_injected_domes_come_back_where_every_facet_has_texture(focus_result):
    """The dome transfer: caps injected on large, richly textured facets come back through
    the focus stage nearly whole (their dome coefficients' gain 0.8-1.25, its bootstrap
    error small); on small facets textured only by sparse pits their heights are borrowed
    and the caps flattened (a gain below the range, well below the textured one's)."""
    rng = np.random.default_rng(3)
    labels = _voronoi((160, 160), 15, np.random.default_rng(4))
    good = _check(focus_result, rng.random(labels.shape).astype(np.float32), labels)
    assert 0.8 <= good.dome_transfer <= 1.25, good.to_json()
    assert 0 < good.dome_transfer_se < 0.1
    small = _voronoi((160, 160), 60, rng)
    sparse = np.full(small.shape, 0.6, np.float32)
    sparse[rng.random(small.shape) < 0.005] = 0.1
    bad = _check(focus_result, sparse, small)
    assert bad.dome_transfer < min(0.8, good.dome_transfer - 0.2), (good.dome_transfer,
                                                                    bad.to_json())


def test_injected_domes_are_caps_of_the_asked_rms_slope():
    """:func:`_domes`: inside each cell a cap −κ r²/2 about its centroid (the dome
    coefficient of each cell's exact heights is −κ/2, the same for every cell) with RMS
    slope κ √⟨r²⟩ = the one asked for."""
    from microfacet.analysis.planes import dome_coefficients
    from microfacet.analysis.self_check import _domes

    cells = _voronoi((96, 96), 12, np.random.default_rng(5))
    caps = _domes(cells, 0.1, (0.25, 0.25))
    c = dome_coefficients(cells, caps, height_sigma_um=1.0, reliable=np.ones(cells.shape, bool),
                          pixel_size_um=0.25, min_pixels=3)
    assert c.ok.all()
    kappa = -2.0 * c.d
    np.testing.assert_allclose(kappa, kappa[0], rtol=1e-6)
    assert kappa[0] * math.sqrt(float(np.sum(c.area * c.r2) / c.area.sum())) == pytest.approx(
        0.1, rel=1e-6)
    # the slopes inside one cell, by central differences, are κ r there
    gy, gx = np.gradient(caps, 0.25)
    inner = (cells[1:-1, 1:-1] == cells[:-2, 1:-1]) & (cells[1:-1, 1:-1] == cells[2:, 1:-1]) & (
        cells[1:-1, 1:-1] == cells[1:-1, :-2]) & (cells[1:-1, 1:-1] == cells[1:-1, 2:])
    g = np.hypot(gy, gx)[1:-1, 1:-1][inner]
    yy, xx = np.indices(cells.shape) * 0.25
    n = np.bincount(cells.ravel())
    cy, cx = (np.bincount(cells.ravel(), v.ravel()) / n for v in (yy, xx))
    r = np.hypot(yy - cy[cells], xx - cx[cells])[1:-1, 1:-1][inner]
    np.testing.assert_allclose(g, kappa[0] * r, atol=1e-9)


@pytest.mark.slow
def test_segments_that_are_not_the_facets_cost_width_not_gain(focus_result):
    """Planes injected on facets independent of the segments: every segment straddles
    several, its plane averages theirs, so the width the NDF would see drops well below 1
    while the gain against what each segment holds stays near 1 (the heights are fine)."""
    rng = np.random.default_rng(8)
    labels = _voronoi((160, 160), 15, rng)
    cells = _voronoi((160, 160), 60, np.random.default_rng(9))   # ~4 per segment
    rich = rng.random(labels.shape).astype(np.float32)
    same = _check(focus_result, rich, labels)
    other = _check(focus_result, rich, labels, cells=cells)
    assert 0.8 <= same.width_transfer <= 1.25, same.to_json()
    assert other.width_transfer < 0.75 and other.width_transfer < same.width_transfer - 0.15
    assert 0.8 <= other.transfer <= 1.25, other.to_json()


def test_the_judgement_follows_the_self_check():
    ok = Judgement(True)
    opts = FitOptions()

    def check(t, width=None):
        width = t if width is None else width
        return SelfCheck([0.1], [0.1 * t], [t], t, 0.0, 50, [width], width)

    assert self_check_judgement(ok, check(1.0), opts) is ok
    assert self_check_judgement(ok, None, opts) is ok              # no check: no change
    bad = self_check_judgement(ok, check(0.4), opts)
    assert not bad.identified and bad.reason.code == "self_check"
    assert bad.reason.parameter == "fits.self_check_range" and "0.40" in bad.reason.plain()
    assert not self_check_judgement(ok, check(math.nan), opts).identified
    assert not self_check_judgement(ok, check(1.4), opts).identified
    wide = FitOptions(self_check_range=(0.3, 1.5))
    assert self_check_judgement(ok, check(0.4), wide).identified
    # slopes recovered without bias, but the width the NDF would see (noise removed) is not
    noisy = self_check_judgement(ok, check(1.0, width=0.3), opts)
    assert not noisy.identified and "0.30" in noisy.reason.plain()
    assert not self_check_judgement(ok, check(1.0, width=math.nan), opts).identified
    already = Judgement(False)
    assert self_check_judgement(already, check(1.0), opts) is already
    none = self_check_judgement(ok, SelfCheck.unmeasured(), opts)
    assert not none.identified and "fewer than 3 facet planes" in none.reason.plain()


def test_a_gain_that_changes_with_the_width_is_not_a_transfer():
    """Both transfers in range, but the slope gain differs between the injected widths by more
    than ``fits.self_check_max_spread`` (half its range): not identified, and the reason names
    the gains and the option; within it, identified."""
    ok = Judgement(True)
    opts = FitOptions()

    def check(ratios):
        t = float(np.median(ratios))
        spread = 0.5 * (max(ratios) - min(ratios))
        return SelfCheck([0.05, 0.1, 0.2], [r * i for r, i in zip(ratios, [0.05, 0.1, 0.2])],
                         list(ratios), t, spread, 50, [0.9] * 3, 0.9)

    steady = check([0.86, 0.88, 0.92])
    assert self_check_judgement(ok, steady, opts) is ok
    varying = check([0.74, 0.98, 0.83])                  # seed-12 g008's gains: transfer 0.83
    assert 0.8 <= varying.transfer <= 1.25 and varying.spread > opts.self_check_max_spread
    bad = self_check_judgement(ok, varying, opts)
    assert not bad.identified and bad.reason.parameter == "fits.self_check_max_spread"
    assert "0.74-0.98" in bad.reason.plain()
    assert self_check_judgement(ok, varying, FitOptions(self_check_max_spread=0.2)) is ok


def test_a_self_check_with_too_few_planes_measures_nothing_and_identifies_nothing():
    """Heights from focus but fewer than 3 facet planes with measurable slopes: the
    self-check runs on nothing, so it reports nothing measured (not "no check"), and the NDF
    those planes gave is not identified; switched off, or on heights not from focus, there
    is no check."""
    from types import SimpleNamespace

    from microfacet.analysis.options import AnalysisOptions
    from microfacet.analysis.pipeline import _self_check
    from microfacet.analysis.planes import fit_facet_planes

    yy, xx = np.mgrid[0:12, 0:24]
    labels = (xx >= 12).astype(np.int32)
    planes = fit_facet_planes(labels, 0.05 * xx * 0.5, height_sigma_um=0.01,
                              reliable=np.ones(labels.shape, bool), pixel_size_um=0.5,
                              min_pixels=8)
    assert planes.fitted.all()                      # two good planes: fewer than 3
    joint = SimpleNamespace(slope_planes=planes, area_px=np.bincount(labels.ravel()))
    scene = SimpleNamespace(from_focus=True, max_tilt_deg=30.0)
    st = SimpleNamespace(has_slices=True)
    opts = AnalysisOptions(fits=FitOptions(self_check=True))
    c = _self_check(st, None, joint, scene, opts, cells=None)
    assert c is not None and c.facets == 0 and math.isnan(c.transfer)
    assert c.to_json()["transfer"] is None
    assert not self_check_judgement(Judgement(True), c, opts.fits).identified
    off = AnalysisOptions(fits=FitOptions(self_check=False))
    assert _self_check(st, None, joint, scene, off, cells=None) is None
    assert _self_check(st, None, joint, SimpleNamespace(from_focus=False, max_tilt_deg=30.0),
                       opts, cells=None) is None


@pytest.mark.slow
def test_the_analysis_records_the_self_check_when_asked(tmp_path):
    """``fits.self_check`` (on by default): the joint analysis of the fixture runs it, records
    it in summary.json (``ndf.self_check``) and judges the NDF by it; off, nothing is
    recorded."""
    from pathlib import Path

    from microfacet.analysis import AnalysisOptions, analyse_stack
    from microfacet.analysis.output import build_summary

    stack = Path(__file__).resolve().parents[2] / "fixtures" / "stacks" / "nd-fixture"
    r = analyse_stack(stack, AnalysisOptions(fits=FitOptions(self_check=True)))
    c = r.self_check
    assert c is not None and c.facets >= 20 and len(c.ratio) == 3
    assert np.all(np.diff(c.injected_rms_slope) > 0)
    s = build_summary(r).to_json()
    assert s["ndf"]["self_check"]["transfer"] == pytest.approx(c.transfer)
    low, high = r.options.fits.self_check_range
    assert r.distributions.ndf_judgement.identified <= (low <= c.transfer <= high)
    # the transfers' standard errors: measured, recorded, and the identification keeps them
    # clear of the range's edges
    assert 0 < c.transfer_se < 0.2 and 0 < c.width_transfer_se < 0.2
    assert s["ndf"]["self_check"]["transfer_se"] == pytest.approx(c.transfer_se)
    assert r.distributions.ndf_judgement.identified <= (
        low + c.transfer_se <= c.transfer <= high - c.transfer_se)
    # the dome transfer: measured, recorded, and the planar-facet check is judged over it
    assert 0 < c.dome_transfer_se < 0.2 and 0.2 < c.dome_transfer < 1.25
    assert s["ndf"]["self_check"]["dome_transfer"] == pytest.approx(c.dome_transfer)
    info = r.distributions.ndf.info
    assert info["dome_share"] == pytest.approx(
        info["dome_share_measured"] / min(c.dome_transfer, 1.0) ** 2)
    assert r.distributions.ndf_judgement.identified <= (
        info["dome_share"] <= r.options.fits.max_dome_share)
    off = AnalysisOptions(fits=FitOptions(self_check=False))
    assert analyse_stack(stack, off).self_check is None


def test_a_transfer_within_its_standard_error_of_the_edge_is_not_established():
    """Both transfers inside ``fits.self_check_range`` but within ``fits.self_check_sigmas``
    of their standard errors of its edge: the stack measured its own transfer too noisily to
    place it inside, so the NDF is not identified, and the reason gives the transfers with
    their errors and names the option; with a smaller error, or no margin asked, identified."""
    ok = Judgement(True)
    opts = FitOptions()

    def check(t, se, width=0.95, width_se=0.01):
        return SelfCheck([0.1], [0.1 * t], [t], t, 0.0, 50, [width], width,
                         transfer_se=se, width_transfer_se=width_se)

    assert self_check_judgement(ok, check(0.85, 0.01), opts) is ok
    noisy = self_check_judgement(ok, check(0.85, 0.08), opts)
    assert not noisy.identified and noisy.reason.parameter == "fits.self_check_sigmas"
    assert "0.85 ± 0.08" in noisy.reason.plain()
    assert not self_check_judgement(ok, check(1.2, 0.08), opts).identified     # upper edge
    assert not self_check_judgement(ok, check(1.0, 0.01, 0.82, 0.05), opts).identified
    assert not self_check_judgement(ok, check(1.0, math.nan), opts).identified
    assert self_check_judgement(ok, check(0.85, 0.08), FitOptions(self_check_sigmas=0)) is ok


def test_the_bootstrap_error_of_the_gain_is_the_regressions_own():
    """The self-check's gain is a regression through 0 of the recovered slope changes on the
    injected slopes; resampling the facets gives its standard error: over many independent
    sets of facets the bootstrap SE matches the scatter of the gain itself."""
    from microfacet.analysis.self_check import _bootstrap_se

    gains, ses = [], []
    for k in range(60):
        rng = np.random.default_rng([5, k])
        n = 300
        x, y = rng.normal(0, 0.1, n), rng.normal(0, 0.1, n)
        w = rng.uniform(20, 200, n)                       # facet areas
        noise = 0.05 / np.sqrt(w / 50)                   # smaller facets, noisier slopes
        gx, gy = 0.85 * x + rng.normal(0, noise), 0.85 * y + rng.normal(0, noise)
        s = np.stack([w * (gx * x + gy * y), w * (x * x + y * y), w, w, w, w])
        gains.append(s[0].sum() / s[1].sum())
        ses.append(_bootstrap_se([s], np.random.default_rng([6, k]))[0])
    assert np.mean(gains) == pytest.approx(0.85, abs=0.01)
    assert np.mean(ses) == pytest.approx(np.std(gains), rel=0.25)


def test_the_facet_sums_give_the_self_checks_own_gain_and_width():
    """The bootstrap resamples per-facet sums (``_facet_sums``); summed over all the facets
    once they give the self-check's own point estimates — the gain of :func:`slope_gain` and
    the noise-removed width of :func:`~microfacet.analysis.planes.deconvolved_rms_slope` over
    the true per-pixel RMS — so its standard errors are of those numbers, slivers (slope
    noise above ``MAX_SLOPE_SIGMA``) left out alike."""
    from microfacet.analysis.planes import MAX_SLOPE_SIGMA, FacetFit, deconvolved_rms_slope
    from microfacet.analysis.self_check import _facet_sums, _ratios, slope_gain

    rng = np.random.default_rng(7)
    n = 50
    tx, ty = rng.normal(0, 0.1, n), rng.normal(0, 0.1, n)
    sx, sy = 0.9 * tx + rng.normal(0, 0.02, n), 0.9 * ty + rng.normal(0, 0.02, n)
    sigma = rng.uniform(0.005, 0.03, n)
    sigma[:4] = MAX_SLOPE_SIGMA * 1.5                                   # four slivers
    fit = FacetFit(sx, sy, np.zeros((n, 2, 2)), sigma,
                   np.degrees(np.arctan(np.hypot(sx, sy))), np.zeros(n), np.full(n, 30),
                   np.ones(n), np.ones(n, bool))
    ok = np.ones(n, bool)
    ok[10] = False
    w = rng.uniform(20, 200, n)[ok]
    px = rng.integers(5, 40, n)[ok]                                      # pixels per facet
    t2 = (tx[ok] ** 2 + ty[ok] ** 2) * px
    s = _facet_sums(fit, ok, w, tx[ok], ty[ok], (sx[ok], sy[ok]), t2, px)
    gain, width = _ratios(s.sum(axis=1))
    assert gain == pytest.approx(slope_gain(sx[ok], sy[ok], tx[ok], ty[ok], w), rel=1e-12)
    true = math.sqrt(t2.sum() / px.sum())
    assert width == pytest.approx(deconvolved_rms_slope(fit, ok, w) / true, rel=1e-12)


def test_the_width_error_carries_the_self_checks_bias_and_spread():
    """The width's error with its systematic part: noise, bias (1 − width transfer) and
    spread in quadrature; without a measured width transfer, not a number."""
    c = SelfCheck([0.1, 0.2], [0.09, 0.18], [0.9, 0.9], 0.9, 0.03, 50, [0.7, 0.9], 0.8)
    assert c.width_error(0.04) == pytest.approx(math.sqrt(0.04 ** 2 + 0.2 ** 2 + 0.03 ** 2),
                                                abs=1e-4)
    assert c.width_error(None) == pytest.approx(math.sqrt(0.2 ** 2 + 0.03 ** 2), abs=1e-4)
    c.width_transfer_se = 0.04                           # a correction by 0.8 ± 0.04: ± 5 %
    assert c.width_error(None) == pytest.approx(math.sqrt(0.2 ** 2 + 0.03 ** 2 + 0.05 ** 2),
                                                abs=1e-4)
    nothing = SelfCheck([math.nan], [math.nan], [math.nan], math.nan, math.nan, 0)
    assert math.isnan(nothing.width_error(0.04))
    flat = SelfCheck([0.1], [0.0], [0.0], 0.0, 0.0, 50, [0.0], 0.0, width_transfer_se=0.01)
    assert flat.width_error(0.04) == pytest.approx(math.sqrt(0.04 ** 2 + 1.0), abs=1e-4)


def test_a_rendered_stack_is_the_same_whenever_it_is_read():
    """RenderedStack renders a slice when it is read: the same slice on every read, the
    slices of two seeds differ only by their noise, and without noise a slice whose blur is
    one of the precomputed levels everywhere is that Gaussian blur of the texture."""
    cv2 = pytest.importorskip("cv2")

    rng = np.random.default_rng(1)
    tex = rng.random((32, 32)).astype(np.float32)
    h = rng.normal(0.0, 0.3, tex.shape)
    z = np.linspace(-1.0, 1.0, 5)
    a = RenderedStack(tex, h, z, blur_px_per_um=2.0, noise_sd=0.01, seed=(3,))
    b = RenderedStack(tex, h, z, blur_px_per_um=2.0, noise_sd=0.01, seed=(4,))
    first = [a[i] for i in range(len(a))]
    assert all(np.array_equal(first[i], a[i]) for i in reversed(range(len(a))))
    assert not np.array_equal(a[2], b[2]) and np.abs(a[2] - b[2]).std() < 0.05
    # a flat surface 0.75 µm from the slice: σ = 0.5 + 2 · 0.75 = 2 px, a level of its own
    quiet = RenderedStack(tex, np.full(tex.shape, 0.25), [1.0], blur_px_per_um=2.0,
                          noise_sd=0.0)
    np.testing.assert_allclose(quiet[0], cv2.GaussianBlur(tex, (0, 0), 2.0), atol=1e-6)
    with pytest.raises(IndexError):
        a[len(a)]
    # a stack given another's blur levels of the same texture renders the same slices
    shared = RenderedStack(tex, h, z, blur_px_per_um=2.0, noise_sd=0.01, seed=(3,),
                           levels=b.levels)
    assert all(np.array_equal(shared[i], first[i]) for i in range(len(a)))


def test_the_blur_level_index_is_np_interp_bit_for_bit():
    """The renderer's level index is arithmetic on the levels' spacing (0.5 px to 2 px, then
    2^m, 1.5 · 2^m): it must equal np.interp over the levels exactly (float32), at the levels,
    one ulp either side of them, past the last and at random blurs from 0.5 px up."""
    from microfacet.analysis.self_check import _LEVELS_PX, _level_index

    rng = np.random.default_rng(2)
    lv = _LEVELS_PX[1:]
    sigma = np.concatenate([lv, np.nextafter(lv, 0.0), np.nextafter(lv, np.inf),
                            rng.uniform(0.5, 40.0, 200_000), rng.uniform(0.5, 2.5, 50_000),
                            [1e6]])
    want = np.interp(sigma, _LEVELS_PX, np.arange(_LEVELS_PX.size, dtype=np.float32))
    got = _level_index(sigma)
    assert got.dtype == np.float32
    assert np.array_equal(got, want.astype(np.float32))
