"""``clcsg batch``: sample (and render) many scenes into a folder, on a process pool or Dask."""

from __future__ import annotations

import textwrap
import warnings

from .app import SUMMARIES, add_subcommand, parse_radius, positive_int
from ..batching.api import batch
from ..progress import current
from .render import parse_size
from .runs import Run
from .sample import parse_positive

#: failed scenes named one per line in warnings; the rest are counted
SHOWN_FAILURES = 10


def add_parser(subparsers):
    p = add_subcommand(
        subparsers,
        "batch",
        help=SUMMARIES["batch"],
        description="""
            Sample every scene of INPUTS into OUTDIR: samples/NAME.parquet (x y z nx ny nz quadric
            primitive radius clipped; --format ply for PLY), with --views N the PNG images
            views/NAME.K.png on an orbit through `clcsg render`'s default camera, with --points or
            --random-points queries/NAME.parquet (x y z inside distance), and a row per
            scene in OUTDIR/manifest.parquet (status ok or error, the error message, statistics,
            timings, the content hash of the scene text and the options).  INPUTS are scene files
            (.json, .csg, .scad), directories (every scene file under them), globs, or manifest
            files with one path or one-line JSON scene per line.  A scene that fails gets an error
            row and the run goes on.  Running the same command again skips the scenes that are
            complete (same hash, files present) and redoes the others.  Files are written
            atomically, as scenes finish.  Engines: a local process pool (default, one process
            per CPU, each with its own OpenCL context), or a Dask cluster (--scheduler ADDRESS,
            or --dask local:N for a local cluster of N worker processes).  Needs the batch extra:
            pip install 'clcsg[batch]'.
        """,
        epilog=textwrap.dedent("""
            examples:
              clcsg batch scenes/ -r 1% -o out/
              clcsg batch 'parts/**/*.csg' -r 0.05 -o out/ --views 4 --size 320x240
              clcsg batch list.txt -r 2% -o out/ --format ply --workers 4
              clcsg batch scenes/ -r 1% -o out/ --random-points 100000   # occupancy and distance too
              clcsg batch scenes/ -r 1% -o out/ --dask local:2
              clcsg batch scenes/ -r 1% -o out/ --scheduler tcp://10.0.0.5:8786

            exit code: 0 if every scene is ok, 3 if some failed (their errors are in the
            manifest), otherwise as for every command (2 bad options, ...).
        """),
    )
    p.add_argument("inputs", metavar="INPUTS", nargs="+",
                   help="scene files, directories, globs or manifest files (one path or JSON scene per line)")
    p.add_argument("-o", "--output", metavar="OUTDIR", required=True, help="folder for the outputs and manifest")
    p.add_argument("-r", "--radius", metavar="R", default="1%",
                   help="coverage radius: scene units, or a percentage of each scene's bound diagonal (default: 1%%)")
    p.add_argument("--format", choices=("parquet", "ply"), default="parquet", help="samples file format (default parquet)")
    p.add_argument("--views", metavar="N", type=int, default=0,
                   help="render N views per scene (orbit cameras, PNG); default 0")
    p.add_argument("--size", metavar="WxH", default="640x480", help="size of the view images (default 640x480)")
    p.add_argument("--points", metavar="P.npy", default=None,
                   help="also query these (N, 3) points in every scene: queries/NAME.parquet with x y z, inside "
                        "(occupancy) and distance (a signed lower bound of the distance to the surface)")
    p.add_argument("--random-points", metavar="N", type=int, default=0,
                   help="also query N points drawn uniformly in each scene's bound (grown by 5%% of its diagonal; "
                        "the same scene text gets the same points)")
    p.add_argument("--workers", metavar="N", type=positive_int, default=None,
                   help="local engine: worker processes (default: one per CPU)")
    g = p.add_mutually_exclusive_group()
    g.add_argument("--scheduler", metavar="ADDRESS", default=None,
                   help="run on the Dask cluster of this scheduler (tcp://host:8786)")
    g.add_argument("--dask", metavar="local:N", default=None,
                   help="run on a Dask LocalCluster of N worker processes started for this run")
    p.add_argument("--retries", metavar="N", type=int, default=2,
                   help="extra attempts for a scene whose worker process died (default 2)")
    p.add_argument("--redo-errors", action="store_true",
                   help="also run again the scenes whose bad input or limit failed them in an earlier run")
    p.add_argument("--normal-form", choices=("tree", "dnf"), default="tree",
                   help="sample the CSG tree itself (default) or the paper's disjunctive normal form")
    p.add_argument("--floor", metavar="F", default=None,
                   help="drop cells still unresolved below this size (default: min(radius / 10, 1/1000 of the diagonal))")
    p.add_argument("--max-samples", metavar="N", type=positive_int, default=None,
                   help="a scene whose estimate passes N samples fails with a limit error (default: 50000000)")
    return p


def run(args) -> int:
    size = parse_size(args.size)
    floor = None if args.floor is None else parse_positive(args.floor, "--floor")
    run = Run("batch")
    table = batch(args.inputs, parse_radius(args.radius), args.output, fmt=args.format, views=args.views, size=size,
                  points=args.points, random_points=args.random_points,
                  workers=args.workers, scheduler=args.scheduler, dask=args.dask, device=args.device,
                  normal_form=args.normal_form, floor=floor, max_samples=args.max_samples, retries=args.retries,
                  redo_errors=args.redo_errors, progress=current())
    rows = table.select(["name", "status", "error", "samples", "skipped"]).to_pylist()
    failed = [r for r in rows if r["status"] != "ok"]
    for r in failed[:SHOWN_FAILURES]:
        warnings.warn(f"scene {r['name']}: {r['error']}", stacklevel=2)
    if len(failed) > SHOWN_FAILURES:
        warnings.warn(f"... and {len(failed) - SHOWN_FAILURES} more failed scenes (see the manifest)", stacklevel=2)
    skipped = sum(bool(r["skipped"]) for r in rows)
    samples = sum(int(r["samples"] or 0) for r in rows if r["status"] == "ok" and not r["skipped"])
    seconds = float(table.schema.metadata[b"clcsg.seconds"])
    run.wrote(f"{args.output.rstrip('/')}/manifest.parquet")
    run.summary(f"{len(rows):,} scenes: {len(rows) - len(failed):,} ok, {len(failed):,} failed, {skipped:,} done "
                f"before; {samples:,} samples ({samples / max(seconds, 1e-9):,.0f} samples/s)",
                scenes=len(rows), ok=len(rows) - len(failed), failed=len(failed), skipped=skipped, samples=samples)
    return 3 if failed else 0
