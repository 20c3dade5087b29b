"""Progress of long steps on stderr (tqdm bars, JSON lines or nothing) and the closing summary.

A :class:`Reporter` shows the steps of a run one after the other: ``with rep.step("load",
"loading part.json") as st: ...``.  Its mode is

``bar``   a tqdm bar per step on stderr, shown only once the step has taken longer than
          :data:`DELAY` (0.5 s; ``CLCSG_PROGRESS_DELAY`` overrides it), cleared when it ends;
``json``  one JSON object per line on stderr for every start, progress, end, warning, error
          and the summary (``{"event": "progress", "step": "sample", "done": 1200, "total":
          5000, "unit": "cells", "elapsed": 0.8, "eta": 2.6, ...}``; ``"eta": null`` while
          the seconds left are not known);
``none``  nothing;
``auto``  ``bar`` when stderr is a terminal, else ``none`` (pipes and files stay clean).

The command line picks the mode with ``--progress`` and ``--quiet`` and makes the reporter
the *current* one (:func:`using`); library code (the sampler's level loop) reports to
:func:`current`, which outside the command line is an ``auto`` reporter.  A step that reports
counts (``st.update(done=..., total=...)``) gets a bar with a rate and an ETA; one that does
not shows its elapsed time.  Steps keep their timings (``st.elapsed``) in every mode, for the
summary line.
"""

from __future__ import annotations

import contextlib
import contextvars
import json
import math
import os
import shutil
import sys
import threading
import time

MODES = ("auto", "bar", "json", "none")


def _delay() -> float:
    try:
        return max(0.0, float(os.environ.get("CLCSG_PROGRESS_DELAY", "0.5")))
    except ValueError:
        return 0.5


#: seconds a step runs before its bar appears
DELAY = _delay()
#: least seconds between two JSON progress lines of a step
JSON_INTERVAL = 0.1
#: seconds between two redraws of a bar that gets no updates (elapsed time, spinner)
TICK = 0.2


def _jsonable(v):
    if isinstance(v, float) and not math.isfinite(v):
        return None
    if hasattr(v, "item"):
        return v.item()
    return v


class Step:
    """One step of a run (see :meth:`Reporter.step`); a context manager."""

    def __init__(self, reporter: "Reporter", name: str, label: str, total=None, unit: str = ""):
        self.reporter = reporter
        self.name = name
        self.label = label
        self.total = total
        self.unit = unit
        self.done = 0
        self.info: dict = {}
        self.note = None
        self.t0 = time.perf_counter()
        self.t_phase = self.t0
        self.forecast = None  # (seconds left, when forecast) as the caller forecast them
        self.t_end = None
        self.bar = None
        self.bar_kind = None  # the format the bar was made with, before the forecast goes in
        self._json_t = -1.0
        reporter._open(self)

    @property
    def elapsed(self) -> float:
        return (self.t_end or time.perf_counter()) - self.t0

    @property
    def closed(self) -> bool:
        return self.t_end is not None

    def eta(self):
        """Seconds left: the caller's last forecast less the time since (see :meth:`update`),
        else at the average rate of the current phase (None if unknown)."""
        if self.forecast is not None:
            left, t = self.forecast
            return None if math.isnan(left) else max(0.0, left - (time.perf_counter() - t))
        if not self.total or self.done <= 0:
            return None
        dt = time.perf_counter() - self.t_phase
        return max(0.0, (self.total - self.done) * dt / self.done)

    def update(self, done=None, total=None, label=None, unit=None, phase=False, note=None, always=False,
               forecast=None, **info):
        """New counts (absolute), label or unit; ``phase``: a new phase starts (its rate and
        ETA count from now; or from ``phase``, a ``time.perf_counter()`` time it started);
        ``forecast``: the seconds left as the caller knows them, the ETA from now on (counting
        down) in place of the one from the rate, which a bar whose total is not the work left
        cannot give (NaN: not known yet, no ETA is shown); ``info``: extra fields for JSON,
        shown after the bar unless a ``note`` (text) is given for the bar.  JSON progress
        lines come at most every :data:`JSON_INTERVAL` seconds, unless ``always``."""
        if self.closed:
            return
        if phase:
            self.t_phase = time.perf_counter() if phase is True else float(phase)
        if forecast is not None:
            self.forecast = (float(forecast), time.perf_counter())
        if label is not None:
            self.label = label
        if unit is not None:
            self.unit = unit
        if total is not None:
            self.total = total
        if done is not None:
            self.done = done
        if note is not None:
            self.note = note
        self.info.update(info)
        self.reporter._update(self, force=phase or always)

    def close(self):
        if not self.closed:
            self.t_end = time.perf_counter()
            self.reporter._close(self)

    def __enter__(self):
        return self

    def __exit__(self, *exc):
        self.close()
        return False


