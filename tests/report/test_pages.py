"""The five pages of the report (microfacet.report.page_*): what each prints, from a real
results folder."""

from __future__ import annotations

import json
import re

import numpy as np
import pytest

from microfacet import __version__
from microfacet.forward.angular import DISPLAY_CORE_DEG, display_exposure, simulate_map
from microfacet.io.results import Results, write_results_files
from microfacet.report import parameter_tables
from microfacet.report.context import Context
from microfacet.report.layout import DE, nice_length
from microfacet.report.page_angular import ANGLES_DEG, WAVELENGTH_NM, optics, predicted_maps
from microfacet.report.page_maps import component_codes


def ctx_field_um(res):
    """The map field's width in µm (from the results' map and pixel size)."""
    px = res.get("inputs", "pixel_size_um")
    px = px[1] if isinstance(px, list) else px
    return res.map("thickness_nm").shape[1] * px


def test_header_and_units_are_on_the_pages(results, report, pdf_text):
    out, _ = report
    res = Results(results)
    p1 = pdf_text(out, 1)
    assert "microfacet report — nd-fixture" in p1 and f"microfacet {__version__}" in p1
    assert "height (µm)" in p1 and "numerical aperture" in p1
    # the three maps' scale bars: the 1-2-5 length of a fifth of the field's width
    field_um = ctx_field_um(res)
    assert p1.count(f"{nice_length(0.2 * field_um):g} µm") >= 3
    p2 = pdf_text(out, 2)
    for label in ("thickness (nm)", "tilt from optical axis (°)", "tilt 1σ (°)", "CIEDE2000",
                  "no value", "component (seed Fig. 18c)"):
        assert label in p2, label
    p3 = pdf_text(out, 3)
    wn, sn = res.ndf_mixture().components[0]
    floor = res.get("parameters", "fits", "thickness_sd_floor_nm")
    one = res.get("thickness", "mixture", "sd_one_region") or []
    comps = res.thickness_mixture().components

    def comp_label(i):     # at the SD floor, or on one region: its spread is not measured
        w, m, s = comps[i]
        sd = ("SD not measured (at the floor)" if s <= floor * 1.0001
              else "SD not measured (one region)" if i in one else f"SD {s:.2f} nm")
        return f"weight {w:.2f}, mean {m:.1f} nm, {sd}"

    for label in ("oxide thickness (nm)", "probability density (1/nm)",
                  "probability density (1/°)", "D(θ) (1/sr)", "fitted mixture",
                  "histogram (thickness_pdf.csv)", "histogram (ndf_pdf.csv)",
                  *(comp_label(i) for i in range(len(comps))),
                  f"weight {wn:.2f}, slope SD {sn:.2f}°"):
        assert label in p3, label
    # the fixture's 108.3 nm population is one region of the field
    assert "SD not measured" in p3 and len(one) + sum(c[2] <= floor * 1.0001
                                                      for c in comps) == 1
    check = res.get("ndf", "self_check")
    assert (f"self-check: injected slopes recovered at {check['transfer']:.2f} ± "
            f"{check['transfer_se']:.2f}×") in p3
    assert f"domes {check['dome_transfer']:.2f} ± {check['dome_transfer_se']:.2f}×" in p3
    p5 = pdf_text(out, 5)
    assert "microfacet thin-film BRDF" in p5 and "light zenith" in p5
    assert "half-vector model" in p5


