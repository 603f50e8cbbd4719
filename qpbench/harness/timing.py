"""How a solve is timed, and how ``--repeat`` times it again from the same state.

The timed region is the backend call and the reading of its answer::

    gc.disable(); t0 = perf_counter_ns()
    sol = backend.solve(problem); sol.x; sol.y; sol.z; sol.z_box
    t1 = perf_counter_ns(); gc.enable()

Reading ``y``, ``z`` and ``z_box`` inside the region makes every backend pay
for its full answer: most build it inside ``solve``, while a backend may
defer the duals until first read (the online network's
:class:`~qpbench.backends.rnn.TickSolution`). The objective is not read: a
solver that reports one computed it inside its call; a backend without one
(``pinv``, ``rnn``) gets it computed from ``x`` on first read by
:class:`~qpbench.backends.base.BackendSolution`, a Python computation the
harness does for every backend anyway (:func:`qpbench.metrics.objective`),
which would charge those backends microseconds the others do not pay. For a
backend that built everything already the reads are attribute look-ups.

Loading, reference solutions, metrics, CSV writing and inter-process
communication are all outside it.

Repeats. A backend carries state from tick to tick (a persistent solver
object warm-started from its last iterate, OSQP's adapted ``rho``, an
active set, the network state of ``rnn``), and most of that state lives in
native objects that can be neither copied nor restored exactly. So
``--repeat R`` never restores a state: the harness keeps R instances of the
backend (:class:`Replicas`, made by :meth:`~qpbench.backends.base.Backend.fresh`),
feeds them the same problems in the same order, resets them at the same
points, and times each one's solve of the problem once. Replica 0 is the
backend a controller running once would have: its answer (status, ``x``,
duals, iterations) is the row's, and it is exactly the answer of
``--repeat 1``. Replicas 1..R-1 do the same work from the same state, so
their times are times of the kept solve; the harness checks that (the same
status, iterations and ``x``, ``y``, ``z``, ``z_box`` bit for bit) and the
row says when it does not hold (``repeat_exact``, ``repeat_note``: a solver
that is not deterministic, a replica that raised). A replica made after
replica 0 has solved problems of the sequence (a ``--repeat`` raised
mid-sequence, a replica dropped after an exception) first solves, untimed,
the problems replica 0 solved since its last reset (:attr:`Replicas.history`),
in order; if that cannot be done the row's other solves are not timed and
``repeat_note`` says why. A failed solve of replica 0 (``error``,
``time_limit``, ``invalid``) is not repeated; the harness resets every
replica before the next solve. In ``independent`` mode every replica is reset
before every problem.
"""

from __future__ import annotations

import gc
import logging
import time
from typing import TYPE_CHECKING

import numpy as np

if TYPE_CHECKING:
    import qpsolvers

    from ..backends.base import Backend, BackendSolution

log = logging.getLogger("qpbench.harness")


#: Fields of a solution read inside the timed region (see the module docstring).
ANSWER_FIELDS = ("x", "y", "z", "z_box")


def read_answer(solution: BackendSolution) -> None:
    """Read every field of :data:`ANSWER_FIELDS` (materialises fields a backend defers)."""
    for name in ANSWER_FIELDS:
        getattr(solution, name, None)


def timed_call(backend: Backend, problem: qpsolvers.Problem) -> tuple[BackendSolution, int]:
    """``(solution, wall time in [ns])`` of ``backend.solve(problem)`` and the reading of
    its answer (:func:`read_answer`), gc off."""
    enabled = gc.isenabled()
    gc.disable()
    try:
        t0 = time.perf_counter_ns()
        solution = backend.solve(problem)
        if solution is not None:
            read_answer(solution)
        t1 = time.perf_counter_ns()
    finally:
        if enabled:
            gc.enable()
    return solution, t1 - t0


class Replicas:
    """The instances of one backend that ``--repeat`` times (see the module docstring).

    Args:
        backend: Replica 0, the backend whose answers are kept.

    Attributes:
        members: The replicas made so far; ``members[0]`` is ``backend``.
        history: Problems replica 0 solved since its last reset, in order.
    """

    def __init__(self, backend: Backend):
        self.members: list[Backend] = [backend]
        self.history: list[qpsolvers.Problem] = []
        self._solved = [0]  # how many problems of ``history`` each member has solved

    def reset(self) -> None:
        """Reset every replica (a failing ``reset`` shows up at the next solve)."""
        for backend in self.members:
            try:
                backend.reset()
            except Exception:  # noqa: BLE001
                pass
        self.history.clear()
        self._solved = [0] * len(self.members)

    def solved(self, r: int, problem: qpsolvers.Problem) -> None:
        """Record that replica ``r`` solved ``problem`` (replica 0: the next problem of the history)."""
        if r == 0:
            self.history.append(problem)
        self._solved[r] += 1

    def drop(self, r: int) -> None:
        """Forget replica ``r`` (its state is suspect); a new one is made when needed."""
        del self.members[r:]
        del self._solved[r:]

    def ready(self, r: int) -> Backend:
        """Replica ``r`` (``r >= 1``) in the state replica 0 had before its last solve.

        Made when missing, then brought forward by solving, untimed, the problems of
        :attr:`history` it has not solved yet (all but the last).

        Raises:
            Exception: the replica cannot be made, or a catch-up solve raised (it is dropped).
        """
        self.make(r + 1)
        backend = self.members[r]
        target = len(self.history) - 1
        try:
            while self._solved[r] < target:
                solution = backend.solve(self.history[self._solved[r]])
                if solution is not None:
                    read_answer(solution)
                self._solved[r] += 1
        except Exception:
            self.drop(r)
            raise
        return backend

    def make(self, count: int) -> None:
        """Make replicas up to ``count`` (new ones start from the reset state)."""
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
