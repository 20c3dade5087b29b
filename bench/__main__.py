"""``python -m bench PART [--quick] [--device D] [--out DIR]``.

Parts: ``micro`` (the paper's Table 1 as OpenCL microbenchmarks, and the tape distance query
on the zoo models), ``sampler`` (sampler throughput), ``models`` (the model zoo: the paper's
Table 2 sampling columns, tree and DNF shape side by side; the everyday OpenSCAD parts and the
Menger sponge), ``render`` (splats against the tree ray tracer per zoo model, each overdraw
optimization on and off), ``peers`` (manifold3d on the same solids and the sponge, OpenSCAD on
the everyday parts), ``plots`` (PNG plots from the JSON files).  Each writes
``bench/results/PART.json`` (``--out`` elsewhere) and prints a Markdown table.  ``--quick``
keeps each part under about a minute on a 2-core machine.
"""

from __future__ import annotations

import argparse
import importlib

PARTS = ("micro", "sampler", "models", "render", "peers", "plots")


def main(argv=None):
    p = argparse.ArgumentParser(prog="python -m bench", description="clcsg benchmarks (write JSON to bench/results/)")
    p.add_argument("part", choices=PARTS)
    p.add_argument("--quick", action="store_true", help="keep the part under a minute")
    p.add_argument("--device", default=None, help="cpu, gpu or P:D (default as for clcsg)")
    p.add_argument("--out", default=None, metavar="DIR",
                   help="write results (JSON, PNG) to DIR instead of bench/results")
    p.add_argument("--gallery", action="store_true", help="render: also write docs/gallery/*.png")
    a = p.parse_args(argv)
    from . import common

    if a.out:
        common.RESULTS = a.out
    module = importlib.import_module(f".{a.part}", __package__)
    kw = {"gallery": True} if a.gallery and a.part == "render" else {}
    module.run(quick=a.quick, device=a.device, **kw)


if __name__ == "__main__":
    main()
