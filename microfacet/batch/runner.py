"""Many stacks at once: local worker processes or an existing Dask cluster.

:func:`run_batch` analyses every stack with :func:`microfacet.analysis.pipeline.analyze_stack` and writes
each results folder (``docs/results-format.md``) under one output folder, named after the
stack folder. It is made for drawers full of stacks:

* **Parallel.** Locally, ``jobs`` worker processes (joblib's loky backend, numerical libraries
  limited to one thread each so the workers do not fight over cores). With ``scheduler``
  (a Dask distributed address such as ``tcp://10.0.0.5:8786``) the stacks are tasks on that
  cluster, so thousands of stacks scale out without new code. Workers read the stacks and
  write the results themselves: the stack paths and the output folder must be visible to the
  workers under the same paths (a shared file system); they are sent as absolute paths.
* **A failing stack does not stop the others.** Its row in ``batch_summary.csv`` has
  ``status = failed`` and a one-line ``reason``; the full traceback goes to
  ``batch_errors.log``. Results folders are written atomically, so a failed or killed analysis
  leaves nothing behind.
* **Resumable.** A stack whose results folder is complete (``summary.json`` written, with the
  same analysis parameters) is skipped (``status = skipped``) and its numbers are copied into
  the summary; ``overwrite=True`` re-analyses everything. A folder made with *different*
  parameters is never silently mixed in: it is a failure that names the difference, until
  the user passes ``overwrite``.
* ``batch_summary.csv`` has one row per stack, in input order, with the main numbers (see
  :data:`SUMMARY_COLUMNS`); it is rewritten (atomically) after every finished stack, so it is
  useful while a long batch runs and after it was interrupted.

Examples
--------
>>> from microfacet.batch.runner import run_batch
>>> result = run_batch(["drawer/a", "drawer/b"], "results", jobs=2)  # doctest: +SKIP
>>> [row["status"] for row in result.rows]  # doctest: +SKIP
['done', 'done']
"""

from __future__ import annotations

import csv
import dataclasses
import io
import json
import logging
import os
import socket
import tempfile
import time
import traceback
from dataclasses import dataclass, field
from pathlib import Path

from ..io.outdir import OutputFolder, check_output, current_umask, sweep_stale

__all__ = ["BatchResult", "SUMMARY_COLUMNS", "result_names", "run_batch", "results_complete"]

log = logging.getLogger(__name__)

SUMMARY_FILE = "batch_summary.csv"
ERRORS_FILE = "batch_errors.log"

#: Fixed columns of ``batch_summary.csv``; the mixture components follow as
#: ``thickness_{k}_weight, thickness_{k}_mean_nm, thickness_{k}_sd_nm`` and
#: ``ndf_{k}_weight, ndf_{k}_sd_deg`` for k = 1 … the most components of any stack.
SUMMARY_COLUMNS = (
    "stack", "results", "status", "reason", "time_s", "worker",
    "height_px", "width_px", "n_slices", "masked_fraction", "exposure",
    "delta_e_mean", "delta_e_median", "thickness_mean_nm", "thickness_sd_nm",
    "thickness_components", "ndf_rms_slope_deg", "ndf_components", "tilt_sigma_deg_median",
)


@dataclass
class BatchResult:
    """What :func:`run_batch` did.

    Attributes
    ----------
    rows : list of dict
        One per stack, in input order, with the keys of :data:`SUMMARY_COLUMNS` (and the
        component columns).
    summary_csv : pathlib.Path
    elapsed_s : float
    """

    rows: list = field(default_factory=list)
    summary_csv: Path | None = None
    elapsed_s: float = 0.0

    def count(self, status: str) -> int:
        return sum(1 for r in self.rows if r["status"] == status)

    @property
    def n_failed(self) -> int:
        return self.count("failed")


