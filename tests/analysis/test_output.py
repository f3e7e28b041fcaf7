"""The results folder of an analysis (microfacet.analysis.output, format
``microfacet-results/1``): what ``microfacet analyze`` writes follows the spec
(docs/results-format.md), and ``write_results`` replaces only its own kind of folder."""

import json
from pathlib import Path

import numpy as np
import pytest

from microfacet.analysis import AnalysisOptions, write_results
from microfacet.analysis.stages import Stage
from microfacet.cli import main
from microfacet.core.errors import InputError
from microfacet.io.summary import Summary

FIXTURE = Path(__file__).resolve().parents[2] / "fixtures" / "stacks" / "nd-fixture"
TRUTH = FIXTURE / "truth"


@pytest.fixture(scope="module")
def results(tmp_path_factory):
    out = tmp_path_factory.mktemp("res") / "nd"
    assert main(["analyze", str(FIXTURE), "--out", str(out), "-q"]) == 0
    return out


def test_results_folder_follows_the_spec(results):
    H, W = np.load(TRUTH / "height_um.npy").shape
    for name, shape in [("height_um", (H, W)), ("normals", (H, W, 3)), ("thickness_nm", (H, W)),
                        ("tilt_deg", (H, W)), ("tilt_sigma_deg", (H, W))]:
        a = np.load(results / f"{name}.npy")
        assert a.dtype == np.float32 and a.shape == shape, name
    n = np.load(results / "normals.npy")
    ok = np.isfinite(n).all(-1)
    np.testing.assert_allclose(np.linalg.norm(n[ok], axis=-1), 1, atol=1e-5)
    assert (n[ok][:, 2] > 0).all()
    for f in ("all_in_focus.png", "report.pdf"):
        assert (results / f).stat().st_size > 0
    s = json.loads((results / "summary.json").read_text())
    assert s["format"] == "microfacet-results/1" and s["summary_version"] == 2
    # the typed summary reads it back unchanged, and its parameters are the options tree
    assert Summary.from_json(s).to_json() == s
    assert AnalysisOptions.from_dict(s["parameters"]) == AnalysisOptions()
    assert s["inputs"]["film"] and "film" not in s           # version 2: no repeated keys
    assert set(s["timings_s"]) >= {st.key for st in Stage if st is not Stage.WRITE}
    for comp in s["thickness"]["mixture"]["components"]:
        assert set(comp) >= {"weight", "mean_nm", "sd_nm"}
    means = [c["mean_nm"] for c in s["thickness"]["mixture"]["components"]]
    assert means == sorted(means)
    sds = [c["sd_deg"] for c in s["ndf"]["mixture"]["components"]]
    assert sds == sorted(sds) and all(c["mean_deg"] == 0 for c in s["ndf"]["mixture"]["components"])
    assert s["ndf"]["mixture"]["bic"] is not None and s["thickness"]["mixture"]["bic"] is not None
    assert s["exposure"] > 0 and 0 <= s["masked_fraction"] < 0.5
    assert s["delta_e"]["mean"] > 0 and s["timings_s"]["total"] > 0
    header = (results / "thickness_roi.csv").read_text().splitlines()[0]
    assert header.startswith("row0,col0,size,thickness_nm,mean_delta_e,n_pixels")
    for name, col in (("thickness_pdf.csv", "thickness_nm"), ("ndf_pdf.csv", "tilt_deg")):
        t = np.genfromtxt(results / name, delimiter=",", names=True)
        assert t.dtype.names == (col, "density", "mixture_density")
        x = t[col]
        for c in ("density", "mixture_density"):
            assert np.trapezoid(t[c], x) == pytest.approx(1.0, abs=0.02), (name, c)
    # Masked pixels are NaN in the colour maps and nowhere else.
    mask = np.load(results / "mask.npy")
    assert np.isnan(np.load(results / "thickness_nm.npy")[mask]).all()


