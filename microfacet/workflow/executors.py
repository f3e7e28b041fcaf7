"""Where the stacks of a batch run: in this process, in local worker processes (joblib's
loky backend), or on a Dask distributed cluster."""

from __future__ import annotations

import contextlib
import logging
import os
import re
import signal
import time
import traceback

from ..core.errors import InputError
from ..core.lazy import load

distributed = load("distributed")
dask_config = load("dask.config")

joblib = load("joblib")

__all__ = ["WORKER_ENVIRONMENT", "check_scheduler", "close_dask", "dask_client", "dask_results",
           "job_script_prologue", "local_results"]

log = logging.getLogger("microfacet.workflow")


def local_results(fn, tasks, jobs):
    """Yield ``fn(*task)`` as tasks finish, in ``jobs`` loky worker processes (in this process
    for 1); workers get ``threads=1``."""
    if jobs == 1:
        for t in tasks:
            yield fn(*t)
        return
    # one thread per worker for BLAS/OpenMP (joblib) and for microfacet's own pool
    parallel = joblib.Parallel(n_jobs=jobs, backend="loky", return_as="generator_unordered",
                        inner_max_num_threads=1)
    yield from parallel(joblib.delayed(fn)(*t, threads=1) for t in tasks)


#: A Dask scheduler address: an optional scheme, a host name, IPv4 or [IPv6] address, a port.
_ADDRESS = re.compile(r"(?:(?:tcp|tls|ucx|ws|wss)://)?"
                      r"(?:\[[0-9A-Fa-f:.]+\]|[A-Za-z0-9_][A-Za-z0-9_.-]*):(\d{1,5})")


def check_scheduler(scheduler) -> None:
    """Raise :class:`~microfacet.core.errors.InputError` unless ``scheduler`` is ``"local"``
    or has the form of a Dask scheduler address (``tcp://10.0.0.5:8786``, ``head:8786``).

    Checked before a Client is made: Dask takes any string and fails only after its connect
    timeout, and then once more on closing the half-made Client.

    >>> check_scheduler("tcp://10.0.0.5:8786"); check_scheduler("local")
    >>> try:
    ...     check_scheduler("locl")
    ... except InputError as exc:
    ...     print(exc.param)
    scheduler
    """
    if scheduler == "local":
        return
    m = _ADDRESS.fullmatch(scheduler) if isinstance(scheduler, str) else None
    if m is None or not 0 < int(m.group(1)) < 65536:
        raise InputError(f"{scheduler!r} is neither 'local' nor a scheduler address with a "
                         f"port such as tcp://10.0.0.5:8786", param="scheduler")


#: Dask configuration for the workers of a LocalCluster (docs/benchmarks.md, "Batch
#: throughput"):
#:
#: - Dask's nanny starts its workers with ``MALLOC_TRIM_THRESHOLD_=65536``, which makes glibc
#:   hand every freed block above 64 kB back to the system; the analysis allocates and frees
#:   large arrays all the time and ran 2.7× slower per stack in such a worker (4 stacks of
#:   512²: 11-13.6 s against 4.3-5.9 s in a loky process or a worker without it; a fixed
#:   threshold of 32 MB in the worker's environment was not enough: any fixed one stops
#:   glibc's own adjustment);
#: - the worker's statistical profiler (a stack sample every 10 ms), its event loop's 20 ms
#:   tick, its 0.5 s system monitor and 0.1 s memory monitor all take the GIL from the
#:   analysis: without them a stack took 4.31-4.48 s against 4.74-4.80 s (8 stacks of 512²,
#:   three runs each; loky processes 4.31-4.52 s). The memory limits still hold, checked
#:   every second instead of ten times a second.
WORKER_CONFIG = {"distributed.nanny.pre-spawn-environ.MALLOC_TRIM_THRESHOLD_": None,
                 "distributed.worker.profile.enabled": False,
                 "distributed.admin.tick.interval": "1s",
                 "distributed.admin.system-monitor.interval": "5s",
                 "distributed.worker.memory.monitor-interval": "1s"}
#: The same for workers a batch system or a user starts (``dask worker`` in a job script):
#: Dask reads these variables into :data:`WORKER_CONFIG`'s keys when the worker starts.
WORKER_ENVIRONMENT = {
    "DASK_DISTRIBUTED__NANNY__PRE_SPAWN_ENVIRON": '{"MALLOC_TRIM_THRESHOLD_": None}',
    "DASK_DISTRIBUTED__WORKER__PROFILE__ENABLED": "False",
    "DASK_DISTRIBUTED__ADMIN__TICK__INTERVAL": "1s",
    "DASK_DISTRIBUTED__ADMIN__SYSTEM_MONITOR__INTERVAL": "5s",
    "DASK_DISTRIBUTED__WORKER__MEMORY__MONITOR_INTERVAL": "1s"}


