"""The ``clcsg`` command line.

Each subcommand is two functions: ``add_<name>_parser(subparsers)`` builds its argparse
parser (with :func:`add_subcommand`, which adds the common options such as ``--device``), and
``run_<name>(args) -> int`` does the work.  :data:`COMMANDS` is the dispatch table; to add a
subcommand, write the two functions and add one line there.

Errors: a :class:`~clcsg.errors.ClcsgError` prints ``clcsg: error: <message>`` (one line) and
exits with its ``exit_code``; a bad command line exits 2 (argparse); Ctrl-C exits 130; anything
else is a bug and prints ``clcsg: internal error: ...`` and exits 1.  ``--debug`` re-raises
instead, to show the traceback.
"""

from __future__ import annotations

import argparse
import json
import math
import os
import re
import sys
import textwrap
from typing import Callable

import numpy as np

from .. import __version__
from ..errors import ClcsgError, DeviceError, UsageError

PROG = "clcsg"

DEVICE_HELP = (
    "OpenCL device: 'cpu', 'gpu', 'P:D' (platform P, device D, as `clcsg devices` lists them), "
    "'P' (first device of platform P) or 'oclgrind' (the simulator, never picked otherwise). "
    "Default: $PYOPENCL_CTX if set (same P:D syntax), else the first GPU, else the first CPU."
)


# -- helpers other subcommands reuse -----------------------------------------------------------


def parse_floats(text: str, n: int, name: str) -> tuple[float, ...]:
    """``n`` finite numbers from ``"a,b,c"`` (commas and/or spaces); UsageError names ``name``.

    >>> parse_floats("0,0,1", 3, "--eye")
    (0.0, 0.0, 1.0)
    """
    parts = [p for p in str(text).replace(",", " ").split()]
    if len(parts) != n:
        raise UsageError(f"{name}: expected {n} comma-separated numbers, got {len(parts)} in {text!r}")
    out = []
    for p in parts:
        try:
            v = float(p)
        except ValueError:
            raise UsageError(f"{name}: {p!r} is not a number (in {text!r})") from None
        if not math.isfinite(v):
            raise UsageError(f"{name}: {p!r} is not a finite number (in {text!r})")
        out.append(v)
    return tuple(out)


def parse_bound(text: str, name: str = "--bound") -> np.ndarray:
    """A (2, 3) bound from ``"x0,y0,z0,x1,y1,z1"`` with lo < hi on every axis."""
    v = np.array(parse_floats(text, 6, name)).reshape(2, 3)
    if np.any(v[1] <= v[0]):
        raise UsageError(f"{name}: need x0 < x1, y0 < y1 and z0 < z1, got {text!r}")
    return v


_NEGATIVE_VECTOR = re.compile(r"^-\.?\d.*,")


def join_negative_vectors(argv: list[str]) -> list[str]:
    """``["--bound", "-1,-1,-1,1,1,1"]`` -> ``["--bound=-1,-1,-1,1,1,1"]``.

    argparse takes a value that starts with '-' and is not a plain number for an option, so
    ``--eye -2,0,1`` would fail; joining it to its option makes vectors with a negative first
    component work without ``=``.  Done for every long option, so new options get it too.
    """
    out: list[str] = []
    it = iter(argv)
    for a in it:
        if a == "--":
            out.append(a)
            out.extend(it)
            break
        prev = out[-1] if out else ""
        if prev.startswith("--") and prev != "--" and "=" not in prev and _NEGATIVE_VECTOR.match(a):
            out[-1] = f"{out[-1]}={a}"
        else:
            out.append(a)
    return out


