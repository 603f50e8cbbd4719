"""Solves in a worker process, for backends that may hang in native code or crash.

:class:`IsolatedRunner` has the interface of
:class:`~qpbench.harness.guard.LocalRunner` but keeps the backend in a child
process (``multiprocessing`` ``forkserver`` context: the server imports
qpbench once, each worker is a fork of it, so a restart costs milliseconds
rather than a fresh interpreter). Requests and results travel over a pipe;
every request has a deadline::

    deadline = time_limit * (solves in the request) + max(1 s, time_limit / 2)

- no answer by the deadline -> the worker is killed (SIGKILL), the solve is
  ``time_limit``, a new worker starts at the next request. This is the only
  place a solve is stopped: inside the worker, as in the parent, a solve is
  never interrupted (see :mod:`qpbench.harness.guard`); one that returns
  late but before the deadline is ``time_limit`` by its wall time;
- the worker dies (segfault, abort, ``os._exit``) -> the solve is
  ``crashed`` with the signal or exit code in ``error``, a new worker starts.

A new worker has lost the backend's state: in sequential mode the next row
says ``state_reset = True``.

No compile in a worker: the parent prepares every numba kernel before it
starts one (:func:`qpbench.jit.warmup`, which leaves them in the on-disk
cache); the forkserver, started and preloaded before the first worker's
clock, imports qpbench and loads the kernels from the cache once
(:mod:`qpbench.harness.preload`), so each worker is forked with them in
memory. A worker started otherwise (``spawn``) loads them when it starts,
before it reports ready (within :data:`~qpbench.harness.workers.START_TIMEOUT_S`, outside any solve's
deadline). The
discarded warm-up solve has an allowance of its own (:data:`WARMUP_TIMEOUT_S`):
a slow one is not a reason to kill the worker.

The timing is taken inside the worker by the same
:class:`~qpbench.harness.guard.LocalRunner` code that runs in-process, around
the backend call only, so pickling and the pipe are not in the reported wall
times; they only add to the run's total duration.
"""

from __future__ import annotations

import logging
import time
from typing import TYPE_CHECKING

import numpy as np

from ..statuses import describe_exception
from .guard import LocalRunner, Outcome
from .workers import START_TIMEOUT_S, death_message, ignore_interrupts, start_worker, stop_worker

if TYPE_CHECKING:
    import qpsolvers

log = logging.getLogger("qpbench.harness")

#: Least slack added to every deadline in [s] (pipe, pickling, scheduling on a loaded
#: machine); the slack is ``max(DEADLINE_MARGIN_S, time_limit / 2)``.
DEADLINE_MARGIN_S = 1.0
#: Time allowed for the discarded warm-up solve in [s] (at least twice the time limit):
#: first-call costs (imports, a solver's set-up) are no reason to kill the worker.
WARMUP_TIMEOUT_S = 30.0

#: Solution attributes sent back from a worker (extras may hold native objects).
_FIELDS = (
    "x",
    "y",
    "z",
    "z_box",
    "found",
    "obj",
    "status",
    "iterations",
    "solver_time_s",
    "wall_time_s",
    "backend",
    "error",
)
_PLAIN = (int, float, str, bool, type(None), np.ndarray, np.generic)


def _strip(outcome: Outcome) -> Outcome:
    """Make an outcome picklable: a plain :class:`BackendSolution` without the problem."""
    sol = outcome.solution
    if sol is not None:
        from ..backends.base import BackendSolution

        plain = BackendSolution(problem=None)
        for name in _FIELDS:
            if hasattr(sol, name):
                setattr(plain, name, getattr(sol, name))
        extras = getattr(sol, "extras", None) or {}
        plain.extras = {k: v for k, v in extras.items() if isinstance(v, _PLAIN)}
        outcome.solution = plain
    return outcome


def _worker_main(conn, spec: dict) -> None:
    """Body of the worker process: build the backend, answer requests until ``stop``."""
    ignore_interrupts()
    try:
        from ..backends import get_backend, load_plugins
        from ..jit import warmup

        # loads the kernels the parent compiled for this backend; nothing is timed yet
        warmup([spec["backend"]], loop=False)
        load_plugins(spec["plugins"])
        backend = get_backend(spec["backend"], spec["profile"], **spec["settings"])
        runner = LocalRunner(backend, spec["time_limit"], spec["sequential"], spec["repeat"])
    except BaseException as exc:  # noqa: BLE001
        conn.send(("exc", describe_exception(exc)))
        return
    conn.send(("ready", None))
    while True:
        try:
            request = conn.recv()
        except EOFError:
            return
        op = request[0]
        try:
            if op == "stop":
                return
            if op == "solve":
                _, problem, repeat, reset_before = request
                answer = _strip(runner.solve(problem, repeat, reset_before))
            elif op == "warmup":
                answer = runner.warmup(request[1])
            elif op == "replay":
                answer = runner.replay(request[1])
            elif op == "reset":
                answer = runner.reset()
            else:
                raise RuntimeError(f"unknown request {op!r}")
            conn.send(("ok", answer))
        except BaseException as exc:  # noqa: BLE001 - harness bug or unpicklable answer
            conn.send(("exc", describe_exception(exc)))


