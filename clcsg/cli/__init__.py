"""The ``clcsg`` command line: :func:`main` parses argv and dispatches to one module per command
(``devices``, ``info``, ``sample``, ``render``); ``app`` holds the framework and shared parsers."""
from .app import COMMANDS, main

__all__ = ["COMMANDS", "main"]
