"""Every study of pipelines/ runs: ``python -m pipelines run NAME --quick --out TMP`` exits 0,
prints a Markdown table and leaves docs/ and fixtures/ untouched (only ``--docs`` writes
docs/; nothing writes fixtures/). The registry lists every study.

Slow (each quick run takes seconds to ~20 s): ``pytest -m slow tests/test_studies.py``.
"""

from __future__ import annotations

import ast
import os
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
STUDIES = ROOT / "pipelines" / "studies"
WATCHED = ("docs", "fixtures")


def _study_names() -> list[str]:
    """The ``name=`` of each ``STUDY = Study(...)`` in pipelines/studies (read, not imported)."""
    names = []
    for path in sorted(STUDIES.glob("[!_]*.py")):
        for node in ast.parse(path.read_text(encoding="utf-8")).body:
            if (isinstance(node, ast.Assign) and [t.id for t in node.targets
                                                  if isinstance(t, ast.Name)] == ["STUDY"]):
                kw = {k.arg: k.value for k in node.value.keywords}
                names.append(ast.literal_eval(kw["name"]))
    return names


def _snapshot() -> dict:
    """Size and modification time of every file under docs/ and fixtures/."""
    out = {}
    for top in WATCHED:
        for dirpath, _, files in os.walk(ROOT / top):
            for f in files:
                st = os.stat(os.path.join(dirpath, f))
                out[os.path.join(dirpath, f)] = (st.st_size, st.st_mtime_ns)
    return out


def _run(*args, timeout=600):
    return subprocess.run([sys.executable, "-m", "pipelines", *args], cwd=ROOT,
                          capture_output=True, text=True, timeout=timeout)


def test_every_study_module_declares_one_study():
    names = _study_names()
    assert len(names) == len(list(STUDIES.glob("[!_]*.py")))
    assert len(set(names)) == len(names)


@pytest.mark.slow
@pytest.mark.subprocess
def test_list_shows_every_study():
    res = _run("list", timeout=120)
    assert res.returncode == 0, res.stderr
    for name in _study_names():
        assert f"`{name}`" in res.stdout


@pytest.mark.slow
@pytest.mark.subprocess
@pytest.mark.parametrize("name", _study_names())
def test_quick_run(name, tmp_path):
    before = _snapshot()
    res = _run("run", name, "--quick", "--out", str(tmp_path / "out"))
    assert res.returncode == 0, res.stderr[-3000:]
    lines = [ln for ln in res.stdout.splitlines() if ln.startswith("|")]
    assert len(lines) >= 3 and lines[1].startswith("|---"), res.stdout[-2000:]
    assert _snapshot() == before, "a quick run changed docs/ or fixtures/"


@pytest.mark.slow
@pytest.mark.subprocess
@pytest.mark.parametrize("args", [
    ["--quick", "--docs"],                       # docs record full runs only
    ["--docs", "--set", "tiles=64"],             # ... with the default options
    ["--out", str(ROOT / "fixtures" / "x")],     # never into an input folder
])
def test_run_refuses_to_write_docs_or_inputs_wrongly(args):
    before = _snapshot()
    res = _run("run", "speed-memory", *args, timeout=120)
    assert res.returncode != 0
    assert _snapshot() == before
    assert not (ROOT / "fixtures" / "x").exists()


