"""Shared benchmark plumbing: machine/device description and result files."""

from __future__ import annotations

import json
import os
import platform
import subprocess
import time

RESULTS = os.path.join(os.path.dirname(__file__), "results")


def git_commit() -> str:
    try:
        return subprocess.check_output(["git", "rev-parse", "--short", "HEAD"], text=True,
                                       cwd=os.path.dirname(__file__), stderr=subprocess.DEVNULL).strip()
    except Exception:
        return "unknown"


def environment(ctx) -> dict:
    import numpy
    import pyopencl

    import clcsg

    return {
        "date": time.strftime("%Y-%m-%dT%H:%M:%S"),
        "machine": platform.machine(),
        "processor": platform.processor() or platform.machine(),
        "cpus": os.cpu_count(),
        "python": platform.python_version(),
        "numpy": numpy.__version__,
        "pyopencl": pyopencl.VERSION_TEXT,
        "clcsg": clcsg.__version__,
        "git_commit": git_commit(),
        "device": ctx.info.name,
        "platform": ctx.info.platform,
        "compute_units": ctx.info.compute_units,
    }


def write(part: str, payload: dict) -> str:
    os.makedirs(RESULTS, exist_ok=True)
    path = os.path.join(RESULTS, f"{part}.json")
    with open(path, "w") as f:
        json.dump(payload, f, indent=2)
    return path


def best_of(fn, repeats: int):
    """(best wall time in seconds, last result) over ``repeats`` runs (noisy 2-core machines)."""
    best, out = float("inf"), None
    for _ in range(repeats):
        t = time.perf_counter()
        out = fn()
        best = min(best, time.perf_counter() - t)
    return best, out
