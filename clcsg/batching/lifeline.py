"""Workers that end when their driver ends, however it ends (SIGKILL included).

:func:`die_with_parent`, called first thing in a worker process, sets two guards:

* on Linux the parent-death signal (``prctl(PR_SET_PDEATHSIG, SIGKILL)`` through ctypes): the
  kernel kills the worker the moment the thread that started it exits;
* everywhere, a watchdog thread that waits on the pipe the parent holds open for its child
  (``multiprocessing.parent_process().sentinel``, which becomes readable when the parent is
  gone), or failing that polls ``os.getppid()``, and ends the process with ``os._exit``.

The second guard covers what the first cannot: other systems, and a parent that died before
the signal was set (checked once right after setting it).
"""

from __future__ import annotations

import ctypes
import ctypes.util
import multiprocessing
import os
import signal
import sys
import threading

#: prctl option number (linux/prctl.h)
PR_SET_PDEATHSIG = 1
#: seconds between two looks at the parent pid where there is no parent pipe
POLL_S = 1.0
#: the exit status of a worker that ends because its driver is gone
ORPHAN_EXIT = 70


def _set_pdeathsig() -> bool:
    if not sys.platform.startswith("linux"):
        return False
    try:
        libc = ctypes.CDLL(ctypes.util.find_library("c") or None, use_errno=True)
        return libc.prctl(PR_SET_PDEATHSIG, signal.SIGKILL, 0, 0, 0) == 0
    except (OSError, AttributeError):
        return False


def _watch(parent_pid: int) -> None:
    parent = multiprocessing.parent_process()
    sentinel = getattr(parent, "sentinel", None) if parent is not None else None
    if sentinel is not None:
        from multiprocessing.connection import wait

        try:
            wait([sentinel])
        except OSError:
            pass
    else:
        import time

        while os.getppid() == parent_pid:
            time.sleep(POLL_S)
    os._exit(ORPHAN_EXIT)


def die_with_parent(parent_pid: int | None = None) -> None:
    """End this process when its parent (``parent_pid``, default the current one) ends."""
    pid = os.getppid() if parent_pid is None else int(parent_pid)
    _set_pdeathsig()
    if os.getppid() != pid:  # the parent died before the signal was set
        os._exit(ORPHAN_EXIT)
    threading.Thread(target=_watch, args=(pid,), name="clcsg-lifeline", daemon=True).start()
