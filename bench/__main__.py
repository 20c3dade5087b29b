"""``python -m bench PART [--quick] [--device D] [--out DIR]``.

Parts: ``micro`` (the paper's Table 1 as OpenCL microbenchmarks, and the tape distance query
on the zoo models), ``sampler`` (sampler throughput), ``models`` (the model zoo: the paper's
Table 2 sampling columns, tree and DNF shape side by side; the everyday OpenSCAD parts and the
Menger sponge), ``render`` (splats against the tree ray tracer per zoo model, each overdraw
optimization on and off), ``peers`` (manifold3d on the same solids and the sponge, OpenSCAD on
the everyday parts), ``plots`` (PNG plots from the JSON files), ``batch`` (scenes and samples
per second of ``clcsg batch`` on 1,000 random programs: one process, the local pool, Dask).  Each writes
``bounds`` (scene bounds and the guard's estimate against the samples, on the zoo, the
examples and ``--programs N`` random programs run through the CLI), ``view`` (``clcsg view``'s frame
times per zoo model at 800x600 and 400x300, where the time goes, and the first frame after a
reload), ``mesh`` (``clcsg mesh`` against ``openscad -o part.stl`` and manifold3d: triangles,
CPU time and measured error on the everyday parts and the zoo), ``compile`` (host compile, tree
bounds and root tapes against the number of primitives: a perforated plate and a union of
spheres, 100 to 5,000 primitives), ``operands`` (meshes minus 20 cylinders: a CAD-like plate with
bosses, tessellated spheres and a 100k-triangle torus; and a sphere of 50k to 500k surfels minus
a box: sampling split by phase and rendering; each against manifold3d's Boolean, the cloud on
an icosphere), ``surfels`` (the surfel rows of ``operands`` alone), ``startup`` (the fixed cost
of a process: ``clcsg --version`` and ``clcsg sample`` of two cubes against a bare numpy +
pyopencl start), ``load`` (reading 0.5, 5 and 50 MB ``.csg`` and ``.json`` scenes: CPU time
and peak memory per byte of the file, ``openscad`` on the same ``.csg``), ``progress`` (the
sampling bar's ETA against the time actually left over the second half of real runs, its
percentage, and the expected sample count against the real one).  Each writes
``bench/results/PART.json`` (``--out`` elsewhere) and prints a Markdown table.  ``--quick``
keeps each part under about a minute on a 2-core machine.
"""

from __future__ import annotations

import argparse
import importlib

#: parts that are a function of another part's module: (module, function)
ENTRIES = {"surfels": ("operands", "run_surfels")}
PARTS = ("micro", "sampler", "models", "render", "peers", "plots", "batch", "bounds", "view", "mesh", "compile", "operands",
         "surfels", "startup", "load", "progress")


def main(argv=None):
    p = argparse.ArgumentParser(prog="python -m bench", description="clcsg benchmarks (write JSON to bench/results/)")
    p.add_argument("part", choices=PARTS)
    p.add_argument("--quick", action="store_true", help="keep the part under a minute")
    p.add_argument("--device", default=None, help="cpu, gpu or P:D (default as for clcsg)")
    p.add_argument("--out", default=None, metavar="DIR",
                   help="write results (JSON, PNG) to DIR instead of bench/results")
    p.add_argument("--gallery", action="store_true", help="render: also write docs/gallery/*.png")
    p.add_argument("--programs", type=int, default=None, metavar="N",
                   help="bounds: how many random programs (default 200, 30 with --quick)")
    a = p.parse_args(argv)
    from . import common

    if a.out:
        common.RESULTS = a.out
    name, entry = ENTRIES.get(a.part, (a.part, "run"))
    module = importlib.import_module(f".{name}", __package__)
    kw = {"gallery": True} if a.gallery and a.part == "render" else {}
    if a.part == "bounds" and a.programs is not None:
        kw["programs"] = a.programs
    getattr(module, entry)(quick=a.quick, device=a.device, **kw)


if __name__ == "__main__":
    main()
