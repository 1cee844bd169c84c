"""The ``relight`` command line: ``commands`` parses and dispatches every verb, ``materials`` and
``export`` add their verbs to its parser; ``common`` holds what they share."""

from .commands import build_parser, main, run

__all__ = ["build_parser", "main", "run"]
