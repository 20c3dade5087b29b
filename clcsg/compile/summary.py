"""A compiled scene's statistics as plain JSON-able data (``clcsg info``)."""

from __future__ import annotations

import math

import numpy as np

from ..model.construction import Construction
from ..model.csg import walk
from ..model.scene import Scene
from ..model.surfels import with_surfaces


def _plain(v):
    return v.item() if hasattr(v, "item") else v


def constructions(shape) -> list[str]:
    """What each construction (extrusion, revolution, hull, Minkowski sum) of the graph expands
    to, one line each: 'hull of 8 spheres: 12 planes, 12 cylinders, 8 spheres'."""
    return [n.describe() for n in walk(shape) if isinstance(n, Construction)]


def scene_info(scene, normal_form: str = "tree", term_limit: int | None = None, bound=None,
               listing: bool = False) -> dict:
    """Statistics of ``scene`` (a Scene or Shape): the tape's, the number of DNF terms
    (counted without building them; None past 1e300), with ``normal_form="dnf"`` the built
    DNF's too, and the bound.  ``bound`` ((2, 3) or None) overrides the scene's bound."""
    sc = scene if isinstance(scene, Scene) else Scene(scene)
    if bound is not None:
        sc = Scene(sc.shape, np.asarray(bound, dtype=float), sc.source)
    tape = sc.compile("tree")
    st = {k: _plain(v) for k, v in tape.stats.items()}
    terms = st.pop("dnf_terms")
    out = {
        "scene": sc.source,
        "unique_quadrics": tape.n_quadrics,
        "tape": st,
        "dnf_terms": int(terms) if math.isfinite(terms) and terms < 2**63 else (None if not math.isfinite(terms) else terms),
        "bound": None if tape.empty else np.asarray(tape.bound).tolist(),
        "user_bound": None if sc.bound is None else np.asarray(sc.bound, dtype=float).tolist(),
        "user_bound_from": None if sc.bound is None else ("--bound" if bound is not None else "scene"),
    }
    out["constructions"] = constructions(with_surfaces(sc.shape))  # a point operand: its surface mesh
    if normal_form == "dnf":
        dnf = sc.compile("dnf", term_limit)
        out["dnf"] = {
            "stats": {k[4:]: _plain(v) for k, v in dnf.stats.items() if k.startswith("dnf_") and k != "dnf_terms"}
            | {"terms": dnf.stats["terms"]},
            "tape": {k: _plain(v) for k, v in dnf.stats.items() if not k.startswith("dnf_")},
        }
    if listing:
        out["listing"] = tape.describe()
    return out
