"""Batches (microfacet.workflow.batch, through ``microfacet batch`` and :func:`run_batch`):
parallel local runs, a real Dask LocalCluster, failures and resume. The stacks are the
``batch_drawer`` fixture (tests/conftest.py). Argument errors of the command:
tests/cli/test_batch.py; result names: test_summary.py."""

import csv
import json
import math
import shutil
from pathlib import Path

import pytest

from microfacet.cli import main
from microfacet.io.results import Results
from microfacet.workflow.batch import run_batch

FAST = ["--roi-size-px", "48", "--no-report", "-q"]


def _rows(folder):
    with open(Path(folder) / "batch_summary.csv", newline="") as fh:
        return list(csv.DictReader(fh))


def _no_partial_folders(folder):
    return not [p for p in Path(folder).iterdir() if p.name.startswith(".")]


@pytest.mark.slow
def test_local_batch_records_failure_finishes_the_rest_and_resumes(batch_drawer, tmp_path,
                                                                   capsys):
    out = tmp_path / "res"
    stacks = [str(batch_drawer / n) for n in ("a", "broken", "b")]
    assert main(["batch", *stacks, "--out", str(out), "--jobs", "2", *FAST]) == 1
    rows = _rows(out)
    assert [Path(r["stack"]).name for r in rows] == ["a", "broken", "b"]  # input order
    assert [r["status"] for r in rows] == ["done", "failed", "done"]
    assert "stack.json" in rows[1]["reason"] and "format" in rows[1]["reason"]
    assert rows[1]["reason"] in (out / "batch_errors.log").read_text()
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


@pytest.mark.slow
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


@pytest.mark.slow
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


@pytest.mark.slow
def test_batch_api_and_local_results_match_the_single_stack_command(batch_drawer, tmp_path):
    """The batch row and results folder are those of `microfacet analyze` on the stack."""
    from microfacet.analysis.options import AnalysisOptions, RoiOptions

    single = tmp_path / "single"
    assert main(["analyze", str(batch_drawer / "b"), "--out", str(single), *FAST]) == 0
    res = run_batch([batch_drawer / "b"], tmp_path / "batch", jobs=1, report=False,
                    options=AnalysisOptions(roi=RoiOptions(size_px=48)))
    assert res.n_failed == 0 and res.rows[0]["status"] == "done"
    s1 = json.loads((single / "summary.json").read_text())
    s2 = json.loads((tmp_path / "batch" / "b" / "summary.json").read_text())
    for key in ("thickness", "ndf"):
        c1, c2 = s1[key]["mixture"]["components"], s2[key]["mixture"]["components"]
        assert len(c1) == len(c2)
        for a, b in zip(c1, c2):
            assert a == pytest.approx(b, rel=1e-4)  # threaded float32 sums differ in order


@pytest.mark.slow
def test_unreachable_scheduler_is_an_argument_error(batch_drawer, tmp_path):
    pytest.importorskip("distributed")   # without it the error is "needs dask.distributed"
    with pytest.raises(ValueError, match="scheduler: cannot connect"):
        run_batch([batch_drawer / "a"], tmp_path / "o", scheduler="tcp://127.0.0.1:9",
                  connect_timeout_s=1)
    assert not (tmp_path / "o").exists()


@pytest.mark.slow
def test_scheduler_local_starts_and_closes_a_local_cluster(batch_drawer, tmp_path):
    pytest.importorskip("distributed")
    out = tmp_path / "res"
    assert main(["batch", str(batch_drawer / "a"), "--out", str(out), "--scheduler", "local",
                 "--jobs", "1", *FAST]) == 0
    row = _rows(out)[0]
    assert row["status"] == "done" and Results.complete(row["results"])[0]


@pytest.mark.slow
def test_local_cluster_workers_keep_glibcs_own_trim_threshold(monkeypatch):
    """Dask's nanny starts workers with MALLOC_TRIM_THRESHOLD_=65536 (the analysis ran 2.7×
    slower per stack there) and leaves it in the starting process's environment; the
    LocalCluster of ``--scheduler local`` starts its workers without it, even after such a
    nanny, and leaves Dask's configuration and this process's environment as they were."""
    pytest.importorskip("distributed")
    import os

    import dask

    from microfacet.workflow import executors

    monkeypatch.setenv("MALLOC_TRIM_THRESHOLD_", "65536")      # as an earlier nanny leaves it
    before = dict(dask.config.get("distributed.nanny.pre-spawn-environ"))
    pair = executors.dask_client("local", 10, jobs=1)
    try:
        got = pair[0].run(lambda: os.environ.get("MALLOC_TRIM_THRESHOLD_"))
        profiler = pair[0].run(lambda: dask.config.get("distributed.worker.profile.enabled"))
    finally:
        executors.close_dask(pair)
    assert list(got.values()) == [None]
    assert list(profiler.values()) == [False]      # the quieter worker (WORKER_CONFIG)
    assert dask.config.get("distributed.nanny.pre-spawn-environ") == before
    assert before.get("MALLOC_TRIM_THRESHOLD_") is not None     # Dask's default, restored
    assert os.environ["MALLOC_TRIM_THRESHOLD_"] == "65536"


