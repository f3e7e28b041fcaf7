"""Batches (microfacet.batch.runner, through ``microfacet batch`` and :func:`run_batch`):
parallel local runs, a real Dask LocalCluster, failures and resume. The stacks are the
``batch_drawer`` fixture (tests/conftest.py). Argument errors of the command:
tests/cli/test_batch.py; result names: test_summary.py."""

import csv
import json
import math
import shutil
from pathlib import Path

import pytest

from microfacet.batch.runner import run_batch
from microfacet.cli import main
from microfacet.io.results import Results

FAST = ["--roi-size-px", "48", "--no-report", "-q"]


def _rows(folder):
    with open(Path(folder) / "batch_summary.csv", newline="") as fh:
        return list(csv.DictReader(fh))


def _no_partial_folders(folder):
    return not [p for p in Path(folder).iterdir() if p.name.startswith(".")]


def test_local_batch_records_failure_finishes_the_rest_and_resumes(batch_drawer, tmp_path,
                                                                   capsys):
    out = tmp_path / "res"
    stacks = [str(batch_drawer / n) for n in ("a", "broken", "b")]
    assert main(["batch", *stacks, "--out", str(out), "--jobs", "2", *FAST]) == 1
    rows = _rows(out)
    assert [Path(r["stack"]).name for r in rows] == ["a", "broken", "b"]  # input order
    assert [r["status"] for r in rows] == ["done", "failed", "done"]
    assert "stack.json" in rows[1]["reason"] and "format" in rows[1]["reason"]
    assert "Traceback" in (out / "batch_errors.log").read_text()
    assert not (out / "broken").exists() and _no_partial_folders(out)

    # the summary's numbers are those of each results folder
    for r in (rows[0], rows[2]):
        s = json.loads((Path(r["results"]) / "summary.json").read_text())
        assert s["inputs"]["stack"] == r["stack"]
        assert float(r["masked_fraction"]) == pytest.approx(s["masked_fraction"], rel=1e-5)
        assert float(r["delta_e_mean"]) == pytest.approx(s["delta_e"]["mean"], rel=1e-5)
        comps = s["thickness"]["mixture"]["components"]
        assert int(r["thickness_components"]) == len(comps) >= 1
        w = sum(c["weight"] for c in comps)
        mean = sum(c["weight"] * c["mean_nm"] for c in comps) / w
        assert float(r["thickness_mean_nm"]) == pytest.approx(mean, rel=1e-5)
        assert float(r["thickness_1_mean_nm"]) == pytest.approx(comps[0]["mean_nm"], rel=1e-5)
        lobes = s["ndf"]["mixture"]["components"]
        rms = math.sqrt(sum(c["weight"] * c["sd_deg"] ** 2 for c in lobes)
                        / sum(c["weight"] for c in lobes))
        assert float(r["ndf_rms_slope_deg"]) == pytest.approx(rms, rel=1e-5)
        assert float(r["time_s"]) > 0

    # rerun: complete results are skipped (not rewritten), the failed stack is retried
    stamp = (out / "a" / "summary.json").stat().st_mtime_ns
    (batch_drawer / "broken" / "stack.json").write_text('{"format": "nope"}')
    try:
        assert main(["batch", *stacks, "--out", str(out), "--jobs", "2", *FAST]) == 1
        rows2 = _rows(out)
        assert [r["status"] for r in rows2] == ["skipped", "failed", "skipped"]
        assert "nope" in rows2[1]["reason"]
        assert rows2[0]["delta_e_mean"] == rows[0]["delta_e_mean"]
        assert (out / "a" / "summary.json").stat().st_mtime_ns == stamp
    finally:
        (batch_drawer / "broken" / "stack.json").write_text("{}")


