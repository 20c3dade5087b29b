"""Errors that clcsg reports to users, each with the CLI exit code it maps to.

Every message is meant to be shown as one line: it names the file, the node and the reason.
The CLI prints ``clcsg: error: <message>`` and exits with ``exit_code``; it never shows a
traceback for these.

Exit codes (documented in README.md):

====  ==================================================================
0     success
1     internal error (a bug: please report it)
2     bad command line (unknown option, bad value such as radius <= 0)
3     bad input: scene file syntax or content, singular transform, ...
4     OpenCL device problem: no platform, unknown device, missing feature
5     a limit was hit: DNF term limit, resource guard
6     an output could not be written (full disk, no permission, ...)
====  ==================================================================
"""

from __future__ import annotations


class ClcsgError(Exception):
    """Base of all errors that clcsg reports to users."""

    exit_code = 1


class UsageError(ClcsgError):
    """A bad argument value (radius <= 0, image size 0, malformed vector)."""

    exit_code = 2


class SceneError(ClcsgError):
    """Bad input geometry or a bad scene file; the message names where."""

    exit_code = 3


class ParameterError(SceneError, ValueError):
    """A bad parameter of a primitive, quadric or operation built in Python (a negative
    radius, a zero axis, a non-symmetric matrix); also a :class:`ValueError`."""


class OperandError(SceneError, TypeError):
    """Something that is not a CSG shape where one is needed; also a :class:`TypeError`."""


class TransformError(SceneError):
    """A transform that is singular, non-affine or not finite."""


class UnboundedError(SceneError):
    """A DNF term whose solid has no finite bound and no user bound was given."""


class DeviceError(ClcsgError):
    """No OpenCL platform, an unknown device, or a device lacking a needed feature."""

    exit_code = 4


class LimitError(ClcsgError):
    """A configured limit was passed (DNF terms, estimated memory)."""

    exit_code = 5


class OutputError(ClcsgError):
    """An output file could not be written (full disk, no permission, a read-only folder);
    the previous file under that name, if any, is left as it was."""

    exit_code = 6


class DnfLimitError(LimitError):
    """Normalization to disjunctive normal form would produce too many terms."""
