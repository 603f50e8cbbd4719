"""Reference solves in worker processes: a hard time limit per solve, and ``--jobs`` in parallel.

:func:`solve_in_workers` runs tasks ``(record, solver)`` (one reference
solver on one problem, :func:`qpbench.reference_solve.solve_candidate`) on up
to ``jobs`` worker processes, each solving one task at a time:

- a task has a deadline of ``time_limit + max(1 s, time_limit / 2)`` from the
  moment it is sent (the slack covers pickling and a loaded machine; the
  solve itself is held to ``time_limit`` inside the worker). Past it the
  worker is killed (SIGKILL) and the task is an ``unknown`` answer with
  ``timed_out`` set; a new worker takes the next task;
- a worker that dies (segfault, abort) makes its task ``unknown`` with the
  exit code as the reason; a new worker takes the next task.

Workers come from the ``multiprocessing`` context given (``qpbench bench``
gives the harness's forkserver, :func:`qpbench.harness.workers.context`:
a fork of a server that has imported the solvers, ready in milliseconds), by
default ``spawn`` (a fresh interpreter); never a fork of this process, which
may hold threads and locks. A worker says it is ready (it has imported
:mod:`qpbench.reference_solve`) before any deadline runs. Each
answer depends on its task only, so the answers are the same whatever
``jobs`` is and in whatever order the tasks finish.
"""

from __future__ import annotations

import logging
import math
import multiprocessing
import signal
import time
from collections import deque
from multiprocessing.connection import wait
from typing import TYPE_CHECKING

if TYPE_CHECKING:
    from collections.abc import Callable, Iterator
    from multiprocessing.connection import Connection
    from multiprocessing.context import BaseContext

log = logging.getLogger("qpbench.reference")

#: Least slack added to a task's time limit before its worker is killed, in [s].
DEADLINE_MARGIN_S = 1.0
#: Time a worker may take to start (import the solvers) in [s].
START_TIMEOUT_S = 120.0


def requests(conn: Connection) -> Iterator:
    """Each request a worker process receives on ``conn``, until ``None`` or the other end closes.

    The loop of every worker process that answers one request at a time
    (here and :mod:`qpbench.executors.local`).
    """
    while True:
        try:
            request = conn.recv()
        except EOFError:
            return
        if request is None:
            return
        yield request


def _worker_main(conn) -> None:
    """Body of a worker: answer ``(record, solver, time_limit)`` requests until ``None``."""
    signal.signal(signal.SIGINT, signal.SIG_IGN)  # Ctrl-C is the parent's business
    from .reference_solve import Candidate, solve_candidate

    conn.send("ready")
    for record, solver, time_limit in requests(conn):
        try:
            answer = solve_candidate(record, solver, time_limit).plain()
        except Exception as exc:  # noqa: BLE001 - a bug in one task must not stop the others
            answer = Candidate(solver, "unknown", None, reason=f"{type(exc).__name__}: {exc}")
        conn.send(answer)


class _Worker:
    """One worker process and the task it is solving."""

    def __init__(self, ctx):
        self.conn, child = ctx.Pipe()
        self.proc = ctx.Process(
            target=_worker_main, args=(child,), name="qpbench-reference", daemon=True
        )
        self.proc.start()
        child.close()
        self.task = None
        self.deadline = math.inf
        self.ready = False

    def wait_ready(self) -> None:
        if not self.conn.poll(START_TIMEOUT_S):
            self.kill()
            raise RuntimeError(f"a reference worker did not start within {START_TIMEOUT_S:g} s")
        if self.conn.recv() != "ready":
            self.kill()
            raise RuntimeError("a reference worker started badly")
        self.ready = True

    def send(self, key, task, time_limit: float | None) -> None:
        self.task = key
        slack = DEADLINE_MARGIN_S if time_limit is None else max(DEADLINE_MARGIN_S, time_limit / 2)
        self.deadline = math.inf if time_limit is None else time.monotonic() + time_limit + slack
        self.conn.send(task)

    def kill(self) -> None:
        if self.proc.is_alive():
            self.proc.kill()
        self.proc.join(5.0)
        self.conn.close()

    def stop(self) -> None:
        try:
            self.conn.send(None)
        except (BrokenPipeError, OSError):
            pass
        self.proc.join(5.0)
        self.kill()


def solve_in_workers(
    tasks: list,
    time_limit: float | None,
    jobs: int,
    on_done: Callable | None = None,
    context: BaseContext | None = None,
) -> dict:
    """Solve every task on up to ``jobs`` workers.

    Args:
        tasks: ``(key, record, solver)`` triples (``key`` identifies the answer).
        time_limit: Limit of each solve in [s] (``None``: none, no deadline).
        jobs: Worker processes (at least 1).
        on_done: Optional ``on_done(key, candidate)`` called as each answer arrives.
        context: ``multiprocessing`` context of the workers (default ``spawn``).

    Returns:
        ``{key: Candidate}`` (plain candidates, see :meth:`Candidate.plain`).
    """
    if not tasks:
        return {}
    ctx = context if context is not None else multiprocessing.get_context("spawn")
    pending = deque(tasks)
    solver_of = {key: solver for key, _, solver in tasks}
    answers: dict = {}
    workers: list[_Worker] = []

    def finish(key, answer) -> None:
        answers[key] = answer
        if on_done is not None:
            on_done(key, answer)

    try:
        workers = [_Worker(ctx) for _ in range(max(1, min(int(jobs), len(tasks))))]
        for w in workers:
            w.wait_ready()
        while pending or any(w.task is not None for w in workers):
            for i, w in enumerate(workers):
                if w.task is None and pending:
                    if not w.ready:
                        workers[i] = w = _Worker(ctx)
                        w.wait_ready()
                    key, record, solver = pending.popleft()
                    w.send(key, (record, solver, time_limit), time_limit)
            busy = [w for w in workers if w.task is not None]
            timeout = max(0.0, min(w.deadline for w in busy) - time.monotonic())
            ready = wait([w.conn for w in busy], None if math.isinf(timeout) else timeout)
            for w in busy:
                done, answer = _answer_of(w, ready, solver_of[w.task], time_limit)
                if done:
                    finish(w.task, answer)
                    w.task = None
    finally:
        for w in workers:
            if w.ready:
                w.stop()
            else:
                w.kill()
    return answers


def _answer_of(
    w: _Worker, ready: list, solver: str, time_limit: float | None
) -> tuple[bool, object]:
    """``(True, answer)`` once busy worker ``w`` is done with its task, else ``(False, None)``.

    The answer is the worker's reply (``w.conn`` among the ``ready`` connections),
    or an ``unknown`` candidate when the worker died or is past its deadline
    (then the worker is killed and marked not ready).
    """
    from .reference_solve import Candidate

    if w.conn in ready:
        try:
            return True, w.conn.recv()
        except (EOFError, OSError):
            w.proc.join(5.0)
            answer = Candidate(
                solver,
                "unknown",
                None,
                reason=f"reference worker died (exit code {w.proc.exitcode})",
            )
            w.kill()
            w.ready = False
            return True, answer
    if time.monotonic() > w.deadline:
        w.kill()
        w.ready = False
        return True, Candidate(
            solver,
            "unknown",
            None,
            timed_out=True,
            reason=f"no answer within the time limit of {time_limit:g} s; worker stopped",
        )
    return False, None
