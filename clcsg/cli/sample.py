"""``clcsg sample``: sample the CSG surface and write the samples (PLY or NPZ)."""

from __future__ import annotations

import textwrap

from ..cl.device import get_context
from ..compile.dnf import DEFAULT_TERM_LIMIT
from ..errors import UsageError
from ..pipeline import Pipeline
from ..writers.output_files import check_output, check_samples_output, write_json, write_samples
from .app import (SUMMARIES, UNRESOLVED_HELP, _jsonable, add_subcommand, parse_bound, parse_floats, parse_radius,
                  positive_int)
from .runs import Run, load_scene


def add_parser(subparsers):
    p = add_subcommand(
        subparsers,
        "sample",
        help=SUMMARIES["sample"],
        description="""
            Generate samples on the exact CSG surface (paper: Trettner & Kobbelt 2021): every
            sample lies on the surface, and every point of the surface has a sample on the
            same quadric within RADIUS.  The output format is the extension of OUT: .ply, a
            binary PLY (x y z nx ny nz in double precision, red green blue of the sample's
            primitive, quadric and primitive ids, radius) that Open3D, MeshLab and plyfile
            read; or .npz, the samples with their CSG tape (clcsg render OUT.npz renders them
            again without the scene, clcsg.load_samples reads them in Python).  "Unresolved"
            cells are cells still undecided when they shrink below the floor (default RADIUS /
            10): they are dropped, and the coverage guarantee holds for every feature wider
            than the floor.
        """,
        epilog=textwrap.dedent("""
            examples:
              clcsg sample examples/drilled_block.json -r 0.02 -o block.ply
              clcsg sample examples/drilled_block.json -r 0.02 -o block.npz   # then: clcsg render block.npz -o b.png
              clcsg sample model.csg -r 0.5 -o model.ply --stats stats.json --device gpu
              clcsg sample model.csg -r 0.5 -o model.ply --progress json 2> progress.jsonl
        """) + textwrap.dedent(UNRESOLVED_HELP),
    )
    p.add_argument("scene", metavar="SCENE", help="scene file (.json, OpenSCAD .csg or .scad)")
    p.add_argument("-r", "--radius", metavar="R", default="1%",
                   help="coverage radius: scene units, or a percentage of the scene bound's diagonal (default: 1%%)")
    p.add_argument("-o", "--output", metavar="OUT.ply", required=True,
                   help="file to write: .ply (binary PLY) or .npz (samples and tape, renders again)")
    p.add_argument("--stats", metavar="S.json", default=None, help="write sampling statistics as JSON")
    p.add_argument("--floor", metavar="F", default=None,
                   help="drop cells still unresolved below this size (default: radius / 10)")
    p.add_argument("--normal-form", choices=("tree", "dnf"), default="tree",
                   help="sample the CSG tree itself (default) or the paper's disjunctive normal form")
    p.add_argument("--term-limit", metavar="N", type=positive_int, default=None,
                   help=f"with --normal-form dnf: stop with exit code 5 past N DNF terms (default: {DEFAULT_TERM_LIMIT})")
    p.add_argument("--float32", action="store_true", help="PLY: write positions and normals as float32 (default: double)")
    p.add_argument("--bound", metavar="x0,y0,z0,x1,y1,z1", default=None,
                   help="box that clips unbounded terms (overrides the scene's own bound)")
    p.add_argument("--no-progress", action="store_true", help="the same as --progress none")
    p.add_argument("--max-samples", metavar="N", type=positive_int, default=None,
                   help="stop with exit code 5 before sampling if the estimate passes N samples "
                        "(default: 50000000)")


def parse_positive(text, name) -> float:
    (v,) = parse_floats(text, 1, name)
    if v <= 0:
        raise UsageError(f"{name} must be positive, got {text}")
    return v


def write_stats(path, stats) -> None:
    write_json(path, stats, "statistics", default=_jsonable)


def run(args) -> int:
    fmt = check_samples_output(args.output)  # before any work: `-o x.png` fails at once
    if args.stats:
        check_output(args.stats, ".json", "statistics", "--stats")
    radius_spec = parse_radius(args.radius)
    floor = None if args.floor is None else parse_positive(args.floor, "--floor")
    bound = None if args.bound is None else parse_bound(args.bound, "--bound")
    if args.float32 and fmt != "PLY":
        raise UsageError("--float32 applies to PLY output; .npz keeps the samples in double precision")
    ctx = get_context(args.device)
    run = Run("sample")
    pipe = Pipeline(load_scene(run, args.scene, bound), ctx, args.normal_form, args.term_limit)
    if radius_spec.relative:
        with run.step("compile", "compiling the scene (the radius is relative to its bound)"):
            radius = pipe.radius(radius_spec)
    else:
        radius = pipe.radius(radius_spec)
    with run.step("sample", "sampling: compiling the scene, building the OpenCL program"):
        s = pipe.samples(radius, floor=floor, progress=None, max_samples=args.max_samples)
    with run.step("write", f"writing {args.output}"):
        write_samples(s, args.output, float32=args.float32)
        run.wrote(args.output)
        if args.stats:
            write_stats(args.stats, s.stats)
            run.wrote(args.stats)
    st = s.stats
    run.summary(f"{len(s):,} samples on {st.get('tape_quadrics', 0)} quadrics (r = {radius:.6g}, "
                f"{st.get('levels', 0)} levels, {st.get('unresolved', 0):,} unresolved cells)",
                samples=len(s), radius=radius, unresolved=st.get("unresolved", 0), levels=st.get("levels", 0))
    return 0