def test_parameter_table_matches_summary(results, report, pdf_text):
    summary = json.loads((results / "summary.json").read_text())
    t = parameter_tables(results)
    comps = summary["thickness"]["mixture"]["components"]
    assert len(comps) >= 2
    unc = summary["thickness"]["mixture"]["mean_uncertainty"]
    assert len(unc) == len(comps) and all(u["sigma_nm"] > 0 for u in unc)
    assert t["thickness"]["rows"] == [
        [str(i + 1), f"{c['weight']:.3f}", f"{c['mean_nm']:.1f}", f"{u['sigma_nm']:.2f}",
         f"{c['sd_nm']:.2f}"] for i, (c, u) in enumerate(zip(comps, unc))]
    lobes = summary["ndf"]["mixture"]["components"]
    assert [r[:3] for r in t["ndf"]["rows"]] == [
        [str(i + 1), f"{c['weight']:.3f}", f"{c['sd_deg']:.2f}"] for i, c in enumerate(lobes)]
    for r, c in zip(t["ndf"]["rows"], lobes):  # tan σ and Beckmann α = √2 tan σ
        assert float(r[3]) == pytest.approx(np.tan(np.radians(c["sd_deg"])), abs=1e-4)
        assert float(r[4]) == pytest.approx(np.sqrt(2) * float(r[3]), abs=2e-4)
    analysis = dict(t["analysis"]["rows"])
    assert analysis["exposure"] == (f"{summary['exposure']:.4g} "
                                    f"({summary['exposure_source']})")
    ff = summary["flat_field"]
    assert analysis["flat field (vignetting)"] == (
        f"{100 * ff['corner_loss']:.0f} % lost at the corners ({ff['source']})"
        if ff["applied"] else f"none: {ff['reason']}")
    order = summary["thickness"]["order"]
    assert analysis["interference order"] == ("established" if order["established"] else
                                              f"not established: {order['reasons'][0]}"
                                              + (f" (+{len(order['reasons']) - 1} more)"
                                                 if len(order["reasons"]) > 1 else ""))
    moves = summary["thickness"]["mixture"].get("order_moves") or []
    assert [v for k, v in t["analysis"]["rows"] if k == "order move"] == [
        f"{m['from_nm']:.1f} → {m['to_nm']:.1f} nm ({100 * m['area_share']:.0f} % of a "
        f"component)" for m in moves]
    de = summary["delta_e"]
    de_row = f"{de['mean']:.2f} / {de['median']:.2f} / {de['p95']:.2f}"
    assert analysis["ΔE₀₀ mean / median / p95"] == de_row
    assert analysis["masked fraction"] == f"{100 * summary['masked_fraction']:.1f} %"
    assert analysis["largest measurable tilt"] == f"{summary['ndf']['max_tilt_deg']:.1f}°"
    timings = dict(t["timings"]["rows"])
    assert timings["total analysis"] == f"{summary['timings_s']['total']:.3g} s"
    assert timings["mixture fits"] == f"{summary['timings_s']['mixtures']:.3g} s"
    bic = summary["thickness"]["mixture"]["bic"]
    assert f"BIC ({bic:.6g}" in t["thickness"]["note"]
    assert f"BIC ({summary['ndf']['mixture']['bic']:.6g}" in t["ndf"]["note"]
    assert "not in the folder" not in dict(t["run"]["rows"])  # the analysis writes them all
    # ... and the PDF's parameter page prints them
    text = pdf_text(report[0], 4)
    for row in t["thickness"]["rows"] + t["ndf"]["rows"]:
        assert re.search(r"\s+".join(map(re.escape, row)), text), row
    assert de_row in text
    iso = dict(t["iso25178"]["rows"])       # height from focus: its reliable pixels
    assert iso["Sq, root mean square height"] == f"{summary['iso25178']['Sq_um']:.4g} µm"
    for row in t["iso25178"]["rows"][:4]:
        assert re.search(r"\s+".join(map(re.escape, " ".join(row).split())), text), row


