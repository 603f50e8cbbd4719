"""Keeping solvers' native chatter off the terminal.

Some solvers print from C code whatever their ``verbose`` setting (HiGHS's
banner, OSQP's "Polishing not needed ..."), straight to file descriptor 1,
where Python cannot intercept it. :func:`silence_native_stdout` points
descriptor 1 at ``/dev/null`` for the duration of a command and gives
Python's ``sys.stdout`` a private duplicate of the real one, so qpbench's own
output still reaches the terminal or pipe while native writes vanish. It is
set up once around a whole command, never around a timed solve, and worker
processes started inside it inherit the silenced descriptor.
"""

from __future__ import annotations

import contextlib
import ctypes
import io
import os
import sys
from typing import TYPE_CHECKING

if TYPE_CHECKING:
    from collections.abc import Iterator

__all__ = ["silence_native_stdout"]


def _flush_c_stdio() -> None:
    """Flush C's stdio buffers (text a solver printed but the C library has not written yet)."""
    try:
        ctypes.CDLL(None).fflush(None)
    except (OSError, AttributeError):  # pragma: no cover - no C library to talk to
        pass


@contextlib.contextmanager
def silence_native_stdout(enabled: bool = True) -> Iterator[None]:
    """Send native writes to descriptor 1 to ``/dev/null``; Python's ``sys.stdout`` keeps the real output.

    Does nothing when ``enabled`` is false, or when ``sys.stdout`` is not the
    process's descriptor 1 (already redirected in Python, e.g. by pytest's
    capture: native output does not reach it anyway).
    """
    try:
        fd = sys.stdout.fileno()
    except (AttributeError, OSError, io.UnsupportedOperation):
        fd = None
    if not enabled or fd != 1:
        yield
        return
    sys.stdout.flush()
    _flush_c_stdio()
    saved = os.dup(1)
    devnull = os.open(os.devnull, os.O_WRONLY)
    old_stdout = sys.stdout
    private = os.fdopen(
        os.dup(saved), "w", buffering=1, encoding=old_stdout.encoding, errors=old_stdout.errors
    )
    try:
        os.dup2(devnull, 1)
        sys.stdout = private
        yield
    finally:
        try:
            private.flush()
        except BrokenPipeError:  # the reader went away (``| head``): nothing more to say
            pass
        _flush_c_stdio()
        os.dup2(saved, 1)
        sys.stdout = old_stdout
        try:
            private.close()
        except BrokenPipeError:
            pass
        os.close(saved)
        os.close(devnull)
