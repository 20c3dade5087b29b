"""``python -m clcsg``: the same as the ``clcsg`` command."""

from .cli import console

if __name__ == "__main__":
    console()