def test_results_made_with_other_parameters_are_not_mixed_in(batch_drawer, tmp_path):
    out = tmp_path / "res"
    a = str(batch_drawer / "a")
    assert main(["batch", a, "--out", str(out), "--jobs", "1", *FAST]) == 0
    assert _rows(out)[0]["status"] == "done"
    # other options: refused (with the differing key named) until --overwrite
    assert main(["batch", a, "--out", str(out), "--jobs", "1", "--mode", "seed", *FAST]) == 1
    row = _rows(out)[0]
    assert row["status"] == "failed" and "mode" in row["reason"] and "overwrite" in row["reason"]
    assert json.loads((out / "a" / "summary.json").read_text())["mode"] == "joint"
    assert main(["batch", a, "--out", str(out), "--jobs", "1", "--mode", "seed", "--overwrite",
                 *FAST]) == 0
    assert json.loads((out / "a" / "summary.json").read_text())["mode"] == "seed"
    # an incomplete folder (no summary.json) is reported, not overwritten silently
    shutil.rmtree(out / "a")
    (out / "a").mkdir()
    ok, why = Results.complete(out / "a")
    assert not ok and "summary.json" in why


def test_batch_through_a_dask_local_cluster(batch_drawer, tmp_path):
    distributed = pytest.importorskip("distributed")
    out = tmp_path / "res"
    stacks = [str(batch_drawer / n) for n in ("a", "b", "broken")]
    with distributed.LocalCluster(n_workers=2, threads_per_worker=1, processes=True,
                                  host="127.0.0.1", dashboard_address=":0") as cluster:
        rc = main(["batch", *stacks, "--out", str(out), "--scheduler",
                   cluster.scheduler_address, *FAST])
        assert rc == 1
        rows = _rows(out)
        assert [r["status"] for r in rows] == ["done", "done", "failed"]
        for r in rows[:2]:
            assert Results.complete(r["results"])[0]
        # a rerun on the cluster skips the complete stacks
        assert main(["batch", *stacks[:2], "--out", str(out), "--scheduler",
                     cluster.scheduler_address, *FAST]) == 0
        assert [r["status"] for r in _rows(out)] == ["skipped", "skipped"]


def test_batch_api_and_local_results_match_the_single_stack_command(batch_drawer, tmp_path):
    """The batch row and results folder are those of `microfacet analyze` on the stack."""
    from microfacet.analysis.pipeline import AnalysisOptions

    single = tmp_path / "single"
    assert main(["analyze", str(batch_drawer / "b"), "--out", str(single), *FAST]) == 0
    res = run_batch([batch_drawer / "b"], tmp_path / "batch", jobs=1, report=False,
                    options=AnalysisOptions(roi_size_px=48))
    assert res.n_failed == 0 and res.rows[0]["status"] == "done"
    s1 = json.loads((single / "summary.json").read_text())
    s2 = json.loads((tmp_path / "batch" / "b" / "summary.json").read_text())
    for key in ("thickness", "ndf"):
        c1, c2 = s1[key]["mixture"]["components"], s2[key]["mixture"]["components"]
        assert len(c1) == len(c2)
        for a, b in zip(c1, c2):
            assert a == pytest.approx(b, rel=1e-4)  # threaded float32 sums differ in order


def test_unreachable_scheduler_is_an_argument_error(batch_drawer, tmp_path):
    pytest.importorskip("distributed")   # without it the error is "needs dask.distributed"
    with pytest.raises(ValueError, match="scheduler: cannot connect"):
        run_batch([batch_drawer / "a"], tmp_path / "o", scheduler="tcp://127.0.0.1:9",
                  connect_timeout_s=1)
    assert not (tmp_path / "o").exists()


def test_scheduler_local_starts_and_closes_a_local_cluster(batch_drawer, tmp_path):
    pytest.importorskip("distributed")
    out = tmp_path / "res"
    assert main(["batch", str(batch_drawer / "a"), "--out", str(out), "--scheduler", "local",
                 "--jobs", "1", *FAST]) == 0
    row = _rows(out)[0]
    assert row["status"] == "done" and Results.complete(row["results"])[0]
