"""Keeping solvers' native chatter (printed from C to file descriptor 1 whatever their
``verbose`` setting) off the terminal, for a whole command; worker processes started inside
inherit the silenced descriptor."""

from __future__ import annotations

import contextlib
import ctypes
import os
import sys
from typing import TYPE_CHECKING

if TYPE_CHECKING:
    from collections.abc import Iterator


def _flush_c_stdio() -> None:
    with contextlib.suppress(OSError, AttributeError):  # no C library to talk to
        ctypes.CDLL(None).fflush(None)


@contextlib.contextmanager
def silence_native_stdout(enabled: bool = True) -> Iterator[None]:
    """Send native writes to descriptor 1 to ``/dev/null``; ``sys.stdout`` keeps the real
    output. Nothing happens when ``sys.stdout`` is not descriptor 1 (e.g. pytest's capture)."""
    try:
        fd = sys.stdout.fileno()
    except (AttributeError, OSError):  # io.UnsupportedOperation is an OSError
        fd = None
    if not enabled or fd != 1:
        yield
        return
    sys.stdout.flush()
    _flush_c_stdio()
    saved = os.dup(1)
    devnull = os.open(os.devnull, os.O_WRONLY)
    private = os.fdopen(
        os.dup(saved), "w", buffering=1, encoding=sys.stdout.encoding, errors=sys.stdout.errors
    )
    try:
        os.dup2(devnull, 1)
        with contextlib.redirect_stdout(private):
            yield
    finally:
        with contextlib.suppress(BrokenPipeError):  # the reader went away (``| head``)
            private.flush()
        _flush_c_stdio()
        os.dup2(saved, 1)
        with contextlib.suppress(BrokenPipeError):
            private.close()
        os.close(saved)
        os.close(devnull)
