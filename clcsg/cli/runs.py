"""What the commands that do work share: their steps on the current progress reporter, the
timings and the closing summary line."""

from __future__ import annotations

import time

from ..progress import current
from ..readers import scenes


class Run:
    """The steps of one command: ``with run.step("load", "loading x.json"): ...``, then
    ``run.summary(text, **fields)`` with the step times appended."""

    def __init__(self, command: str):
        self.command = command
        self.reporter = current()
        self.t0 = time.perf_counter()
        self.times: dict[str, float] = {}
        self.outputs: list[str] = []

    def step(self, name: str, label: str):
        st = self.reporter.step(name, label)
        self.times.setdefault(name, 0.0)
        run = self

        class _Timed:
            def __enter__(self):
                return st

            def __exit__(self, *exc):
                st.close()
                run.times[name] += st.elapsed
                return False

        return _Timed()

    def wrote(self, path) -> None:
        if path:
            self.outputs.append(str(path))

    def summary(self, text: str, **fields) -> None:
        total = time.perf_counter() - self.t0
        steps = ", ".join(f"{k} {v:.2f}" for k, v in self.times.items())
        line = f"{text} in {total:.2f} s ({steps})" if steps else f"{text} in {total:.2f} s"
        if self.outputs:
            line += " -> " + ", ".join(self.outputs)
        self.reporter.summary(self.command, line, seconds={**{k: round(v, 4) for k, v in self.times.items()},
                                                           "total": round(total, 4)},
                              outputs=self.outputs, **fields)


def load_scene(run: Run, path, bound=None):
    """The scene at ``path`` (with ``bound`` if given), loaded in a step."""
    with run.step("load", f"loading {path}"):
        return scenes.as_scene(scenes.load(path), bound)
