"""OpenSCAD programs (``.scad``): run the ``openscad`` binary, then read its CSG export.

clcsg does not interpret the OpenSCAD language.  ``load_scad("model.scad")`` runs::

    openscad -o TMPDIR/model.csg /abs/path/model.scad

in a fresh temporary directory and reads the export with :func:`clcsg.readers.openscad.parse_csg`.
The returned :class:`~clcsg.model.scene.Scene` keeps ``model.scad`` as its ``source``.

* The binary is ``$OPENSCAD`` if that is set (a path or a command name), else ``openscad`` on
  ``PATH``.
* OpenSCAD's ``WARNING:`` and ``DEPRECATED:`` lines are re-emitted as
  :class:`~clcsg.readers.openscad.OpenScadWarning`.  Any ``ERROR:`` line fails the load, also when
  OpenSCAD exits with status 0 (OpenSCAD 2021.01 does so after a failed ``assert`` or a
  recursion error, having written an empty export).
* OpenSCAD gets :data:`DEFAULT_TIMEOUT` seconds (``$CLCSG_OPENSCAD_TIMEOUT`` or the
  ``timeout`` argument override it); then it is killed.

Every failure is a one-line :class:`~clcsg.errors.SceneError` that starts with the ``.scad``
path, for example::

    model.scad: openscad failed (exit code 1): ERROR: Parser error: syntax error in file model.scad, line 2
    model.scad: OpenSCAD not found: no 'openscad' on PATH; install OpenSCAD or set $OPENSCAD

Errors in the export itself (an unsupported node such as ``hull()``) name the line of the
export: ``model.scad (CSG export):12:3: hull() is not supported: ...``; write the export with
``openscad -o model.csg model.scad`` to look at that line.
"""

from __future__ import annotations

import os
import shutil
import tempfile
import warnings

from ..errors import SceneError
from ..model.scene import Scene
from .openscad import OpenScadWarning, parse_csg

__all__ = ["load_scad", "export_csg", "find_openscad", "parse_dependencies", "DEFAULT_TIMEOUT"]

#: seconds OpenSCAD may take to export a model (``$CLCSG_OPENSCAD_TIMEOUT`` overrides it)
DEFAULT_TIMEOUT = 120.0

_INSTALL_HINT = "install OpenSCAD or set $OPENSCAD"


def _one_line(s: str) -> str:
    return " ".join(str(s).split())


def find_openscad(source: str = "openscad") -> str:
    """The OpenSCAD executable: ``$OPENSCAD`` if set, else ``openscad`` on ``PATH``."""
    env = os.environ.get("OPENSCAD")
    if env:
        exe = shutil.which(env)
        if exe is None:
            raise SceneError(_one_line(
                f"{source}: OpenSCAD not found: $OPENSCAD={env} is not an executable file; {_INSTALL_HINT}"
            ))
        return exe
    exe = shutil.which("openscad")
    if exe is None:
        raise SceneError(f"{source}: OpenSCAD not found: no 'openscad' on PATH; {_INSTALL_HINT}")
    return exe


def _timeout(timeout, source: str) -> float:
    what = "timeout"
    if timeout is None:
        env = os.environ.get("CLCSG_OPENSCAD_TIMEOUT")
        if not env:
            return DEFAULT_TIMEOUT
        what = "$CLCSG_OPENSCAD_TIMEOUT"
        try:
            timeout = float(env)
        except ValueError:
            timeout = env
    try:
        ok = float(timeout) > 0  # also False for NaN
    except (TypeError, ValueError):
        ok = False
    if not ok:
        raise SceneError(_one_line(f"{source}: the OpenSCAD {what} must be a positive number of seconds, got {timeout!r}"))
    return float(timeout)


