"""Where the stacks of a batch run: in this process, in local worker processes (joblib's
loky backend), or on a Dask distributed cluster."""

from __future__ import annotations

import logging
import os
import time
import traceback

from ..core.errors import InputError
from ..core.lazy import load

distributed = load("distributed")

joblib = load("joblib")

__all__ = ["close_dask", "dask_client", "dask_results", "local_results"]

log = logging.getLogger("microfacet.batch")


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


def dask_client(scheduler, timeout_s, jobs=None):
    """``(client, cluster)``: a Client of the scheduler at ``scheduler``, or of a new
    LocalCluster for ``"local"`` (``cluster`` is None for an existing scheduler)."""
    try:
        Client, LocalCluster = distributed.Client, distributed.LocalCluster
    except ImportError:  # the lazy module is imported here: dask[distributed] is optional
        raise InputError("needs dask.distributed (pip install 'dask[distributed]' or "
                         "microfacet[cluster])", param="scheduler") from None
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
        raise InputError(f"cannot connect to {scheduler} ({' '.join(str(exc).split())})",
                         param="scheduler") from None


def close_dask(dask):
    """Close a :func:`dask_client` pair."""
    client, cluster = dask
    client.close()
    if cluster is not None:
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
    finally:
        close_dask(dask)


