"""Worker processes: how one is started, stopped, and how its death is told.

Used by the per-tick bench's isolated backends (:mod:`qpbench.harness.isolation`)
and by the closed loop's isolated runs (:mod:`qpbench.harness.loop_workers`),
so both start workers the same way and word a death the same way.

Start method: ``forkserver`` where the platform has one, else ``spawn``. The
forkserver is started once, before the first worker's clock, with qpbench
preloaded (:mod:`qpbench.harness.preload` loads the numba kernels the parent
prepared, and only those, from the on-disk cache), so a worker is a fork of a process that
already holds qpbench and the kernels and never compiles.
"""

from __future__ import annotations

import multiprocessing
import os
import signal
from typing import TYPE_CHECKING

if TYPE_CHECKING:
    from collections.abc import Callable
    from multiprocessing.connection import Connection
    from multiprocessing.process import BaseProcess

__all__ = [
    "START_TIMEOUT_S",
    "context",
    "death_message",
    "ignore_interrupts",
    "start_worker",
    "stop_worker",
]

#: Time allowed for the forkserver's preload and for a worker to start [s].
START_TIMEOUT_S = 120.0

#: Environment variable naming the kernel groups the forkserver's preload prepares
#: (:func:`qpbench.jit.prepared` of the process that starts it, comma-separated).
PRELOAD_KERNELS_ENV = "QPBENCH_PRELOAD_KERNELS"

#: Modules the forkserver imports once, for every worker forked from it.
PRELOAD = (
    "qpbench.harness.workers",
    "qpbench.harness.isolation",
    "qpbench.backends",
    "numpy",
    "scipy.sparse",
    "qpbench.harness.preload",
)

_CTX = None


def context() -> multiprocessing.context.BaseContext:
    """The start method's context; the forkserver preloads the kernels this process prepared.

    The command has compiled (or loaded) the kernels of the backends it runs
    before (:func:`qpbench.jit.warmup`), so no worker ever compiles: it
    only loads them.
    """
    global _CTX
    from ..jit import prepared

    if _CTX is None:
        method = (
            "forkserver" if "forkserver" in multiprocessing.get_all_start_methods() else "spawn"
        )
        ctx = multiprocessing.get_context(method)
        if method == "forkserver":
            # the forkserver loads what this process prepared (the command's backends' kernels)
            os.environ[PRELOAD_KERNELS_ENV] = ",".join(prepared())
            ctx.set_forkserver_preload(list(PRELOAD))
            # start the server now and wait for its preload (a no-op child), so that no
            # worker's deadline ever covers it
            proc = ctx.Process(target=_noop, name="qpbench-forkserver-ready")
            proc.start()
            proc.join(START_TIMEOUT_S)
        _CTX = ctx
    return _CTX


def _noop() -> None:
    """A child that does nothing: its start waits for the forkserver's preload."""


def start_worker(
    target: Callable[..., None], args: tuple, name: str, duplex: bool = True
) -> tuple[BaseProcess, Connection]:
    """Start ``target(conn, *args)`` in a worker process; return ``(process, conn)``.

    ``conn`` is this side of the pipe (the worker gets the other end as its
    first argument). The worker is a daemon: it dies with this process.
    """
    ctx = context()  # forkserver (qpbench preloaded) where there is one, else spawn
    parent, child = ctx.Pipe(duplex=duplex)
    proc = ctx.Process(target=target, args=(child, *args), daemon=True, name=name)
    proc.start()
    child.close()
    return proc, parent


def stop_worker(proc: BaseProcess | None, conn: Connection | None) -> None:
    """Kill the worker if it is alive (SIGKILL), reap it and close the pipe."""
    if proc is not None:
        if proc.is_alive():
            proc.kill()
        proc.join(5)
    if conn is not None:
        try:
            conn.close()
        except OSError:  # pragma: no cover
            pass


def death_message(exitcode: int | None) -> str:
    """How a worker ended without an answer: ``worker process killed by SIGSEGV``, or
    ``worker process exited with code 3``."""
    if exitcode is not None and exitcode < 0:
        try:
            return f"worker process killed by {signal.Signals(-exitcode).name}"
        except ValueError:
            return f"worker process killed by signal {-exitcode}"
    return f"worker process exited with code {exitcode}"


def ignore_interrupts() -> None:
    """In a worker: Ctrl-C is the parent's business (it stops the workers itself)."""
    signal.signal(signal.SIGINT, signal.SIG_IGN)
