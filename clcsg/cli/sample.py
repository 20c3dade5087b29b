"""``clcsg sample``: sample the CSG surface and write the samples (PLY)."""

from __future__ import annotations

import json

from .app import _jsonable, add_subcommand, parse_bound, parse_floats, positive_int
from ..errors import UsageError

def add_parser(subparsers):
    from ..compile.dnf import DEFAULT_TERM_LIMIT

    p = add_subcommand(
        subparsers,
        "sample",
        help="sample the CSG surface and write a PLY point cloud",
        description="""
            Generate samples on the exact CSG surface (paper: Trettner & Kobbelt 2021): every
            sample lies on the surface, and every point of the surface has a sample on the
            same quadric within RADIUS.  Writes a binary PLY (x y z nx ny nz in double
            precision, red green blue of the sample's primitive, quadric and primitive ids,
            radius) that Open3D, MeshLab and plyfile read.  "Unresolved" cells are cells still
            undecided when they shrink below the floor (default RADIUS / 10): they are dropped,
            and the coverage guarantee holds for every feature wider than the floor.
        """,
        epilog="""
            examples:
              clcsg sample examples/drilled_block.json -r 0.02 -o block.ply
              clcsg sample model.csg -r 0.5 -o model.ply --stats stats.json --device gpu
        """,
    )
    p.add_argument("scene", metavar="SCENE", help="scene file (.json or OpenSCAD .csg)")
    p.add_argument("-r", "--radius", metavar="R", required=True, help="coverage radius in scene units")
    p.add_argument("-o", "--output", metavar="OUT.ply", required=True, help="PLY file to write")
    p.add_argument("--stats", metavar="S.json", default=None, help="write sampling statistics as JSON")
    p.add_argument("--floor", metavar="F", default=None,
                   help="drop cells still unresolved below this size (default: radius / 10)")
    p.add_argument("--normal-form", choices=("tree", "dnf"), default="tree",
                   help="sample the CSG tree itself (default) or the paper's disjunctive normal form")
    p.add_argument("--term-limit", metavar="N", type=positive_int, default=None,
                   help=f"with --normal-form dnf: stop with exit code 5 past N DNF terms (default: {DEFAULT_TERM_LIMIT})")
    p.add_argument("--float32", action="store_true", help="write positions and normals as float32 (default: double)")
    p.add_argument("--bound", metavar="x0,y0,z0,x1,y1,z1", default=None,
                   help="box that clips unbounded terms (overrides the scene's own bound)")
    p.add_argument("--no-progress", action="store_true", help="no progress display on stderr")
    p.add_argument("--max-samples", metavar="N", type=positive_int, default=None,
                   help="stop with exit code 5 before sampling if the estimate passes N samples "
                        "(default: 50000000)")


def parse_positive(text, name) -> float:
    (v,) = parse_floats(text, 1, name)
    if v <= 0:
        raise UsageError(f"{name} must be positive, got {text}")
    return v


def run(args) -> int:
    from ..sampling.sampler import sample
    from ..model.scene import as_scene, load

    radius = parse_positive(args.radius, "--radius")
    floor = None if args.floor is None else parse_positive(args.floor, "--floor")
    bound = None if args.bound is None else parse_bound(args.bound, "--bound")
    from ..cl.device import get_context

    ctx = get_context(args.device)
    scene = as_scene(load(args.scene), bound)
    s = sample(scene, radius, device=ctx, floor=floor, normal_form=args.normal_form, term_limit=args.term_limit,
               progress=False if args.no_progress else None, max_samples=args.max_samples)
    s.to_ply(args.output, float32=args.float32)
    if args.stats:
        with open(args.stats, "w") as f:
            json.dump(s.stats, f, indent=2, default=_jsonable)
    st = s.stats
    print(f"{len(s)} samples on {st['tape_quadrics']} quadrics ({st['normal_form']} tape of "
          f"{st['tape_instructions']} instructions; {st['distance_queries']} distance queries, "
          f"{st['leaf_distances_per_query']:.2f} leaf distances each, {st['levels']} levels, "
          f"{st['unresolved']} unresolved cells) in {st['total_s']:.3f} s -> {args.output}")
    return 0