def result_names(stacks) -> list[str]:
    """Results-folder names for the stack paths: the folder name, made unique by prefixing
    parent folder names (joined by ``_``) where two stacks share a name.

    >>> result_names(["a/s1", "b/s1", "b/s2"])
    ['a_s1', 'b_s1', 's2']
    """
    parts = [Path(os.path.abspath(s)).parts for s in stacks]
    depth = [1] * len(parts)
    while True:
        names = ["_".join(p[-d:]) if len(p) > 1 else "stack" for p, d in zip(parts, depth)]
        seen: dict[str, list[int]] = {}
        for i, n in enumerate(names):
            seen.setdefault(n, []).append(i)
        clash = [i for idx in seen.values() if len(idx) > 1 for i in idx]
        grow = [i for i in clash if depth[i] < len(parts[i]) - 1]
        if not grow:
            if clash:  # the same stack given twice
                dup = sorted({str(stacks[i]) for i in clash})
                raise ValueError(f"STACK: given more than once: {', '.join(dup)}")
            return names
        for i in grow:
            depth[i] += 1


def _json_parameters(options) -> dict:
    from ..analysis.pipeline import _clean

    return json.loads(json.dumps(_clean(dataclasses.asdict(options))))


def results_complete(folder, options=None) -> tuple[bool, str]:
    """Whether ``folder`` holds complete results (made with ``options``, if given).

    Returns
    -------
    complete : bool
    reason : str
        Why not ("" when complete, or when the folder does not exist).
    """
    folder = Path(folder)
    summary = folder / "summary.json"
    if not folder.exists():
        return False, ""
    try:
        data = json.loads(summary.read_text())
    except FileNotFoundError:
        return False, f"{folder}: exists but has no summary.json (incomplete results)"
    except (OSError, ValueError) as exc:
        return False, f"{summary}: unreadable ({exc})"
    if data.get("format") != "microfacet-results/1":
        return False, f"{summary}: key 'format' is not microfacet-results/1"
    if options is not None:
        want = _json_parameters(options)
        have = data.get("parameters", {})
        diff = sorted(k for k in want if have.get(k) != want[k])
        if diff:
            return False, (f"{summary}: made with different parameters ({', '.join(diff)}); "
                           f"re-analysed only with overwrite")
    return True, ""


def _row_from_summary(summary: dict) -> dict:
    """The numbers of one results folder's summary.json for batch_summary.csv."""
    from ..core.distributions import NDFMixture, ThicknessMixture

    row = {}
    shape = summary.get("inputs", {}).get("shape") or [None, None]
    row["height_px"], row["width_px"] = shape[0], shape[1]
    row["n_slices"] = summary.get("inputs", {}).get("n_slices")
    row["masked_fraction"] = summary.get("masked_fraction")
    row["exposure"] = summary.get("exposure")
    de = summary.get("delta_e") or {}
    row["delta_e_mean"] = de.get("mean")
    row["delta_e_median"] = de.get("median")
    thick = (summary.get("thickness", {}).get("mixture") or {})
    comps = thick.get("components") or []
    row["thickness_components"] = len(comps)
    if comps:
        mix = ThicknessMixture.from_json(thick)
        row["thickness_mean_nm"], row["thickness_sd_nm"] = mix.mean_nm, mix.sd_nm
    for k, c in enumerate(comps, 1):
        row[f"thickness_{k}_weight"] = c["weight"]
        row[f"thickness_{k}_mean_nm"] = c["mean_nm"]
        row[f"thickness_{k}_sd_nm"] = c["sd_nm"]
    ndf = (summary.get("ndf", {}).get("mixture") or {})
    lobes = ndf.get("components") or []
    row["ndf_components"] = len(lobes)
    if lobes:
        row["ndf_rms_slope_deg"] = NDFMixture.from_json(ndf).rms_sd_deg
    for k, c in enumerate(lobes, 1):
        row[f"ndf_{k}_weight"] = c["weight"]
        row[f"ndf_{k}_sd_deg"] = c["sd_deg"]
    row["tilt_sigma_deg_median"] = (summary.get("tilt_information") or {}).get(
        "tilt_sigma_deg_median")
    return row


