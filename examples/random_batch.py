"""Generate 1,000 random CSG programs and sample them all with clcsg.batch.

    python examples/random_batch.py                       # 1,000 programs, local process pool
    python examples/random_batch.py -n 200 --dask local:2 # 200 programs on a 2-worker Dask cluster
    python examples/random_batch.py --manifest            # programs as JSON lines of one manifest

The programs (clcsg.model.random_programs: boxes, spheres, cylinders and cone frusta, rotated
and scaled, in unions, differences and intersections up to three deep) are written as OpenSCAD
.csg files into OUT/scenes/ (or, with --manifest, as one-line JSON scenes into
OUT/programs.txt); the samples go to OUT/batch/ (samples/*.parquet and manifest.parquet).
Running it again skips every scene already done.
"""

from __future__ import annotations

import argparse
import json
import os

import numpy as np


def write_programs(folder: str, n: int, seed: int = 0, max_depth: int = 3, manifest: bool = False) -> str:
    """Write ``n`` random programs into ``folder``: ``scenes/prog_NNNNN.csg``, or with
    ``manifest`` one JSON scene per line in ``programs.txt``; returns the batch input (the
    scenes folder or the manifest file).  The same seed gives the same programs."""
    from clcsg.readers.scenefile import scene_to_dict
    from clcsg.model.random_programs import random_program

    rng = np.random.default_rng(seed)
    programs = [random_program(rng, max_depth=max_depth) for _ in range(n)]
    if manifest:
        path = os.path.join(folder, "programs.txt")
        os.makedirs(folder, exist_ok=True)
        with open(path, "w", encoding="utf-8") as f:
            for p in programs:
                f.write(json.dumps(scene_to_dict(p.shape), separators=(",", ":")) + "\n")
        return path
    scenes = os.path.join(folder, "scenes")
    os.makedirs(scenes, exist_ok=True)
    for k, p in enumerate(programs):
        path = os.path.join(scenes, f"prog_{k:05d}.csg")
        if not os.path.exists(path):
            with open(path, "w", encoding="utf-8") as f:
                f.write(p.csg)
    return scenes


def main(argv=None) -> None:
    import clcsg

    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("-n", type=int, default=1000, help="number of programs (default 1000)")
    ap.add_argument("-o", "--out", default="random_batch", help="output folder (default random_batch/)")
    ap.add_argument("-r", "--radius", default="1%", help="radius, scene units or %% of the diagonal (default 1%%)")
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--manifest", action="store_true", help="write the programs as JSON lines of one manifest")
    ap.add_argument("--workers", type=int, default=None, help="local engine: worker processes")
    ap.add_argument("--dask", default=None, metavar="local:N", help="run on a Dask LocalCluster of N workers")
    a = ap.parse_args(argv)
    source = write_programs(a.out, a.n, a.seed, manifest=a.manifest)
    table = clcsg.batch(source, a.radius, os.path.join(a.out, "batch"), workers=a.workers, dask=a.dask)
    rows = table.select(["status", "samples", "skipped"]).to_pylist()
    ok = [r for r in rows if r["status"] == "ok"]
    print(f"{len(rows)} programs: {len(ok)} ok, {len(rows) - len(ok)} failed, "
          f"{sum(r['skipped'] for r in rows)} done before; {sum(r['samples'] for r in ok):,} samples "
          f"in {table.schema.metadata[b'clcsg.seconds'].decode()} s -> {os.path.join(a.out, 'batch')}")


if __name__ == "__main__":  # the process pool and Dask start new interpreters that import this file
    main()
