"""Backend ``noop``, the null backend: the machine's noise floor, not a solver.

It answers every QP with ``x = 0``, status ``optimal``, at once: a closed loop run with it does
everything a tick does but solve, so its ticks over ``dt`` are the machine's own
(docs/verdicts.md, "The noise floor"), judged on its whole ticks (``tick_time_s``). The
compiled engine runs it too (:mod:`qpbench.engine.solvers`).
Every closed-loop run set runs it once per scenario beside the candidates; ``all`` leaves it
out, the per-tick bench refuses it and the recommendation never ranks it. Duals: zero
(``x = 0`` solves no QP but the trivial one, so residuals mean nothing here). No time of its
own (``solver_time_s`` is ``None``).
"""

from __future__ import annotations

import numpy as np

from . import register
from .base import Backend, new_solution


@register
class NoopBackend(Backend):
    """``x = 0`` as ``optimal``, instantly: the loop without a solver."""

    name = "noop"  # not "null": pandas reads "null" in a CSV as a missing value
    family = "none: x = 0 at once (the machine's noise floor, not a candidate)"
    certifies_infeasibility = False
    infeasibility_note = "it solves nothing: x = 0 whatever the QP"
    noise_floor = True

    @classmethod
    def setting_names(cls) -> frozenset[str]:
        """None: there is nothing to set."""
        return frozenset()

    def _solve(self, problem, warm_start):
        n = problem.q.shape[0]
        sol = new_solution(problem, "optimal", {})
        sol.x = np.zeros(n)
        sol.y = np.zeros(0 if problem.A is None else problem.A.shape[0])
        sol.z = np.zeros(0 if problem.G is None else problem.G.shape[0])
        sol.z_box = np.zeros(n if problem.lb is not None or problem.ub is not None else 0)
        sol.iterations = 0
        return sol
