"""The local engine: a process pool on this machine, one OpenCL context per worker process.

Workers end when the driver ends, however it ends (:func:`clcsg.batching.lifeline.die_with_parent`:
a parent-death signal and a watchdog on the driver's pipe), so a killed ``clcsg batch``
leaves no worker holding memory and a device context.  Workers are started with the ``spawn`` method (a process forked after OpenCL was initialized
in the parent may hang or crash in the driver) and open their device once, in the pool's
initializer (:func:`clcsg.batching.task.init_worker`).  Results are yielded as scenes finish.

A worker that dies (a crash in a driver, the out-of-memory killer, ``os._exit``) breaks the
whole pool (``BrokenProcessPool``): every unfinished scene is submitted again to a new pool.
Each worker reports the scene it starts on a queue, so the scenes that were running when the
pool broke are known: only they are charged an attempt.  A scene charged more than
``retries`` + 1 attempts gets an error row instead of another try, so a scene that always
kills its worker ends the loop.
"""

from __future__ import annotations

import multiprocessing
import os
from concurrent.futures import ProcessPoolExecutor, as_completed
from concurrent.futures.process import BrokenProcessPool

from .lifeline import die_with_parent
from .task import Result, init_worker, run_job

_state = {"queue": None, "options": None}


def _init(driver_pid, device, started, options) -> None:
    """The pool's initializer: the lifeline to the driver, the device, the queue of started
    scenes and the batch options (sent once per worker, not with every scene: query points
    may be large)."""
    die_with_parent(driver_pid)
    _state["queue"], _state["options"] = started, options
    init_worker(device)


def _run(job) -> Result:
    _state["queue"].put(job.name)
    return run_job(job, _state["options"])


def default_workers() -> int:
    return max(1, os.cpu_count() or 1)


def _drain(q, into: set) -> set:
    """Move what the workers reported into ``into`` (a SimpleQueue: each put is written to
    the pipe before the worker goes on, so a worker that dies right after it is still heard;
    drained after every result, so the pipe never fills)."""
    try:
        while not q.empty():
            into.add(q.get())
    except (OSError, EOFError):
        pass
    return into


def died_row(job, attempts: int) -> dict:
    """The error row of a scene whose worker died on every attempt."""
    return {"name": job.name, "source": job.source, "status": "error",
            "error": f"the worker process died while running this scene ({attempts} attempts)", "error_code": 1}


def run(jobs, options, workers: int | None = None, retries: int = 2):
    """Yield (job, Result, attempts) for every job, in the order they finish."""
    ctx = multiprocessing.get_context("spawn")
    pending = {job.name: job for job in jobs}
    attempts = {name: 0 for name in pending}
    workers = default_workers() if workers is None else max(1, int(workers))
    while pending:
        started = ctx.SimpleQueue()
        heard: set = set()
        pool = ProcessPoolExecutor(max_workers=min(workers, len(pending)), mp_context=ctx, initializer=_init,
                                   initargs=(os.getpid(), options.device, started, options))
        broken = False
        try:
            futures = {pool.submit(_run, job): job for job in pending.values()}
            for fut in as_completed(futures):
                job = futures[fut]
                try:
                    result = fut.result()
                except BrokenProcessPool:
                    broken = True
                    continue
                _drain(started, heard)
                del pending[job.name]
                attempts[job.name] += 1
                yield job, result, attempts[job.name]
        finally:
            pool.shutdown(wait=True, cancel_futures=True)
        if not broken:
            break
        running = _drain(started, heard) & set(pending)
        started.close()
        for name in running or set(pending):  # nothing reported: charge all, so the loop ends
            attempts[name] += 1
            if attempts[name] > retries:
                job = pending.pop(name)
                yield job, Result(died_row(job, attempts[name])), attempts[name]


__all__ = ["run", "default_workers"]
