"""Backend ``pinv``: the paper's comparison baseline, Jacobian Moore-Penrose inverse (JMPI).

The JMPI controller of the paper's section 4, ``v = J^+ b0``, ignores obstacles and joint
limits. As a QP "solver": with equalities ``x = A^+ b`` (the minimum-norm solution, the QP's
minimiser when ``P = I, q = 0`` as in the paper's eq. 11), else ``x = -P^+ q``; status
``optimal`` whenever an ``x`` was produced. Duals: ``y = -(A')^+ (P x + q)`` (least squares of
the stationarity condition), ``z`` and ``z_box`` zero.
"""

from __future__ import annotations

import numpy as np

from . import register
from ._common import as_dense
from .base import Backend, BackendSolution, error_solution


@register
class PinvBackend(Backend):
    """JMPI: ``x = A^+ b`` (or ``-P^+ q`` without equalities); constraints ignored."""

    name = "pinv"
    certifies_infeasibility = False
    infeasibility_note = (
        "x = A^+ b solves the equalities in the least-squares sense and ignores the rest"
    )
    family = "pseudo-inverse (JMPI, ignores inequalities and bounds)"
    package = "numpy"

    @classmethod
    def setting_names(cls) -> frozenset[str]:
        """None: the pseudo-inverse has no tolerance, limit or option to set."""
        return frozenset()

    def _solve(self, problem, warm_start):
        sol = BackendSolution(problem)
        P = as_dense(problem.P)
        q = np.asarray(problem.q, dtype=float)
        n = q.shape[0]
        try:
            if problem.A is not None and problem.A.shape[0] > 0:
                # One thin SVD A = U S V' gives both pseudo-inverse solutions:
                # x = V S^+ U' b and y = -U S^+ V' (P x + q).
                A = as_dense(problem.A)
                U, s, Vt = np.linalg.svd(A, full_matrices=False)
                keep = s > max(A.shape) * np.finfo(float).eps * (s[0] if s.size else 0.0)
                s_inv = np.where(keep, 1.0 / np.where(keep, s, 1.0), 0.0)
                x = Vt.T @ (s_inv * (U.T @ np.asarray(problem.b, dtype=float)))
                y = -U @ (s_inv * (Vt @ (P @ x + q)))
            else:
                x = np.linalg.lstsq(P, -q, rcond=None)[0]
                y = np.zeros(0)
        except np.linalg.LinAlgError as exc:
            return error_solution(problem, exc)
        sol.x = x
        sol.y = y
        sol.z = np.zeros(0 if problem.G is None else problem.G.shape[0])
        sol.z_box = np.zeros(n if problem.lb is not None or problem.ub is not None else 0)
        sol.status = "optimal"
        sol.iterations = 0
        return sol
