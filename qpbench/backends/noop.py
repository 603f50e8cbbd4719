"""Backend ``noop``, the null backend: the machine's noise floor, not a solver.

It answers every QP with ``x = 0``, status ``optimal``, zero duals, no time of its own: a
closed loop run with it does everything a tick does but solve (docs/verdicts.md, "The noise
floor"). Every closed-loop run set runs it; ``all`` and the per-tick bench leave it out.
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
