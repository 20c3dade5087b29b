"""The ``clcsg`` command line.

Each subcommand is a module of this package with two functions: ``add_parser(subparsers)``
builds its argparse parser (with :func:`add_subcommand`, which adds the common options such as
``--device``), and ``run(args) -> int`` does the work.  :data:`COMMANDS` is the dispatch table
(modules are imported on first use, which keeps ``clcsg --help`` fast); to add a subcommand,
write the module and add one line there.  Only the chosen command's module is imported (and
its parser built): ``clcsg --version`` and ``clcsg --help`` load neither numpy nor pyopencl.

Errors: a :class:`~clcsg.errors.ClcsgError` prints ``clcsg: error: <message>`` (one line) and
exits with its ``exit_code``; a bad command line exits 2 (argparse); Ctrl-C exits 130; anything
else is a bug and prints ``clcsg: internal error: ...`` and exits 1.  ``--debug`` re-raises
instead, to show the traceback.

Progress: every subcommand takes ``--progress {auto,bar,json,none}`` and ``--quiet``;
:func:`main` makes the matching :class:`~clcsg.progress.Reporter` the current one while the
command runs (steps longer than half a second get a bar on a terminal, nothing in a pipe; with
``json`` every event, warnings and errors included, is one JSON object per line on stderr).
Commands end with a one-line summary on stdout (not with ``--quiet``).
"""

from __future__ import annotations

import argparse
import json
import math
import os
import re
import sys
import textwrap
import importlib
import warnings
from typing import Callable

from .. import __version__
from ..errors import ClcsgError, UsageError
from ..progress import Reporter, using
from ..sampling.radius import Radius

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


def parse_bound(text: str, name: str = "--bound") -> tuple:
    """A bound ``((x0, y0, z0), (x1, y1, z1))`` from ``"x0,y0,z0,x1,y1,z1"`` with lo < hi on
    every axis."""
    v = parse_floats(text, 6, name)
    lo, hi = v[:3], v[3:]
    if any(b <= a for a, b in zip(lo, hi)):
        raise UsageError(f"{name}: need x0 < x1, y0 < y1 and z0 < z1, got {text!r}")
    return lo, hi


_NEGATIVE_VECTOR = re.compile(r"^-\.?\d.*,")


def parse_radius(text: str, name: str = "--radius"):
    """``--radius``: scene units or a percentage of the bound's diagonal
    (:class:`~clcsg.sampling.radius.Radius`)."""
    return Radius.parse(text, name)


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


PROGRESS_HELP = (
    "progress on stderr: 'auto' (default: bars on a terminal, nothing in a pipe), 'bar', 'json' (one JSON "
    "object per line: start, progress, end, warning, error and summary events) or 'none'"
)

#: what "unresolved cells" are, for the epilogs of the commands that sample
UNRESOLVED_HELP = """
    unresolved cells:
      The sampler subdivides every quadric's sampling planes into cells.  A cell it still cannot
      decide (surface or not, covered or not) when it has shrunk below the floor (clcsg sample
      --floor; default min(RADIUS / 10, 1/1000 of the scene's diagonal)) is dropped and counted as
      "unresolved" (statistic "unresolved").  Such cells lie along edges and tangent contacts,
      where two surfaces meet: thousands are normal, their number grows with the length of the
      edges over the floor.  The coverage guarantee holds for every feature wider than the
      floor; a feature thinner than the floor can be missed: pass a smaller --floor.
"""


def add_subcommand(subparsers, name: str, help: str, description: str, epilog: str = ""):
    """A subcommand parser with the options every subcommand has (``--device``, ``--debug``,
    ``--quiet``, ``--progress``)."""
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
    g.add_argument("-q", "--quiet", action="store_true", help="no progress and no summary line (errors and "
                   "warnings are still shown)")
    g.add_argument("--progress", choices=("auto", "bar", "json", "none"), default="auto", help=PROGRESS_HELP)
    return p


def _fmt(x: float) -> str:
    return f"{float(x):.6g}"


def _vec(v) -> str:
    return "(" + ", ".join(_fmt(x) for x in v) + ")"


def _box(b) -> str:
    return f"{_vec(b[0])} .. {_vec(b[1])}"


def _jsonable(x):
    if hasattr(x, "tolist"):
        return x.tolist()
    if hasattr(x, "item"):
        return x.item()
    return str(x)


# -- the dispatch table -----------------------------------------------------------------------

def _lazy(module: str, name: str) -> Callable:
    """Function ``name`` of ``clcsg.cli.<module>``, imported on first call."""

    def call(*args, **kw):
        return getattr(importlib.import_module(f"clcsg.cli.{module}"), name)(*args, **kw)

    call.__name__ = f"{module}.{name}"
    return call


def _command(module: str) -> tuple[Callable, Callable]:
    return _lazy(module, "add_parser"), _lazy(module, "run")


#: name -> (add_parser(subparsers), run(args) -> exit code), in --help order
COMMANDS: dict[str, tuple[Callable, Callable]] = {
    "devices": _command("devices"),
    "info": _command("info"),
    "sample": _command("sample"),
    "render": _command("render"),
    "batch": _command("batch"),
    "view": _command("view"),
    "mesh": _command("mesh"),
}