def job_script_prologue() -> list[str]:
    """Shell lines that give the Dask workers of a job script :data:`WORKER_ENVIRONMENT`:
    for ``job_script_prologue=`` of a dask-jobqueue cluster (docs/cluster.md).

    >>> print(job_script_prologue()[0])
    export DASK_DISTRIBUTED__NANNY__PRE_SPAWN_ENVIRON='{"MALLOC_TRIM_THRESHOLD_": None}'
    """
    return [f"export {k}='{v}'" for k, v in WORKER_ENVIRONMENT.items()]


def dask_client(scheduler, timeout_s, jobs=None):
    """``(client, cluster)``: a Client of the scheduler at ``scheduler``, or of a new
    LocalCluster for ``"local"`` (``cluster`` is None for an existing scheduler)."""
    check_scheduler(scheduler)
    try:
        Client, LocalCluster = distributed.Client, distributed.LocalCluster
    except ImportError:  # the lazy module is imported here: dask[distributed] is optional
        raise InputError("needs dask.distributed (pip install 'dask[distributed]' or "
                         "microfacet[cluster])", param="scheduler") from None
    if not log.isEnabledFor(logging.DEBUG):  # Dask's INFO chatter only with -vv
        logging.getLogger("distributed").setLevel(logging.WARNING)
    if scheduler == "local":
        # workers are processes with one thread each; the cluster closes with the client.
        # They start with Ctrl-C ignored: this process handles it and closes them (else each
        # idle worker prints its KeyboardInterrupt traceback). Their own logging (read from
        # the environment when they start) stays at errors unless -vv.
        quiet = {} if log.isEnabledFor(logging.DEBUG) else {"DASK_LOGGING__DISTRIBUTED": "error"}
        # a nanny started earlier in this process left its threshold in our environment
        quiet["MALLOC_TRIM_THRESHOLD_"] = None
        with _environ(quiet), _ignoring_sigint(), dask_config.set(WORKER_CONFIG):
            cluster = LocalCluster(n_workers=jobs or os.cpu_count() or 1, threads_per_worker=1,
                                   processes=True, host="127.0.0.1", dashboard_address=":0")
        log.info("Dask LocalCluster at %s, dashboard %s", cluster.scheduler_address,
                 cluster.dashboard_link)
        return Client(cluster, set_as_default=False), cluster
    try:
        return Client(scheduler, timeout=timeout_s, set_as_default=False), None
    except (OSError, TimeoutError, ValueError) as exc:
        raise InputError(f"cannot connect to {scheduler} ({' '.join(str(exc).split())})",
                         param="scheduler") from None


@contextlib.contextmanager
def _environ(values: dict):
    """Set environment variables for the block (for the processes started in it); a value of
    None unsets the variable."""
    saved = {k: os.environ.get(k) for k in values}
    for k, v in values.items():
        if v is None:
            os.environ.pop(k, None)
        else:
            os.environ[k] = v
    try:
        yield
    finally:
        for k, v in saved.items():
            if v is None:
                os.environ.pop(k, None)
            else:
                os.environ[k] = v


@contextlib.contextmanager
def _ignoring_sigint():
    """SIGINT ignored in the block: processes started in it inherit that (not restored by
    exec), while this process's handler comes back afterwards."""
    try:
        previous = signal.signal(signal.SIGINT, signal.SIG_IGN)
    except ValueError:  # not the main thread: signals are not ours to change
        yield
        return
    try:
        yield
    finally:
        signal.signal(signal.SIGINT, previous)


def close_dask(dask):
    """Close a :func:`dask_client` pair; closing it again does nothing."""
    client, cluster = dask
    if client.status not in ("closed", "closing"):
        client.close()
    if cluster is not None and str(getattr(cluster, "status", "")).split(".")[-1] != "closed":
        with contextlib.suppress(RuntimeError):  # its event loop is already gone
            cluster.close()


def dask_results(fn, tasks, dask):
    """Yield ``fn(*task)`` rows as tasks finish on the Dask cluster; closes the client (and
    cluster)."""
    client = dask[0]
    try:
        futures = {client.submit(fn, *t, threads=1, pure=False,
                                 key=f"microfacet-{i}-{os.getpid()}-{time.time_ns()}"): t
                   for i, t in enumerate(tasks)}
        with client.as_current():
            finished = distributed.as_completed(list(futures))
        for fut in finished:
            stack, out = futures[fut][:2]
            try:
                yield fut.result()
            except Exception as exc:  # worker died (KilledWorker), cancelled, ...
                yield {"stack": stack, "results": out, "status": "failed",
                       "reason": f"{type(exc).__name__}: {' '.join(str(exc).split())}",
                       "traceback": traceback.format_exc(), "time_s": None, "worker": ""}
    except BaseException:  # Ctrl-C or closed early: the cluster's shutdown warnings are noise
        if not log.isEnabledFor(logging.DEBUG):
            logging.getLogger("distributed").setLevel(logging.ERROR)
        raise
    finally:
        close_dask(dask)


