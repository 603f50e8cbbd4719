"""Where work runs: this process, local worker processes, or a Dask cluster.

:mod:`.process` is the one module that starts, feeds, times out and reaps
worker processes (:class:`~.process.Worker`, the pool
:func:`~.process.run_tasks`); every other module goes through it.

The sweep's executors run independent tasks ``fn(arg)`` (``fn`` a
module-level function, so that a worker can import it by name; ``arg``
plain picklable data); each value comes back as a :class:`Done`, in the
order the tasks finish. Every executor gives the same values for the same
tasks: only where and when they ran differs.

- :class:`SerialExecutor`: in this process, one task after the other (for
  the Python API; a crash in a solver ends the process).
- :class:`ProcessExecutor`: ``jobs`` long-lived local worker processes; a
  worker that dies loses only its task, retried once, then reported lost.
- :class:`DaskExecutor`: an existing ``distributed`` cluster (``scheduler``
  address, ``tls://`` with a :func:`load_security` file) or an in-process
  ``LocalCluster`` bound to 127.0.0.1, with the same retry (:mod:`.dask_`).

Dask's workers run whatever pickled code their scheduler sends them: a
scheduler reachable by others lets them run code on every worker. Hence the
local cluster listens on 127.0.0.1 only, and a remote cluster should be
reached over ``tls://`` with certificates (:func:`load_security`).

Only :mod:`.dask_worker` imports ``distributed`` at import time, and only
:class:`DaskExecutor` imports it.
"""

from __future__ import annotations

import logging
import os
from collections.abc import Callable, Iterator

from ..exceptions import ParamError
from .dask_ import DaskExecutor, load_security
from .process import MAX_ATTEMPTS, Done, run_located, run_tasks

log = logging.getLogger("qpbench.runner")

__all__ = [
    "EXECUTORS",
    "MAX_ATTEMPTS",
    "DaskExecutor",
    "Done",
    "ProcessExecutor",
    "SerialExecutor",
    "default_jobs",
    "load_security",
    "make_executor",
]

#: Names of ``--executor``.
EXECUTORS = ("local", "dask")


def default_jobs() -> int:
    """Cores this process may use."""
    try:
        return len(os.sched_getaffinity(0))
    except AttributeError:  # pragma: no cover - not Linux
        return os.cpu_count() or 1


class SerialExecutor:
    """Every task in this process, in order."""

    name = "serial"
    concurrency = 1

    def run(self, fn: Callable, items: list[tuple]) -> Iterator[Done]:
        for key, arg in items:
            value, host, _ = run_located(fn, arg)
            yield Done(key, value, None, 1, host, "main", 1)

    def close(self) -> None:
        pass


class ProcessExecutor:
    """``jobs`` long-lived local worker processes (:func:`~.process.run_tasks`, forked from
    the forkserver that holds qpbench and its compiled kernels).

    A worker that dies (a segfault in a solver, SIGKILL from the out-of-memory
    killer) loses only its task: it is retried once on a fresh worker, then
    reported lost. With one job the tasks run one after the other, the only
    setting in which solve times are not disturbed by other runs.
    """

    name = "processes"

    def __init__(self, jobs: int):
        if jobs < 1:
            raise ParamError(f"must be >= 1, got {jobs}", key="--jobs")
        self.concurrency = jobs

    def run(self, fn: Callable, items: list[tuple]) -> Iterator[Done]:
        tasks = [(key, arg, None) for key, arg in items]
        for done in run_tasks(
            fn, tasks, self.concurrency, attempts=MAX_ATTEMPTS, on_retry=_log_retry
        ):
            if done.status == "crashed":
                done.lost += f" (attempt {done.attempts} of {MAX_ATTEMPTS})"
            done.concurrent = self.concurrency
            yield done

    def close(self) -> None:
        """Nothing to release: :meth:`run` stops its workers when it ends."""


def _log_retry(key, why: str) -> None:
    log.warning("%s: %s; running it again", key, why)


def make_executor(
    name: str, jobs: int, scheduler: str | None = None, security_file: str | None = None
) -> SerialExecutor | ProcessExecutor | DaskExecutor:
    """The executor of ``--executor NAME --jobs N [--scheduler ADDRESS --security FILE]``.

    ``local`` is :class:`ProcessExecutor`: with one job the runs are made
    one after the other, as serially as in this process (the worker times
    them itself) but a crash in a solver loses only the run it hit;
    ``dask`` is :class:`DaskExecutor`.

    Raises:
        ParamError: an unknown executor, a scheduler or security file without
            ``dask``, a ``tls://`` address without a security file.
    """
    if name not in EXECUTORS:
        raise ParamError(
            f"unknown executor '{name}' (choose from {', '.join(EXECUTORS)})", key="--executor"
        )
    if jobs < 1:
        raise ParamError(f"must be >= 1, got {jobs}", key="--jobs")
    if name == "local":
        if scheduler is not None or security_file is not None:
            raise ParamError("--scheduler and --security need --executor dask", key="--scheduler")
        return ProcessExecutor(jobs)
    if scheduler is not None and scheduler.startswith("tls://") and security_file is None:
        raise ParamError(
            "a tls:// scheduler needs --security FILE (CA, certificate, key)", key="--security"
        )
    if security_file is not None and scheduler is not None and not scheduler.startswith("tls://"):
        raise ParamError("--security needs a tls:// scheduler address", key="--scheduler")
    if scheduler is not None and not scheduler.startswith("tls://"):
        log.warning(
            "Dask scheduler %s without TLS: whoever can reach it can run code on every worker "
            "(use tls:// and --security)",
            scheduler,
        )
    security = load_security(security_file) if security_file is not None else None
    return DaskExecutor(scheduler, security, jobs)