def export_csg(scad_path, csg_path, *, timeout: float | None = None, source: str | None = None,
               deps_path=None) -> list[str]:
    """Run ``openscad -o csg_path scad_path``; return OpenSCAD's warning lines.

    With ``deps_path`` OpenSCAD also writes the files the program read (``-d deps_path``, a
    Makefile rule: see :func:`parse_dependencies`).

    Raises a one-line :class:`SceneError` (prefixed with ``source``, default the ``.scad``
    path) if OpenSCAD is missing, cannot be run, times out, reports an ``ERROR:`` or writes
    no file.
    """
    p = os.fspath(scad_path)
    source = p if source is None else source
    seconds = _timeout(timeout, source)
    exe = find_openscad(source)
    scad = os.path.abspath(p)
    out = os.path.abspath(os.fspath(csg_path))  # OpenSCAD resolves a relative -o against the input's directory
    cmd = [exe, "-o", out, scad]
    if deps_path is not None:
        cmd[1:1] = ["-d", os.path.abspath(os.fspath(deps_path))]
    import subprocess  # here, not at the top: reading a .csg or .json needs no child process

    try:
        proc = subprocess.run(
            cmd,
            stdin=subprocess.DEVNULL,
            capture_output=True,
            timeout=seconds,
            cwd=os.path.dirname(scad) or None,
        )
    except subprocess.TimeoutExpired:
        raise SceneError(
            f"{source}: openscad did not finish within {seconds:g} s and was stopped "
            "(a slow model? set $CLCSG_OPENSCAD_TIMEOUT to allow longer)"
        ) from None
    except OSError as e:
        raise SceneError(_one_line(f"{source}: cannot run OpenSCAD ({exe}): {e.strerror or e}; {_INSTALL_HINT}")) from None
    lines = [ln.strip() for ln in (proc.stderr + proc.stdout).decode("utf-8", "replace").splitlines()]
    lines = [ln for ln in lines if ln]
    errors = [ln for ln in lines if ln.startswith("ERROR:")]
    if proc.returncode != 0 or errors:
        if errors:
            why = errors[0]
        else:
            why = next((ln for ln in lines if not ln.startswith(("ECHO:", "TRACE:"))), None)
            why = why or "no message"
        status = f"exit code {proc.returncode}" if proc.returncode >= 0 else f"killed by signal {-proc.returncode}"
        what = "failed" if proc.returncode != 0 else "reported an error"
        raise SceneError(_one_line(f"{source}: openscad {what} ({status}): {why}"))
    if not os.path.isfile(out):
        raise SceneError(f"{source}: openscad exited without writing {os.path.basename(out)}")
    return [ln for ln in lines if ln.startswith(("WARNING:", "DEPRECATED:"))]


def parse_dependencies(text: str, base_dir: str) -> list[str]:
    """The prerequisites of the Makefile rule ``openscad -d`` writes (``out.csg: a.scad \\
    b.scad ...``; a space in a name is ``\\ ``), as absolute paths (relative ones are taken
    from ``base_dir``, OpenSCAD's working directory), without duplicates, in order."""
    words, cur, escaped = [], [], False
    _, _, body = text.partition(":")
    for ch in body:
        if escaped and ch not in "\r\n":
            cur.append(ch)
            escaped = False
        elif ch == "\\" and not escaped:
            escaped = True
        elif ch.isspace():  # a line continuation (backslash, newline) separates words too
            escaped = False
            if cur:
                words.append("".join(cur))
                cur = []
        else:
            cur.append(ch)
    if cur:
        words.append("".join(cur))
    out: list[str] = []
    for w in words:
        full = os.path.normpath(os.path.join(base_dir, w))
        if full not in out:
            out.append(full)
    return out


def load_scad(path, *, timeout: float | None = None, with_dependencies: bool = False):
    """Export an OpenSCAD program with the ``openscad`` binary and load the CSG tree.

    Returns the :class:`~clcsg.model.scene.Scene`; with ``with_dependencies`` the pair (scene,
    the absolute paths of every file the program read: itself and what it ``include``s and
    ``use``s, directly or not).
    """
    p = os.fspath(path)
    if not os.path.isfile(p):
        raise SceneError(f"{p}: no such file" if not os.path.exists(p) else f"{p}: not a file")
    stem = os.path.splitext(os.path.basename(p))[0] or "model"
    deps = [os.path.abspath(p)]
    with tempfile.TemporaryDirectory(prefix="clcsg-scad-") as tmp:
        csg = os.path.join(tmp, stem + ".csg")
        mk = os.path.join(tmp, "deps.mk") if with_dependencies else None
        notes = export_csg(p, csg, timeout=timeout, source=p, deps_path=mk)
        try:
            with open(csg, "rb") as f:
                text = f.read().decode("utf-8", errors="replace")
            if mk is not None and os.path.isfile(mk):
                with open(mk, encoding="utf-8", errors="replace") as f:
                    deps += [d for d in parse_dependencies(f.read(), os.path.dirname(os.path.abspath(p)))
                             if d not in deps]
        except OSError as e:
            raise SceneError(f"{p}: cannot read OpenSCAD's export: {e.strerror or e}") from None
    for note in notes:
        warnings.warn(_one_line(f"{p}: OpenSCAD: {note}"), OpenScadWarning, stacklevel=2)
    scene = parse_csg(text, source=f"{p} (CSG export)", base=p)
    scene = Scene(scene.shape, scene.bound, p)
    return (scene, deps) if with_dependencies else scene
