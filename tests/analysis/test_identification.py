"""Identification (microfacet.analysis.identification): whether colour can carry tilt
(against docs/conditioning.md), the thickness and NDF reasons, the user warnings, and the
distributions stage of the joint mode on a small synthetic stack (with and without focus
information)."""

from __future__ import annotations

import dataclasses
import math
from types import SimpleNamespace as NS

import numpy as np
import pytest
from scipy import stats

from microfacet.analysis import AnalysisOptions, analyze_stack
from microfacet.analysis.identification import (
    AMBIGUOUS_ORDER_DE,
    EXCESS_DELTA_E,
    MAX_WIDTH_ERROR,
    MEDIAN_NOISE_FLOOR_FACTOR,
    MIN_NDF_FACETS,
    NOISE_FLOOR_FACTOR,
    analysis_warnings,
    colour_tilt_contrast,
    fit_joint_distributions,
    mean_plane_tilt_deg,
    thickness_reason,
    unexplained_facets,
)
from microfacet.analysis.mixtures import MixtureFit
from microfacet.core.distributions import ThicknessMixture
from microfacet.forward.synth import generate_stack, preset
from microfacet.io.stack import read_stack, write_stack

N_SLICES = 8

# ------------------------------------------------------------------ colour_tilt_contrast


@pytest.fixture(scope="module")
def table():
    from microfacet.colour.table import build_colour_table

    return build_colour_table(thickness_range_nm=(30.0, 160.0), theta_range_deg=(0.0, 20.0))


def _raw_tilt_change(table, d, tilt=10.0):
    """ΔE00 between (tilt, d) and (0°, d): the tilt's colour change at a known thickness."""
    from microfacet.colour.colorimetry import xyz_to_lab
    from microfacet.colour.difference import delta_e

    white = table.white_xyz.astype(np.float32)
    a = xyz_to_lab(table.xyz_at(tilt, d).astype(np.float32), white=white)
    b = xyz_to_lab(table.xyz_at(0.0, d).astype(np.float32), white=white)
    return float(delta_e(a[None], b[None], method="CIEDE2000")[0])


@pytest.mark.parametrize("d, j10", [(51.0, 0.057), (130.0, 0.253)])
def test_tilt_colour_change_agrees_with_the_conditioning_page(table, d, j10):
    """docs/conditioning.md, "At selected thicknesses": J at 10° is 0.057 ΔE00/° at 51 nm and
    0.253 at 130 nm, and "J grows linearly from zero at normal incidence", so a 10° tilt
    changes the colour by ∫₀¹⁰ J dθ ≈ J(10°)·10/2 (0.29 and 1.27 ΔE00)."""
    expected = j10 * 10.0 / 2.0
    assert _raw_tilt_change(table, d) == pytest.approx(expected, rel=0.3)


def test_colour_tilt_contrast_is_small_at_a_thin_film(table):
    # docs/conditioning.md: at 51 nm σ_tilt is 17° at 10° with σ_n = 1 ("tilt from colour is
    # weak everywhere"; "1° of tilt at 10° looks like 0.1 nm of thickness"): a 10° tilt at
    # 51 nm is mimicked by a thickness change, far below half a ΔE00
    c = colour_tilt_contrast(table, 51.0, exposure=1.0)
    assert 0.0 <= c < 0.5
    # never more than the tilt's raw change (d itself is among the candidate thicknesses)
    for d in (51.0, 100.0, 130.0):
        assert colour_tilt_contrast(table, d, exposure=1.0) <= _raw_tilt_change(table, d) + 1e-3
    # and at 130 nm, where the raw change is > 1 ΔE00, a ±10 % thickness change still
    # mimics most of it ("one degree ≙ 0.06 nm")
    assert colour_tilt_contrast(table, 130.0, exposure=1.0) < 0.5 * _raw_tilt_change(table, 130.0)


def test_colour_tilt_contrast_grows_with_the_tilt(table):
    # a tilt of 0° changes nothing; the contrast is a distance, ≥ 0
    assert colour_tilt_contrast(table, 51.0, exposure=1.0, tilt_deg=0.0) == pytest.approx(
        0.0, abs=1e-3)
    c = [colour_tilt_contrast(table, 130.0, exposure=1.0, tilt_deg=t) for t in (5.0, 20.0)]
    assert 0.0 <= c[0] <= c[1]


