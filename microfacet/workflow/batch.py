"""Many stacks at once: local worker processes or an existing Dask cluster.

:func:`run_batch` analyses every stack with
:func:`~microfacet.workflow.analyse.analyse_to_folder` and writes
each results folder (``docs/results-format.md``) under one output folder, named after the
stack folder. It is made for drawers full of stacks:

* **Parallel.** Locally, ``jobs`` worker processes (joblib's loky backend, numerical libraries
  limited to one thread each so the workers do not fight over cores). With ``scheduler``
  (a Dask distributed address such as ``tcp://10.0.0.5:8786``) the stacks are tasks on that
  cluster, so thousands of stacks scale out without new code. Workers read the stacks and
  write the results themselves: the stack paths and the output folder must be visible to the
  workers under the same paths (a shared file system); they are sent as absolute paths.
* **Checked up front.** Every stack to analyse is read and validated here
  (:func:`~microfacet.io.stack.read_stack`: ``stack.json`` and the image headers) before
  any analysis starts; a broken one is logged in one line, skipped and recorded as failed
  with the reason, so a long batch does not stop hours later on a typo.
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
  useful while a long batch runs and after it was interrupted. Ctrl-C raises
  :class:`BatchInterrupted`, which says how many stacks are done.

Examples
--------
>>> from microfacet.workflow import run_batch
>>> result = run_batch(["drawer/a", "drawer/b"], "results", jobs=2)  # doctest: +SKIP
>>> [row["status"] for row in result.rows]  # doctest: +SKIP
['done', 'done']
"""

from __future__ import annotations

import logging
import os
import socket
import time
import traceback
from dataclasses import dataclass, field
from pathlib import Path

from ..analysis.options import AnalysisOptions
from ..core.errors import InputError
from ..core.threads import limit_malloc_arenas, set_num_threads
from ..io.outdir import OutputFolder, check_output, sweep_stale
from ..io.results import Results
from ..io.stack import read_stack
from .analyse import analyse_to_folder
from .batch_summary import ERRORS_FILE, SUMMARY_FILE, result_names, row_from_results, write_summary
from .executors import check_scheduler, close_dask, dask_client, dask_results, local_results

__all__ = ["BatchInterrupted", "BatchResult", "run_batch"]

log = logging.getLogger("microfacet.workflow")


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


class BatchInterrupted(KeyboardInterrupt):
    """Ctrl-C during :func:`run_batch`, after the finished stacks were recorded in
    ``batch_summary.csv``; a rerun resumes.

    Attributes
    ----------
    done : int
        Stacks whose results are complete (analysed now or skipped as complete).
    total : int
        Stacks of the batch.
    summary_csv : pathlib.Path
    """

    def __init__(self, done: int, total: int, summary_csv: Path):
        super().__init__(f"interrupted; {done} of {total} stacks done")
        self.done, self.total, self.summary_csv = done, total, summary_csv


