"""Watching the scene's files for changes (watchfiles).

:func:`watch` watches the *directories* of the files, not the files: editors often save by
writing a new file and renaming it over the old one, which a watch on the old file's inode
would miss; a deleted file that comes back is seen too.  Only events on the files themselves
pass the filter.  When the set of files changes (a ``.scad`` file now includes another one)
the watch starts again on the new directories.
"""

from __future__ import annotations

import asyncio
import os
from typing import Awaitable, Callable, Iterable

#: milliseconds of quiet that end a burst of changes (one reload per save)
STEP_MS = 50
#: the longest a burst is collected before a reload, milliseconds
DEBOUNCE_MS = 400


def _key(path) -> str:
    return os.path.realpath(os.path.abspath(os.fspath(path)))


async def watch(files: Callable[[], Iterable[str]], on_change: Callable[[set], Awaitable[None]],
                stop: asyncio.Event, force_polling: bool | None = None) -> None:
    """Until ``stop`` is set: await ``on_change(changed paths)`` after every burst of changes
    (created, modified, deleted) to one of ``files()``."""
    from watchfiles import awatch

    while not stop.is_set():
        wanted = {_key(f) for f in files()}
        dirs = sorted({os.path.dirname(f) for f in wanted if os.path.isdir(os.path.dirname(f))})
        if not dirs:  # the directory itself went away: look again later
            await _wait(stop, 0.5)
            continue

        def keep(_change, path, wanted=wanted) -> bool:
            return _key(path) in wanted

        try:
            async for changes in awatch(*dirs, watch_filter=keep, stop_event=stop, recursive=False,
                                        debounce=DEBOUNCE_MS, step=STEP_MS, force_polling=force_polling):
                await on_change({p for _, p in changes})
                if {_key(f) for f in files()} != wanted:
                    break
        except (OSError, RuntimeError):  # a watched directory was removed
            await _wait(stop, 0.5)


async def _wait(stop: asyncio.Event, seconds: float) -> None:
    try:
        await asyncio.wait_for(stop.wait(), seconds)
    except asyncio.TimeoutError:
        pass
