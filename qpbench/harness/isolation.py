"""Solves in a worker process, for backends that may hang in native code or crash.

:class:`IsolatedRunner` has the interface of
:class:`~qpbench.harness.guard.LocalRunner` but keeps the backend in a child
process (a :class:`~qpbench.runner.process.Worker`: a fork of a server that
imported qpbench once, so a restart costs milliseconds rather than a fresh
interpreter). Requests and results travel over a pipe; every request has a
deadline (:func:`~qpbench.runner.process.deadline`)::

    deadline = time_limit * (solves in the request) + max(1 s, time_limit / 2)

- no answer by the deadline -> the worker is killed (SIGKILL), the solve is
  ``time_limit``, a new worker starts at the next request. This is the only
  place a solve is stopped: inside the worker, as in the parent, a solve is
  never interrupted (see :mod:`qpbench.harness.guard`); one that returns
  late but before the deadline is ``time_limit`` by its wall time;
- the worker dies (segfault, abort, ``os._exit``) -> the solve is
  ``crashed`` with the signal or exit code in ``error``, a new worker starts.

A new worker has lost the backend's state (and its replicas'): in sequential
mode the next row says ``state_reset = True``.

No compile in a worker: the parent prepares the kernels of the backends it
runs before it starts one (:func:`qpbench.jit.warmup`, which leaves them in the
on-disk cache); the forkserver, started and preloaded before the first worker's
clock, imports qpbench and loads the kernels from the cache once
(:mod:`qpbench.harness.preload`), so each worker is forked with them in
memory. A worker started otherwise (``spawn``) loads them when it starts,
before it reports ready (within :data:`~qpbench.runner.process.START_TIMEOUT_S`, outside any
solve's deadline). The
discarded warm-up solve has an allowance of its own (:data:`WARMUP_TIMEOUT_S`):
a slow one is not a reason to kill the worker.

The timing is taken inside the worker by the same
:class:`~qpbench.harness.guard.LocalRunner` code that runs in-process, around
the backend call only, so pickling and the pipe are not in the reported wall
times; they only add to the run's total duration.
"""

from __future__ import annotations

import logging
from typing import TYPE_CHECKING

import numpy as np

from ..runner.process import START_TIMEOUT_S, Worker, WorkerDied, deadline
from .guard import LocalRunner, Outcome

if TYPE_CHECKING:
    import qpsolvers

log = logging.getLogger("qpbench.harness")

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

#: In a worker process: the guarded backend the requests go to (:func:`_build`).
_RUNNER: LocalRunner | None = None


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


def _build(spec: dict) -> None:
    """In the worker: load the plugins, build the backend and its :class:`LocalRunner`."""
    global _RUNNER
    from ..backends import get_backend, load_plugins
    from ..jit import warmup

    # loads the kernels the parent compiled for this backend; nothing is timed yet
    warmup([spec["backend"]], loop=False)
    load_plugins(spec["plugins"])
    backend = get_backend(spec["backend"], spec["profile"], **spec["settings"])
    _RUNNER = LocalRunner(backend, spec["time_limit"], spec["sequential"], spec["repeat"])


def _request(request: tuple):
    """In the worker: ``(method, *args)`` of the :class:`LocalRunner`."""
    op, *args = request
    if op == "solve":
        return _strip(_RUNNER.solve(*args))
    return getattr(_RUNNER, op)(*args)


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
        self._worker: Worker | None = None
        self.restarts = 0

    def _call(self, request: tuple, timeout: float, what: str):
        try:
            if self._worker is None:
                self._worker = Worker(name=f"qpbench-{self.name}")
                try:
                    self._worker.call(_build, self.spec, START_TIMEOUT_S, "start")
                except WorkerDied as died:
                    if died.status != "error":
                        raise
                    self.close()
                    raise WorkerDied("error", f"worker could not build backend: {died.message}")
                log.debug("worker for %s started (pid %s)", self.name, self._worker.proc.pid)
            return self._worker.call(_request, request, timeout, what)
        except WorkerDied as died:
            if died.status != "error":  # the worker is gone: a new one at the next request
                self._worker = None
                self.restarts += 1
            raise

    # -- interface shared with LocalRunner -------------------------------------------
    def reset(self) -> None:
        if self._worker is None:
            return  # a new worker has no state anyway
        try:
            self._call(("reset",), deadline(self.time_limit), "reset")
        except WorkerDied:
            pass

    def warmup(self, problem: qpsolvers.Problem) -> str:
        """The discarded warm-up solve, allowed :data:`WARMUP_TIMEOUT_S` (its slowness has no consequence)."""
        try:
            timeout = max(WARMUP_TIMEOUT_S, 2 * self.time_limit)
            return self._call(("warmup", problem), timeout, "warm-up")
        except WorkerDied as died:
            return died.status

    def replay(self, problem: qpsolvers.Problem) -> str:
        try:
            return self._call(("replay", problem), deadline(self.time_limit), "replay")
        except WorkerDied as died:
            return died.status

    # Same signature as LocalRunner.solve, on purpose: harness/bench.py calls either runner the
    # same way, and the worker passes these arguments on to a LocalRunner.
    def solve(
        self, problem: qpsolvers.Problem, repeat: int | None = None, reset_before: bool = False
    ) -> Outcome:
        n = self.spec["repeat"] if repeat is None else max(1, int(repeat))
        try:
            outcome = self._call(
                ("solve", problem, repeat, reset_before), deadline(self.time_limit, n), "solve"
            )
        except WorkerDied as died:
            outcome = Outcome(died.status, None, [], died.message)
        if outcome.solution is not None:
            outcome.solution.problem = problem
        outcome.isolated = True
        outcome.state_reset = bool(reset_before and self.sequential)
        return outcome

    def close(self) -> None:
        if self._worker is not None:
            self._worker.stop()
            self._worker = None

    def __del__(self):  # pragma: no cover - best effort
        try:
            self.close()
        except Exception:  # noqa: BLE001
            pass
