"""A scene: a CSG shape plus the optional bound that unbounded terms are clipped to.

``load`` and ``save`` pick the format from the file name: ``.json`` is clcsg's own scene
format (:mod:`clcsg.readers.scenefile`), ``.csg`` is OpenSCAD's CSG export (:mod:`clcsg.readers.openscad`)
and ``.scad`` an OpenSCAD program, exported to CSG by the ``openscad`` binary first
(:mod:`clcsg.readers.scad`).
"""

from __future__ import annotations

import os
from dataclasses import dataclass, field

import numpy as np

from .csg import Shape
from ..errors import SceneError


@dataclass
class Scene:
    shape: Shape
    bound: np.ndarray | None = None  # (2, 3) lo, hi corners, or None
    source: str = "scene"  # file name or description, used in error messages
    _tapes: dict = field(default_factory=dict, init=False, repr=False, compare=False)

    def compile(self, normal_form: str = "tree", term_limit: int | None = None):
        """The scene's :class:`~clcsg.compile.tape.Tape`: the CSG tree itself (``"tree"``, the
        default) or the paper's disjunctive normal form as an OR of ANDs (``"dnf"``; the term
        limit applies to it only).  Compiled once per (shape, bound, normal form, term limit):
        the callers that need the bound before sampling (a relative radius, the viewer, the
        batch tasks) and the sampler share one tape."""
        from ..compile.tape import compile_scene

        bound = None if self.bound is None else np.asarray(self.bound, dtype=np.float64).tobytes()
        key = (bound, normal_form, term_limit)
        shape, tape = self._tapes.get(key, (None, None))
        if shape is not self.shape:
            tape = compile_scene(self, normal_form, term_limit)
            self._tapes[key] = (self.shape, tape)
        return tape

    def normalize(self, term_limit: int | None = None):
        """The scene's :class:`~clcsg.compile.dnf.Dnf`."""
        from ..compile.dnf import DEFAULT_TERM_LIMIT, normalize

        return normalize(
            self.shape,
            term_limit=DEFAULT_TERM_LIMIT if term_limit is None else term_limit,
            user_bound=self.bound,
            source=self.source,
        )


def as_scene(obj, bound=None) -> Scene:
    """A :class:`Scene` from a Scene, a Shape or a path."""
    if isinstance(obj, Scene):
        if bound is not None:
            return Scene(obj.shape, np.asarray(bound, dtype=float), obj.source)
        return obj
    if isinstance(obj, Shape):
        return Scene(obj, None if bound is None else np.asarray(bound, dtype=float))
    if isinstance(obj, (str, os.PathLike)):
        sc = load(obj)
        return as_scene(sc, bound)
    raise SceneError(f"expected a Shape, a Scene or a scene file path, got {type(obj).__name__}")


def load(path) -> Scene:
    """Load a scene file (``.json``, OpenSCAD ``.csg``, or OpenSCAD ``.scad`` via ``openscad``)."""
    p = os.fspath(path)
    if not os.path.exists(p):
        raise SceneError(f"{p}: no such file")
    ext = os.path.splitext(p)[1].lower()
    if ext == ".json":
        from ..readers.scenefile import load_json

        return load_json(p)
    if ext == ".csg":
        from ..readers.openscad import load_csg

        return load_csg(p)
    if ext == ".scad":
        from ..readers.scad import load_scad

        return load_scad(p)
    raise SceneError(f"{p}: unknown scene format {ext!r} (expected .json, .csg or .scad)")


def save(obj, path) -> None:
    """Save a Shape or Scene as a ``.json`` scene file."""
    p = os.fspath(path)
    if os.path.splitext(p)[1].lower() != ".json":
        raise SceneError(f"{p}: scenes are saved as .json")
    from ..readers.scenefile import save_json

    save_json(as_scene(obj), p)
