"""The ``clcsg`` command line: :func:`main` parses argv and dispatches to one module per command
(``devices``, ``info``, ``sample``, ``render``, ...), :func:`console` is the program around it;
``app`` holds the framework and shared parsers."""
from .app import COMMANDS, console, main

__all__ = ["COMMANDS", "console", "main"]
