
"""A backend of the plugin tests: DAQP through qpsolvers.solve_problem."""

import qpsolvers

from qpbench.backends import Backend, BackendSolution, register


@register
class DroppedIn(Backend):
    name = "test-dropped-in"
    family = "active set (test)"
    risky = False
    certifies_infeasibility = False
    infeasibility_note = "qpsolvers drops DAQP's exit flag"

    def _solve(self, problem, warm_start):
        result = qpsolvers.solve_problem(problem, "daqp")
        sol = BackendSolution(problem, status="optimal" if result.found else "not_solved")
        sol.x, sol.y, sol.z, sol.z_box = result.x, result.y, result.z, result.z_box
        return sol
