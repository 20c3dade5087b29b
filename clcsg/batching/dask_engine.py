"""The Dask engine: the same scene tasks on a Dask distributed cluster.

One task per scene (:func:`clcsg.batching.task.run_job`), submitted at once; results come back to
this process as they finish (``distributed.as_completed``) and are written to OUTDIR here, so
the workers need no access to it.  Each worker opens its OpenCL device once, when it joins
(:class:`DevicePlugin`, a ``distributed.WorkerPlugin``): the device spec of the batch
(``--device``) if one is given, else the worker's own default, so ``PYOPENCL_CTX=0:1 dask
worker ADDRESS`` pins a worker to a device.  Dask reschedules the tasks of a worker that dies
on another worker; a task that has killed more than ``distributed.scheduler.allowed-failures``
workers fails with ``KilledWorker`` and gets an error row.

``address`` is a scheduler's address (``tcp://host:8786``) or ``local:N``: a ``LocalCluster``
of N worker processes with one thread each, started here and closed at the end (its
allowed-failures set to ``retries``).  A local cluster's nannies run in this process and keep
watching their workers as usual; the worker processes, children of this process, also end
with it however it ends (:mod:`clcsg.batching.lifeline`: a parent-death signal and a watchdog
on the parent's pipe, set up by :class:`DevicePlugin`).
"""

from __future__ import annotations

import logging
import uuid

from ..errors import UsageError
from .lifeline import die_with_parent
from .local import died_row
from .options import require
from .task import Result, init_worker, run_job

try:
    from distributed import WorkerPlugin as _WorkerPlugin
except ImportError:  # the engine then stops at _distributed() with a DependencyError
    _WorkerPlugin = object


def _distributed():
    return require("distributed", "the Dask engine (--scheduler, --dask)")


class DevicePlugin(_WorkerPlugin):
    """Opens the batch's OpenCL device once per worker process, when it joins."""

    name = "clcsg-device"

    def __init__(self, device=None, lifeline: bool = False):
        self.device = device
        self.lifeline = lifeline

    def setup(self, worker):
        if self.lifeline:
            die_with_parent()
        init_worker(self.device)


def parse_local(address: str) -> int | None:
    """N of ``local:N`` (None for a scheduler address); UsageError for a bad N."""
    text = str(address).strip()
    if not text.lower().startswith("local"):
        return None
    _, _, n = text.partition(":")
    try:
        k = int(n) if n else 1
    except ValueError:
        raise UsageError(f"--dask: expected local:N with N a number of workers, got {address!r}") from None
    if k < 1:
        raise UsageError(f"--dask: need at least one worker, got {address!r}")
    return k


def _connect(address: str, retries: int):
    """(client, cluster or None)."""
    distributed = _distributed()
    import dask

    n = parse_local(address)
    if n is None:
        try:
            return distributed.Client(address, timeout="30s"), None
        except (OSError, TimeoutError) as e:
            raise UsageError(f"--scheduler {address}: cannot connect: {' '.join(str(e).split())}") from None
    with dask.config.set({"distributed.scheduler.allowed-failures": int(retries)}):
        cluster = distributed.LocalCluster(n_workers=n, threads_per_worker=1, processes=True,
                                           dashboard_address=None, silence_logs=logging.CRITICAL)
        return distributed.Client(cluster), cluster


def run(jobs, options, address: str, retries: int = 2):
    """Yield (job, Result, None) for every job, in the order they finish (attempts are not
    known under Dask)."""
    distributed = _distributed()
    client, cluster = _connect(address, retries)
    try:
        client.register_plugin(DevicePlugin(options.device, lifeline=cluster is not None))
        tag = uuid.uuid4().hex[:8]
        # query points go to every worker once, not with each task (scattered data is lost only
        # if every worker holding it dies; the options alone are small: sent with each task)
        shared = client.scatter(options, broadcast=True) if options.points is not None else options
        futures = {client.submit(run_job, job, shared, key=f"clcsg-{job.name}-{tag}", pure=False): job
                   for job in jobs}
        for fut in distributed.as_completed(list(futures)):
            job = futures.pop(fut)
            try:
                result = fut.result()
            except distributed.KilledWorker:
                result = Result(died_row(job, retries + 1))
            except Exception as e:  # cancelled, lost, or failed to deserialize
                result = Result({"name": job.name, "source": job.source, "status": "error",
                                 "error": f"the Dask task failed: {type(e).__name__}: {' '.join(str(e).split())}",
                                 "error_code": 1})
            fut.release()
            yield job, result, None
    finally:
        client.close()
        if cluster is not None:
            cluster.close()