def test_sweep_scores_count_the_targets_from_a_runs_files(tmp_path):
    """Three scenes of one run: the NDF identified on two (one 30 % off, one 10 %), the
    count right on one and the distinct count on two, one scene read in a wrong order
    without the flag, two determined white-balance gains, one of them 5 % off, and two
    scenes with more than 5 % of the map read an order off, one with its count right; a run
    without that column scores it "–"."""
    import csv
    import json

    from pipelines.sweep_scores import read_runs, scores

    out, work = tmp_path / "out", tmp_path / "work"
    out.mkdir()
    rows = {"name": ["g000", "g001", "g002"], "mode": ["joint"] * 3,
            "identified": [True, True, False], "textured": [True, True, False],
            "lobe_rms_ratio": [0.7, 1.1, 0.5], "ndf_w1_deg": [2.0, 1.0, 9.0],
            "censored_fraction": [0.1, 0.0, 0.0], "past_limit_fraction": [0.05, 0.0, 0.0],
            "height_coverage": [0.9, 0.95, 1.0], "pops_found": [2, 3, 1],
            "pops_distinct": [2, 2, 1], "pops_true": [2, 2, 2],
            "region_mae_nm": [0.2, 0.4, 9.0], "v_white_balance": [0, 1, 0],
            "order_wrong": [False, False, True], "order_flagged": [False, False, False],
            "wb_true_r": [1.0, 1.1, 1.0], "wb_true_b": [1.0, 0.9, 1.0],
            "order_off_fraction": [0.3, 0.01, 0.08]}

    def write(rows):
        with open(out / "generalization.csv", "w", newline="") as f:
            w = csv.writer(f)
            w.writerow(rows)
            w.writerows(zip(*rows.values()))

    write(rows)
    for name, est, det in (("g000", [1.01, 1.0, 1.0], [True, False]),
                           ("g001", [1.1, 1.0, 0.945], [False, True])):
        (work / "results" / "joint" / name).mkdir(parents=True)
        (work / "results" / "joint" / name / "summary.json").write_text(json.dumps(
            {"white_balance": {"estimate_rgb": est, "determined_rb": det}}))
    s = scores(read_runs(f"{out}:{work}"))
    assert s["… off by more than 25 %"] == "1" and s["… within 15 %"] == "1 of 2"
    assert s["true population count"] == "1"
    assert s["… counting order aliases with their component"] == "2"
    assert s["order said established"] == "3"
    assert s["read in a wrong order (not flagged)"] == "1 (1)"
    assert s["white-balance gains determined (within 2 %)"] == "2 (1)"
    assert s["region MAE, median (nm)"] == "0.400"
    assert s["… white-balance scenes / the others"] == "0.40 / 4.60"
    assert s["map read an order off, median / mean share"] == "0.080 / 0.130"
    assert s["… true count where more than 5 % is"] == "1 of 2"
    write({k: v for k, v in rows.items() if k != "order_off_fraction"})
    s = scores(read_runs(f"{out}:{work}"))
    assert s["map read an order off, median / mean share"] == "–"
    assert s["true population count"] == "1"


def test_sweep_limits_tell_a_lost_population_from_misread_facets(tmp_path):
    """Two scenes' set-aside components: 178.7 nm lies on a true population no kept
    component lies on (lost); 330 nm on none, and 130.5 nm on one a kept component already
    covers (both misread facets, not losses)."""
    from pipelines.sweep_limits import set_aside_line

    rows = []
    for name, pops, kept, gone in (
            ("g000", [(119.0, 0.8), (178.0, 0.2)], [118.9], [(178.7, "colour")]),
            ("g001", [(130.0, 0.9), (250.0, 0.01)], [130.2],
             [(330.0, "colour"), (130.5, "scattered")])):
        meta = {"populations": [{"mean_nm": m, "area_fraction": a} for m, a in pops]}
        summary = {"thickness": {"mixture": {
            "components": [{"mean_nm": m} for m in kept],
            "misread_components": [{"mean_nm": m, "why": w} for m, w in gone]}}}
        rows.append(({}, summary, meta, tmp_path / name / "truth"))
    assert set_aside_line(rows) == ("set aside as misread: 3; on a true population no kept "
                                    "component lies on: 1 (colour 1); others: colour 1, "
                                    "scattered 1")


def test_sweep_limits_count_by_the_share_read_an_order_off():
    """Four scenes: two below 1 % (one count right), one at 20 % read in a wrong order, one
    recorded without the column (left out)."""
    from pipelines.sweep_limits import order_off_line

    rows = [({"order_off_fraction": f, "pops_found": found, "pops_true": "2",
              "order_wrong": wrong},) for f, found, wrong in
            (("0.004", "2", "False"), ("0.01", "3", "False"), ("0.2", "2", "True"),
             ("", "2", "False"))]
    assert order_off_line(rows) == (
        "true count by the share of the map read an order off: <= 1 %: 1 of 2 (0 wrong "
        "order); <= 5 %: 0 of 0 (0 wrong order); <= 15 %: 0 of 0 (0 wrong order); <= 30 %: "
        "1 of 1 (1 wrong order); <= 100 %: 0 of 0 (0 wrong order)")
    assert order_off_line(rows[3:]) == "map read an order off: not recorded"