#: the one-line help of each command in ``clcsg --help`` (the command's own parser is built only
#: when it runs)
SUMMARIES = {
    "devices": "list OpenCL devices and show which one is used",
    "info": "compile a scene and print its statistics",
    "sample": "sample the CSG surface and write a PLY point cloud (or .npz)",
    "render": "render a scene to an image (splats or exact ray tracing)",
    "batch": "sample (and render) many scenes into a folder: process pool or Dask, restartable",
    "view": "preview a scene in the web browser, redrawn when the file changes",
    "mesh": "write a closed triangle mesh (STL, 3MF, OBJ, PLY, OFF) with vertices on the exact surface",
}


def _chosen(argv: list[str]) -> str | None:
    """The command named in ``argv`` (the first word that is one), or None."""
    return next((a for a in argv if a in COMMANDS), None)


def build_parser(argv: list[str] | None = None) -> argparse.ArgumentParser:
    """The parser; with ``argv``, only the command it names gets its full parser (the others
    are listed with their one-line help), so a command imports only what it uses."""
    parser = argparse.ArgumentParser(
        prog=PROG,
        description="Exact point sampling and splat rendering of quadric CSG solids on OpenCL.",
        epilog=textwrap.dedent(
            """
            examples:
              clcsg devices                         # list OpenCL devices, '*' = default
              clcsg info examples/bracket.json      # tape statistics of a scene
              clcsg info --help                     # options of a subcommand

            exit codes: 0 ok, 1 internal error, 2 bad command line, 3 bad input,
                        4 OpenCL device problem, 5 a limit was hit, 6 an output could not be written
            """
        ).strip(),
        formatter_class=_Formatter,
    )
    parser.add_argument("--version", action="version", version=f"%(prog)s {__version__}")
    parser.add_argument("--debug", action="store_true", help="show the traceback on errors")
    sub = parser.add_subparsers(dest="command", metavar="COMMAND", title="commands")
    sub.required = True
    chosen = None if argv is None else _chosen(argv)
    for name, (add, _run) in COMMANDS.items():
        if argv is None or name == chosen:
            add(sub)
        else:
            sub.add_parser(name, help=SUMMARIES[name], add_help=False)
    return parser


def _err(msg: str) -> None:
    print(f"{PROG}: {msg}", file=sys.stderr, flush=True)


def _format_warning(message, category, filename, lineno, line=None) -> str:
    """Warnings as one line, like errors: ``clcsg: warning: <message>``."""
    return f"{PROG}: warning: {' '.join(str(message).split())}\n"


def _json_warning(message, category, filename, lineno, line=None) -> str:
    """Warnings as JSON lines (``--progress json``)."""
    return json.dumps({"event": "warning", "message": " ".join(str(message).split()),
                       "category": category.__name__}) + "\n"


def _reporter(args):
    """The progress reporter that ``args`` (--progress, --quiet, sample's --no-progress) ask for."""
    mode = getattr(args, "progress", "auto")
    if getattr(args, "no_progress", False) and mode != "json":
        mode = "none"
    quiet = bool(getattr(args, "quiet", False))
    if quiet and mode in ("auto", "bar"):
        mode = "none"
    return Reporter(mode, quiet=quiet)


def main(argv: list[str] | None = None) -> int:
    """Run the command line; returns the exit code (never raises unless ``--debug``)."""
    warnings.formatwarning = _format_warning
    argv = list(sys.argv[1:] if argv is None else argv)
    debug = "--debug" in argv  # known even if parsing fails
    as_json = False
    try:
        argv = join_negative_vectors(argv)
        parser = build_parser(argv)
        try:
            args = parser.parse_args(argv)
        except SystemExit as e:  # --help, --version, bad command line
            return e.code if isinstance(e.code, int) else (0 if e.code is None else 2)
        debug = bool(getattr(args, "debug", False))
        rep = _reporter(args)
        as_json = rep.mode == "json"
        if as_json:
            warnings.formatwarning = _json_warning
        _add, run = COMMANDS[args.command]
        with using(rep):
            return int(run(args) or 0)
    except ClcsgError as e:
        if debug:
            raise
        msg = " ".join(str(e).split("\n")) or type(e).__name__
        if as_json:
            print(json.dumps({"event": "error", "message": msg, "exit_code": e.exit_code}), file=sys.stderr, flush=True)
        else:
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


def console() -> None:
    """The ``clcsg`` program: :func:`main`, then leave the process without Python's teardown.

    Every output file is complete when :func:`main` returns (written through
    :mod:`clcsg.atomic`: synced and renamed), so the teardown would only free memory: collect
    the garbage of a few hundred modules and release the OpenCL context, about 20 ms, a tenth
    of a small job's process.  Standard output and error are flushed first; the teardown still
    runs where another (non-daemon) thread or ``--debug`` asks for it."""
    code = main()
    import threading

    if "--debug" in sys.argv or any(t is not threading.main_thread() and not t.daemon
                                    for t in threading.enumerate()):
        sys.exit(code)
    for stream in (sys.stdout, sys.stderr):
        try:
            stream.flush()
        except (OSError, ValueError):
            code = code or 1
    os._exit(code)

