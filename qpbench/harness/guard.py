"""Guarded solves in this process: every way a solve can go wrong becomes a status
(:func:`qpbench.statuses.classify`); a solve is never interrupted here (a worker process,
:mod:`qpbench.harness.isolation`, runs this same class)."""

from __future__ import annotations

import logging
from dataclasses import dataclass, field
from typing import TYPE_CHECKING

from ..statuses import FAILURE_STATUSES, classify, describe_exception
from .timing import Replicas, difference, timed_call

if TYPE_CHECKING:
    import qpsolvers

log = logging.getLogger("qpbench.harness")


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
        self.repeat = max(1, int(repeat))
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
        count = self.repeat if repeat is None else max(1, int(repeat))
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
