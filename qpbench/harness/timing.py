"""The one clock around a solve (:func:`timed_call`), and how ``--repeat R`` times a solve again
from the same state: R instances of a backend fed the same problems (:class:`Replicas`), since
its state mostly lives in native objects that cannot be restored."""

from __future__ import annotations

import gc
import time
from typing import TYPE_CHECKING

import numpy as np

if TYPE_CHECKING:
    import qpsolvers

    from ..backends.base import Backend, BackendSolution

#: Fields of a solution read inside the timed region.
ANSWER_FIELDS = ("x", "y", "z", "z_box")


def timed_call(backend: Backend, problem: qpsolvers.Problem) -> tuple[BackendSolution, int]:
    """``(solution, wall time [ns])`` of ``backend.solve(problem)`` and the reading of its
    :data:`ANSWER_FIELDS` (a backend deferring its duals pays for them), gc off."""
    enabled = gc.isenabled()
    gc.disable()
    try:
        t0 = time.perf_counter_ns()
        solution = backend.solve(problem)
        if solution is not None:  # materialises the fields a backend defers
            for name in ANSWER_FIELDS:
                getattr(solution, name, None)
        t1 = time.perf_counter_ns()
    finally:
        if enabled:
            gc.enable()
    return solution, t1 - t0


class Replicas:
    """The instances of one backend that ``--repeat`` times; ``members[0]`` is the kept one;
    ``history``: the problems replica 0 solved since its last reset, in order."""

    def __init__(self, backend: Backend):
        self.members: list[Backend] = [backend]
        self.history: list[qpsolvers.Problem] = []
        self._solved = [0]  # how many problems of ``history`` each member has solved

    def reset(self) -> None:
        for backend in self.members:
            try:
                backend.reset()
            except Exception:  # noqa: BLE001
                pass
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
