"""Batch inputs: scene files named by paths, globs, directories or manifest files, and scenes
given as Python objects, turned into :class:`Job` s (one per scene).

An input is

* a scene file (``.json``, OpenSCAD ``.csg`` or ``.scad``);
* a directory: every scene file under it (recursively, sorted);
* a glob (``scenes/*.csg``, ``**`` recurses): every scene file or directory it matches;
* any other file: a *manifest*, one scene per line — a path (relative to the manifest's
  folder) or a JSON scene written on one line (``{"root": ...}``); blank lines and lines
  starting with ``#`` are skipped;
* a :class:`~clcsg.model.csg.Shape` or :class:`~clcsg.model.scene.Scene` (Python API only),
  stored as its JSON scene text.

A job holds the scene's text, read once here, so workers need no access to the input files
(except for ``.scad``, which the ``openscad`` binary reads from its path), and the sha256 of
that text, from which the content hash of its outputs is made.  A file that cannot be read is
a job with an error (it gets an error row); an input that names nothing is a UsageError.
Names (the stems of the output files) are the file stems, made safe for file names and unique
in order of appearance (``part``, ``part-2``, ...).
"""

from __future__ import annotations

import glob
import hashlib
import os
import re
from dataclasses import dataclass

from ..errors import UsageError
from ..readers.scenefile import dumps, scene_to_dict
from ..model.csg import Shape
from ..model.scene import Scene

SCENE_EXTENSIONS = (".json", ".csg", ".scad")
_UNSAFE = re.compile(r"[^A-Za-z0-9._-]+")


@dataclass(frozen=True)
class Job:
    """One scene of a batch: ``name`` (unique, the stem of its outputs), ``source`` (its path, or
    ``manifest:line``), ``kind`` (``.json``, ``.csg`` or ``.scad``), ``text`` (None if it could
    not be read), ``path`` (the file, None for inline scenes), ``error`` and ``digest`` (sha256
    of the text)."""

    name: str
    source: str
    kind: str
    text: str | None
    path: str | None = None
    error: str | None = None

    @property
    def digest(self) -> str:
        body = self.text if self.text is not None else f"unreadable:{self.source}"
        return hashlib.sha256(f"{self.kind}\n{body}".encode()).hexdigest()


def _read(path: str) -> tuple[str | None, str | None]:
    """(text, error) of a file."""
    try:
        with open(path, encoding="utf-8-sig") as f:
            return f.read(), None
    except FileNotFoundError:
        return None, f"{path}: no such file"
    except UnicodeDecodeError as e:
        return None, f"{path}: not UTF-8 text ({e.reason} at byte {e.start})"
    except OSError as e:
        return None, f"{path}: cannot read: {e.strerror or e}"


def _scene_file(path: str, stem: str | None = None) -> dict:
    text, error = _read(path)
    kind = os.path.splitext(path)[1].lower()
    return dict(stem=stem or os.path.splitext(os.path.basename(path))[0], source=path, kind=kind, text=text,
                path=path, error=error)


def _in_directory(folder: str) -> list[str]:
    out = []
    for root, dirs, files in os.walk(folder):
        dirs.sort()
        out.extend(os.path.join(root, f) for f in sorted(files) if os.path.splitext(f)[1].lower() in SCENE_EXTENSIONS)
    return out


def _manifest(path: str) -> list[dict]:
    text, error = _read(path)
    if error:
        raise UsageError(error)
    folder = os.path.dirname(path)
    stem = os.path.splitext(os.path.basename(path))[0]
    out = []
    for lineno, line in enumerate(text.splitlines(), 1):
        line = line.strip()
        if not line or line.startswith("#"):
            continue
        where = f"{path}:{lineno}"
        if line.startswith("{"):
            out.append(dict(stem=f"{stem}-{lineno}", source=where, kind=".json", text=line, path=None, error=None))
            continue
        p = line if os.path.isabs(line) else os.path.join(folder, line)
        ext = os.path.splitext(p)[1].lower()
        if ext not in SCENE_EXTENSIONS:
            out.append(dict(stem=f"{stem}-{lineno}", source=where, kind=ext or "?", text=None, path=p,
                            error=f"{where}: {line!r} is not a scene file (expected .json, .csg or .scad)"))
        else:
            out.append(_scene_file(p))
    return out


def _expand_one(item) -> list[dict]:
    p = os.fspath(item)
    if glob.has_magic(p):
        matches = sorted(glob.glob(p, recursive=True))
        files = []
        for m in matches:
            if os.path.isdir(m):
                files.extend(_in_directory(m))
            elif os.path.splitext(m)[1].lower() in SCENE_EXTENSIONS:
                files.append(m)
        if not files:
            raise UsageError(f"{p}: no scene file (.json, .csg, .scad) matches")
        return [_scene_file(f) for f in files]
    if os.path.isdir(p):
        files = _in_directory(p)
        if not files:
            raise UsageError(f"{p}: no scene file (.json, .csg, .scad) in this directory")
        return [_scene_file(f) for f in files]
    if not os.path.exists(p):
        raise UsageError(f"{p}: no such file or directory")
    if os.path.splitext(p)[1].lower() in SCENE_EXTENSIONS:
        return [_scene_file(p)]
    return _manifest(p)


def _object(obj, k: int) -> dict:
    name = f"scene-{k:05d}"
    return dict(stem=name, source=f"<object {k}>", kind=".json", text=dumps(scene_to_dict(obj)), path=None,
                error=None)


def jobs(inputs) -> list[Job]:
    """The jobs of ``inputs`` (one input or a list of them; see the module docstring), in
    order; the same file named twice is one job."""
    if isinstance(inputs, (str, os.PathLike, Shape, Scene)):
        inputs = [inputs]
    items: list[dict] = []
    objects = 0
    for item in inputs:
        if isinstance(item, (Shape, Scene)):
            items.append(_object(item, objects))
            objects += 1
        elif isinstance(item, (str, os.PathLike)):
            items.extend(_expand_one(item))
        else:
            raise UsageError(f"batch inputs are paths, globs, Shapes or Scenes, got {type(item).__name__}")
    if not items:
        raise UsageError("no scenes to run")
    out, seen_paths, names = [], set(), set()
    for it in items:
        if it["path"] is not None and it["kind"] in SCENE_EXTENSIONS:
            real = os.path.realpath(it["path"])
            if real in seen_paths:
                continue
            seen_paths.add(real)
        base = _UNSAFE.sub("_", it.pop("stem")).strip("._") or "scene"
        name, k = base, 1
        while name in names:
            k += 1
            name = f"{base}-{k}"
        names.add(name)
        out.append(Job(name=name, **it))
    return out
