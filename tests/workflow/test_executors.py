"""microfacet.workflow.executors: the cluster recipe of docs/cluster.md, run without a batch
system. dask-jobqueue writes the job script a SLURM node would run; here bash runs it, its
workers join the cluster's scheduler and a batch runs on them."""

from __future__ import annotations

import os
import signal
import subprocess

import pytest

from microfacet.io.results import Results
from microfacet.workflow.batch import run_batch
from microfacet.workflow.executors import WORKER_CONFIG, WORKER_ENVIRONMENT, job_script_prologue


def test_prologue_exports_the_worker_environment():
    """The lines, run by a shell, leave exactly :data:`WORKER_ENVIRONMENT` in its
    environment (quotes and all)."""
    script = "\n".join(job_script_prologue() + ["env -0"])
    run = subprocess.run(["bash", "-c", script], capture_output=True, check=True,
                         env={"PATH": os.environ.get("PATH", "/usr/bin:/bin")})
    env = dict(v.split("=", 1) for v in run.stdout.decode().split("\0") if "=" in v)
    assert {k: env.get(k) for k in WORKER_ENVIRONMENT} == WORKER_ENVIRONMENT


def test_the_environment_is_the_local_clusters_worker_config(monkeypatch):
    """The variables are what Dask reads into the keys a LocalCluster's workers are given."""
    dask = pytest.importorskip("dask")
    for k, v in WORKER_ENVIRONMENT.items():
        monkeypatch.setenv(k, v)
    env = dask.config.collect_env()
    assert len(WORKER_ENVIRONMENT) == len(WORKER_CONFIG)
    for key, value in WORKER_CONFIG.items():
        assert dask.config.get(key, config=env) == value, key


@pytest.mark.slow
def test_the_slurm_recipe_runs_a_batch_on_workers_its_job_script_starts(batch_drawer,
                                                                        tmp_path):
    jobqueue = pytest.importorskip("dask_jobqueue")
    distributed = pytest.importorskip("distributed")
    cluster = jobqueue.SLURMCluster(
        cores=2, processes=2, memory="4GB", walltime="00:10:00",
        job_script_prologue=job_script_prologue(),
        scheduler_options={"host": "127.0.0.1", "dashboard_address": ":0"})
    script = tmp_path / "job.sh"
    script.write_text(cluster.job_script())
    text = script.read_text()
    assert "--nthreads 1" in text and "--nworkers 2" in text and job_script_prologue()[0] in text
    env = {k: v for k, v in os.environ.items() if k != "MALLOC_TRIM_THRESHOLD_"}
    job = subprocess.Popen(["bash", str(script)], env=env, start_new_session=True,
                           stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    client = distributed.Client(cluster.scheduler_address, set_as_default=False)
    try:
        client.wait_for_workers(2, timeout=120)
        workers = client.run(lambda: os.environ.get("MALLOC_TRIM_THRESHOLD_", "unset"))
        assert list(workers.values()) == ["unset", "unset"]
        for key, value in WORKER_CONFIG.items():
            if "pre-spawn" not in key:     # the nanny's, seen above in the environment
                got = client.run(lambda key=key: __import__("dask").config.get(key))
                assert list(got.values()) == [value, value], key
        info = client.scheduler_info()["workers"]
        assert sorted(w["nthreads"] for w in info.values()) == [1, 1]
        out = tmp_path / "res"
        res = run_batch([batch_drawer / "a", batch_drawer / "b"], out, report=False,
                        scheduler=cluster.scheduler_address)
        assert [r["status"] for r in res.rows] == ["done", "done"]
        for r in res.rows:
            assert Results.complete(r["results"])[0]
    finally:
        client.close()
        os.killpg(job.pid, signal.SIGTERM)
        try:
            job.wait(timeout=30)
        except subprocess.TimeoutExpired:
            os.killpg(job.pid, signal.SIGKILL)
            job.wait()
        cluster.close()