# ------------------------------------------------------------------ thickness_reason


def _roi(thickness, ambiguity, runner_up=None):
    t = np.asarray(thickness, float)
    return NS(thickness_nm=t, ambiguity_delta_e=np.asarray(ambiguity, float),
              runner_up_thickness_nm=(t + 100.0 if runner_up is None
                                      else np.asarray(runner_up, float)))


def test_thickness_reason_empty_for_unambiguous_rois():
    assert thickness_reason(_roi([120, 131, 140, 150], [5.0, 3.0, 2.0, 8.0])) == ""
    # exactly half ambiguous is not "most"
    assert thickness_reason(_roi([120, 131, 140, 150], [0.2, 0.3, 2.0, 8.0])) == ""


def test_thickness_reason_names_the_ambiguous_regions():
    roi = _roi([120, 131, 140, 150, np.nan], [0.2, 0.9, 0.1, 8.0, 0.0],
               runner_up=[240, 262, 287, 300, 10])
    r = thickness_reason(roi)
    # 3 of the 4 ROIs with a value (the NaN ROI does not count); the example is the most
    # ambiguous one (140 nm, runner-up 287 nm)
    assert "3 of 4 regions" in r
    assert "140 nm" in r and "287 nm" in r
    assert "--thickness-range" in r


def test_thickness_reason_edge_and_joint_mode():
    unamb = _roi([120, 131], [5.0, 5.0])
    assert thickness_reason(unamb, edge_fraction=0.4) == ""
    edge = thickness_reason(unamb, edge_fraction=0.7)
    assert "70 %" in edge and "edge" in edge
    # joint mode: by area (other_order_fraction), whatever the ROIs say
    amb_rois = _roi([120, 131], [0.1, 0.1])
    assert thickness_reason(amb_rois, other_order_fraction=0.2) == ""
    r = thickness_reason(unamb, other_order_fraction=0.8)
    assert "80 %" in r and "interference order uncertain" in r
    assert "70 %" in thickness_reason(unamb, edge_fraction=0.7, other_order_fraction=0.1)


# ------------------------------------------------------------------ analysis_warnings


def test_noise_floor_factors_are_those_of_three_gaussian_components():
    # ΔE of N(0, σ² I₃) is σ·χ₃: mean 2·sqrt(2/π), median sqrt(median of χ²₃)
    assert NOISE_FLOOR_FACTOR == pytest.approx(stats.chi(3).mean(), rel=1e-12)
    assert MEDIAN_NOISE_FLOOR_FACTOR == pytest.approx(math.sqrt(stats.chi2(3).median()),
                                                      abs=1e-4)


def _fit(identified=True, reason=""):
    return MixtureFit(ThicknessMixture([(1.0, 130.0, 3.0)]), 0.0, {1: 0.0}, 10, 10.0,
                      identified=identified, reason=reason)


def test_analysis_warnings_none_when_all_is_well():
    roi = _roi([130.0, 131.0], [5.0, 5.0])
    assert analysis_warnings(thickness_fit=_fit(), ndf_fit=_fit(), roi=roi,
                             delta_e_median=1.0, noise_de=1.0) == []
    assert analysis_warnings(thickness_fit=_fit(), ndf_fit=_fit(), roi=roi,
                             delta_e_median=None, noise_de=1.0) == []


def test_analysis_warnings_lines():
    roi = _roi([130.0, 131.0, 150.0, np.nan], [0.2, 5.0, AMBIGUOUS_ORDER_DE - 0.01, 0.0])
    w = analysis_warnings(thickness_fit=_fit(False, "the order is uncertain"),
                          ndf_fit=_fit(False, "no height"), roi=roi, delta_e_median=1.0,
                          noise_de=1.0)
    assert len(w) == 3
    assert w[0].startswith("thickness distribution not identified") and \
        w[0].endswith("the order is uncertain")
    assert w[1].startswith("NDF not identified") and w[1].endswith("no height")
    assert w[2].startswith("2 of 3 ROIs have an ambiguous interference order")
    missing = analysis_warnings(thickness_fit=None, ndf_fit=_fit(), roi=_roi([1.0], [9.0]),
                                delta_e_median=None, noise_de=1.0)
    assert len(missing) == 1 and "no thickness values" in missing[0]