def positive_int(text: str) -> int:
    """argparse type: an integer >= 1."""
    try:
        v = int(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected a positive integer, got {text!r}") from None
    if v < 1:
        raise argparse.ArgumentTypeError(f"expected a positive integer, got {text!r}")
    return v


class _Formatter(argparse.RawDescriptionHelpFormatter):
    def __init__(self, prog):
        super().__init__(prog, max_help_position=30, width=min(100, _term_width()))


def _term_width() -> int:
    try:
        return os.get_terminal_size().columns - 2
    except OSError:
        return 98


def add_subcommand(subparsers, name: str, help: str, description: str, epilog: str = ""):
    """A subcommand parser with the options every subcommand has (``--device``, ``--debug``)."""
    p = subparsers.add_parser(
        name,
        help=help,
        description=textwrap.dedent(description).strip(),
        epilog=textwrap.dedent(epilog).strip() or None,
        formatter_class=_Formatter,
    )
    g = p.add_argument_group("common options")
    g.add_argument("--device", metavar="D", default=None, help=DEVICE_HELP)
    g.add_argument(
        "--debug", action="store_true", default=argparse.SUPPRESS, help="show the traceback on errors"
    )
    return p


def _fmt(x: float) -> str:
    return f"{float(x):.6g}"


def _vec(v) -> str:
    return "(" + ", ".join(_fmt(x) for x in v) + ")"


def _box(b) -> str:
    return f"{_vec(b[0])} .. {_vec(b[1])}"


# -- clcsg devices ----------------------------------------------------------------------------


def add_devices_parser(subparsers):
    p = add_subcommand(
        subparsers,
        "devices",
        help="list OpenCL devices and show which one is used",
        description="""
            List every OpenCL device with its P:D index, type and the features clcsg uses
            (fp64, 64-bit atomics).  The device used by default is marked with '*' (with
            --device D: the device D selects).  Oclgrind, a simulator about 1000x slower, is
            listed but never chosen unless asked for by name or index.
        """,
        epilog="""
            examples:
              clcsg devices
              clcsg devices --device gpu        # which device 'gpu' selects
              PYOPENCL_CTX=1:0 clcsg devices    # the default follows PYOPENCL_CTX
              clcsg devices --json
        """,
    )
    p.add_argument("--json", action="store_true", help="print the list as JSON")


def run_devices(args) -> int:
    from ..cl.device import choose, list_devices

    infos = list_devices()
    problem = None
    try:
        chosen = choose(infos, args.device, os.environ)
    except DeviceError as e:
        if args.device is not None:
            raise
        chosen, problem = None, e  # show the table anyway: it helps fix PYOPENCL_CTX
    if args.json:
        rows = [dict(i.as_dict(), selected=(k == chosen)) for k, i in enumerate(infos)]
        print(json.dumps(rows, indent=2))
    else:
        head = ["", "P:D", "type", "name", "platform", "CUs", "fp64", "64-bit atomics", ""]
        rows = []
        for k, i in enumerate(infos):
            rows.append(
                [
                    "*" if k == chosen else "",
                    i.spec,
                    i.type,
                    i.name,
                    i.platform,
                    str(i.compute_units),
                    "yes" if i.fp64 else "no",
                    "yes" if i.int64_atomics else "no",
                    "(simulator, never chosen by default)" if i.is_oclgrind else "",
                ]
            )
        widths = [max(len(r[c]) for r in rows + [head]) for c in range(len(head))]
        right = {5}
        for r in [head] + rows:
            cells = [r[c].rjust(widths[c]) if c in right else r[c].ljust(widths[c]) for c in range(len(r))]
            print("  ".join(cells).rstrip())
        print()
        if args.device is not None:
            print(f"* = the device selected by --device {args.device}")
        elif os.environ.get("PYOPENCL_CTX", "").strip():
            print(f"* = the default device (PYOPENCL_CTX={os.environ['PYOPENCL_CTX'].strip()})")
        else:
            print("* = the default device (PYOPENCL_CTX unset: the first GPU, else the first CPU)")
    if problem is not None:
        raise problem
    return 0


# -- clcsg info -------------------------------------------------------------------------------


def add_info_parser(subparsers):
    from ..compile.dnf import DEFAULT_TERM_LIMIT

    p = add_subcommand(
        subparsers,
        "info",
        help="normalize a scene and print its statistics",
        description="""
            Load a scene (.json or OpenSCAD .csg), normalize it to disjunctive normal form (a
            union of intersections of quadric literals) and print what the samplers will work
            on: primitives, unique quadrics, DNF terms before and after pruning, term sizes,
            term bounds and the scene bound.  Runs on the host only; the device line shows
            which device sample/render would use.
        """,
        epilog="""
            examples:
              clcsg info examples/bracket.json
              clcsg info model.csg --term-limit 1000000
              clcsg info examples/bracket.json --bound -1,-1,-1,1,1,1
              clcsg info examples/bracket.json --json > stats.json
        """,
    )
    p.add_argument("scene", metavar="SCENE", help="scene file (.json or OpenSCAD .csg)")
    p.add_argument(
        "--term-limit",
        metavar="N",
        type=positive_int,
        default=None,
        help=f"stop with exit code 5 if the DNF would have more than N terms (default: {DEFAULT_TERM_LIMIT})",
    )
    p.add_argument(
        "--bound",
        metavar="x0,y0,z0,x1,y1,z1",
        default=None,
        help="box that clips unbounded terms (overrides the scene's own bound)",
    )
    p.add_argument("--json", action="store_true", help="print the statistics as JSON")


MAX_LISTED_TERMS = 20


def scene_info(
    scene, term_limit: int | None = None, bound=None, device: str | None = None, _device: dict | None = None
) -> dict:
    """Statistics of ``scene`` (a Scene, Shape or path) as plain JSON-able data.

    ``bound`` ((2, 3) or None) overrides the scene's bound.  ``device`` is a device spec; the
    result's ``"device"`` is that device's info, or None with ``"device_problem"`` set when no
    device is available and none was asked for explicitly.
    """
    from ..model.scene import as_scene

    sc = as_scene(scene, bound)
    dnf = sc.normalize(term_limit)
    sizes = [len(t) for t in dnf.terms]
    out = {
        "scene": sc.source,
        "stats": {k: (v.item() if hasattr(v, "item") else v) for k, v in dnf.stats.items()},
        "term_sizes": {
            "min": min(sizes, default=0),
            "mean": float(np.mean(sizes)) if sizes else 0.0,
            "max": max(sizes, default=0),
        },
        "term_bounds": dnf.term_bounds.tolist(),
        "bound": dnf.bound.tolist() if dnf.n_terms else None,
        "user_bound": None if sc.bound is None else np.asarray(sc.bound, dtype=float).tolist(),
        "user_bound_from": None if sc.bound is None else ("--bound" if bound is not None else "scene"),
    }
    out.update(device_summary(device) if _device is None else _device)
    return out


def device_summary(spec: str | None) -> dict:
    """``{"device": info dict}`` for the device ``spec`` selects.

    With ``spec`` None and no usable device: ``{"device": None, "device_problem": message}``
    (host-only commands still work); an explicit ``spec`` that fails raises DeviceError.
    """
    from ..cl.device import choose, list_devices

    try:
        infos = list_devices()
        return {"device": infos[choose(infos, spec, os.environ)].as_dict()}
    except DeviceError as e:
        if spec is not None:
            raise
        return {"device": None, "device_problem": str(e)}


def format_info(info: dict) -> str:
    """The text ``clcsg info`` prints for a :func:`scene_info` result."""
    s = info["stats"]
    lines = []

    def row(label, value):
        lines.append(f"{label + ':':<22}{value}")

    row("scene", info["scene"])
    d = info.get("device")
    if d is not None:
        fp64 = "fp64" if d["fp64"] else "no fp64"
        atomics = "64-bit atomics" if d["int64_atomics"] else "no 64-bit atomics"
        feats = f"{d['type']}, {fp64}, {atomics}"
        row("device", f"{d['spec']} {d['name']} ({feats})")
    else:
        row("device", f"none ({info.get('device_problem', 'not available')})")
    row("primitives", s["primitives"])
    row("literal instances", s["literal_instances"])
    row("unique quadrics", s["unique_quadrics"])
    row("DNF terms", f"{s['terms']} after pruning, {s['terms_before_pruning']} before")
    lines.append(
        f"  pruned while distributing: {s['terms_pruned_contradiction']} holding K and not-K, "
        f"{s['terms_pruned_disjoint']} with disjoint literal boxes"
    )
    lines.append(f"  pruned after:              {s['terms_pruned_empty']} with an empty supporting polytope")
    ts = info["term_sizes"]
    row(
        "term sizes",
        f"min {ts['min']}, mean {ts['mean']:.3g}, max {ts['max']} literals ({s['literals']} in all)",
    )
    tb = info["term_bounds"]
    if tb:
        lines.append("term bounds:")
        w = len(str(len(tb) - 1))
        for k, b in enumerate(tb[:MAX_LISTED_TERMS]):
            lines.append(f"  {k:>{w}}  {_box(b)}")
        if len(tb) > MAX_LISTED_TERMS:
            lines.append(f"  ... and {len(tb) - MAX_LISTED_TERMS} more (all of them with --json)")
    if info["user_bound"] is not None:
        src = "from --bound" if info["user_bound_from"] == "--bound" else "from the scene file"
        row("user bound", f"{_box(info['user_bound'])} ({src})")
    row("scene bound", "empty (the solid has no points)" if info["bound"] is None else _box(info["bound"]))
    return "\n".join(lines)


def run_info(args) -> int:
    from ..model.scene import load

    bound = None if args.bound is None else parse_bound(args.bound, "--bound")
    dev = device_summary(args.device)  # a bad --device fails before the scene is read
    scene = load(args.scene)
    info = scene_info(scene, term_limit=args.term_limit, bound=bound, _device=dev)
    if args.json:
        print(json.dumps(info, indent=2))
    else:
        print(format_info(info))
    return 0


# -- clcsg sample -----------------------------------------------------------------------------


def add_sample_parser(subparsers):
    from ..compile.dnf import DEFAULT_TERM_LIMIT

    p = add_subcommand(
        subparsers,
        "sample",
        help="sample the CSG surface and write a PLY point cloud",
        description="""
            Generate samples on the exact CSG surface (paper: Trettner & Kobbelt 2021): every
            sample lies on the surface, and every point of the surface has a sample on the
            same quadric within RADIUS.  Writes a binary PLY (x y z nx ny nz quadric radius)
            that Open3D and MeshLab read.
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
    p.add_argument("--term-limit", metavar="N", type=positive_int, default=None,
                   help=f"stop with exit code 5 past N DNF terms (default: {DEFAULT_TERM_LIMIT})")
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


def run_sample(args) -> int:
    from ..sampling.sampler import sample
    from ..model.scene import as_scene, load

    radius = parse_positive(args.radius, "--radius")
    floor = None if args.floor is None else parse_positive(args.floor, "--floor")
    bound = None if args.bound is None else parse_bound(args.bound, "--bound")
    from ..cl.device import get_context

    ctx = get_context(args.device)
    scene = as_scene(load(args.scene), bound)
    s = sample(scene, radius, device=ctx, floor=floor, term_limit=args.term_limit,
               progress=False if args.no_progress else None, max_samples=args.max_samples)
    s.to_ply(args.output)
    if args.stats:
        with open(args.stats, "w") as f:
            json.dump(s.stats, f, indent=2, default=_jsonable)
    st = s.stats
    print(f"{len(s)} samples on {st['dnf_unique_quadrics']} quadrics, {st['dnf_terms']} terms "
          f"({st['distance_queries']} distance queries, {st['levels']} levels, "
          f"{st['unresolved']} unresolved cells) in {st['total_s']:.3f} s -> {args.output}")
    return 0


def _jsonable(x):
    if hasattr(x, "tolist"):
        return x.tolist()
    if hasattr(x, "item"):
        return x.item()
    return str(x)


# -- the dispatch table -----------------------------------------------------------------------

def _lazy(module: str, name: str) -> Callable:
    """A function of ``clcsg.<module>`` imported on first call (keeps ``clcsg --help`` fast)."""

    def call(*args, **kw):
        import importlib

        return getattr(importlib.import_module(f"clcsg.{module}"), name)(*args, **kw)

    call.__name__ = name
    return call


#: name -> (add_<name>_parser(subparsers), run_<name>(args) -> exit code), in --help order
COMMANDS: dict[str, tuple[Callable, Callable]] = {
    "devices": (add_devices_parser, run_devices),
    "info": (add_info_parser, run_info),
    # ---- more subcommands go here, in the same style: ----
    "sample": (add_sample_parser, run_sample),
    "render": (_lazy("cli.render", "add_render_parser"), _lazy("cli.render", "cli_render")),
}


def build_parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(
        prog=PROG,
        description="Exact point sampling and splat rendering of quadric CSG solids on OpenCL.",
        epilog=textwrap.dedent(
            """
            examples:
              clcsg devices                         # list OpenCL devices, '*' = default
              clcsg info examples/bracket.json      # DNF statistics of a scene
              clcsg info --help                     # options of a subcommand

            exit codes: 0 ok, 1 internal error, 2 bad command line, 3 bad input,
                        4 OpenCL device problem, 5 a limit was hit
            """
        ).strip(),
        formatter_class=_Formatter,
    )
    parser.add_argument("--version", action="version", version=f"%(prog)s {__version__}")
    parser.add_argument("--debug", action="store_true", help="show the traceback on errors")
    sub = parser.add_subparsers(dest="command", metavar="COMMAND", title="commands")
    sub.required = True
    for add, _run in COMMANDS.values():
        add(sub)
    return parser


def _err(msg: str) -> None:
    print(f"{PROG}: {msg}", file=sys.stderr, flush=True)


def _format_warning(message, category, filename, lineno, line=None) -> str:
    """Warnings as one line, like errors: ``clcsg: warning: <message>``."""
    return f"{PROG}: warning: {' '.join(str(message).split())}\n"


def main(argv: list[str] | None = None) -> int:
    """Run the command line; returns the exit code (never raises unless ``--debug``)."""
    import warnings

    warnings.formatwarning = _format_warning
    argv = list(sys.argv[1:] if argv is None else argv)
    debug = "--debug" in argv  # known even if parsing fails
    try:
        parser = build_parser()
        try:
            args = parser.parse_args(join_negative_vectors(argv))
        except SystemExit as e:  # --help, --version, bad command line
            return e.code if isinstance(e.code, int) else (0 if e.code is None else 2)
        debug = bool(getattr(args, "debug", False))
        _add, run = COMMANDS[args.command]
        return int(run(args) or 0)
    except ClcsgError as e:
        if debug:
            raise
        msg = " ".join(str(e).split("\n")) or type(e).__name__
        _err(f"error: {msg}")
        return e.exit_code
    except KeyboardInterrupt:
        if debug:
            raise
        _err("interrupted")
        return 130
    except BrokenPipeError:  # e.g. `clcsg devices | head -1`
        try:
            devnull = os.open(os.devnull, os.O_WRONLY)
            os.dup2(devnull, sys.stdout.fileno())
        except (OSError, ValueError):
            pass
        return 1
    except Exception as e:  # a bug
        if debug:
            raise
        msg = " ".join(str(e).split()) or "(no message)"
        _err(f"internal error: {type(e).__name__}: {msg} (run with --debug for the traceback)")
        return 1


if __name__ == "__main__":  # pragma: no cover
    sys.exit(main())
