"""2-D profile objects of the scene format (``{"square": ...}``, ``{"polygon": ...}``, ...)
turned into :class:`~clcsg.model.profile.Profile` s.  The schema has checked the structure;
this checks one kind key per object and builds it (2-D transform steps applied in order).
Saving needs nothing here: a profile records its own scene-file object (``Profile.spec``)."""

from __future__ import annotations

import numpy as np

from ..errors import SceneError
from ..model.profile import circle, difference2d, intersection2d, polygon, square, union2d
from ..model.profile_ops import hull2d_of, offset
from .scene_schema import key

PROFILE_KINDS = ("square", "circle", "polygon", "offset", "hull", "union", "intersection", "difference")


def profile_from_json(v: dict, path: str, fail):
    """The profile of scene-file object ``v`` at JSON ``path``; ``fail(path, reason)`` raises."""
    kinds = [k for k in v if k in PROFILE_KINDS]
    if len(kinds) != 1:
        fail(path, f"a profile needs exactly one of {', '.join(PROFILE_KINDS)}, got {len(kinds)}")
    kind = kinds[0]
    arg, kpath = v[kind], key(path, kind)
    try:
        if kind == "square":
            p = square(arg.get("size", 1.0), arg.get("center", False))
        elif kind == "circle":
            p = circle(arg.get("radius", 1.0), arg.get("center", (0.0, 0.0)))
        elif kind == "polygon":
            p = polygon(arg["points"], arg.get("paths"))
        elif kind == "offset":
            child = profile_from_json(arg["profile"], key(kpath, "profile"), fail)
            if ("r" in arg) == ("delta" in arg):
                fail(kpath, "offset needs exactly one of r and delta")
            p = offset(child, r=arg.get("r"), delta=arg.get("delta"), chamfer=arg.get("chamfer", False))
        else:
            kids = [profile_from_json(c, f"{kpath}[{i}]", fail) for i, c in enumerate(arg)]
            if kind != "union" and not kids:
                fail(kpath, f"{kind} needs at least one profile")
            p = {"union": union2d, "intersection": intersection2d, "difference": difference2d,
                 "hull": hull2d_of}[kind](*kids)
    except SceneError as e:
        fail(kpath, str(e))
    for i, step in enumerate(v.get("transform", [])):
        (op, a), = step.items()
        try:
            if op == "translate":
                p = p.translate(a)
            elif op == "rotate":
                p = p.rotate(a)
            elif op == "scale":
                p = p.scale(a)
            elif op == "mirror":
                p = p.mirror(a)
            else:
                p = p.transform(np.asarray(a, dtype=np.float64))
        except (SceneError, ValueError, ArithmeticError) as e:
            fail(key(f"{key(path, 'transform')}[{i}]", op), str(e))
    return p