class Reporter:
    """Shows steps in one mode (``bar``, ``json`` or ``none``; ``auto`` picks) on ``stream``."""

    def __init__(self, mode: str = "auto", stream=None, quiet: bool = False, delay: float | None = None):
        if mode not in MODES:
            raise ValueError(f"progress mode must be one of {', '.join(MODES)}, got {mode!r}")
        self.stream = sys.stderr if stream is None else stream
        self.quiet = bool(quiet)
        if mode == "auto":
            isatty = getattr(self.stream, "isatty", None)
            mode = "bar" if (not quiet and isatty is not None and isatty()) else "none"
        self.mode = mode
        self.delay = DELAY if delay is None else float(delay)
        self.t0 = time.perf_counter()
        self.steps: list[Step] = []
        self._lock = threading.RLock()
        self._ticker = None

    # -- the API for code that runs steps -------------------------------------------------------
    def step(self, name: str, label: str, total=None, unit: str = "") -> Step:
        """Start a step (ends with ``close()`` or at the end of its ``with`` block)."""
        return Step(self, name, label, total, unit)

    def active(self) -> Step | None:
        """The innermost step that is still open, if any."""
        with self._lock:
            return self.steps[-1] if self.steps else None

    def event(self, event: str, **fields) -> None:
        """A JSON line (json mode only)."""
        if self.mode != "json":
            return
        rec = {"event": event, "time": round(time.perf_counter() - self.t0, 4)}
        rec.update({k: _jsonable(v) for k, v in fields.items()})
        with self._lock:
            self.stream.write(json.dumps(rec, default=str) + "\n")
            self.stream.flush()

    def summary(self, command: str, text: str, out=None, **fields) -> None:
        """The one line a command ends with: ``text`` on stdout (not with --quiet) and, in json
        mode, a ``summary`` event with ``fields``."""
        self.close_all()
        self.event("summary", command=command, text=text, **fields)
        if not self.quiet:
            stream = sys.stdout if out is None else out
            stream.write(text + "\n")
            stream.flush()

    def close_all(self) -> None:
        for st in list(reversed(self.steps)):
            st.close()

    # -- internals ----------------------------------------------------------------------------
    def _open(self, st: Step) -> None:
        with self._lock:
            self.steps.append(st)
        self.event("start", step=st.name, label=st.label)
        if self.mode == "bar":
            self._start_ticker()
            if self.delay <= 0:
                self._draw(st)

    def _update(self, st: Step, force=False) -> None:
        if self.mode == "json":
            now = time.perf_counter()
            if force or now - st._json_t >= JSON_INTERVAL or (st.total is not None and st.done >= st.total):
                st._json_t = now
                eta = st.eta()
                self.event("progress", step=st.name, label=st.label, done=st.done, total=st.total, unit=st.unit,
                           elapsed=round(st.elapsed, 4), eta=None if eta is None else round(eta, 3), **st.info)
        elif self.mode == "bar":
            self._draw(st)

    def _close(self, st: Step) -> None:
        with self._lock:
            if st in self.steps:
                self.steps.remove(st)
            bar, st.bar = st.bar, None
            if bar is not None:
                bar.close()
        self.event("end", step=st.name, label=st.label, elapsed=round(st.elapsed, 4), **st.info)

    def _draw(self, st: Step) -> None:
        """Create or redraw the bar of ``st`` once it is older than the delay."""
        with self._lock:
            if st.closed or time.perf_counter() - st.t0 < self.delay:
                return
            from tqdm import tqdm

            counted = st.total is not None or st.done > 0
            fmt = ("{desc}: {percentage:3.0f}%|{bar}| {n_fmt}/{total_fmt} {unit} [{elapsed}<{remaining}{postfix}]"
                   if st.total else "{desc}: {n_fmt} {unit} [{elapsed}{postfix}]" if counted
                   else "{desc} [{elapsed}{postfix}]")
            # the caller's forecast in place of tqdm's ETA from the rate (Step.update)
            eta = st.eta()
            remaining = "?" if eta is None else tqdm.format_interval(eta)
            shown = fmt if st.forecast is None else fmt.replace("{remaining}", remaining)
            bar = st.bar
            if bar is None or st.bar_kind != fmt:
                if bar is not None:
                    bar.close()
                # the size from $COLUMNS or the terminal, 100 x 20 where it reports none (a new pty)
                cols, rows = shutil.get_terminal_size((100, 20))
                bar = st.bar = tqdm(total=st.total, desc=st.label, unit=st.unit, file=self.stream, leave=False,
                                    ncols=max(40, min(cols, 160)), nrows=max(rows, 2), bar_format=shown, unit_scale=max(st.total or 0, st.done) >= 10_000,
                                    mininterval=0, miniters=0, smoothing=0)
                bar.start_t -= time.perf_counter() - st.t_phase  # the phase started before the bar
                st.bar_kind = fmt
            bar.bar_format = shown
            bar.desc = st.label
            bar.unit = st.unit
            bar.total = st.total
            bar.n = st.done
            note = st.note if st.note is not None else ", ".join(f"{k} {_fmt(v)}" for k, v in st.info.items())
            bar.set_postfix_str(note, refresh=False)
            bar.refresh()

    def _start_ticker(self) -> None:
        with self._lock:
            if self._ticker is not None and self._ticker.is_alive():
                return
            self._ticker = threading.Thread(target=self._tick, name="clcsg-progress", daemon=True)
            self._ticker.start()

    def _tick(self) -> None:
        while True:
            time.sleep(TICK)
            st = self.active()
            if st is None:
                with self._lock:
                    if not self.steps:
                        self._ticker = None
                        return
                continue
            try:
                self._draw(st)
            except Exception:  # never let the display break a run
                return


def _fmt(v) -> str:
    if isinstance(v, float):
        return f"{v:.3g}"
    if isinstance(v, int) and abs(v) >= 10_000:
        return f"{v:,}"
    return str(v)


# -- the current reporter ---------------------------------------------------------------------
_current: contextvars.ContextVar = contextvars.ContextVar("clcsg_progress", default=None)


def current() -> Reporter:
    """The reporter of the running command, else a new ``auto`` one (a bar on a terminal)."""
    rep = _current.get()
    return rep if rep is not None else Reporter("auto")


@contextlib.contextmanager
def using(reporter: Reporter):
    """Make ``reporter`` the current one inside the ``with`` block; its open steps are closed
    at the end."""
    token = _current.set(reporter)
    try:
        yield reporter
    finally:
        reporter.close_all()
        _current.reset(token)


def for_option(progress) -> Reporter:
    """The reporter for a ``progress=`` argument: None the current one, False none, True a
    bar, a mode name, or a :class:`Reporter`."""
    if isinstance(progress, Reporter):
        return progress
    if progress is None:
        return current()
    if progress is True:
        return Reporter("bar")
    if progress is False:
        return Reporter("none")
    return Reporter(str(progress))
