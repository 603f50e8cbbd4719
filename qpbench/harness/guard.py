"""Guarded, timed solves (:func:`timed_call`, the one clock; ``--repeat``: :class:`Replicas`).
Every way a solve can go wrong is a status: :class:`LocalRunner` in this process,
:class:`IsolatedRunner` in a worker process, replaced after a death or a missed deadline."""

from __future__ import annotations

import logging
from contextlib import suppress
from dataclasses import dataclass, field
from typing import TYPE_CHECKING

import numpy as np

from ..backends.base import ANSWER_FIELDS, timed_call
from ..runner.process import START_TIMEOUT_S, Worker, WorkerDied, deadline
from ..statuses import FAILURE_STATUSES, classify, describe_exception

if TYPE_CHECKING:
    import qpsolvers

    from ..backends.base import Backend, BackendSolution

log = logging.getLogger("qpbench.harness")


class Replicas:
    """The instances of one backend that ``--repeat`` times; ``members[0]`` is the kept one;
    ``history``: the problems replica 0 solved since its last reset, in order."""

    def __init__(self, backend: Backend):
        self.members: list[Backend] = [backend]
        self.history: list[qpsolvers.Problem] = []
        self._solved = [0]  # how many problems of ``history`` each member has solved

    def reset(self) -> None:
        for backend in self.members:
            with suppress(Exception):  # a failing reset shows up at the next solve
                backend.reset()
        self.history.clear()
        self._solved = [0] * len(self.members)

    def solved(self, r: int, problem: qpsolvers.Problem) -> None:
        """Record that replica ``r`` solved ``problem`` (replica 0: the next of the history)."""
        if r == 0:
            self.history.append(problem)
        self._solved[r] += 1

    def drop(self, r: int) -> None:
        """Forget replica ``r`` and later ones (state suspect)."""
        del self.members[r:]
        del self._solved[r:]

    def ready(self, r: int) -> Backend:
        """Replica ``r >= 1`` in the state replica 0 had before its last solve: made if missing,
        then brought forward by solving the history it has not solved (all but the last)."""
        self.make(r + 1)
        backend = self.members[r]
        try:
            while self._solved[r] < len(self.history) - 1:
                timed_call(backend, self.history[self._solved[r]])  # untimed: only the state counts
                self._solved[r] += 1
        except Exception:
            self.drop(r)
            raise
        return backend

    def make(self, count: int) -> None:
        while len(self.members) < count:
            self.members.append(self.members[0].fresh())
            self._solved.append(0)


def difference(kept: BackendSolution | None, other: BackendSolution | None) -> str | None:
    """How ``other`` differs from ``kept`` (status, iterations, answer bit for bit), or ``None``."""
    if kept is None or other is None:
        return None if kept is other else "one repeat has no solution"
    if kept.status != other.status:
        return f"status {other.status} against {kept.status}"
    if kept.iterations != other.iterations:
        return f"{other.iterations} iterations against {kept.iterations}"
    for name in ANSWER_FIELDS:
        a, b = getattr(kept, name, None), getattr(other, name, None)
        if a is None or b is None:
            if (a is None) != (b is None):
                return f"{name} missing in one repeat"
            continue
        a, b = np.asarray(a), np.asarray(b)
        if a.shape != b.shape or a.tobytes() != b.tobytes():
            gap = float(np.max(np.abs(a - b))) if a.shape == b.shape and a.size else float("nan")
            return f"{name} differs (by {gap:.3g})"
    return None


@dataclass
class Outcome:
    """What one guarded (possibly repeated) solve produced: its status, replica 0's solution,
    ``wall_times_s`` of each timed repeat [s]; ``repeat_exact``: every repeat gave the kept
    answer bit for bit (else why in ``repeat_note``); ``state_reset``: the solve did not start
    from the previous one's state; ``isolated``: it ran in a worker process."""

    status: str
    solution: object | None = None
    wall_times_s: list = field(default_factory=list)
    error: str | None = None
    state_reset: bool = False
    isolated: bool = False
    repeat_exact: bool = True
    repeat_note: str = ""


