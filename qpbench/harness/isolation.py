"""Solves in a worker process, for backends that may hang in native code or crash: a
:class:`~qpbench.harness.guard.LocalRunner` in a :class:`~qpbench.runner.process.Worker`, which
is replaced, without the backend's state, after a death or a missed deadline."""

from __future__ import annotations

import logging
from typing import TYPE_CHECKING

import numpy as np

from ..runner.process import START_TIMEOUT_S, Worker, WorkerDied, deadline
from .guard import LocalRunner, Outcome
from .timing import ANSWER_FIELDS

if TYPE_CHECKING:
    import qpsolvers

log = logging.getLogger("qpbench.harness")

ISOLATE = ("auto", "always", "never")
#: Time allowed for the discarded warm-up solve [s] (at least twice the time limit).
WARMUP_TIMEOUT_S = 30.0

#: Solution attributes sent back from a worker (extras may hold native objects).
_FIELDS = (
    *ANSWER_FIELDS,
    "found",
    "obj",
    "status",
    "iterations",
    "solver_time_s",
    "backend",
    "error",
)
_PLAIN = (int, float, str, bool, type(None), np.ndarray, np.generic)

#: In a worker process: the guarded backend the requests go to.
_RUNNER: LocalRunner | None = None


def wants_worker(isolate: str, backend: str, learned=()) -> bool:
    """Whether ``backend`` runs in a worker under ``isolate`` (:data:`ISOLATE`): ``always``, or
    ``auto`` and its class says ``risky = True`` or it is in ``learned`` (seen to crash here)."""
    from ..backends import backend_class
    from ..exceptions import BackendNotFound

    if isolate != "auto":
        return isolate == "always"
    try:
        return backend in learned or bool(backend_class(backend).risky)
    except BackendNotFound:
        return False


def _strip(outcome: Outcome) -> Outcome:
    """The outcome with a plain, picklable :class:`BackendSolution` without the problem."""
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
    """In the worker: load kernels and plugins, build the backend and its :class:`LocalRunner`."""
    global _RUNNER
    from ..backends import get_backend, load_plugins
    from ..jit import warmup

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
    """A backend in a worker process: ``profile``, ``settings``: as for
    :func:`qpbench.backends.get_backend`; ``time_limit`` [s], ``sequential``, ``repeat``: as for
    :class:`LocalRunner`."""

    isolated = True

    def __init__(
        self, name: str, profile, settings: dict, time_limit: float, sequential: bool, repeat=1
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

    def _status(self, request: tuple, timeout: float, what: str):
        """The worker's answer to ``request``, or the status of its failure."""
        try:
            return self._call(request, timeout, what)
        except WorkerDied as died:
            return died.status

    def reset(self) -> None:
        if self._worker is not None:  # a new worker has no state anyway
            self._status(("reset",), deadline(self.time_limit), "reset")

    def warmup(self, problem: qpsolvers.Problem) -> str:
        timeout = max(WARMUP_TIMEOUT_S, 2 * self.time_limit)
        return self._status(("warmup", problem), timeout, "warm-up")

    def replay(self, problem: qpsolvers.Problem) -> str:
        return self._status(("replay", problem), deadline(self.time_limit), "replay")

    def solve(
        self, problem: qpsolvers.Problem, repeat: int | None = None, reset_before: bool = False
    ) -> Outcome:
        n = self.spec["repeat"] if repeat is None else max(1, int(repeat))
        request = ("solve", problem, repeat, reset_before)
        try:
            outcome = self._call(request, deadline(self.time_limit, n), "solve")
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