class WorkerDied(Exception):
    """The worker exited or was killed; ``status`` is ``crashed`` or ``time_limit``."""

    def __init__(self, status: str, message: str):
        super().__init__(message)
        self.status = status
        self.message = message


class IsolatedRunner:
    """A backend living in a worker process; same interface as :class:`LocalRunner`.

    Args:
        name: Backend name; profile, settings: as for :func:`qpbench.backends.get_backend`.
        time_limit: Per-solve limit in [s].
        sequential: State carried between solves.
        repeat: Timed solves per problem (the worker's :class:`LocalRunner` keeps that
            many replicas).

    The worker loads this process's plugin files
    (:func:`qpbench.backends.plugin_files`) before building the backend.
    """

    isolated = True

    def __init__(
        self,
        name: str,
        profile,
        settings: dict,
        time_limit: float,
        sequential: bool,
        repeat: int = 1,
    ):
        from ..backends import plugin_files

        self.name = name
        self.time_limit = float(time_limit)
        self.sequential = sequential
        self.spec = {
            "backend": name,
            "profile": profile,
            "settings": dict(settings),
            "plugins": plugin_files(),
            "time_limit": float(time_limit),
            "sequential": sequential,
            "repeat": max(1, int(repeat)),
        }
        self._proc = None
        self._conn = None
        self.restarts = 0

    # -- process management --------------------------------------------------------
    def _start(self) -> None:
        proc, parent = start_worker(_worker_main, (self.spec,), name=f"qpbench-{self.name}")
        self._proc, self._conn = proc, parent
        try:
            kind, payload = self._receive(START_TIMEOUT_S, what="start")
        except WorkerDied:
            self._proc = self._conn = None
            raise
        if kind != "ready":
            self._kill()
            raise WorkerDied("error", f"worker could not build backend: {payload}")
        log.debug("worker for %s started (pid %s)", self.name, proc.pid)

    def _kill(self) -> None:
        stop_worker(self._proc, self._conn)
        self._proc = self._conn = None

    def _death_message(self) -> str:
        self._proc.join(2)
        return death_message(self._proc.exitcode)

    def _receive(self, timeout: float, what: str):
        deadline = time.monotonic() + timeout
        while True:
            left = deadline - time.monotonic()
            try:
                ready = self._conn.poll(max(left, 0.0))
            except (EOFError, OSError):
                ready = True
            if ready:
                try:
                    return self._conn.recv()
                except (EOFError, OSError):
                    message = self._death_message()
                    self._kill()
                    self.restarts += 1
                    raise WorkerDied("crashed", f"{message} during {what}") from None
            if left <= 0:
                self._kill()
                self.restarts += 1
                raise WorkerDied(
                    "time_limit", f"no answer after {timeout:.3g} s during {what}; worker killed"
                )

    def _call(self, request: tuple, n_solves: int, what: str, timeout: float | None = None):
        if self._proc is None:
            self._start()
        self._conn.send(request)
        if timeout is None:
            timeout = self.time_limit * n_solves + max(DEADLINE_MARGIN_S, self.time_limit / 2)
        kind, payload = self._receive(timeout, what)
        if kind == "exc":
            raise WorkerDied("error", payload)
        return payload

    # -- interface shared with LocalRunner -------------------------------------------
    def reset(self) -> None:
        if self._proc is None:
            return  # a new worker has no state anyway
        try:
            self._call(("reset",), 1, "reset")
        except WorkerDied:
            pass

    def warmup(self, problem: qpsolvers.Problem) -> str:
        """The discarded warm-up solve, allowed :data:`WARMUP_TIMEOUT_S` (its slowness has no consequence)."""
        try:
            return self._call(
                ("warmup", problem),
                1,
                "warm-up",
                timeout=max(WARMUP_TIMEOUT_S, 2 * self.time_limit),
            )
        except WorkerDied as died:
            return died.status

    def replay(self, problem: qpsolvers.Problem) -> str:
        try:
            return self._call(("replay", problem), 1, "replay")
        except WorkerDied as died:
            return died.status

    # Same signature as LocalRunner.solve, on purpose: harness/bench.py calls either runner the
    # same way, and the worker passes these arguments on to a LocalRunner.
    def solve(
        self, problem: qpsolvers.Problem, repeat: int | None = None, reset_before: bool = False
    ) -> Outcome:
        n = self.spec["repeat"] if repeat is None else max(1, int(repeat))
        try:
            outcome = self._call(("solve", problem, repeat, reset_before), n, "solve")
        except WorkerDied as died:
            outcome = Outcome(died.status, None, [], died.message)
        if outcome.solution is not None:
            outcome.solution.problem = problem
        outcome.isolated = True
        outcome.state_reset = bool(reset_before and self.sequential)
        return outcome

    def close(self) -> None:
        if self._proc is not None and self._proc.is_alive():
            try:
                self._conn.send(("stop",))
                self._proc.join(2)
            except (OSError, EOFError, BrokenPipeError):
                pass
        self._kill()

    def __del__(self):  # pragma: no cover - best effort
        try:
            self._kill()
        except Exception:  # noqa: BLE001
            pass