class LocalRunner:
    """One backend's guarded, timed solves in this process: ``backend`` is replica 0;
    ``time_limit`` [s] is checked when a solve returns; ``sequential``: state carried between
    solves; ``repeat``: timed solves per problem."""

    isolated = False

    def __init__(self, backend, time_limit: float, sequential: bool, repeat: int = 1):
        self.replicas = Replicas(backend)
        self.name = backend.name
        self.time_limit = float(time_limit)
        self.sequential = sequential
        self.repeat = repeat
        if self.repeat > 1:
            try:
                self.replicas.make(self.repeat)
            except Exception as exc:  # noqa: BLE001 - reported by the first repeated solve
                log.debug("%s: cannot make replicas now (%s)", self.name, exc)

    @property
    def backend(self):
        """Replica 0: the backend whose answers are kept."""
        return self.replicas.members[0]

    def _guarded(self, problem, backend=None) -> Outcome:
        """One timed solve by ``backend`` (default: replica 0), never an exception."""
        try:
            solution, ns = timed_call(self.backend if backend is None else backend, problem)
        except Exception as exc:  # noqa: BLE001 - turned into a status on purpose
            return Outcome("error", None, [], describe_exception(exc))
        wall = ns * 1e-9
        status, error = classify(solution, wall, self.time_limit)
        return Outcome(status, solution, [wall], error)

    def reset(self) -> None:
        self.replicas.reset()

    def warmup(self, problem: qpsolvers.Problem) -> str:
        """A discarded solve by each replica (first-call costs), then a reset."""
        status = self._guarded(problem).status
        for backend in self.replicas.members[1:]:
            self._guarded(problem, backend)
        self.reset()
        return status

    def replay(self, problem: qpsolvers.Problem) -> str:
        """An unrecorded solve that only moves the state forward (resume)."""
        outcome = self._guarded(problem)
        self.replicas.solved(0, problem)
        return outcome.status

    def solve(
        self, problem: qpsolvers.Problem, repeat: int | None = None, reset_before: bool = False
    ) -> Outcome:
        """Solve ``problem`` once per replica (``repeat``, default the runner's), each from the
        same state; ``reset_before``: reset first (after a failure)."""
        if reset_before or not self.sequential:
            self.reset()
        count = repeat or self.repeat
        outcome = self._guarded(problem)
        self.replicas.solved(0, problem)
        if count > 1 and outcome.status not in FAILURE_STATUSES:
            self._repeat(problem, outcome, count)
        outcome.state_reset = bool(reset_before and self.sequential)
        return outcome

    def _repeat(self, problem, outcome: Outcome, count: int) -> None:
        """Time ``problem`` on replicas 1..count-1; their times and agreement go into ``outcome``."""
        notes = []
        for r in range(1, count):
            try:
                backend = self.replicas.ready(r)
            except Exception as exc:  # noqa: BLE001 - the row says so; the kept answer stands
                notes.append(
                    f"{r} of {count} solves timed: replica {r + 1}: {describe_exception(exc)}"
                )
                break
            other = self._guarded(problem, backend)
            self.replicas.solved(r, problem)
            outcome.wall_times_s.extend(other.wall_times_s)
            if other.status == "error":  # raised: its state is suspect, a new one is made next time
                self.replicas.drop(r)
            diff = difference(outcome.solution, other.solution)
            if diff is None and other.status == "error":
                diff = other.error
            if diff is not None:
                outcome.repeat_exact = False
                notes.append(f"repeat {r + 1}: {diff}")
        outcome.repeat_note = "; ".join(notes)

    def close(self) -> None:
        pass


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


def _build(spec: tuple) -> None:
    """In the worker: load kernels and plugins, build the backend and its :class:`LocalRunner`
    (``spec``: name, profile, settings, plugin files, then the runner's arguments)."""
    global _RUNNER
    from ..backends import get_backend, load_plugins
    from ..jit import warmup

    name, profile, settings, plugins, *guard = spec
    warmup([name], loop=False)
    load_plugins(plugins)
    _RUNNER = LocalRunner(get_backend(name, profile, **settings), *guard)


def _request(request: tuple):
    """In the worker: ``(method, *args)`` of the :class:`LocalRunner`."""
    op, *args = request
    if op == "solve":
        return _strip(_RUNNER.solve(*args))
    return getattr(_RUNNER, op)(*args)


class IsolatedRunner:
    """A backend in a worker process (arguments: :func:`qpbench.backends.get_backend`'s and
    :class:`LocalRunner`'s)."""

    isolated = True

    def __init__(
        self, name: str, profile, settings: dict, time_limit: float, sequential: bool, repeat=1
    ):
        from ..backends import plugin_files

        self.name = name
        self.time_limit = float(time_limit)
        self.sequential = sequential
        self.repeat = repeat
        plugins = plugin_files()
        self.spec = (name, profile, dict(settings), plugins, self.time_limit, sequential, repeat)
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
        request = ("solve", problem, repeat, reset_before)
        try:
            outcome = self._call(request, deadline(self.time_limit, repeat or self.repeat), "solve")
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
