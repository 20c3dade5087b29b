"""Atomic output files: a file under its final name is complete, or the old one is still there.

:func:`atomic_open` writes to a new file in the target's folder and, only when all was
written and ``fsync`` ed, renames it over the target (``os.replace``, atomic on POSIX within a
folder), then syncs the folder so the rename itself survives a power cut.  On Linux the new
file is created with ``O_TMPFILE``: it has no name until it is complete, so even a process
killed with SIGKILL in the middle of the write leaves nothing behind (it is linked under a
hidden temporary name just before the rename, a window of two system calls).  Elsewhere, or
on a file system without ``O_TMPFILE``, a hidden named temporary ``.NAME.XXXX.tmp`` is used
and removed on every failure Python sees.

:func:`stage` splits the two steps: the file is written and synced first, and
:meth:`Staged.publish` renames it later, so a caller can record in between that it is coming.

Any ``OSError`` (a full disk, a read-only folder, a quota) becomes a one-line
:class:`~clcsg.errors.OutputError` (exit code 6) naming the file; the previous file under
that name is left as it was.
"""

from __future__ import annotations

import contextlib
import os

from .errors import OutputError

#: the permission bits of a new output file before the umask (as ``open(path, "w")``)
_MODE = 0o666


def _umask() -> int:
    mask = os.umask(0)
    os.umask(mask)
    return mask


def _tmp_name(path: str) -> str:
    folder, base = os.path.split(path)
    return os.path.join(folder, f".{base}.{os.urandom(6).hex()}.tmp")


def _open_unnamed(folder: str):
    """(fd, None) of an unnamed file in ``folder`` (O_TMPFILE), or None if not supported."""
    flag = getattr(os, "O_TMPFILE", 0)
    if not flag or not os.path.isdir("/proc/self/fd"):
        return None
    try:
        return os.open(folder, flag | os.O_WRONLY, _MODE)
    except OSError as e:
        import errno

        if e.errno in (errno.EOPNOTSUPP, errno.EISDIR, errno.EINVAL, errno.ENOENT):
            return None  # no O_TMPFILE here: a named temporary instead
        raise


def _sync_folder(folder: str) -> None:
    try:
        fd = os.open(folder, os.O_RDONLY)
    except OSError:
        return
    try:
        os.fsync(fd)
    except OSError:
        pass  # some file systems cannot sync a directory; the data itself is synced
    finally:
        os.close(fd)


def _publish(fd: int, tmp: str | None, path: str) -> None:
    """Give the finished file ``fd`` the name ``path`` (via ``tmp`` if it has one)."""
    if tmp is None:
        tmp = _tmp_name(path)
        # an explicit src_dir_fd makes os.link call linkat(..., AT_SYMLINK_FOLLOW) (plain link()
        # would try to link the /proc symlink itself); the path is absolute, so it is not used
        folder = os.open(os.path.dirname(os.path.abspath(path)), os.O_RDONLY)
        try:
            os.link(f"/proc/self/fd/{fd}", tmp, src_dir_fd=folder, follow_symlinks=True)
        finally:
            os.close(folder)
    try:
        os.replace(tmp, path)
    except BaseException:
        with contextlib.suppress(OSError):
            os.unlink(tmp)
        raise


class Staged:
    """A file written and synced but not yet under its name (:func:`stage`); :meth:`publish`
    renames it into place, :meth:`discard` drops it.  Between the two a caller can record
    that the file is coming (a batch journals its row there, so a file under its final name
    always has its row)."""

    def __init__(self, path: str, what: str = "file"):
        self.path = os.fspath(path)
        self.what = what
        self.folder = os.path.dirname(os.path.abspath(self.path))
        self.tmp = None
        try:
            self.fd = _open_unnamed(self.folder)
            if self.fd is None:
                self.tmp = _tmp_name(os.path.abspath(self.path))
                self.fd = os.open(self.tmp, os.O_WRONLY | os.O_CREAT | os.O_EXCL, 0o600)
                os.fchmod(self.fd, _MODE & ~_umask())
        except OSError as e:
            raise self.error(e) from None

    def error(self, e: OSError) -> OutputError:
        return OutputError(f"{self.path}: cannot write {self.what}: {e.strerror or e}")

    def sync(self) -> None:
        try:
            os.fsync(self.fd)
        except OSError as e:
            raise self.error(e) from None

    def publish(self) -> None:
        """Rename the synced file over :attr:`path` and sync the folder."""
        try:
            _publish(self.fd, self.tmp, self.path)
            self.tmp = None
            _sync_folder(self.folder)
        except OSError as e:
            raise self.error(e) from None
        finally:
            self.discard()

    def discard(self) -> None:
        """Close the file; a named temporary is removed (an unnamed one vanishes)."""
        if self.fd is not None:
            with contextlib.suppress(OSError):
                os.close(self.fd)
            self.fd = None
        if self.tmp is not None:
            with contextlib.suppress(OSError):
                os.unlink(self.tmp)
            self.tmp = None


def stage(path, data: bytes, what: str = "file") -> Staged:
    """``data`` written and synced into a :class:`Staged` file for ``path``."""
    st = Staged(path, what)
    try:
        view = memoryview(data)
        while view:
            view = view[os.write(st.fd, view):]
        st.sync()
    except BaseException as e:
        st.discard()
        if isinstance(e, OSError):
            raise st.error(e) from None
        raise
    return st


@contextlib.contextmanager
def atomic_open(path, mode: str = "wb", what: str = "file", encoding: str | None = None):
    """A file object for writing ``path`` atomically (see the module docstring): on a normal
    exit of the ``with`` block the data is synced and renamed into place; on any exception
    nothing is left and an existing ``path`` is unchanged.  ``mode`` is ``"wb"`` or ``"w"``
    (text, ``encoding`` default UTF-8)."""
    st = Staged(path, what)
    try:
        f = os.fdopen(os.dup(st.fd), mode, encoding=encoding or ("utf-8" if "b" not in mode else None))
    except OSError as e:
        st.discard()
        raise st.error(e) from None
    try:
        with f:
            yield f
            f.flush()
        st.sync()
        st.publish()
    except OSError as e:
        raise st.error(e) from None
    finally:
        st.discard()


def write_bytes(path, data: bytes, what: str = "file") -> None:
    """Write ``data`` to ``path`` atomically."""
    stage(path, data, what).publish()
