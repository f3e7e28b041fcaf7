"""The distributions stage (microfacet.analysis.distributions) on real analyses: the joint
mode's facet samples of a small synthetic stack, with and without focus information, its
judgements when planes are few or the surface mostly censored; the seed mode's per-ROI
samples on the bundled fixture."""

from __future__ import annotations

import dataclasses
import math
from pathlib import Path

import numpy as np
import pytest

from microfacet.analysis import AnalysisOptions, analyse_stack
from microfacet.analysis.distributions import (
    correct_ndf_width,
    fit_joint_distributions,
    fit_seed_distributions,
)
from microfacet.analysis.identification import (
    colour_tilt_contrast,
    self_check_judgement,
    unexplained_facets,
)
from microfacet.analysis.options import FitOptions
from microfacet.analysis.self_check import measured_rms_slope
from microfacet.core.distributions import NDFMixture
from microfacet.forward.synth import generate_stack, preset
from microfacet.io.stack import read_stack, write_stack

N_SLICES = 8
ND_TRUTH = Path(__file__).resolve().parents[2] / "fixtures" / "stacks" / "nd-fixture" / "truth"
OPTIONS = FitOptions()


@pytest.fixture(scope="module")
def nd(tmp_path_factory):
    """A small nd stack (96×96 px, 8 slices), its joint analysis, and the same slice 8
    times (no focus information) analysed too."""
    root = tmp_path_factory.mktemp("ident")
    path = root / "nd"
    generate_stack(path, preset("nd", height_px=96, width_px=96, n_slices=N_SLICES, seed=3))
    r = analyse_stack(path, AnalysisOptions(mode="joint"))
    st = read_stack(path)
    mid = np.round(st.read_slice(N_SLICES // 2) * 255).astype(np.uint8)
    write_stack(root / "same", [mid] * N_SLICES, z_step_um=0.5, pixel_size_um=st.pixel_size_um,
                illumination=st.illumination)
    same = analyse_stack(root / "same", AnalysisOptions(mode="joint"))
    return {"path": path, "result": r, "same": same}


def test_joint_ndf_judged_by_its_evidence_and_then_by_its_self_check(nd):
    """Reliable heights and enough planes pass the evidence; the self-check and the
    planar-facet check then decide. On this 96-px scene the self-check measures a transfer
    out of range, and the truth agrees that the NDF is too narrow: the facet planes' RMS
    slope is < 0.8 of the true one, so the NDF is not identified (its facets, ~9 px across,
    are also too small for their heights to show whether they are planar)."""
    r = nd["result"]
    assert r.focus.reliable.mean() > 0.5                  # the premise: heights are reliable
    nfit, nj = r.ndf_fit, r.distributions.ndf_judgement
    # the evidence's judgement alone: the facets taken as measured planar, no self-check
    evidence = _refit(r, dataclasses.replace(r.joint, dome_ms_slope=(0.0, 0.0))).ndf_judgement
    assert evidence.identified is True and evidence.reason is None
    low, high = OPTIONS.self_check_range
    check = r.self_check
    assert check is not None and not (low <= check.transfer <= high
                                      and low <= check.width_transfer <= high)
    assert self_check_judgement(evidence, check, OPTIONS).reason.code == "self_check"
    assert nj.identified is False and nj.reason.code in ("self_check", "curved_facets")
    true_tilt = np.load(nd["path"] / "truth" / "tilt_deg.npy")
    seen = np.isfinite(true_tilt) & (true_tilt < r.scene.max_tilt_deg)
    true_rms = np.sqrt(np.mean(np.tan(np.radians(true_tilt[seen])) ** 2))
    assert measured_rms_slope(r.joint, r.scene.max_tilt_deg) < 0.8 * true_rms
    assert nfit.info["facets"] >= OPTIONS.min_ndf_facets
    assert nfit.info["width_relative_error"] <= OPTIONS.max_width_error
    # one sample per facet with a height plane: the facets used are the independent samples
    assert nfit.n_samples == nfit.info["facets"]
    assert nfit.info["samples"].startswith("facet plane tilts")
    tfit = r.thickness_fit
    j = r.joint
    cens_frac = np.bincount(j.facets.ravel(), weights=j.censored.ravel(),
                            minlength=j.area_px.size) / j.area_px
    samples = (np.isfinite(j.thickness.thickness_nm) & (cens_frac < 0.5)
               & ~unexplained_facets(j.thickness.delta_e, OPTIONS.unexplained_mads))
    assert r.distributions.thickness_judgement.identified
    assert tfit.info["facets"] == int(samples.sum()) == tfit.n_samples
    # n_eff: the area-weighted count of the thickness regions, at most their number
    assert 1.0 <= tfit.n_effective <= tfit.info["thickness_regions"]


def test_joint_ndf_not_identified_without_focus_information(nd):
    s = nd["same"]
    assert not s.focus.reliable.any()                      # the premise: no focus information
    nfit, nj = s.ndf_fit, s.distributions.ndf_judgement
    assert nfit is not None and nj.identified is False
    assert nj.reason.code == "few_planes" and "height" in nj.reason.plain()
    assert nfit.info["facets"] == 0
    assert nfit.info["samples"].startswith("per-pixel tilt")
    # colour at ~115 nm cannot stand in (a 10° tilt is mimicked by a thickness change)
    assert "colour cannot carry tilt" in nj.reason.plain()
    assert any(w.code == "not_identified_ndf" and "height" in w.plain() for w in s.warnings)


def test_joint_ndf_reason_without_focus_names_the_missing_heights(nd):
    s = nd["same"]
    j = s.joint
    dark = float(j.censored.mean())
    assert dark < 0.05                              # the premise: few dark pixels, if any
    # the reason is the missing heights, not censoring of "100 %" of the surface
    reason = s.distributions.ndf_judgement.reason.plain()
    assert f"height from focus gives a plane on 0 of {j.area_px.size} facets" in reason
    assert "tilted past the objective's acceptance" not in reason


def _usable_planes(j):
    """Facets whose plane tilt the NDF may use: fitted, finite, not dark (a bright plane
    steeper than the acceptance is a noisy sample, not a censored one)."""
    cens_frac = np.bincount(j.facets.ravel(), weights=j.censored.ravel(),
                            minlength=j.area_px.size) / j.area_px
    return j.planes.fitted & np.isfinite(j.planes.tilt_deg) & (cens_frac < 0.5)


def _planes_only(j, **changes):
    """``j`` with its NDF made of ``j.planes`` (no evidence planes) and facets measured
    planar (a dome term of 0 ± 0), so that the judgement under test is the evidence's."""
    return dataclasses.replace(j, evidence_planes=None, dome_ms_slope=(0.0, 0.0), **changes)


def _refit(r, joint, options=OPTIONS):
    return fit_joint_distributions(joint, r.roi, r.model, r.scene, options)


def test_joint_ndf_few_planes_is_not_identified(nd):
    r = nd["result"]
    j = r.joint
    keep = np.flatnonzero(_usable_planes(j))[:OPTIONS.min_ndf_facets - 5]
    fitted = np.zeros_like(j.planes.fitted)
    fitted[keep] = True
    few = _planes_only(j, planes=dataclasses.replace(j.planes, fitted=fitted),
                       censored=np.zeros_like(j.censored))
    d = _refit(r, few)
    nfit, nj = d.ndf, d.ndf_judgement
    assert nj.identified is False and nj.reason.code == "few_planes"
    assert f"plane on {keep.size} of {j.area_px.size} facets" in nj.reason.plain()
    assert nfit.n_samples == keep.size
    # the fewest facets is the option: with it just below their number, identified again
    lower = _refit(r, few, FitOptions(min_ndf_facets=keep.size, max_width_error=10.0))
    assert lower.ndf_judgement.identified


def test_joint_ndf_mostly_censored_is_not_identified(nd):
    r = nd["result"]
    j = r.joint
    # the largest facets, covering more than 60 % of the area, past the acceptance (dark)
    order = np.argsort(j.area_px)[::-1]
    n = int(np.searchsorted(np.cumsum(j.area_px[order]), 0.6 * j.area_px.sum())) + 1
    dark = np.isin(j.facets, order[:n])
    cens = _planes_only(j, censored=dark)
    d = _refit(r, cens)
    nfit, nj = d.ndf, d.ndf_judgement
    used = _usable_planes(cens)
    # only what is dark is censored, as a share of the film seen: the facets with a plane
    # and those without one that are mostly usable film
    usable = np.bincount(j.facets.ravel(), weights=j.usable.ravel()) / j.area_px
    lit = np.bincount(j.facets.ravel(), weights=dark.ravel()) <= 0.5 * j.area_px
    seen = used | (lit & (usable >= 0.5))
    c = dark.sum()
    frac = c / (c + j.area_px[seen].sum())
    assert frac > 0.5
    assert nj.identified is False and nj.reason.code == "censored"
    assert f"{100 * frac:.0f} % of the surface is tilted past" in nj.reason.plain()
    assert nfit.info["censored_fraction"] == pytest.approx(frac, rel=1e-9)
    assert nfit.n_samples == int(used.sum())


def test_seed_mode_fits_per_roi_and_judges_the_ndf_by_colour(nd_analysis):
    """The seed's distributions on the bundled fixture: the thickness of each ROI repeated
    over its pixels (one independent sample per ROI), the tilt from colour judged by the
    colour's tilt contrast at the median thickness against the pixel noise."""
    r = nd_analysis("seed")
    px, d = r.pixels, r.distributions
    assert r.joint is None
    n_rois = int(np.isfinite(r.roi.thickness_nm).sum())
    assert d.thickness.n_effective <= n_rois and d.ndf.n_effective <= n_rois
    assert d.roi_fitted.sum() == n_rois
    d_med = float(np.nanmedian(px.thickness_nm))
    contrast = colour_tilt_contrast(r.model, d_med)
    assert d.ndf.info["colour_tilt_contrast_de"] == pytest.approx(contrast)
    assert d.ndf_judgement.identified == (
        contrast > OPTIONS.colour_contrast_factor * r.colour.noise_de)
    again = fit_seed_distributions(px, r.roi, r.model, r.colour.noise_de, OPTIONS)
    assert again.thickness.mixture == d.thickness.mixture
    # a noise far above the contrast: never identified from colour alone
    noisy = fit_seed_distributions(px, r.roi, r.model, 10 * contrast + 1.0, OPTIONS)
    assert not noisy.ndf_judgement.identified
    assert noisy.ndf_judgement.reason.code == "colour_only"


def _split_joint(seed=5, n_up=160, gap_down=3.0, gap_up=(0.2, 0.6)):
    """Facets of 8×8 px on a 160×160 image: a 52 nm population, 400 - ``n_up`` facets read
    right (their runner-up order ``gap_down`` ΔE00 worse) and ``n_up`` read one order up at
    ~163 nm (their colours fit both about alike: runner-up worse by uniform ``gap_up``),
    beside nothing else; the runner-up orders as in facets.csv."""
    from types import SimpleNamespace

    from microfacet.analysis.facet_thickness import FacetThickness

    rng = np.random.default_rng(seed)
    labels = np.arange(400).reshape(20, 20).repeat(8, axis=0).repeat(8, axis=1)
    d = np.concatenate([rng.normal(52, 0.8, 400 - n_up), rng.normal(163, 0.8, n_up)])
    d = rng.permutation(d)
    up = d > 100
    other = np.where(up, d - 111, d + 111)
    de = rng.uniform(0.8, 1.2, 400)
    ft = FacetThickness(d, np.full(400, 0.5), de, np.zeros(400, bool), np.full(400, 64),
                        de + np.where(up, rng.uniform(*gap_up, 400), gap_down), other)
    return SimpleNamespace(thickness=ft, area_px=np.full(400, 64), facets=labels,
                           censored=np.zeros(labels.shape, bool)), up


def _resolve_at(keep):
    """A stand-in for joint.facets_in_other_order: the moved facets take the centre they are
    given, their old order becoming their runner-up (thickness and ΔE00 swapped), but those
    in ``keep`` (their own order fits far better) stay."""
    def resolve(joint, moved, centre_nm):
        ft = joint.thickness
        go = np.asarray(moved) & ~keep
        new = dataclasses.replace(
            ft, thickness_nm=np.where(go, centre_nm, ft.thickness_nm),
            thickness_other_order_nm=np.where(go, ft.thickness_nm, ft.thickness_other_order_nm),
            delta_e=np.where(go, ft.delta_e_other_order, ft.delta_e),
            delta_e_other_order=np.where(go, ft.delta_e, ft.delta_e_other_order))
        return type(joint)(**{**vars(joint), "thickness": new})
    return resolve


@pytest.mark.slow
def test_a_population_split_between_orders_is_pooled_into_one():
    """Before: two components an order apart (52 and 163 nm). The 163 nm facets fit the
    52 nm order within the margin: pooled, one component at 52 nm, and the move recorded;
    with `fits.order_moves = off` nothing moves."""
    from microfacet.analysis.distributions import (
        _thickness_fit,
        _thickness_samples,
        pool_interference_orders,
    )

    joint, up = _split_joint()
    ok, _, regions = _thickness_samples(joint, OPTIONS)
    before = _thickness_fit(joint, ok, regions, OPTIONS, 0)
    assert before.n_components == 2
    pooled = pool_interference_orders(joint, _resolve_at(np.zeros(400, bool)),
                                      period_nm=111.0, window_nm=50.0, options=OPTIONS)
    moves, after = pooled.moves, pooled.joint
    assert len(moves) == 1 and moves[0].facets == int(up.sum())
    assert moves[0].to_nm == pytest.approx(52.0, abs=0.5)
    assert np.all(np.abs(after.thickness.thickness_nm - 52.0) < 5.0)
    ok, _, regions = _thickness_samples(after, OPTIONS)
    refit = _thickness_fit(after, ok, regions, OPTIONS, 0)
    assert refit.n_components == 1
    # the last round's mixture is of the returned facets: the mixture stage reuses it
    assert pooled.fit.mixture.components == refit.mixture.components
    np.testing.assert_array_equal(pooled.samples[0], ok)



def _misread_joint(seed=2, n_minor=90, de_minor=(3.5, 5.5), grains=False):
    """Facets of 8×8 px on a 240×240 image: blocks of 3×3 facets (regions) of a 130 nm and
    a 175 nm population, a checkerboard (ΔE00 0.3-3.0), and ``n_minor`` facets read at 250
    nm with ΔE00 drawn from ``de_minor``: scattered over both, or (``grains``) whole blocks."""
    from types import SimpleNamespace

    from microfacet.analysis.facet_thickness import FacetThickness

    rng = np.random.default_rng(seed)
    labels = np.arange(900).reshape(30, 30).repeat(8, axis=0).repeat(8, axis=1)
    row, col = np.divmod(np.arange(900), 30)
    d = np.where((row // 3 + col // 3) % 2, 130.0, 175.0) + rng.normal(0, 0.8, 900)
    de = rng.uniform(0.3, 3.0, 900)
    minor = np.zeros(900, bool)
    if grains:
        minor[np.isin(row // 3 * 10 + col // 3, rng.choice(100, n_minor // 9, replace=False))] \
            = True
    else:
        minor[rng.choice(900, n_minor, replace=False)] = True
    d[minor] = rng.normal(250, 0.8, n_minor)
    de[minor] = rng.uniform(*de_minor, n_minor)
    ft = FacetThickness(d, np.full(900, 0.5), de, np.zeros(900, bool), np.full(900, 64),
                        de + 3.0, d + 111.0)
    return SimpleNamespace(thickness=ft, area_px=np.full(900, 64), facets=labels,
                           censored=np.zeros(labels.shape, bool)), minor


@pytest.mark.parametrize("de_minor, grains, why", [((3.5, 5.5), False, "colour"),
                                                   ((0.3, 3.0), False, "scattered"),
                                                   ((0.3, 3.0), True, None)])
def test_misread_facets_are_set_aside_not_a_population(de_minor, grains, why):
    """Facets read at 250 nm form a third component. Scattered one by one with colours that
    fit the film far worse than the two populations' (median ΔE00 4.5 against 1.65), or as
    well but scattered (regions of a facet or two, where the populations' hold nine), they
    are set aside: the refit has the two populations, the record says what went and why,
    and their facets join the unexplained ones. As whole blocks (grains of nine facets)
    with the populations' colours, the component stays."""
    from microfacet.analysis.distributions import (
        _set_aside_misread,
        _thickness_fit,
        _thickness_samples,
    )

    joint, minor = _misread_joint(de_minor=de_minor, grains=grains)
    samples = _thickness_samples(joint, OPTIONS)
    assert not (samples[1] & minor).any()       # not robust outliers of the ΔE00 alone
    before = _thickness_fit(joint, samples[0], samples[2], OPTIONS, 0)
    assert before.n_components == 3
    fit, (ok, unexplained, _), records = _set_aside_misread(joint, before, samples, OPTIONS, 0)
    if why is None:
        assert fit is before and records == []
        return
    assert [round(m) for m in fit.mixture.means_nm] == [130, 175]
    ((r,),) = (records,)
    assert r["mean_nm"] == pytest.approx(250, abs=1) and r["facets"] == minor.sum()
    assert r["why"] == why
    if why == "colour":
        assert r["delta_e"] > 1.5 * r["delta_e_populations"] + 0.5
    else:
        assert r["facets_per_region"] < 6.0 and r["delta_e"] < 2.0
    np.testing.assert_array_equal(unexplained, minor)
    np.testing.assert_array_equal(ok, ~minor)


def test_an_order_move_most_facets_refuse_is_not_made():
    """Solved again in the other order, most of the 163 nm facets keep their own (it fits
    them better by more than the switch margin): the move is dropped, the facets unchanged."""
    from microfacet.analysis.consistency import order_move
    from microfacet.analysis.distributions import (
        _thickness_fit,
        _thickness_samples,
        pool_interference_orders,
    )

    joint, up = _split_joint()
    ok, _, regions = _thickness_samples(joint, OPTIONS)
    th = joint.thickness
    proposed, _ = order_move(_thickness_fit(joint, ok, regions, OPTIONS, 0).mixture,
                             th.thickness_nm, th.thickness_other_order_nm,
                             th.delta_e_other_order - th.delta_e, joint.area_px,
                             margin_de=1.0, min_separation_nm=61.0)
    assert proposed is not None and proposed.from_nm > 150          # proposed, then refused
    keep = up & (np.cumsum(up) % 3 != 0)               # two thirds of them keep their order
    pooled = pool_interference_orders(joint, _resolve_at(keep), period_nm=111.0,
                                      window_nm=50.0, options=OPTIONS)
    assert pooled.moves == [] and pooled.joint is joint
    # nor into (or out of) a component as wide as an order's window: no order to move to
    wide = pool_interference_orders(joint, _resolve_at(np.zeros(400, bool)),
                                    period_nm=111.0, window_nm=1.0, options=OPTIONS)
    assert wide.moves == [] and wide.joint is joint


@pytest.mark.slow
def test_an_order_move_records_what_moved_and_is_never_undone():
    """40 % of the 163 nm facets keep their own order: the move is kept (60 % land on the
    52 nm population) and records that share and those facets, not what it proposed.
    The facets it moved now have their old order as a runner-up that fits better, which
    would draw the 52 nm component back up an order: a facet moves once, so no second move
    takes them back (the 52 nm facets here fit the order above within the margin too)."""
    from microfacet.analysis.distributions import pool_interference_orders

    joint, up = _split_joint(n_up=240, gap_down=0.5, gap_up=(0.3, 0.3))
    keep = up & (np.cumsum(up) <= 0.4 * up.sum())      # 40 % of them keep their order
    pooled = pool_interference_orders(joint, _resolve_at(keep), period_nm=111.0,
                                      window_nm=50.0, options=OPTIONS)
    moves, after = pooled.moves, pooled.joint
    assert len(moves) == 1 and moves[0].to_nm < 60 < moves[0].from_nm
    went = up & ~keep
    assert moves[0].facets == int(went.sum())
    assert moves[0].area_share == pytest.approx(went.sum() / up.sum())
    t = after.thickness.thickness_nm
    assert np.all(np.abs(t[went] - 52.0) < 5.0) and np.all(t[keep] > 150)


# ------------------------------------------------------------------ mean_uncertainty


def _mean_unc(sd=(2.0, 3.0), region_values=(99.0, 101.0, 98.0, 102.0, 139.0, 141.0),
              areas=None, sigma=0.0, shifts=None, touching=None):
    from microfacet.analysis.distributions import mean_uncertainty
    from microfacet.analysis.sampling import Regions
    from microfacet.core.distributions import ThicknessMixture

    v = np.asarray(region_values, float)
    a = np.full(v.size, 100.0) if areas is None else np.asarray(areas, float)
    mix = ThicknessMixture([(0.6, 100.0, sd[0]), (0.4, 140.0, sd[1])])
    regions = Regions(np.arange(v.size), v, np.full(v.size, sigma), a, 0.0)
    return mean_uncertainty(mix, regions, v, a, touching=touching, gain_shifts_nm=shifts)


def test_a_components_mean_is_uncertain_by_its_spread_over_its_regions():
    """Equal regions: sd/√n; unequal areas count as their Kish number; the regions' own
    errors add in quadrature (area-weighted mean of independent errors)."""
    u = _mean_unc()
    assert [x["regions"] for x in u] == [4.0, 2.0]
    assert [x["sampling_nm"] for x in u] == pytest.approx([2.0 / 2.0, 3.0 / np.sqrt(2.0)],
                                                          abs=1e-4)
    u = _mean_unc(areas=[300, 100, 100, 100, 100, 100])
    n = 600.0 ** 2 / (300 ** 2 + 3 * 100 ** 2)
    assert u[0]["regions"] == pytest.approx(n, abs=0.01)
    assert u[0]["sampling_nm"] == pytest.approx(2.0 / np.sqrt(n), abs=1e-3)
    u = _mean_unc(sigma=1.0)                                  # 4 equal regions ± 1 nm each
    assert u[0]["sampling_nm"] == pytest.approx(np.sqrt(1.0 + 1.0 / 4.0), abs=1e-4)
    assert u[0]["white_balance_nm"] is None and u[0]["sigma_nm"] == u[0]["sampling_nm"]


def test_a_component_without_a_measured_spread_takes_the_others():
    """On one region the spread of the measured components stands in, and is said not
    measured; with none measured the sampling part is unknown. An SD at the floor over
    several separate regions is a measured (small) spread."""
    u = _mean_unc(sd=(2.0, 0.1), region_values=(99.0, 101.0, 98.0, 102.0, 140.0))
    assert [x["spread_measured"] for x in u] == [True, False]
    assert u[1]["sampling_nm"] == pytest.approx(2.0, abs=1e-4)      # one region, SD 2
    u = _mean_unc(sd=(0.1, 0.1), region_values=(100.0, 140.0))
    assert [x["sampling_nm"] for x in u] == [None, None]
    assert [x["sigma_nm"] for x in u] == [None, None]
    u = _mean_unc(sd=(2.0, 0.1), region_values=(99.0, 101.0, 140.0, 140.05))
    assert u[1]["spread_measured"] and u[1]["sampling_nm"] == pytest.approx(0.1 / np.sqrt(2),
                                                                             abs=1e-4)


def test_a_component_on_pieces_of_one_region_has_no_measured_spread():
    """Regions of one component that touch may be one true region split by noise: their
    SD is no measure of the population's spread until two separate groups exist; touching
    regions of two components stay apart; the count of regions is not merged."""
    u = _mean_unc(touching=np.array([[0, 1], [1, 2], [2, 3], [4, 5]]))
    assert [x["groups"] for x in u] == [1, 1]
    assert [x["spread_measured"] for x in u] == [False, False]
    assert [x["sampling_nm"] for x in u] == [None, None]
    u = _mean_unc(touching=np.array([[0, 1], [2, 3]]))
    assert [x["groups"] for x in u] == [2, 2] and all(x["spread_measured"] for x in u)
    assert u[0]["regions"] == pytest.approx(4.0)
    assert u[0]["sampling_nm"] == pytest.approx(1.0, abs=1e-4)
    u = _mean_unc(touching=np.array([[3, 4]]))                      # 102 nm beside 139 nm
    assert [x["groups"] for x in u] == [4, 2]


def test_touching_regions_from_the_facet_labels():
    from microfacet.analysis.distributions import touching_regions
    from microfacet.analysis.segmentation import neighbour_pairs

    labels = np.array([[0, 0, 1, 2],
                       [0, 0, 1, 2],
                       [3, 3, 3, 2]])
    pairs = touching_regions(neighbour_pairs(labels), np.array([0, 0, 1, -1]))  # 3: none
    assert pairs.tolist() == [[0, 1]]


def test_the_white_balance_part_is_the_components_facets_move():
    """The area-weighted mean move of each component's facets, R and B in quadrature;
    facets off every component do not count."""
    v = [99.0, 101.0, 98.0, 102.0, 139.0, 141.0, 500.0]
    shifts = np.array([[0.2, 0.4, 0.2, 0.4, -1.0, -1.0, 50.0],
                       [0.0, 0.0, 0.0, 0.0, 0.5, 0.5, 50.0]])
    u = _mean_unc(region_values=v, areas=[100, 100, 100, 100, 100, 300, 100], shifts=shifts)
    assert u[0]["white_balance_nm"] == pytest.approx(0.3, abs=1e-4)
    assert u[1]["white_balance_nm"] == pytest.approx(np.hypot(1.0, 0.5), abs=1e-4)
    assert u[1]["sigma_nm"] == pytest.approx(np.hypot(u[1]["sampling_nm"], np.hypot(1.0, 0.5)),
                                             abs=1e-3)


def test_the_dome_share_is_over_the_planes_that_carry_slope():
    """The planar-facet check's denominator, the planes' noise-removed mean square slope,
    leaves out slivers whose slope noise exceeds planes.MAX_SLOPE_SIGMA (as the self-check's
    measured RMS does): one plane with a huge σ no longer swamps it into "not measured";
    with nothing but slivers, or no dome term, it is not measured (NaN); without planes,
    nothing to judge (None)."""
    from microfacet.analysis.distributions import _dome_share
    from microfacet.analysis.planes import MAX_SLOPE_SIGMA, FacetFit

    slope = np.array([0.10, -0.05, 0.08, 0.0])
    sigma = np.array([0.01, 0.01, 0.01, 1e3])            # the last: a sliver along an edge
    n = slope.size
    planes = FacetFit(slope, np.zeros(n), np.zeros((n, 2, 2)), sigma,
                      np.degrees(np.arctan(np.abs(slope))), np.ones(n), np.full(n, 20),
                      np.ones(n), np.ones(n, bool))
    use, area = np.ones(n, bool), np.full(n, 50.0)
    good = sigma < MAX_SLOPE_SIGMA
    ms = np.average(slope[good] ** 2 - 2 * sigma[good] ** 2)
    assert _dome_share((0.001, 0.0005), planes, use, area) == pytest.approx(0.002 / ms)
    assert math.isnan(_dome_share((0.001, 0.0005), planes, ~good, area))
    assert math.isnan(_dome_share(None, planes, use, area))
    assert _dome_share((0.001, 0.0005), planes, np.zeros(n, bool), area) is None


@pytest.mark.parametrize("gain, share, expected", [
    (0.5, 0.1, 0.4),           # heights that show half a dome: its mean square is 4× the shown
    (1.0, 0.2, 0.2),
    (1.6, 0.2, 0.2),           # heights that exaggerate domes are not credited
    (0.0, 0.1, math.inf),      # domes flattened to nothing: the facets are not shown planar
    (-0.2, 0.0, 0.0),
])
def test_the_dome_share_is_over_what_the_heights_show_of_a_dome(gain, share, expected):
    """:func:`calibrate_dome_share`: the measured share over the self-check's dome transfer
    squared, the measured one kept, and the NDF judged again at fits.max_dome_share; without a
    transfer (NaN) or a measured share (None, NaN) nothing changes."""
    from microfacet.analysis.distributions import Distributions, calibrate_dome_share
    from microfacet.analysis.identification import Judgement
    from microfacet.analysis.mixtures import MixtureFit
    from microfacet.analysis.self_check import SelfCheck

    def dist(s):
        fit = MixtureFit.__new__(MixtureFit)
        fit.info = {"dome_share": s}
        return Distributions(None, fit, Judgement(True), Judgement(True))

    check = SelfCheck([], [], [], 1.0, 0.0, 10, dome_transfer=gain)
    out = calibrate_dome_share(dist(share), check, FitOptions())
    assert out.ndf.info["dome_share"] == pytest.approx(expected)
    assert out.ndf.info["dome_share_measured"] == share
    assert out.ndf_judgement.identified == (expected <= FitOptions().max_dome_share)
    if not out.ndf_judgement.identified:
        assert out.ndf_judgement.reason.parameter == "fits.max_dome_share"
    for s in (None, math.nan):
        assert calibrate_dome_share(dist(s), check, FitOptions()).ndf_judgement.identified
    unmeasured = SelfCheck([], [], [], 1.0, 0.0, 10)
    kept = calibrate_dome_share(dist(0.2), unmeasured, FitOptions())
    assert kept.ndf.info == {"dome_share": 0.2} and kept.ndf_judgement.identified
    assert calibrate_dome_share(dist(0.2), None, FitOptions()).ndf_judgement.identified


def _rms_slope(lobes, limit_deg):
    """RMS slope (E[tan² θ]^½) of Gaussian-slope lobes ``[(weight, sd_deg)]`` truncated at
    ``limit_deg``: the lobe density in tan θ (m = tan θ, Rayleigh in m) integrated on a grid."""
    m = np.linspace(0.0, math.tan(math.radians(limit_deg)), 20001)
    pdf = sum(w * m / math.tan(math.radians(sd)) ** 2
              * np.exp(-0.5 * (m / math.tan(math.radians(sd))) ** 2) for w, sd in lobes)
    return math.sqrt(float(np.trapezoid(pdf * m * m, m) / np.trapezoid(pdf, m)))


def test_the_ndf_corrected_by_its_self_check_meets_the_truth(nd_analysis):
    """The bundled fixture's self-check measures a width transfer below 1 (its heights
    flatten the slopes by a gain it can measure): the lobes are scaled until their RMS slope
    below the acceptance is the planes' (noise removed) over that transfer, and the truth
    agrees. Against the true per-pixel tilts of the facets (below the acceptance), the
    uncorrected lobes' RMS slope is > 10 % low and the corrected one's within 5 %."""
    r = nd_analysis("joint")
    check, ndf = r.self_check, r.ndf_fit
    assert OPTIONS.self_check_min_transfer <= check.width_transfer < 0.9
    corr = ndf.info["width_correction"]
    assert corr["slope_gain"] == pytest.approx(check.width_transfer, rel=1e-12)
    limit = r.scene.max_tilt_deg
    planes = measured_rms_slope(r.joint, limit)
    assert corr["planes_rms_slope"] == pytest.approx(planes, rel=1e-12)
    # the corrected lobes' RMS slope below the acceptance, integrated on a grid, is the
    # planes' over the transfer; their weights are the fit's
    fixed = _rms_slope(r.ndf_fit.mixture.components, limit)
    assert fixed == pytest.approx(planes / check.width_transfer, rel=1e-4)
    assert [w for w, _ in r.ndf_fit.mixture.components] == pytest.approx(
        [c["weight"] for c in corr["uncorrected"]], rel=1e-12)
    truth = np.load(ND_TRUTH / "tilt_deg.npy").astype(np.float64)
    seen = truth[np.isfinite(truth) & (truth < limit)]
    true_rms = math.sqrt(float(np.mean(np.tan(np.radians(seen)) ** 2)))
    raw = _rms_slope([(c["weight"], c["sd_deg"]) for c in corr["uncorrected"]], limit)
    assert raw / true_rms < 0.9
    assert abs(fixed / true_rms - 1.0) < 0.05
    # the correction's size stays in the width's error
    assert ndf.info["width_relative_error_total"] >= 1.0 - check.width_transfer


def test_no_correction_outside_the_transfers_bounds_or_when_switched_off(nd_analysis):
    """A self-check whose slope gain or width transfer lies outside
    [fits.self_check_min_transfer, the top of fits.self_check_range] or was not measured,
    planes whose second moment covers too little of the NDF's (a third too noisy for a
    slope), or ``fits.self_check_correct`` off, leaves the lobes as fitted; a transfer below the
    identification range but above that floor corrects them (identified or not); a transfer
    of 1 scales them to the planes' own RMS slope."""
    j = nd_analysis("joint")
    before = [(c["weight"], c["sd_deg"]) for c in j.ndf_fit.info["width_correction"][
        "uncorrected"]]
    fitted = dataclasses.replace(j.ndf_fit, mixture=NDFMixture(before), info={
        k: v for k, v in j.ndf_fit.info.items() if k != "width_correction"})
    d = dataclasses.replace(j.distributions, ndf=fitted)
    off = FitOptions(self_check_correct=False)
    assert correct_ndf_width(d, j.joint, j.scene, off, j.self_check) is d
    assert correct_ndf_width(d, j.joint, j.scene, OPTIONS, None) is d
    floor = OPTIONS.self_check_min_transfer
    for out in ({"width_transfer": 1.3}, {"transfer": 0.05}, {"transfer": math.nan},
                {"width_transfer": floor - 0.01}, {"transfer": floor - 0.01}):
        check = dataclasses.replace(j.self_check, **out)
        assert correct_ndf_width(d, j.joint, j.scene, OPTIONS, check) is d
    # planes too noisy for a slope over a third of the area: the second moment the
    # self-check calibrates stands for a selection, not for the NDF's planes
    pl = j.joint.slope_planes
    third = (np.arange(pl.slope_sigma.size) % 3 == 0)
    field = "planes" if j.joint.evidence_planes is None else "evidence_planes"
    noisy = dataclasses.replace(j.joint, **{field: dataclasses.replace(
        pl, slope_sigma=np.where(third, 1.0, pl.slope_sigma))})
    assert correct_ndf_width(d, noisy, j.scene, OPTIONS, j.self_check) is d
    limit = j.scene.max_tilt_deg
    planes = measured_rms_slope(j.joint, limit)
    for wt in (1.0, floor + 0.05):
        check = dataclasses.replace(j.self_check, width_transfer=wt)
        got = correct_ndf_width(d, j.joint, j.scene, OPTIONS, check).ndf
        assert _rms_slope(got.mixture.components, limit) == pytest.approx(planes / wt, rel=1e-4)
        assert got.info["width_correction"]["scale"] == pytest.approx(
            math.tan(math.radians(got.mixture.components[0][1]))
            / math.tan(math.radians(before[0][1])), rel=1e-9)


def test_a_component_misfit_only_at_the_images_balance_is_not_misread():
    """A minor component whose colours fit the film 4× worse than the population's is misread
    facets; where the scene's white-balance estimate (not applied) fits them as well as the
    population's, the misfit is the camera's balance and the component stays; where it
    fits them as badly, they are set aside as before."""
    from types import SimpleNamespace

    from microfacet.analysis.distributions import _misread
    from microfacet.analysis.sampling import Regions
    from microfacet.core.distributions import ThicknessMixture

    d = np.r_[np.full(85, 130.0), np.full(15, 250.0)]
    de = np.r_[np.full(85, 1.0), np.full(15, 4.0)]
    fit = SimpleNamespace(mixture=ThicknessMixture([(0.85, 130.0, 1.0), (0.15, 250.0, 1.0)]))
    th = SimpleNamespace(thickness_nm=d, delta_e=de)
    region = (d > 200).astype(int)             # two grains: neither component is scattered
    area = np.full(100, 64.0)
    reg = Regions(region, np.array([130.0, 250.0]), np.full(2, 0.1),
                  np.bincount(region, area), 0.0)
    ok = np.ones(100, bool)
    assert [(k, rec["why"]) for k, rec, _ in _misread(fit, th, ok, reg, area)] == [(1, "colour")]
    assert _misread(fit, th, ok, reg, area, lambda: np.full(100, 1.1)) == []
    assert [k for k, *_ in _misread(fit, th, ok, reg, area, lambda: de + 0.2)] == [1]
    # the same facets as one corner block of a 10 × 10 grid of facets cover a grain: kept;
    # each apart from the others (a checkerboard's cells), they are misread as before
    from microfacet.analysis.segmentation import neighbour_pairs

    grid = np.arange(100).reshape(10, 10)
    order = np.r_[np.flatnonzero((grid < 70).ravel() | (grid % 10 < 5).ravel()),
                  np.flatnonzero((grid >= 70).ravel() & (grid % 10 >= 5).ravel())]
    labels = np.argsort(order)[grid]           # facet i (d[i]) at the cell order[i]
    assert (d[labels[7:, 5:]] == 250.0).all()
    assert _misread(fit, th, ok, reg, area, pairs=neighbour_pairs(labels)) == []
    apart = np.flatnonzero(((grid // 10 + grid % 10) % 2 == 0).ravel())[::3][:15]
    order = np.r_[np.setdiff1d(np.arange(100), apart), apart]   # the same facets, apart
    labels = np.argsort(order)[grid]
    assert [(k, rec["why"]) for k, rec, _ in _misread(
        fit, th, ok, reg, area, pairs=neighbour_pairs(labels))] == [(1, "colour")]
