"""``clcsg info``: what a scene compiles to (primitives, quadrics, the tape, DNF size, bound)."""

from __future__ import annotations

import json
import os

from ..errors import DeviceError
from ..readers import scenes
from .app import SUMMARIES, _box, add_subcommand, parse_bound, positive_int
from ..compile.dnf import DEFAULT_TERM_LIMIT
from ..cl.device import choose, list_devices
from ..compile.summary import scene_info
from .runs import Run


def add_parser(subparsers):
    p = add_subcommand(
        subparsers,
        "info",
        help=SUMMARIES["info"],
        description="""
            Load a scene (.json, OpenSCAD .csg or .scad), compile it to a tape over unique
            canonical quadrics and print what the sampler and the renderers will work on:
            primitives, unique quadrics, the tape (instructions, leaves, registers, depth), the
            number of terms its disjunctive normal form would have (counted, not built) and the
            scene bound.  With --normal-form dnf the DNF is built too, with its pruning
            statistics.  Runs on the host only; the device line shows which device sample and
            render would use.
        """,
        epilog="""
            examples:
              clcsg info examples/rook.csg
              clcsg info examples/bracket.json --normal-form dnf
              clcsg info examples/bracket.json --bound -1,-1,-1,1,1,1
              clcsg info examples/bracket.json --json > stats.json
        """,
    )
    p.add_argument("scene", metavar="SCENE", help="scene file (.json, OpenSCAD .csg or .scad)")
    p.add_argument("--normal-form", choices=("tree", "dnf"), default="tree",
                   help="tree (default) or dnf: also build the disjunctive normal form")
    p.add_argument("--term-limit", metavar="N", type=positive_int, default=None,
                   help=f"with --normal-form dnf: stop with exit code 5 past N terms (default: {DEFAULT_TERM_LIMIT})")
    p.add_argument("--bound", metavar="x0,y0,z0,x1,y1,z1", default=None,
                   help="box that clips an unbounded solid (overrides the scene's own bound)")
    p.add_argument("--tape", action="store_true", help="also list the tape's first instructions")
    p.add_argument("--json", action="store_true", help="print the statistics as JSON")


def device_summary(spec: str | None) -> dict:
    """``{"device": info dict}`` for the device ``spec`` selects.

    With ``spec`` None and no usable device: ``{"device": None, "device_problem": message}``
    (host-only commands still work); an explicit ``spec`` that fails raises DeviceError.
    """
    try:
        infos = list_devices()
        return {"device": infos[choose(infos, spec, os.environ)].as_dict()}
    except DeviceError as e:
        if spec is not None:
            raise
        return {"device": None, "device_problem": str(e)}


def format_info(info: dict) -> str:
    """The text ``clcsg info`` prints for a :func:`clcsg.compile.summary.scene_info` result."""
    t = info["tape"]
    lines = []

    def row(label, value):
        lines.append(f"{label + ':':<22}{value}")

    row("scene", info["scene"])
    d = info.get("device")
    if d is not None:
        fp64 = "fp64" if d["fp64"] else "no fp64"
        atomics = "64-bit atomics" if d["int64_atomics"] else "no 64-bit atomics"
        row("device", f"{d['spec']} {d['name']} ({d['type']}, {fp64}, {atomics})")
    else:
        row("device", f"none ({info.get('device_problem', 'not available')})")
    row("primitives", t["primitives"])
    for k, line in enumerate(info.get("constructions", [])):
        lines.append(f"{'constructions:' if k == 0 else '':<22}{line}")
    row("unique quadrics", f"{info['unique_quadrics']} ({t['quadrics']} in the tape)")
    row("tape", f"{t['instructions']} instructions, {t['leaves']} leaves, {t['registers']} registers, "
                f"depth {t['depth']}")
    terms = info["dnf_terms"]
    row("DNF terms", f"{terms} (counted, not built)" if terms is not None else "more than 1e300 (counted, not built)")
    dnf = info.get("dnf")
    if dnf is not None:
        s = dnf["stats"]
        row("DNF built", f"{s['terms']} terms after pruning, {s['terms_before_pruning']} before, "
                         f"{s['literals']} literals, as a tape of {dnf['tape']['instructions']} instructions")
    if info.get("listing"):
        lines.append("tape listing:")
        lines.extend("  " + ln for ln in info["listing"].splitlines())
    if info["user_bound"] is not None:
        src = "from --bound" if info["user_bound_from"] == "--bound" else "from the scene file"
        row("user bound", f"{_box(info['user_bound'])} ({src})")
    row("scene bound", "empty (the solid has no points)" if info["bound"] is None else _box(info["bound"]))
    return "\n".join(lines)


def run(args) -> int:
    bound = None if args.bound is None else parse_bound(args.bound, "--bound")
    dev = device_summary(args.device)  # a bad --device fails before the scene is read
    run = Run("info")
    with run.step("load", f"loading {args.scene}"):
        scene = scenes.load(args.scene)
    with run.step("compile", "compiling the scene" + (" and its DNF" if args.normal_form == "dnf" else "")):
        info = scene_info(scene, normal_form=args.normal_form, term_limit=args.term_limit, bound=bound,
                          listing=args.tape)
    info.update(dev)
    print(json.dumps(info, indent=2) if args.json else format_info(info))
    if not args.json:  # --json output stays one JSON document
        t = info["tape"]
        run.summary(f"{args.scene}: {t['primitives']} primitives, {info['unique_quadrics']} unique quadrics, "
                    f"tape of {t['instructions']} instructions")
    else:
        run.reporter.close_all()
    return 0
