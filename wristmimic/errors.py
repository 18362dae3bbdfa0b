"""Errors raised for bad input: one line naming the file, the key and what was expected."""

from __future__ import annotations

from pathlib import Path


class WristmimicError(Exception):
    """Base class of every error this package raises on purpose."""


class InputError(WristmimicError):
    """A file (or part of one) is not what a stage expects.

    The message is one line: ``<file>: <key>: <problem> (expected <expected>)``.
    """

    def __init__(self, path: str | Path | None, key: str | None, problem: str, expected: str | None = None):
        self.path = None if path is None else str(path)
        self.key = key
        self.problem = problem
        self.expected = expected
        parts = [p for p in (self.path, key) if p]
        msg = ": ".join([*parts, problem])
        if expected:
            msg += f" (expected {expected})"
        super().__init__(msg)


class SchemaVersionError(InputError):
    """A canonical file written with another major schema version."""