def _analyse_one(stack: str, out: str, options, overwrite: bool, report: bool,
                 threads: int | None = None) -> dict:
    """One stack, in a worker: analyse and write; never raises (failures are returned).

    ``threads`` (in a worker process only) limits microfacet's own thread pool, as the
    worker already shares the machine with the others.
    """
    from ..analysis.pipeline import analyze_stack, write_results

    if threads is not None:
        os.environ["MICROFACET_NUM_THREADS"] = str(threads)

    t0 = time.perf_counter()
    row = {"stack": stack, "results": out, "worker": socket.gethostname()}
    try:
        if not Path(stack).exists():
            raise FileNotFoundError(f"{stack}: no such stack folder on worker "
                                    f"{socket.gethostname()} (a shared file system is needed)")
        result = analyze_stack(stack, options)
        write_results(result, out, overwrite=overwrite, report=report)
        row.update(status="done", reason="")
        row.update(_row_from_summary(json.loads((Path(out) / "summary.json").read_text())))
    except Exception as exc:  # recorded, the batch goes on
        reason = " ".join(str(exc).split()) or type(exc).__name__
        if not isinstance(exc, (ValueError, OSError)):  # not a user error: say what it was
            reason = f"{type(exc).__name__}: {reason}"
        row.update(status="failed", reason=reason, traceback=traceback.format_exc())
    row["time_s"] = round(time.perf_counter() - t0, 2)
    return row


def _write_summary(path: Path, rows: list[dict]) -> None:
    """``batch_summary.csv``, atomically (a temporary sibling renamed over it)."""
    extra = []
    for prefix, fields in (("thickness", ("weight", "mean_nm", "sd_nm")),
                           ("ndf", ("weight", "sd_deg"))):
        k_max = max((int(r.get(f"{prefix}_components") or 0) for r in rows), default=0)
        extra += [f"{prefix}_{k}_{f}" for k in range(1, k_max + 1) for f in fields]
    columns = list(SUMMARY_COLUMNS) + extra
    buf = io.StringIO()
    writer = csv.DictWriter(buf, fieldnames=columns, extrasaction="ignore", lineterminator="\n")
    writer.writeheader()
    for r in rows:
        writer.writerow({c: _csv_value(r.get(c)) for c in columns})
    fd, tmp = tempfile.mkstemp(prefix=f".{path.name}.", dir=path.parent)
    with os.fdopen(fd, "w", newline="") as fh:
        fh.write(buf.getvalue())
    os.chmod(tmp, 0o666 & ~current_umask())
    os.replace(tmp, path)


def _csv_value(v):
    if v is None:
        return ""
    if isinstance(v, float):
        return f"{v:.6g}"
    return v


def _local_results(tasks, jobs):
    """Yield rows as stacks finish, in ``jobs`` loky worker processes (or in-process for 1)."""
    if jobs == 1:
        for t in tasks:
            yield _analyse_one(*t)
        return
    from joblib import Parallel, delayed

    # one thread per worker for BLAS/OpenMP (joblib) and for microfacet's own pool
    parallel = Parallel(n_jobs=jobs, backend="loky", return_as="generator_unordered",
                        inner_max_num_threads=1)
    yield from parallel(delayed(_analyse_one)(*t, threads=1) for t in tasks)