def test_sweep_limits_count_by_jpeg_quality():
    """Lossless scenes (no quality) first, then the quality bins; each scene in one bin."""
    from pipelines.sweep_limits import jpeg_line

    rows = [({"pops_found": f, "pops_true": "2"}, None, {"params": {"jpeg_quality": q}}, None)
            for f, q in (("2", None), ("3", None), ("2", 72), ("2", 90), ("1", 91))]
    assert jpeg_line(rows) == ("true count by the slices' JPEG quality: lossless 1 of 2; "
                               "1-75: 1 of 1; 76-80: 0 of 0; 81-85: 0 of 0; 86-90: 1 of 1; "
                               "91-100: 0 of 1")


def _scene_at_truth(work, name, region_means):
    """A results folder and its truth: 8 x 8 px facets on 32 x 32 px true regions (16 facets
    each) of the given means, every facet with a thickness and σ 0.2 nm."""
    import json

    import numpy as np

    side = 32 * int(np.sqrt(len(region_means)))
    y, x = np.mgrid[:side, :side]
    labels = (y // 8) * (side // 8) + x // 8
    rid = (y // 32) * (side // 32) + x // 32
    res, truth = work / "results" / "joint" / name, work / "stacks" / name / "truth"
    res.mkdir(parents=True)
    truth.mkdir(parents=True)
    np.save(res / "facets.npy", labels.astype(np.int32))
    np.save(truth / "region_id.npy", rid.astype(np.int32))
    (truth / "params.json").write_text(json.dumps(
        {"regions": [{"mean_thickness_nm": m} for m in region_means]}))
    (res / "summary.json").write_text("{}")
    rows = ["facet,n_pixels,tilt_deg,tilt_sigma_deg,height_plane,thickness_nm,"
            "thickness_sigma_nm"]
    rows += [f"{k},64,5,1,1,{123.0 if k % 7 else 'nan'},0.2" for k in range(labels.max() + 1)]
    (res / "facets.csv").write_text("\n".join(rows) + "\n")
    return res, truth


def test_sweep_limits_count_at_truth_is_the_model_choice_on_true_thicknesses(tmp_path):
    """Facets set to their true region's thickness: sixteen regions of two populations 50 nm
    apart (each spread evenly over 4 nm) give two components, sixteen of one population one,
    whatever the facets' noise draw; the line counts a scene right at truth and, as read, by
    its own count."""
    import numpy as np

    from pipelines.sweep_limits import ceiling_line, count_at_truth

    order = np.random.default_rng(1).permutation(16)
    two = np.r_[np.linspace(98, 102, 8), np.linspace(148, 152, 8)][order]
    one = np.linspace(118, 122, 16)[order]
    at = {}
    for name, means in (("g000", two), ("g001", one)):
        at[name] = _scene_at_truth(tmp_path, name, means)
        assert {count_at_truth(*at[name], 10.0, seed=s) for s in range(5)} == {
            2 if name == "g000" else 1}
    rows = [({"name": n, "seed": "7", "pops_true": t, "pops_found": f},
             {"thickness": {"mixture": {"sd_ceiling_nm": 10.0}}}, None, at[n][1])
            for n, t, f in (("g000", "2", "3"), ("g001", "1", "1"))]
    assert ceiling_line(rows).endswith("ceiling): 2 of 2; as read: 1 of 2")


def test_sweep_limits_summarize_the_dome_transfer():
    """The dome transfer's line: percentiles and the standard error's median over the scenes
    that measured it (a scene with a null transfer, or none recorded, left out), and its
    correlation with the slope transfer."""
    import numpy as np

    from pipelines.sweep_limits import _dome_line

    g = np.linspace(0.5, 0.9, 11)
    sc = [({}, None, {"dome_transfer": v, "dome_transfer_se": 0.05, "transfer": 2 * v})
          for v in g]
    sc += [({}, None, {"dome_transfer": None, "transfer": 0.8}), ({}, None, {})]
    q = np.percentile(g, [10, 50, 90])
    assert _dome_line(sc) == (f"dome transfer (11 textured scenes): 10th / 50th / 90th "
                              f"percentile {q[0]:.2f} / {q[1]:.2f} / {q[2]:.2f}, standard "
                              f"error median 0.05; correlation with the slope transfer 1.00")
    assert _dome_line(sc[:2]).startswith("dome transfer: measured on fewer than 3")


def test_sweep_limits_score_the_white_balance_estimate_against_the_truth():
    """The white-balance lines: the estimate's |log error| against each scene's true gains,
    in its own σ, the share within 2σ over the scenes whose σ is finite (a null σ, one film
    colour, counts in the errors but not in the coverage), and by film colours."""
    import math

    from pipelines.sweep_limits import white_balance_lines

    flags = {"v_jpeg": "0", "v_white_balance": "1"}
    rows = [({"wb_true_r": "1.1", "wb_true_b": "0.9", **flags}, {"white_balance": {
        "estimate_rgb": [1.1 * math.exp(e), 1.0, 0.9 * math.exp(-e)],
        "estimate_sigma_rb": sig, "film_colours": c}}, None, None)
        for e, sig, c in ((0.01, [0.01, 0.01], 2), (0.05, [0.02, 0.1], 3),
                          (0.1, [None, None], 1))]
    first, by, _ = white_balance_lines(rows)
    assert first == ("white-balance estimate, |log error| median R 0.050, B 0.050 (3 scenes); "
                     "in its own σ 1.75 / 0.75; within 2σ (R / B, of the scenes with a finite "
                     "σ) 1 of 2 / 2 of 2; σ median 0.015 / 0.055")
    assert by == "by film colours (R / B): 1: 0.100 / 0.100, 2: 0.010 / 0.010, 3: 0.050 / 0.050"


def test_sweep_limits_tally_the_region_mae_by_kind_and_the_gains_a_rule_would_apply(tmp_path):
    """Three scenes' thickness maps against their truth (two 30 x 30 px regions each): one
    within 0.5 nm, one with a region read an order off, one with both regions 1 nm thin (off
    alike, with a white-balance error); the signed error over the balanced scenes without an
    order-off region. The gains a σ-capped rule would apply: an estimate off 1 by 10 % ± 2 %
    on a white-balance scene (right within 2 %) and on a balanced one (put 10 % off), one at
    ± 4 % (σ too wide) and one within 3 % of 1 (not off 1)."""
    import numpy as np

    from pipelines.sweep_limits import apply_rule_line, region_mae_lines

    rows = []
    for name, errs, wb, est, sig, true_r in (
            ("g000", (0.2, -0.3), "0", (1.10, 1.0, 1.0), (0.02, 0.5), "1"),
            ("g001", (0.1, 110.0), "0", (1.10, 1.0, 1.0), (0.04, 0.5), "1"),
            ("g002", (-1.0, -1.0), "1", (1.10, 1.0, 1.02), (0.02, 0.001), "1.1")):
        truth = tmp_path / "stacks" / name / "truth"
        res = tmp_path / "results" / "joint" / name
        truth.mkdir(parents=True)
        res.mkdir(parents=True)
        rid = np.repeat(np.arange(2), 30)[:, None] * np.ones((1, 30), int)
        means = [100.0, 150.0]
        np.save(truth / "region_id.npy", rid)
        np.save(res / "thickness_nm.npy", np.choose(rid, [m + e for m, e in zip(means, errs)]))
        params = {"regions": [{"mean_thickness_nm": m} for m in means]}
        summary = {"white_balance": {"estimate_rgb": list(est), "estimate_sigma_rb": list(sig)}}
        rows.append(({"name": name, "world": "faceted", "v_white_balance": wb,
                      "wb_true_r": true_r, "wb_true_b": "1"}, summary, params, truth))
    lines = region_mae_lines(rows)
    assert lines[0] == ("region MAE by kind, white-balance scenes: alike 1; the others: met 1, "
                        "order off 1")
    assert lines[1].startswith("signed region error, median over the scenes without a "
                               "white-balance error or a region an order off: -0.050 nm (1)")
    assert apply_rule_line(rows) == ("gains off 1 (> 3σ, > 3 %) with σ < 3 %: 1 on "
                                     "white-balance scenes (1 within 2 %), 1 on balanced ones "
                                     "(1 more than 3 % off)")


def test_facet_gain_scores_planes_on_the_true_facets(tmp_path):
    """pipelines.facet_gain on a generated nd stack (planar facets): planes through the
    evidence heights on the true facets are flattened (0.68 of the true slopes here, their
    errors twice their σ); the unmixed planes keep the slopes (1.02) with errors their σ
    covers."""
    from microfacet.forward.synth import generate_stack, preset
    from pipelines.facet_gain import facet_gains

    stack = tmp_path / "s"
    generate_stack(stack, preset("nd", height_px=128, width_px=128, n_slices=16, seed=5))
    g = facet_gains(stack)
    (plain, zp, n_plain), (unmixed, zu, n_unmixed) = g["plain"], g["unmixed"]
    assert n_plain >= 10 and n_unmixed >= 10
    assert plain < 0.85 and 0.9 < unmixed < 1.1
    assert zu < 1.3 < zp


def test_self_check_oracle_renders_the_truth_as_the_stack_does():
    """pipelines.self_check_oracle on the bundled fixture: the self-check's renderer and
    plane fits applied to the true heights let through about the width the real stack does
    (0.79 against 0.85 here), both well below 1; the reported lobes, scaled to the planes'
    width over the self-check's transfer, meet the truth's RMS slope where the lobes as
    fitted do not."""
    from pipelines.self_check_oracle import scene_ratios

    got = scene_ratios(Path(__file__).parents[1] / "fixtures" / "stacks" / "nd-fixture")
    assert got["scene"] < 0.9 and got["oracle"] < 0.9
    assert abs(got["oracle"] - got["scene"]) < 0.15
    assert abs(got["ndf"] - 1.0) < 0.05 < abs(got["ndf_fitted"] - 1.0)


def test_sweep_limits_width_correction_line(tmp_path):
    """correction_line on two corrected textured scenes whose truth is one 8° lobe: the
    planes' second moment, the lobes as fitted (6°, 0.75 of the truth) and as corrected
    (8°, the truth's) scored against the truth; a constant of 4/3 meets it where 1.1 does
    not; an uncorrected scene is left out."""
    import math

    import numpy as np

    from microfacet.core.distributions import NDFMixture
    from pipelines._scoring import lobe_rms_ratio
    from pipelines.sweep_limits import correction_line

    rng = np.random.default_rng(0)
    s = math.tan(math.radians(8.0))
    tilt = np.degrees(np.arctan(np.hypot(*rng.normal(0, s, (2, 200_000))))).reshape(400, 500)
    truth = tmp_path / "truth"
    truth.mkdir()
    np.save(truth / "tilt_deg.npy", tilt.astype(np.float32))
    lim = 26.57
    seen = tilt[tilt < lim]
    true = math.sqrt(float(np.mean(np.tan(np.radians(seen)) ** 2)))
    rows = []
    for name, corrected in (("g000", True), ("g001", True), ("g002", False)):
        corr = ({"planes_rms_slope": 0.7 * true, "uncorrected": [
            {"weight": 1.0, "mean_deg": 0.0, "sd_deg": math.degrees(math.atan(0.75 * s))}]}
            if corrected else None)
        mix = {"components": [{"weight": 1.0, "mean_deg": 0.0, "sd_deg": 8.0}]}
        if corr:
            mix["width_correction"] = corr
        row = {"name": name, "textured": "True",
               "lobe_rms_ratio": str(lobe_rms_ratio([(1.0, 8.0)], tilt, lim))}
        rows.append((row, {"ndf": {"max_tilt_deg": lim, "mixture": mix}}, {}, truth))
    line = correction_line(rows, constants=(1.1, 4 / 3))
    fitted = lobe_rms_ratio(NDFMixture([(1.0, math.degrees(math.atan(0.75 * s)))]).components,
                            tilt, lim)
    assert line.startswith("width correction (2 textured scenes): planes' second moment "
                           "median 0.70, within 15 % 0%, off > 25 % 100%; lobes as fitted "
                           f"median {fitted:.2f}, within 15 % 0%")
    assert "corrected median 1.00, within 15 % 100%, off > 25 % 0%" in line
    assert "×1.1: median 0.83, within 15 % 0%, off > 25 % 0%" in line
    assert "×1.33333: median 1.00, within 15 % 100%" in line


def _segments_on_disk(tmp_path, name, segments, true_facets):
    """A sweep scene's truth folder with ``true_facets`` and its joint results' ``segments``
    (facets.npy) under ``tmp_path/work``; the truth folder."""
    import numpy as np

    truth = tmp_path / "work" / "stacks" / name / "truth"
    res = tmp_path / "work" / "results" / "joint" / name
    truth.mkdir(parents=True)
    res.mkdir(parents=True)
    np.save(truth / "facet_id.npy", true_facets)
    np.save(res / "facets.npy", segments.astype(np.int32))
    return truth


def test_sweep_limits_measure_the_segments_purity_against_the_true_facets(tmp_path):
    """Two textured faceted scenes whose segments are half (a segment across two true
    facets of equal size) and wholly (the true facets) pure: purities 0.5 and 1, median
    0.75; their lobe ratios follow the purity (correlation 1); a scene of another world is
    left out."""
    import numpy as np

    from pipelines.sweep_limits import purity_line

    true = np.repeat(np.arange(4), 4)[None, :].repeat(3, 0)        # four true facets
    rows = []
    for name, seg, ratio, world in (("g000", true // 2, "0.6", "faceted"),
                                    ("g001", true, "0.95", "faceted"),
                                    ("g002", true // 4, "0.1", "measured")):
        truth = _segments_on_disk(tmp_path, name, seg, true)
        rows.append(({"name": name, "textured": "True", "world": world,
                      "lobe_rms_ratio": ratio}, {}, {}, truth))
    assert purity_line(rows) == ("segment purity (textured faceted, 2 scenes): median 0.75, "
                                 "quartiles 0.62-0.88; correlation with the lobe RMS ratio "
                                 "1.00")


def test_sweep_limits_purity_of_the_identified_and_the_reported_ndfs(tmp_path):
    """The identified scenes' purity by their error (0.5 for the one 40 % off, 1 for the one
    within 15 %; the unidentified one left out), and the reported NDFs' ratio shares and the
    dome share read on the faceted scenes without rounded facets."""
    import numpy as np

    from pipelines.sweep_limits import purity_identified_line, reported_line

    true = np.repeat(np.arange(4), 4)[None, :].repeat(3, 0)
    rows, tex = [], []
    for name, seg, ratio, ident, dome in (("g000", true // 2, "0.6", True, 0.4),
                                          ("g001", true, "0.95", True, 0.1),
                                          ("g002", true // 4, "0.7", False, 0.2)):
        truth = _segments_on_disk(tmp_path, name, seg, true)
        row = {"name": name, "textured": "True", "world": "faceted", "v_rounded": "0",
               "lobe_rms_ratio": ratio, "ndf_w1_deg": ratio}
        summary = {"ndf": {"identified": ident, "mixture": {"dome_share_measured": dome}}}
        rows.append((row, summary, {}, truth))
        tex.append((row, summary))
    assert purity_identified_line(rows) == ("segment purity of the identified NDFs: within "
                                            "15 % 1.00-1.00, more than 25 % off 0.50-0.50")
    assert reported_line(tex) == ("reported NDFs (3 textured scenes): ratio median 0.70, "
                                  "within 15 % on 33%, off by more than 25 % on 67%, W1 "
                                  "median 0.70°; dome share read, faceted without rounding "
                                  "(3): median 0.20, quartiles 0.15-0.30")
    assert reported_line([], "scenes without focus texture") == (
        "reported NDFs (scenes without focus texture): none scored")
