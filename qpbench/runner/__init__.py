"""Where work runs: this process, local worker processes (:mod:`.process`), or a Dask cluster;
the sweep's executors yield a :class:`Done` per task ``fn(arg)`` as it finishes."""

from __future__ import annotations

import logging
import os
from collections.abc import Callable, Iterator

from ..exceptions import ParamError, check_choice, positive_count
from .dask_ import DaskExecutor, load_security
from .process import MAX_ATTEMPTS, Done, run_located, run_tasks

log = logging.getLogger("qpbench.runner")

#: Names of ``--executor``.
EXECUTORS = ("local", "dask")


def default_jobs() -> int:
    """Cores this process may use."""
    try:
        return len(os.sched_getaffinity(0))
    except AttributeError:  # pragma: no cover - not Linux
        return os.cpu_count() or 1


class SerialExecutor:
    """Every task in this process, in order (a crash in a solver ends the process)."""

    name = "serial"
    concurrency = 1

    def run(self, fn: Callable, items: list[tuple]) -> Iterator[Done]:
        for key, arg in items:
            value, host, _ = run_located(fn, arg)
            yield Done(key, value, None, 1, host, "main", 1)

    def close(self) -> None:
        pass


class ProcessExecutor:
    """``jobs`` long-lived local worker processes (:func:`~.process.run_tasks`)."""

    name = "processes"

    def __init__(self, jobs: int):
        self.concurrency = jobs

    def run(self, fn: Callable, items: list[tuple]) -> Iterator[Done]:
        tasks = [(key, arg, None) for key, arg in items]
        for done in run_tasks(fn, tasks, self.concurrency, attempts=MAX_ATTEMPTS):
            done.concurrent = self.concurrency
            yield done

    def close(self) -> None:
        pass


def make_executor(
    name: str, jobs: int, scheduler: str | None = None, security_file: str | None = None
) -> SerialExecutor | ProcessExecutor | DaskExecutor:
    """The executor of ``--executor local|dask --jobs N [--scheduler ADDRESS --security FILE]``;
    :class:`ParamError` for options that do not go together."""
    check_choice(name, EXECUTORS, "executor", "--executor")
    positive_count(jobs, "--jobs")
    if name == "local":
        if scheduler is not None or security_file is not None:
            raise ParamError("--scheduler and --security need --executor dask", key="--scheduler")
        return ProcessExecutor(jobs)
    tls = scheduler is not None and scheduler.startswith("tls://")
    if tls and security_file is None:
        raise ParamError(
            "a tls:// scheduler needs --security FILE (CA, certificate, key)", key="--security"
        )
    if scheduler is not None and not tls:
        if security_file is not None:
            raise ParamError("--security needs a tls:// scheduler address", key="--scheduler")
        why = "whoever can reach it can run code on every worker (use tls:// and --security)"
        log.warning("Dask scheduler %s without TLS: %s", scheduler, why)
    security = load_security(security_file) if security_file is not None else None
    return DaskExecutor(scheduler, security, jobs)
