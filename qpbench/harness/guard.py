"""Guarded solves in this process.

:class:`LocalRunner` wraps one backend instance and turns every way a solve
can go wrong into a status, never an exception:

- a Python exception escaping the backend -> ``error``, with
  ``"Type: message"`` in :attr:`Outcome.error`;
- a solve longer than the time limit -> ``time_limit``. The solve is never
  interrupted: its wall time is compared with the limit when it returns.
  Raising an exception asynchronously inside a backend (a signal handler, as
  ``SIGALRM`` would) can land in foreign code (a solver's Python wrapper,
  numba's compiler, a C extension's callback) and leave it broken, so this
  process does not; a solve that must be stopped (a hang in native or Python
  code) needs a worker process, which is killed at its deadline (see
  :mod:`qpbench.harness.isolation`; the bench moves a backend that overran
  its limit in this process to one, under ``--isolate auto``);
- a non-finite ``x`` (or ``optimal`` without ``x``) -> ``invalid``.

After ``error``, ``time_limit`` and ``invalid`` (:data:`qpbench.statuses.FAILURE_STATUSES`) the
backend is reset before its next solve: its state can no longer be trusted. The
classification itself (:func:`qpbench.statuses.classify`) is shared with the closed loop.

The same class runs inside the worker process of an isolated backend, so the
timed region is identical in both cases.
"""

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
    """What one guarded (possibly repeated) solve produced.

    Attributes:
        status: Backend status, or ``error``/``time_limit``/``invalid``/``crashed``.
        solution: The solution of the kept solve (``None`` if there is none): replica 0's,
            the one a controller solving once gets (:mod:`qpbench.harness.timing`).
        wall_times_s: Wall time of each timed repeat in [s].
        repeat_exact: Every timed repeat did the kept solve's work: it returned the
            kept status, iterations and answer bit for bit.
        repeat_note: Why ``repeat_exact`` is false or fewer repeats were timed than
            asked (empty otherwise; a failed solve is not repeated and needs no note).
        error: ``"Type: message"`` or a description of the failure.
        state_reset: The solve did not start from the state the previous
            solve of the sequence left (a reset after a failure, a new worker).
        isolated: The solve ran in a worker process.
    """

    status: str
    solution: object | None = None
    wall_times_s: list = field(default_factory=list)
    error: str | None = None
    state_reset: bool = False
    isolated: bool = False
    repeat_exact: bool = True
    repeat_note: str = ""


class LocalRunner:
    """Run one backend's solves in this process, guarded and timed.

    Args:
        backend: A backend instance (its profile carries the time limit): replica 0.
        time_limit: Per-solve limit in [s], checked when the solve returns.
        sequential: State carried between solves (else reset before each).
        repeat: Timed solves per problem: the replicas made now (and warmed up by
            :meth:`warmup`); :meth:`solve` makes more if asked for more.
    """

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

    # -- helpers -------------------------------------------------------------
    def _guarded(self, problem, backend=None) -> Outcome:
        """One solve by ``backend`` (default: replica 0): an :class:`Outcome` with one wall
        time, never an exception. The solve runs to its end; a late one is ``time_limit`` by
        its wall time.
        """
        try:
            solution, ns = timed_call(self.backend if backend is None else backend, problem)
        except Exception as exc:  # noqa: BLE001 - turned into a status on purpose
            return Outcome("error", None, [], describe_exception(exc))
        wall = ns * 1e-9
        status, error = classify(solution, wall, self.time_limit)
        return Outcome(status, solution, [wall], error)

    # -- interface shared with IsolatedRunner -----------------------------------
    def reset(self) -> None:
        """Forget the backend's state (a new sequence starts): every replica's."""
        self.replicas.reset()

    def warmup(self, problem: qpsolvers.Problem) -> str:
        """A discarded solve by each replica (imports, first-call allocations, a compile for an
        unusual problem shape), then a reset. Its status and time have no consequence."""
        status = self._guarded(problem).status
        for backend in self.replicas.members[1:]:
            self._guarded(problem, backend)
        self.reset()
        return status

    def replay(self, problem: qpsolvers.Problem) -> str:
        """An untimed, unrecorded solve that only moves the state forward (resume); the other
        replicas follow at their next solve (:meth:`Replicas.ready`)."""
        outcome = self._guarded(problem)
        self.replicas.solved(0, problem)
        return outcome.status

    # Same signature as IsolatedRunner.solve, on purpose: harness/bench.py calls either runner
    # the same way (tests/test_guard.py drives both).
    def solve(
        self, problem: qpsolvers.Problem, repeat: int | None = None, reset_before: bool = False
    ) -> Outcome:
        """Solve ``problem`` once per replica, each from the same state; time each.

        Args:
            problem: The QP.
            repeat: Number of timed solves (R >= 1; default: the runner's).
            reset_before: Reset the backend first (independent mode, or after a failure).
        """
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
        """Nothing to release in this process (the interface of :class:`IsolatedRunner`)."""
