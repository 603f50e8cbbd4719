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

from dataclasses import dataclass, field
from typing import TYPE_CHECKING

from ..statuses import FAILURE_STATUSES, classify, describe_exception
from .timing import StateRestorer, timed_call

if TYPE_CHECKING:
    import qpsolvers


@dataclass
class Outcome:
    """What one guarded (possibly repeated) solve produced.

    Attributes:
        status: Backend status, or ``error``/``time_limit``/``invalid``/``crashed``.
        solution: The solution of the last repeat (``None`` if there is none).
        wall_times_s: Wall time of each timed repeat in [s].
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


class LocalRunner:
    """Run one backend's solves in this process, guarded and timed.

    Args:
        backend: A backend instance (its profile carries the time limit).
        time_limit: Per-solve limit in [s], checked when the solve returns.
        sequential: State carried between solves (else reset before each).
    """

    isolated = False

    def __init__(self, backend, time_limit: float, sequential: bool):
        self.backend = backend
        self.name = backend.name
        self.time_limit = float(time_limit)
        self.sequential = sequential
        self.restorer = StateRestorer(sequential)

    # -- helpers -------------------------------------------------------------
    def _guarded(self, problem) -> Outcome:
        """One solve: an :class:`Outcome` with one wall time, never an exception.

        The solve runs to its end; a late one is ``time_limit`` by its wall time.
        """
        try:
            solution, ns = timed_call(self.backend, problem)
        except Exception as exc:  # noqa: BLE001 - turned into a status on purpose
            return Outcome("error", None, [], describe_exception(exc))
        wall = ns * 1e-9
        status, error = classify(solution, wall, self.time_limit)
        return Outcome(status, solution, [wall], error)

    # -- interface shared with IsolatedRunner -----------------------------------
    def reset(self) -> None:
        """Forget the backend's state (a new sequence starts)."""
        try:
            self.backend.reset()
        except Exception:  # noqa: BLE001 - a failing reset shows up at the next solve
            pass

    def warmup(self, problem: qpsolvers.Problem) -> str:
        """A discarded solve (imports, first-call allocations, a compile for an unusual
        problem shape), then a reset. Its status and time have no consequence."""
        outcome = self._guarded(problem)
        self.reset()
        return outcome.status

    def replay(self, problem: qpsolvers.Problem) -> str:
        """An untimed, unrecorded solve that only moves the state forward (resume)."""
        return self._guarded(problem).status

    # Same signature as IsolatedRunner.solve, on purpose: harness/bench.py calls either runner
    # the same way (tests/test_guard.py drives both).
    def solve(
        self,
        problem: qpsolvers.Problem,
        repeat: int = 1,
        reset_before: bool = False,
        prev_problem: qpsolvers.Problem | None = None,
    ) -> Outcome:
        """Solve ``problem`` ``repeat`` times from the same state; time each.

        Args:
            problem: The QP.
            repeat: Number of timed solves (R >= 1).
            reset_before: Reset the backend first (independent mode, or after a failure).
            prev_problem: The previous problem of the sequence (for restoring by replay).
        """
        if reset_before or not self.sequential:
            self.reset()
        if repeat <= 1:
            outcome = self._guarded(problem)
        else:
            times = []
            self.restorer.snapshot(self.backend)
            for r in range(repeat):
                if r > 0:
                    try:
                        self.backend = self.restorer.restore(self.backend, prev_problem)
                    except Exception as exc:  # noqa: BLE001
                        outcome = Outcome(
                            "error", None, times, f"restoring state: {describe_exception(exc)}"
                        )
                        break
                outcome = self._guarded(problem)
                times.extend(outcome.wall_times_s)
                if outcome.status in FAILURE_STATUSES:
                    break
            outcome.wall_times_s = times
        outcome.state_reset = bool(reset_before and self.sequential)
        return outcome

    def close(self) -> None:
        """Nothing to release in this process (the interface of :class:`IsolatedRunner`)."""
