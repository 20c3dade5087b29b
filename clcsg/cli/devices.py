"""``clcsg devices``: list the OpenCL devices and mark the one that would be used."""

from __future__ import annotations

import json
import os

from ..errors import DeviceError
from .app import SUMMARIES, add_subcommand
from ..cl.device import _build_error, _enumerate, choose_usable

def add_parser(subparsers):
    p = add_subcommand(
        subparsers,
        "devices",
        help=SUMMARIES["devices"],
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


def run(args) -> int:
    found = _enumerate()
    infos = [i for i, _ in found]
    errors: dict = {}

    def build_error(k):
        errors[k] = _build_error(found[k][1])
        return errors[k]

    problem = None
    try:
        chosen = choose_usable(infos, args.device, os.environ, build_error)
    except DeviceError as e:
        if args.device is not None:
            raise
        chosen, problem = None, e  # show the table anyway: it helps fix PYOPENCL_CTX
    if args.json:
        rows = [dict(i.as_dict(), selected=(k == chosen), build_error=errors.get(k)) for k, i in enumerate(infos)]
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
                    "(simulator, never chosen by default)" if i.is_oclgrind
                    else f"(cannot compile: {errors[k]})" if errors.get(k) else "",
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