def test_parameter_page_shows_the_iso25178_parameters_by_their_names(tmp_path):
    """Hand-made summaries: the ISO 25178-2 names with their units and the conventions
    beside them; no rows for a summary without the section (an older writer's)."""
    iso = {"standard": "ISO 25178-2", "reference": "least-squares plane",
           "differences": "forward", "n_points": 65536, "Sq_um": 1.31822, "Sa_um": 1.08070,
           "Sdq": 0.504387, "Sdr_percent": 8.87537, "plane_tilt_deg": 2.80371,
           "rms_height_um": 1.53259, "rms_gradient": 0.503508, "rms_slope_normals": 0.373076}
    for name, summary in (("new", {"iso25178": iso}), ("old", {})):
        (tmp_path / name).mkdir()
        write_results_files(tmp_path / name, summary=summary, maps={})
    assert parameter_tables(tmp_path / "new")["iso25178"]["rows"] == [
        ["Sq, root mean square height", "1.318 µm"],
        ["Sa, arithmetic mean height", "1.081 µm"],
        ["Sdq, root mean square gradient", "0.5044"],
        ["Sdr, developed interfacial area ratio", "8.875 %"],
        ["reference (S-F surface)", "least-squares plane, tilt 2.8°, 65536 pixels"],
        ["as measured: RMS height / gradient", "1.533 µm / 0.5035 (SurfaceTopography)"],
        ["RMS slope of the normals (microfacet)", "0.3731 (central differences)"]]
    assert parameter_tables(tmp_path / "old")["iso25178"]["rows"] == []


def test_missing_files_are_listed_on_the_parameter_page(results_copy):
    folder = results_copy()
    for name in ("mask.npy", "delta_e.npy", "tilt_height_deg.npy"):
        (folder / name).unlink()
    assert dict(parameter_tables(folder)["run"]["rows"])["not in the folder"] == \
        "mask.npy, delta_e.npy, tilt_height_deg.npy"


def test_component_map_has_no_value_exactly_where_thickness_has_none(results):
    res = Results(results)
    th = res.map("thickness_nm")
    codes = component_codes(th, res.thickness_mixture())
    assert np.array_equal(codes < 0, ~np.isfinite(th))
    assert set(np.unique(codes[codes >= 0])) == set(range(len(res.thickness_mixture()
                                                                .components)))


def test_angular_maps_are_shown_at_the_display_exposure_the_page_states(results):
    res = Results(results)
    ctx = Context(res)
    maps = predicted_maps(ctx)
    assert [title.split()[0] for title, _, _ in maps] == ["microfacet", "half-vector"]
    # the same map, simulated here from the folder's fits, and its display exposure
    raw = simulate_map(model="microfacet", thickness=res.thickness_mixture(),
                       ndf=res.ndf_mixture(), theta_light_deg=ANGLES_DEG,
                       theta_view_deg=ANGLES_DEG, wavelength_nm=WAVELENGTH_NM, **optics(ctx))
    e = display_exposure(raw)
    assert abs(e - 1.0) > 0.1  # the rule matters for this map
    _, m, note = maps[0]
    stated = float(re.search(r"π·f_r × ([0-9.e+-]+):", note).group(1))
    assert stated == pytest.approx(e, rel=5e-3)
    assert m.meta["exposure"] == pytest.approx(e, rel=1e-9)
    # what the note states holds for the map drawn
    assert f"angles ≤ {DISPLAY_CORE_DEG:g}° shown at 0.9 of white" in note
    core = ANGLES_DEG <= DISPLAY_CORE_DEG
    assert np.percentile(m.xyz[np.ix_(core, core)][..., 1], 98) == pytest.approx(0.9, rel=1e-6)
    # the half-vector map is shown at exposure 1, as its note says
    _, hv, hv_note = maps[1]
    assert display_exposure(hv) == 1.0 and hv.meta["exposure"] == 1.0
    assert "exposure 1 (a white diffuser is white)" in hv_note


def test_the_pdf_prints_the_angular_notes(results, report, pdf_text):
    p5 = pdf_text(report[0], 5)
    for _, _, note in predicted_maps(Context(Results(results))):
        for line in note.splitlines():
            assert line in p5, line


def test_angular_page_without_fits(tmp_path):
    """Edge cases, hand-made: no NDF fit (the half-vector map alone), no thickness fit
    (nothing to predict)."""
    thick = {"components": [{"weight": 1.0, "mean_nm": 130.0, "sd_nm": 3.0}]}
    none = {"components": [], "bic": None}
    for name, summary, models in (("no-ndf", {"thickness": {"mixture": thick},
                                              "ndf": {"mixture": none}}, ["half-vector"]),
                                  ("no-fit", {"thickness": {"mixture": none}}, [])):
        (tmp_path / name).mkdir()
        write_results_files(tmp_path / name, summary=summary, maps={})
        maps = predicted_maps(Context.open(tmp_path / name))
        assert [t.split()[0] for t, _, _ in maps] == models


