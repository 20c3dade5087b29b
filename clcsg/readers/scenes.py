"""Scene files in and out, the format picked from the file name: ``.json`` is clcsg's own
scene format (:mod:`clcsg.readers.scenefile`), ``.csg`` is OpenSCAD's CSG export
(:mod:`clcsg.readers.openscad`) and ``.scad`` an OpenSCAD program, exported to CSG by the
``openscad`` binary first (:mod:`clcsg.readers.scad`).  :func:`as_scene` is what every API
that takes "a Shape, a Scene or a path" calls."""

from __future__ import annotations

import importlib
import os

import numpy as np

from ..errors import SceneError
from ..model.csg import Shape
from ..model.scene import Scene

#: file name extension -> (module of this folder, its loader): a reader is imported when its
#: format is read, so a command pays only for its own (the JSON reader's streaming parser, the
#: OpenSCAD tokenizer)
READERS = {".json": ("scene_stream", "load_json"), ".csg": ("openscad", "load_csg"), ".scad": ("scad", "load_scad")}
#: the JSON writer (beside the JSON reader, whose imports reach most of :mod:`clcsg.model`:
#: 8 ms of a short run that only reads a ``.csg``), imported when a scene is saved
WRITER = ("scenefile", "save_json")


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
    if ext not in READERS:
        *first, last = READERS
        raise SceneError(f"{p}: unknown scene format {ext!r} (expected {', '.join(first)} or {last})")
    module, name = READERS[ext]
    return getattr(importlib.import_module(f"{__package__}.{module}"), name)(p)


def save(obj, path) -> None:
    """Save a Shape or Scene as a ``.json`` scene file."""
    p = os.fspath(path)
    if os.path.splitext(p)[1].lower() != ".json":
        raise SceneError(f"{p}: scenes are saved as .json")
    module, name = WRITER
    getattr(importlib.import_module(f"{__package__}.{module}"), name)(as_scene(obj), p)