def test_write_results_replaces_only_its_own_kind(nd_analysis, tmp_path):
    """An empty folder is used; an earlier results folder needs overwrite; anything else is
    never replaced, with or without overwrite."""
    res = nd_analysis("seed")
    out = tmp_path / "r"
    out.mkdir()
    write_results(res, out)                   # empty: nothing to lose
    assert (out / "summary.json").is_file()
    with pytest.raises(InputError, match="already exists"):
        write_results(res, out)
    (out / "note.txt").write_text("mine")
    write_results(res, out, overwrite=True)   # a results folder: replaced
    assert not (out / "note.txt").exists()
    other = tmp_path / "photos"
    other.mkdir()
    (other / "cat.jpg").write_bytes(b"\xff\xd8")
    for overwrite in (False, True):
        with pytest.raises(InputError, match="never replaced") as err:
            write_results(res, other, overwrite=overwrite)
        assert err.value.param == "out"
    assert (other / "cat.jpg").read_bytes() == b"\xff\xd8"
    assert sorted(p.name for p in tmp_path.iterdir()) == ["photos", "r"]


def test_an_ambiguous_roi_is_reported_with_both_candidates(nd_analysis):
    """Issue 23: an ambiguous interference order is reported with both candidates' ΔE in
    summary.json, never silently picked (the fixture's one ROI, marked ambiguous here)."""
    import dataclasses

    from microfacet.analysis.output import build_summary
    res = nd_analysis("joint")
    n = res.roi.thickness_nm.size
    amb = dataclasses.replace(res, distributions=dataclasses.replace(
        res.distributions, roi_ambiguous=np.ones(n, bool)))
    roi = build_summary(amb).to_json()["thickness"]["roi"]
    assert roi["ambiguous_count"] == n == len(roi["ambiguous"])
    first = roi["ambiguous"][0]
    assert first["thickness_nm"] == pytest.approx(float(res.roi.thickness_nm[0]))
    assert first["runner_up_thickness_nm"] == pytest.approx(
        float(res.roi.runner_up_thickness_nm[0]))
    assert first["runner_up_delta_e"] >= first["delta_e"]
    assert build_summary(res).to_json()["thickness"]["roi"]["ambiguous"] == []
    Summary.from_json(build_summary(amb).to_json())          # the schema reads it back


def test_gains_the_colours_leave_free_reach_the_summary(nd_analysis):
    """The fixture's result with a white-balance estimate whose spread is unbounded and no
    reference: summary.json's thickness.order is not established, with the reason, and the
    warnings name the references; with its own (finite) estimate it is established."""
    import dataclasses

    from microfacet.analysis.output import build_summary
    res = nd_analysis("joint")
    free = dataclasses.replace(res, white_balance=dataclasses.replace(
        res.white_balance, source="none", estimate_sigma=(float("inf"), float("inf"))))
    order = build_summary(free).to_json()["thickness"]["order"]
    assert not order["established"]
    assert any("white balance free" in r for r in order["reasons"])
    assert "white_balance_free" in [w.code for w in free.warnings]
    assert build_summary(res).to_json()["thickness"]["order"]["established"]


def test_the_height_sigma_covers_the_fixtures_true_errors(results):
    """``height_sigma_um.npy`` against the fixture's true height: 2σ covers ≥ 90 % of the
    reliable pixels' errors; it holds the unresolved-relief term of the map's own RMS gradient
    (``height.relief_rms_gradient`` = Sdq of ``height_um.npy`` about its plane, ISO 25178-2)."""
    from microfacet.analysis.iso25178 import areal_parameters
    from microfacet.focus.uncertainty import RELIEF_COEFFICIENT, window_spread_px

    s = json.loads((results / "summary.json").read_text())
    h, sig = np.load(results / "height_um.npy"), np.load(results / "height_sigma_um.npy")
    truth = np.load(TRUTH / "height_um.npy")
    ok = np.isfinite(h)
    assert np.isfinite(sig[ok]).all() and np.isnan(sig[~ok]).all()
    px = s["inputs"]["pixel_size_um"]
    sdq = areal_parameters(h, pixel_size_um=px).Sdq
    assert s["height"]["relief_rms_gradient"] == pytest.approx(sdq, rel=1e-9)
    assert s["height"]["relief_coefficient"] == RELIEF_COEFFICIENT
    floor = RELIEF_COEFFICIENT * sdq * window_spread_px(3) * float(np.mean(px))
    assert sig[ok].min() >= floor * 0.999
    cover = float(np.mean(np.abs(h - truth)[ok] <= 2 * sig[ok]))
    assert cover >= 0.90, cover
