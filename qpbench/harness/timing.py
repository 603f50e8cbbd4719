"""How a solve is timed, and how a backend's state is restored between repeats.

The timed region is the backend call and the reading of its answer::

    gc.disable(); t0 = perf_counter_ns()
    sol = backend.solve(problem); sol.x; sol.y; sol.z; sol.z_box
    t1 = perf_counter_ns(); gc.enable()

Reading ``y``, ``z`` and ``z_box`` inside the region makes every backend pay
for its full answer: most build it inside ``solve``, while a backend may
defer the duals until first read (the online network's
:class:`~qpbench.backends.rnn.TickSolution`: about 1 us a tick on
``problems/wall``). The objective is not read: a solver that reports one
computed it inside its call; a backend without one (``pinv``, ``rnn``) gets
it computed from ``x`` on first read by
:class:`~qpbench.backends.base.BackendSolution`, a Python computation the
harness does for every backend anyway (:func:`qpbench.metrics.objective`),
which would charge those backends microseconds the others do not pay. For a
backend that built everything already the reads are attribute look-ups.

Loading, reference solutions, metrics, CSV writing and inter-process
communication are all outside it. With ``--repeat R`` the same problem is
solved R times from the same backend state; the row reports the minimum and
the median of the R wall times and the metrics of the last repeat.

A backend carries state from tick to tick (a persistent solver object, a warm
start, the network state of ``rnn``). So that each repeat starts from the
state the first one started from, :class:`StateRestorer` uses, in this order:

1. ``backend.get_state()`` / ``backend.set_state(state)`` when the backend has
   them (exact, cheap);
2. ``copy.deepcopy(backend)`` of the backend taken before the first repeat,
   deep-copied again for each repeat (exact for pure-Python/numpy state);
3. when neither works (a native handle that cannot be copied):
   ``backend.reset()`` then an untimed solve of the previous problem of the
   sequence. This rebuilds the state exactly for backends whose state is a
   function of the last problem they solved (a persistent OSQP/Clarabel/
   ProxQP object warm-started from its last answer), which is what every
   built-in stateful backend keeps.

In ``independent`` mode there is nothing to restore: every repeat starts
with ``backend.reset()``.
"""

from __future__ import annotations

import copy
import gc
import logging
import time
from typing import TYPE_CHECKING

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


class StateRestorer:
    """Snapshot a backend before repeat 1 and bring it back before repeats 2..R.

    Args:
        sequential: ``False`` for independent mode (restore = reset).

    Attributes:
        method: ``"reset"``, ``"state"``, ``"deepcopy"`` or ``"replay"``, the
            method used for the last snapshot.
    """

    def __init__(self, sequential: bool):
        self.sequential = sequential
        self.method = "reset" if not sequential else None
        self._snap = None
        self._no_deepcopy: set[str] = set()

    def snapshot(self, backend: Backend) -> None:
        """Remember ``backend``'s current state."""
        if not self.sequential:
            return
        if hasattr(backend, "get_state") and hasattr(backend, "set_state"):
            self.method = "state"
            self._snap = backend.get_state()
            return
        if backend.name not in self._no_deepcopy:
            try:
                self._snap = copy.deepcopy(backend)
                self.method = "deepcopy"
                return
            except Exception as exc:  # native handles that cannot be copied
                log.debug("%s cannot be deep-copied (%s): restoring by replay", backend.name, exc)
                self._no_deepcopy.add(backend.name)
        self.method = "replay"
        self._snap = None

    def restore(self, backend: Backend, prev_problem: qpsolvers.Problem | None) -> Backend:
        """Return a backend in the snapshot state (``backend`` itself or a copy)."""
        if self.method == "reset":
            backend.reset()
            return backend
        if self.method == "state":
            backend.set_state(self._snap)
            return backend
        if self.method == "deepcopy":
            return copy.deepcopy(self._snap)
        backend.reset()
        if prev_problem is not None:
            backend.solve(prev_problem)
        return backend