def _analyse_one(stack: str, out: str, options, overwrite: bool, report: bool,
                 threads: int | None = None) -> dict:
    """One stack, in a worker: analyse and write; never raises (failures are returned).

    ``threads`` (in a worker process only) limits microfacet's own thread pool, as the
    worker already shares the machine with the others.
    """
    if threads is not None:
        set_num_threads(threads)
        limit_malloc_arenas()
    t0 = time.perf_counter()
    row = {"stack": stack, "results": out, "worker": socket.gethostname()}
    try:
        if not Path(stack).exists():
            raise FileNotFoundError(f"{stack}: no such stack folder on worker "
                                    f"{socket.gethostname()} (a shared file system is needed)")
        analyse_to_folder(stack, out, options=options, overwrite=overwrite, report=report)
        row.update(status="done", reason="")
        row.update(row_from_results(Results(out)))
    except Exception as exc:  # recorded, the batch goes on
        reason = " ".join(str(exc).split()) or type(exc).__name__
        if not isinstance(exc, (ValueError, OSError)):  # not a user error: say what it was
            reason = f"{type(exc).__name__}: {reason}"
        row.update(status="failed", reason=reason, traceback=traceback.format_exc())
    row["time_s"] = round(time.perf_counter() - t0, 2)
    return row


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
    options : microfacet.analysis.options.AnalysisOptions, optional
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
    InputError
        Bad arguments, naming the parameter: no stacks, the same stack twice, ``jobs`` < 1, an
        unreachable scheduler or one that is not an address, an ``out_dir`` that breaks
        the output rules.
    BatchInterrupted
        Ctrl-C while stacks run; ``batch_summary.csv`` holds the finished ones.
    """
    t0 = time.perf_counter()
    options = AnalysisOptions() if options is None else options
    stacks = [os.path.abspath(s) for s in stacks]
    if not stacks:
        raise InputError("no stacks given", param="stacks")
    if jobs is not None and jobs < 1:
        raise InputError(f"must be >= 1, got {jobs}", param="jobs")
    if scheduler:
        check_scheduler(scheduler)
    out_dir = Path(os.path.abspath(out_dir))
    # the batch folder is reused, never replaced: an existing batch output is fine
    check_output(out_dir, kind="batch", inputs=stacks, overwrite=True)
    names = result_names(stacks)
    dask = (dask_client(scheduler, connect_timeout_s, jobs) if scheduler  # before writing
            else None)
    try:
        claim = OutputFolder(out_dir, kind="batch", inputs=stacks, overwrite=True)
        with claim:
            return _run_claimed(stacks, names, out_dir, options, dask, jobs, overwrite, report,
                                progress, t0)
    except BaseException:
        if dask is not None:
            close_dask(dask)
        raise


def _run_claimed(stacks, names, out_dir, options, dask, jobs, overwrite, report, progress, t0):
    """:func:`run_batch` once the output folder is claimed (no other run writes it)."""
    out_dir.mkdir(exist_ok=True)
    for p in sweep_stale(out_dir):
        log.info("removed %s, left by an interrupted run", p)

    rows: list[dict | None] = [None] * len(stacks)
    tasks, index = [], {}
    for i, (stack, name) in enumerate(zip(stacks, names)):
        out = str(out_dir / name)
        complete, why = Results.complete(out, options.to_dict())
        refused = ""
        try:  # an existing folder that is not a results folder is never replaced
            check_output(out, kind="results", inputs=[stack], overwrite=True)
        except InputError as exc:
            refused = exc.reason
        if complete and not overwrite:
            done_res = Results(out)
            rows[i] = {"stack": stack, "results": out, "status": "skipped",
                       "reason": "complete results exist", "worker": "",
                       "time_s": done_res.get("timings_s", "total"),
                       **row_from_results(done_res)}
        elif refused or (why and Path(out).exists() and not overwrite):
            rows[i] = {"stack": stack, "results": out, "status": "failed",
                       "reason": refused or why}
            log.warning("%s: failed: %s", stack, refused or why)
        elif (invalid := _invalid_stack(stack)):
            rows[i] = {"stack": stack, "results": out, "status": "failed", "reason": invalid,
                       "worker": ""}
            log.warning("%s: skipped: %s", stack, invalid)
        else:
            index[stack] = i
            tasks.append((stack, out, options, overwrite, report))

    summary_csv = out_dir / SUMMARY_FILE
    errors_log = out_dir / ERRORS_FILE  # this run's failures only
    errors_log.unlink(missing_ok=True)
    _log_errors(errors_log, [r for r in rows if r is not None and r["status"] == "failed"])
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
            _log_errors(errors_log, [row], tb)
        else:
            log.info("%s: done in %.1f s", row["stack"], row.get("time_s") or 0.0)
        write_summary(summary_csv, [r for r in rows if r is not None])
        if progress is not None:
            progress(done, len(stacks), row)

    write_summary(summary_csv, [r for r in rows if r is not None])
    if tasks:
        if dask is not None:
            results = dask_results(_analyse_one, tasks, dask)
        else:
            n = min(jobs or os.cpu_count() or 1, len(tasks))
            results = local_results(_analyse_one, tasks, n)
        try:
            for row in results:
                finish(row)
        except KeyboardInterrupt:
            results.close()  # stops the workers' queue (and closes a Dask client)
            finished = [r for r in rows if r is not None]
            write_summary(summary_csv, finished)
            n_done = sum(1 for r in finished if r["status"] in ("done", "skipped"))
            raise BatchInterrupted(n_done, len(stacks), summary_csv) from None
        except Exception as exc:  # the pool itself broke (a worker was killed, ...)
            reason = f"{type(exc).__name__}: {' '.join(str(exc).split())}"
            for stack, i in index.items():
                if rows[i] is None:
                    finish({"stack": stack, "results": str(out_dir / names[i]),
                            "status": "failed", "reason": f"not finished: {reason}",
                            "traceback": traceback.format_exc()})
    elif dask is not None:
        close_dask(dask)
    write_summary(summary_csv, rows)
    return BatchResult(rows=rows, summary_csv=summary_csv, elapsed_s=time.perf_counter() - t0)


def _invalid_stack(stack: str) -> str:
    """Why ``stack`` cannot be analysed (its :func:`read_stack` error, one line), or ``""``.

    Reads ``stack.json`` and the image headers only, in this process: a batch checks every
    stack before any analysis starts.
    """
    try:
        read_stack(stack)
    except (ValueError, OSError) as exc:
        return " ".join(str(exc).split()) or type(exc).__name__
    return ""


def _log_errors(errors_log: Path, rows, tb: str | None = None) -> None:
    """Append failed ``rows`` to ``batch_errors.log`` (the traceback ``tb`` or the reason)."""
    if not rows:
        return
    with open(errors_log, "a") as fh:
        for row in rows:
            fh.write(f"== {time.strftime('%Y-%m-%d %H:%M:%S')} {row['stack']}\n"
                     f"{tb or row['reason']}\n")