def test_analysis_warnings_excess_delta_e_threshold():
    # the median ΔE00 of pure noise σ per Lab component is σ·sqrt(median χ²₃)
    roi = _roi([130.0], [5.0])
    for noise in (0.5, 2.0):
        floor = noise * math.sqrt(stats.chi2(3).median())

        def warn(median):
            return analysis_warnings(thickness_fit=_fit(), ndf_fit=_fit(), roi=roi,
                                     delta_e_median=median, noise_de=noise)
        assert warn(floor + EXCESS_DELTA_E - 0.01) == []
        w = warn(floor + EXCESS_DELTA_E + 0.01)
        assert len(w) == 1 and w[0].startswith(f"median dE00 {floor + EXCESS_DELTA_E + 0.01:.2f}")
        assert "noise floor" in w[0]


# ------------------------------------------------------------------ the joint mode's fits


@pytest.fixture(scope="module")
def nd(tmp_path_factory):
    """A small nd stack (96×96 px, 8 slices), its joint analysis, and the same slice 8
    times (no focus information) analysed too."""
    root = tmp_path_factory.mktemp("ident")
    path = root / "nd"
    generate_stack(path, preset("nd", height_px=96, width_px=96, n_slices=N_SLICES, seed=3))
    r = analyze_stack(path, AnalysisOptions(mode="joint"))
    st = read_stack(path)
    mid = np.round(st.read_slice(N_SLICES // 2) * 255).astype(np.uint8)
    write_stack(root / "same", [mid] * N_SLICES, z_step_um=0.5, pixel_size_um=st.pixel_size_um,
                illumination=st.illumination)
    same = analyze_stack(root / "same", AnalysisOptions(mode="joint"))
    return {"path": path, "result": r, "same": same}


def test_joint_ndf_identified_with_good_heights(nd):
    r = nd["result"]
    assert r.focus.reliable.mean() > 0.5                  # the premise: heights are good
    nfit = r.ndf_fit
    assert nfit.identified is True and nfit.reason == ""
    assert nfit.info["facets"] >= MIN_NDF_FACETS
    assert nfit.info["width_relative_error"] <= MAX_WIDTH_ERROR
    # one sample per facet with a height plane: the facets used are the independent samples
    assert nfit.n_samples == nfit.info["facets"]
    assert nfit.info["samples"].startswith("facet plane tilts")
    assert not any(w.startswith("NDF not identified") for w in r.warnings)
    tfit = r.thickness_fit
    j = r.joint
    cens_frac = np.bincount(j.facets.ravel(), weights=j.censored.ravel(),
                            minlength=j.area_px.size) / j.area_px
    samples = (np.isfinite(j.thickness.thickness_nm) & (cens_frac < 0.5)
               & ~unexplained_facets(j.thickness.delta_e))
    assert tfit.identified and tfit.info["facets"] == int(samples.sum()) == tfit.n_samples
    # n_eff: the area-weighted count of the thickness regions, at most their number
    assert 1.0 <= tfit.n_effective <= tfit.info["thickness_regions"]


def test_joint_ndf_not_identified_without_focus_information(nd):
    s = nd["same"]
    assert not s.focus.reliable.any()                      # the premise: no focus information
    nfit = s.ndf_fit
    assert nfit is not None and nfit.identified is False
    assert "height" in nfit.reason
    assert nfit.info["facets"] == 0
    assert nfit.info["samples"].startswith("per-pixel tilt")
    # colour at ~115 nm cannot stand in (a 10° tilt is mimicked by a thickness change)
    assert "colour cannot carry tilt" in nfit.reason
    assert any(w.startswith("NDF not identified") and "height" in w for w in s.warnings)


def test_joint_ndf_reason_without_focus_names_the_missing_heights(nd):
    s = nd["same"]
    j = s.joint
    dark = float(j.censored.mean())
    assert dark < 0.05                              # the premise: few dark pixels, if any
    # the reason is the missing heights, not censoring of "100 %" of the surface
    reason = s.ndf_fit.reason
    assert f"height from focus gives a plane on 0 of {j.area_px.size} facets" in reason
    assert "tilted past the objective's acceptance" not in reason


def _usable_planes(r):
    """Facets whose plane tilt the NDF may use: fitted, finite, not dark, within the
    acceptance (steeper planes count as censored)."""
    j = r.joint
    cens_frac = np.bincount(j.facets.ravel(), weights=j.censored.ravel(),
                            minlength=j.area_px.size) / j.area_px
    t = j.planes.tilt_deg
    return (j.planes.fitted & np.isfinite(t) & (cens_frac < 0.5)
            & (np.nan_to_num(t, nan=90.0) <= r.max_tilt_deg))


def test_joint_ndf_few_planes_is_not_identified(nd):
    r = nd["result"]
    j = r.joint
    keep = np.flatnonzero(_usable_planes(r))[:MIN_NDF_FACETS - 5]
    fitted = np.zeros_like(j.planes.fitted)
    fitted[keep] = True
    few = dataclasses.replace(j, planes=dataclasses.replace(j.planes, fitted=fitted),
                              censored=np.zeros_like(j.censored))
    _, nfit = fit_joint_distributions(few, roi=r.roi, table=r.table,
                                      max_tilt_deg=r.max_tilt_deg)
    assert nfit.identified is False
    assert f"plane on {keep.size} of {j.area_px.size} facets" in nfit.reason
    assert nfit.n_samples == keep.size


def test_joint_ndf_mostly_censored_is_not_identified(nd):
    r = nd["result"]
    j = r.joint
    # the largest facets, covering more than 60 % of the area, past the acceptance (dark)
    order = np.argsort(j.area_px)[::-1]
    n = int(np.searchsorted(np.cumsum(j.area_px[order]), 0.6 * j.area_px.sum())) + 1
    dark = np.isin(j.facets, order[:n])
    cens = dataclasses.replace(j, censored=dark)
    _, nfit = fit_joint_distributions(cens, roi=r.roi, table=r.table,
                                      max_tilt_deg=r.max_tilt_deg)
    used = _usable_planes(NS(joint=cens, max_tilt_deg=r.max_tilt_deg))
    steep = (j.planes.fitted & ~np.isin(np.arange(j.area_px.size), order[:n])
             & (np.nan_to_num(j.planes.tilt_deg) > r.max_tilt_deg))
    c = dark.sum() + j.area_px[steep].sum()
    frac = c / (c + j.area_px[used].sum())
    assert frac > 0.5
    assert nfit.identified is False
    assert f"{100 * frac:.0f} % of the surface is tilted past" in nfit.reason
    assert nfit.info["censored_fraction"] == pytest.approx(frac, rel=1e-9)
    assert nfit.n_samples == int(used.sum())


def _joint_with_planes(slope_x, slope_y, area):
    planes = NS(fitted=np.isfinite(slope_x), slope_x=np.nan_to_num(slope_x),
                slope_y=np.nan_to_num(slope_y))
    return NS(planes=planes, area_px=np.asarray(area))


def test_mean_plane_tilt_is_the_area_weighted_facet_slope():
    rng = np.random.default_rng(3)
    n = 400
    a = 0.1 + rng.normal(0, 0.05, n)               # a 5.7° mounting tilt along x
    b = rng.normal(0, 0.05, n)
    area = rng.integers(5, 50, n)
    a[:10] = np.nan                                # facets without a plane do not count
    tilt = mean_plane_tilt_deg(_joint_with_planes(a, b, area))
    ok = np.isfinite(a)
    expect = np.degrees(np.arctan(np.hypot(np.average(a[ok], weights=area[ok]),
                                           np.average(b[ok], weights=area[ok]))))
    assert tilt == pytest.approx(expect, rel=1e-12)
    assert mean_plane_tilt_deg(None) is None
    assert mean_plane_tilt_deg(_joint_with_planes(np.full(3, np.nan), np.zeros(3), [1, 1, 1])) \
        is None


@pytest.mark.parametrize("tilt,warned", [(1.9, False), (2.1, True)])
def test_a_sample_tilted_by_half_the_ndf_width_is_reported(tilt, warned):
    ndf = NS(mixture=NS(rms_sd_deg=4.0), identified=True, reason="")
    roi = NS(thickness_nm=np.array([100.0]), ambiguity_delta_e=np.array([9.0]))
    w = analysis_warnings(thickness_fit=None, ndf_fit=ndf, roi=roi, delta_e_median=None,
                          noise_de=1.0, mean_plane_tilt_deg=tilt)
    assert any("mean plane is tilted" in x for x in w) == warned
