"""Tasks in this process or on local worker processes, and what every executor gives back.

- :class:`SerialExecutor`: in this process, one task after the other (for
  the Python API; a crash in a solver ends the process).
- :class:`ProcessExecutor`: ``jobs`` long-lived worker processes, forked from
  the forkserver that holds qpbench and its compiled kernels
  (:func:`qpbench.harness.workers.context`). A worker that dies (a
  segfault in a solver, SIGKILL from the out-of-memory killer) loses only its
  task: it is retried once on a fresh worker, then reported lost. With one
  job the tasks run one after the other, the only setting in which solve
  times are not disturbed by other runs.
"""

from __future__ import annotations

import logging
import os
import socket
import sys
from collections import deque
from collections.abc import Callable, Iterator
from dataclasses import dataclass

from ..exceptions import ParamError
from ..harness.workers import context, death_message, ignore_interrupts
from ..reference_pool import requests

log = logging.getLogger("qpbench.executors")

__all__ = ["MAX_ATTEMPTS", "Done", "ProcessExecutor", "SerialExecutor", "default_jobs"]

#: Runs of a task before it is reported lost (the first and one retry).
MAX_ATTEMPTS = 2


def default_jobs() -> int:
    """Cores this process may use."""
    try:
        return len(os.sched_getaffinity(0))
    except AttributeError:  # pragma: no cover - not Linux
        return os.cpu_count() or 1


@dataclass
class Done:
    """A finished task.

    Attributes:
        key: The task's key, as given.
        value: ``fn(arg)``, or ``None`` when the task was lost.
        lost: Why it gave nothing (its worker was lost :data:`MAX_ATTEMPTS` times), else ``None``.
        attempts: Times it was started.
        host, worker: Where its last attempt ran.
        concurrent: Tasks that could run at once on that host.
    """

    key: object
    value: object
    lost: str | None
    attempts: int
    host: str
    worker: str
    concurrent: int


def run_located(fn: Callable, arg) -> tuple:
    """``fn(arg)`` with the host and worker that ran it."""
    worker = f"pid{os.getpid()}"
    if "distributed" in sys.modules:  # on a Dask worker: its address
        try:
            worker = sys.modules["distributed"].get_worker().address
        except ValueError:
            pass
    return fn(arg), socket.gethostname(), worker


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


def _worker_loop(conn, environ: dict) -> None:
    """Body of a worker process: run ``(id, fn, arg)`` requests until ``None``.

    The worker takes the environment of the process that started it
    (``environ``), not the one the forkserver was started with.
    """
    ignore_interrupts()
    os.environ.clear()
    os.environ.update(environ)
    for tid, fn, arg in requests(conn):
        conn.send((tid, run_located(fn, arg)))


class _Worker:
    def __init__(self, ctx, index: int):
        self.conn, child = ctx.Pipe()
        self.proc = ctx.Process(
            target=_worker_loop,
            args=(child, dict(os.environ)),
            daemon=True,
            name=f"qpbench-worker-{index}",
        )
        self.proc.start()
        child.close()
        self.task = None  # (tid, key, arg, attempts)

    def stop(self, kill: bool = False) -> None:
        try:
            if kill:
                self.proc.kill()
            else:
                self.conn.send(None)
        except (OSError, ValueError):
            pass
        self.proc.join(5)
        if self.proc.is_alive():
            self.proc.kill()
            self.proc.join(5)
        self.conn.close()


class ProcessExecutor:
    """``jobs`` local worker processes; a lost worker's task is retried once, then reported lost."""

    name = "processes"

    def __init__(self, jobs: int):
        if jobs < 1:
            raise ParamError(f"must be >= 1, got {jobs}", key="--jobs")
        self.concurrency = jobs
        self._workers: list[_Worker] = []

    def _start(self, index: int) -> _Worker:
        return _Worker(context(), index)

    def run(self, fn: Callable, items: list[tuple]) -> Iterator[Done]:
        from multiprocessing.connection import wait

        host = socket.gethostname()
        queue = deque((i, key, arg, 0) for i, (key, arg) in enumerate(items))
        self._workers = [self._start(i) for i in range(min(self.concurrency, len(items)))]
        try:
            while queue or any(w.task for w in self._workers):
                for w in self._workers:
                    if w.task is None and queue:
                        tid, key, arg, attempts = queue.popleft()
                        w.task = (tid, key, arg, attempts + 1)
                        w.conn.send((tid, fn, arg))
                busy = [w for w in self._workers if w.task]
                wait([w.conn for w in busy] + [w.proc.sentinel for w in busy])
                for i, w in enumerate(self._workers):
                    if not w.task:
                        continue
                    done = self._collect(w, host)
                    if done is None and w.proc.is_alive():
                        continue
                    if done is None:  # the worker died with the task
                        done = self._lost(w, queue, host)
                        self._workers[i] = self._start(i)
                    if done is not None:
                        yield done
        finally:
            self.close()

    def _collect(self, w: _Worker, host: str) -> Done | None:
        try:
            if not w.conn.poll():
                return None
            _, (value, _, worker) = w.conn.recv()
        except (EOFError, OSError):
            return None
        _, key, _, attempts = w.task
        w.task = None
        return Done(key, value, None, attempts, host, worker, self.concurrency)

    def _lost(self, w: _Worker, queue: deque, host: str) -> Done | None:
        w.proc.join(5)
        why = death_message(w.proc.exitcode)
        tid, key, arg, attempts = w.task
        w.task = None
        w.conn.close()
        if attempts < MAX_ATTEMPTS:
            log.warning("%s: %s; running it again", key, why)
            queue.appendleft((tid, key, arg, attempts))
            return None
        return Done(
            key,
            None,
            f"{why} (attempt {attempts} of {MAX_ATTEMPTS})",
            attempts,
            host,
            f"pid{w.proc.pid}",
            self.concurrency,
        )

    def close(self) -> None:
        for w in self._workers:
            w.stop(kill=w.task is not None)
        self._workers = []