def _dask_client(scheduler, timeout_s, jobs=None):
    """``(client, cluster)``: a Client of the scheduler at ``scheduler``, or of a new
    LocalCluster for ``"local"`` (``cluster`` is None for an existing scheduler)."""
    try:
        from distributed import Client, LocalCluster
    except ImportError:
        raise ValueError("scheduler: needs dask.distributed (pip install 'dask[distributed]' "
                         "or microfacet[cluster])") from None
    if not log.isEnabledFor(logging.DEBUG):  # Dask's INFO chatter only with -vv
        logging.getLogger("distributed").setLevel(logging.WARNING)
    if scheduler == "local":
        # workers are processes with one thread each; the cluster closes with the client
        cluster = LocalCluster(n_workers=jobs or os.cpu_count() or 1, threads_per_worker=1,
                               processes=True, host="127.0.0.1", dashboard_address=":0")
        log.info("Dask LocalCluster at %s, dashboard %s", cluster.scheduler_address,
                 cluster.dashboard_link)
        return Client(cluster, set_as_default=False), cluster
    try:
        return Client(scheduler, timeout=timeout_s, set_as_default=False), None
    except (OSError, TimeoutError, ValueError) as exc:
        raise ValueError(f"scheduler: cannot connect to {scheduler} "
                         f"({' '.join(str(exc).split())})") from None


def _close(dask):
    client, cluster = dask
    client.close()
    if cluster is not None:
        cluster.close()


def _dask_results(tasks, dask):
    """Yield rows as stacks finish on the Dask cluster; closes the client (and cluster)."""
    from distributed import as_completed

    client = dask[0]
    try:
        futures = {client.submit(_analyse_one, *t, threads=1, pure=False,
                                 key=f"microfacet-{i}-{os.getpid()}-{time.time_ns()}"): t
                   for i, t in enumerate(tasks)}
        with client.as_current():
            finished = as_completed(list(futures))
        for fut in finished:
            stack, out = futures[fut][:2]
            try:
                yield fut.result()
            except Exception as exc:  # worker died (KilledWorker), cancelled, ...
                yield {"stack": stack, "results": out, "status": "failed",
                       "reason": f"{type(exc).__name__}: {' '.join(str(exc).split())}",
                       "traceback": traceback.format_exc(), "time_s": None, "worker": ""}
    finally:
        _close(dask)


def run_batch(stacks, out_dir, *, options=None, jobs=None, scheduler=None, overwrite=False,
              report=True, progress=None, connect_timeout_s=10.0) -> BatchResult:
    """Analyse many stacks; write ``out_dir/<name>/`` per stack and ``batch_summary.csv``.

    Parameters
    ----------
    stacks : sequence of path-like
        Stack folders.
    out_dir : path-like
        Output folder (created); results go to ``out_dir/<name>`` with the names of
        :func:`result_names`.
    options : microfacet.analysis.pipeline.AnalysisOptions, optional
        The same for every stack.
    jobs : int, optional
        Local worker processes (default: the CPU count, at most the number of stacks);
        1 runs in this process. With ``scheduler="local"``: the cluster's workers.
    scheduler : str, optional
        Address of a Dask distributed scheduler; the stacks run as tasks there.
        ``"local"`` starts a Dask ``LocalCluster`` on this machine (loopback only) for the
        batch and closes it afterwards.
    overwrite : bool
        Re-analyse stacks whose results exist.
    report : bool
        Write each ``report.pdf``.
    progress : callable, optional
        ``progress(done, total, row)`` after each stack.
    connect_timeout_s : float
        How long to try to reach ``scheduler``.

    Returns
    -------
    BatchResult

    Raises
    ------
    ValueError
        Bad arguments (no stacks, the same stack twice, ``jobs`` < 1, unreachable scheduler).
    """
    from ..analysis.pipeline import AnalysisOptions
    from ..core.errors import InputError

    t0 = time.perf_counter()
    options = AnalysisOptions() if options is None else options
    options.validate()
    stacks = [os.path.abspath(s) for s in stacks]
    if not stacks:
        raise ValueError("STACK: no stacks given")
    if jobs is not None and jobs < 1:
        raise ValueError(f"jobs: must be >= 1, got {jobs}")
    out_dir = Path(os.path.abspath(out_dir))
    # the batch folder is reused, never replaced: an existing batch output is fine
    check_output(out_dir, kind="batch", inputs=stacks, overwrite=True)
    names = result_names(stacks)
    dask = (_dask_client(scheduler, connect_timeout_s, jobs) if scheduler  # before writing
            else None)
    try:
        claim = OutputFolder(out_dir, kind="batch", inputs=stacks, overwrite=True)
        with claim:
            return _run_claimed(stacks, names, out_dir, options, dask, jobs, overwrite, report,
                                progress, t0)
    except BaseException:
        if dask is not None:
            _close(dask)
        raise


