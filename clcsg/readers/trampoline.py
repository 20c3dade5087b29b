"""Deep recursion without the Python stack: rules written as generators that yield their
sub-rules, run by an explicit stack.

A rule ``x = yield sub`` runs the generator ``sub`` to completion and gets its return value
back as ``x``; the pending generators live on a list, so arbitrarily deep call chains need no
Python (or C) stack.  The scene-file loader and saver walk graphs of any depth this way
(``yield from`` would recurse in C once per level).
"""

from __future__ import annotations

from types import GeneratorType


def run(gen, handle=None):
    """Drive the generator ``gen`` and return its result.

    A generator may also yield a request that is not a generator; ``handle(request)`` then
    returns the value to send back, or a generator to run first (whose result is sent back).
    """
    stack = [gen]
    value = None
    while True:
        try:
            req = stack[-1].send(value)
        except StopIteration as stop:
            stack.pop()
            if not stack:
                return stop.value
            value = stop.value
            continue
        if type(req) is not GeneratorType:
            if handle is None:
                raise TypeError(f"a rule yielded {type(req).__name__}, not a generator")
            req = handle(req)
            if type(req) is not GeneratorType:
                value = req
                continue
        stack.append(req)
        value = None