def test_reported_candidate_populations_are_drawn_dashed_and_only_they(results_copy):
    """summary.json's thickness.mixture.candidates: the reported ones are dashed lines at
    their means, with one legend entry; the others (mis-read regions, or a field too large
    to matter) are not drawn."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    from microfacet.report.page_distributions import _thickness_panel

    folder = results_copy()
    summary = json.loads((folder / "summary.json").read_text())
    summary["thickness"]["mixture"]["candidates"] = [
        {"mean_nm": 171.5, "reported": True}, {"mean_nm": 95.0, "reported": False}]
    (folder / "summary.json").write_text(json.dumps(summary))
    fig, ax = plt.subplots()
    _thickness_panel(ax, Context(Results(folder)))
    vertical = [ln for ln in ax.get_lines() if ln.get_linestyle() == "--"
                and len(set(np.ravel(ln.get_xdata()))) == 1]
    assert [ln.get_xdata()[0] for ln in vertical] == [171.5]
    labels = ax.get_legend_handles_labels()[1]
    assert labels.count("candidate population (field too small to decide)") == 1
    plt.close(fig)


def test_candidate_populations_are_not_drawn_on_the_tilt_panel(results_copy):
    """A thickness candidate (nm) has no place on the tilt axis (°)."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    from microfacet.report.page_distributions import _tilt_panel

    folder = results_copy()
    summary = json.loads((folder / "summary.json").read_text())
    summary["thickness"]["mixture"]["candidates"] = [{"mean_nm": 17.5, "reported": True}]
    (folder / "summary.json").write_text(json.dumps(summary))
    fig, ax = plt.subplots()
    _tilt_panel(ax, Context(Results(folder)))
    assert "candidate population (field too small to decide)" not in \
        ax.get_legend_handles_labels()[1]
    assert not any(ln.get_xdata()[0] == 17.5 for ln in ax.get_lines()
                   if len(set(np.ravel(ln.get_xdata()))) == 1)
    plt.close(fig)



def test_the_parameter_page_states_the_order_and_each_order_move(results_copy):
    """summary.json's thickness.order (its first reason and how many more), each
    thickness.mixture.order_moves entry, the order cut and each misread_components entry are
    rows of the analysis table."""
    folder = results_copy()
    summary = json.loads((folder / "summary.json").read_text())
    summary["thickness"]["order"] = {"established": False, "reasons": [
        "the facets of a 163.1 nm component were read in the order of the 50.1 nm one",
        "28 % of the facets' area has a runner-up order"]}
    summary["thickness"]["mixture"]["order_moves"] = [
        {"from_nm": 163.1, "to_nm": 50.1, "area_share": 0.92, "mean_gap_de": 0.56,
         "facets": 172}]
    summary["thickness"]["mixture"]["misread_components"] = [
        {"mean_nm": 367.04, "weight": 0.048, "delta_e": 1.33, "delta_e_populations": 0.55,
         "facets": 974}]
    summary["thickness"]["mixture"]["order_cut"] = {"facets": 136, "area_fraction": 0.0895}
    (folder / "summary.json").write_text(json.dumps(summary))
    rows = parameter_tables(folder)["analysis"]["rows"]
    assert dict(rows)["interference order"] == (
        "not established: the facets of a 163.1 nm component were read in the order of the "
        "50.1 nm one (+1 more)")
    assert [v for k, v in rows if k == "order move"] == ["163.1 → 50.1 nm (92 % of a component)"]
    assert [v for k, v in rows if k == "set aside (misread)"] == [
        f"367.0 nm (5 %; {DE} 1.3 vs 0.6)"]
    assert dict(rows)["order cut"] == "136 facets to their runner-up order (8.9 % of the area)"