def _run_claimed(stacks, names, out_dir, options, dask, jobs, overwrite, report, progress, t0):
    """:func:`run_batch` once the output folder is claimed (no other run writes it)."""
    from ..core.errors import InputError

    out_dir.mkdir(exist_ok=True)
    for p in sweep_stale(out_dir):
        log.info("removed %s, left by an interrupted run", p)

    rows: list[dict | None] = [None] * len(stacks)
    tasks, index = [], {}
    for i, (stack, name) in enumerate(zip(stacks, names)):
        out = str(out_dir / name)
        complete, why = results_complete(out, options)
        refused = ""
        try:  # an existing folder that is not a results folder is never replaced
            check_output(out, kind="results", inputs=[stack], overwrite=True)
        except InputError as exc:
            refused = exc.reason
        if complete and not overwrite:
            summary = json.loads((Path(out) / "summary.json").read_text())
            rows[i] = {"stack": stack, "results": out, "status": "skipped",
                       "reason": "complete results exist", "worker": "",
                       "time_s": (summary.get("timings_s") or {}).get("total"),
                       **_row_from_summary(summary)}
        elif refused or (why and Path(out).exists() and not overwrite):
            rows[i] = {"stack": stack, "results": out, "status": "failed",
                       "reason": refused or why}
            log.warning("%s: failed: %s", stack, refused or why)
        else:
            index[stack] = i
            tasks.append((stack, out, options, overwrite, report))

    summary_csv = out_dir / SUMMARY_FILE
    errors_log = out_dir / ERRORS_FILE  # this run's failures only
    errors_log.unlink(missing_ok=True)
    done = len(stacks) - len(tasks)
    log.info("batch: %d stacks, %d to analyse, %d already complete or refused",
             len(stacks), len(tasks), done)
    if progress is not None:
        progress(done, len(stacks), None)

    def finish(row):
        nonlocal done
        tb = row.pop("traceback", None)
        rows[index[row["stack"]]] = row
        done += 1
        if row["status"] == "failed":
            log.warning("%s: failed: %s", row["stack"], row["reason"])
            with open(errors_log, "a") as fh:
                fh.write(f"== {time.strftime('%Y-%m-%d %H:%M:%S')} {row['stack']}\n"
                         f"{tb or row['reason']}\n")
        else:
            log.info("%s: done in %.1f s", row["stack"], row.get("time_s") or 0.0)
        _write_summary(summary_csv, [r for r in rows if r is not None])
        if progress is not None:
            progress(done, len(stacks), row)

    _write_summary(summary_csv, [r for r in rows if r is not None])
    if tasks:
        if dask is not None:
            results = _dask_results(tasks, dask)
        else:
            n = min(jobs or os.cpu_count() or 1, len(tasks))
            results = _local_results(tasks, n)
        try:
            for row in results:
                finish(row)
        except Exception as exc:  # the pool itself broke (a worker was killed, ...)
            reason = f"{type(exc).__name__}: {' '.join(str(exc).split())}"
            for stack, i in index.items():
                if rows[i] is None:
                    finish({"stack": stack, "results": str(out_dir / names[i]),
                            "status": "failed", "reason": f"not finished: {reason}",
                            "traceback": traceback.format_exc()})
    elif dask is not None:
        _close(dask)
    _write_summary(summary_csv, rows)
    return BatchResult(rows=rows, summary_csv=summary_csv, elapsed_s=time.perf_counter() - t0)
