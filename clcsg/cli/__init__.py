"""The ``clcsg`` command line: :func:`main` parses argv and dispatches to one module per command."""
from .app import COMMANDS, build_parser, join_negative_vectors, main, parse_bound, parse_floats, positive_int, scene_info

__all__ = ["COMMANDS", "build_parser", "join_negative_vectors", "main", "parse_bound", "parse_floats",
           "positive_int", "scene_info"]
