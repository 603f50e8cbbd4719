"""Exceptions of qpbench: each names the offending file, key or value, so the CLI prints
one clear line and exits with :attr:`QpbenchError.exit_code`."""

from __future__ import annotations

import difflib
import math
import numbers
from pathlib import Path


class QpbenchError(Exception):
    """Base class of every error qpbench raises on purpose."""

    #: Exit code the CLI uses for this error.
    exit_code: int = 2


class InputError(QpbenchError):
    """Bad user input: ``message`` (one line) about a ``path`` and ``key``, if any."""

    def __init__(self, message: str, path: str | Path | None = None, key: str | None = None):
        self.path = None if path is None else Path(path)
        self.key = key
        self.message = message
        super().__init__(message)

    def __str__(self) -> str:
        key = None if self.key is None else f"key '{self.key}'"
        return ": ".join(str(w) for w in (self.path, key, self.message) if w is not None)


class ProblemFormatError(InputError):
    """A problem file or problem set is unreadable, corrupt or inconsistent."""


class ScenarioError(InputError):
    """A scenario file has a missing, unknown or impossible key."""


class ParamError(InputError):
    """A backend, profile or command parameter has a value that is not allowed."""


def did_you_mean(name: str, choices) -> str:
    """``"did you mean 'a' or 'b'? "``: up to three ``choices`` close to ``name``, or ``""``."""
    folded = {str(c).casefold(): c for c in choices}
    close = difflib.get_close_matches(str(name).casefold(), list(folded), n=3, cutoff=0.6)
    return f"did you mean {' or '.join(repr(folded[c]) for c in close)}? " if close else ""


def check_choice(
    value, choices, what: str, key: str, error: type[InputError] = ParamError, path=None
):
    """``value`` if among ``choices``, else ``error`` "unknown WHAT 'VALUE' (choose from ...)"."""
    if value not in choices:
        message = f"unknown {what} '{value}' (choose from {', '.join(choices)})"
        raise error(message, path=path, key=key)
    return value


def check_known_keys(
    table: dict, known, path: str | Path | None, prefix: str, error: type[InputError] = InputError
) -> None:
    """Raise ``error`` naming ``prefix.KEY`` for the first key of ``table`` not in ``known``."""
    for key in table:
        if key not in known:
            message = f"unknown key (expected one of: {', '.join(known)})"
            raise error(message, path=path, key=f"{prefix}.{key}")


class BackendNotFound(QpbenchError):
    """No backend is registered under the requested name, or it is unavailable."""


class BackendError(QpbenchError):
    """A backend failed in a way that is not a solver status (a bug or a crash)."""

    exit_code = 1


class OutputExistsError(QpbenchError):
    """An output exists and neither ``--force`` nor ``--resume`` was given."""


def positive_seconds(value, key: str, path: str | Path | None = None) -> float:
    """``value`` as a duration [s] if a finite number > 0, else a :class:`ParamError`."""
    try:
        seconds = float(value)
    except (TypeError, ValueError):
        seconds = float("nan")
    if isinstance(value, bool) or not (seconds > 0 and math.isfinite(seconds)):
        raise ParamError(f"must be a positive number of seconds, got {value!r}", path=path, key=key)
    return seconds


def positive_count(value, key: str, path: str | Path | None = None) -> int:
    """``value`` if an integer >= 1, else a :class:`ParamError` naming ``key``."""
    if isinstance(value, bool) or not isinstance(value, numbers.Integral) or value < 1:
        raise ParamError(f"must be an integer >= 1, got {value!r}", path=path, key=key)
    return int(value)