def test_every_stack_is_validated_before_any_analysis(batch_drawer, tmp_path, monkeypatch,
                                                      caplog):
    from microfacet.workflow import batch as runner

    events = []
    caplog.set_level("WARNING", logger="microfacet.workflow")
    monkeypatch.setattr(caplog.handler, "emit",
                        lambda rec: events.append(("logged", rec.getMessage())))

    def fake_analyse(stack, out, *a, **k):
        events.append(("analysed", stack))
        return {"stack": stack, "results": out, "status": "done", "reason": "", "worker": ""}

    monkeypatch.setattr(runner, "_analyse_one", fake_analyse)
    stacks = [batch_drawer / "a", batch_drawer / "broken", tmp_path / "missing",
              batch_drawer / "b"]
    res = run_batch(stacks, tmp_path / "res", jobs=1, report=False)
    assert [r["status"] for r in res.rows] == ["done", "failed", "failed", "done"]
    assert "format" in res.rows[1]["reason"] and "not found" in res.rows[2]["reason"]
    kinds = [kind for kind, _ in events]
    assert kinds == ["logged", "logged", "analysed", "analysed"]   # both listed up front
    assert all(len(msg.splitlines()) == 1 for kind, msg in events if kind == "logged")
    rows = _rows(tmp_path / "res")
    assert [r["status"] for r in rows] == ["done", "failed", "failed", "done"]
    assert rows[2]["reason"] == res.rows[2]["reason"]


def test_mistyped_scheduler_fails_fast_without_a_client(batch_drawer, tmp_path, capfd,
                                                        monkeypatch):
    import time

    from microfacet.workflow import executors

    def no_client(*a, **k):
        raise AssertionError("a Client was made for a malformed address")

    distributed = pytest.importorskip("distributed")
    monkeypatch.setattr(distributed, "Client", no_client)
    t0 = time.perf_counter()
    rc = main(["batch", str(batch_drawer / "a"), "--out", str(tmp_path / "o"),
               "--scheduler", "locl"])
    assert time.perf_counter() - t0 < 2.0        # generous: it fails before any connection
    err = capfd.readouterr().err
    assert rc == 2 and "Traceback" not in err and len(err.strip().splitlines()) == 1
    assert err.startswith("microfacet batch: error: --scheduler: 'locl' is neither 'local'")
    assert not (tmp_path / "o").exists()
    for good in ("tcp://10.0.0.5:8786", "head:8786", "tls://[::1]:8786", "local"):
        executors.check_scheduler(good)
    for bad in ("tcp://head", "locl", "http://head:8786", "head:99999", ""):
        with pytest.raises(ValueError, match="scheduler"):
            executors.check_scheduler(bad)


@pytest.mark.slow
def test_ctrl_c_during_a_dask_run_says_how_far_it_got_and_exits_130(batch_drawer, tmp_path,
                                                                    capfd, monkeypatch):
    from microfacet.workflow import batch as runner

    closed = []

    def interrupted_after_one(fn, tasks, dask):
        try:
            yield fn(*tasks[0])                  # the first stack really is analysed
            raise KeyboardInterrupt
        finally:
            closed.append(dask)

    monkeypatch.setattr(runner, "dask_client", lambda *a, **k: ("client", None))
    monkeypatch.setattr(runner, "close_dask", lambda dask: closed.append(dask))
    monkeypatch.setattr(runner, "dask_results", interrupted_after_one)
    out = tmp_path / "res"
    stacks = [str(batch_drawer / "a"), str(batch_drawer / "b")]
    rc = main(["batch", *stacks, "--out", str(out), "--scheduler", "tcp://127.0.0.1:8786",
               *FAST[:-1]])
    err = capfd.readouterr().err
    assert rc == 130 and "Traceback" not in err
    assert err.strip().splitlines() == [
        "microfacet batch: interrupted; 1 of 2 stacks done, rerun to resume"]
    assert closed                                # the client was closed
    assert [r["status"] for r in _rows(out)] == ["done"]
    assert _no_partial_folders(out)
    # rerun to resume: the finished stack is skipped
    assert main(["batch", *stacks, "--out", str(out), "--jobs", "1", *FAST]) == 0
    assert [r["status"] for r in _rows(out)] == ["skipped", "done"]
