"""Backend ``pinv``: the paper's comparison baseline, Jacobian Moore-Penrose inverse (JMPI).

The JMPI controller of the paper's section 4, ``v = J^+ b0``, ignores obstacles and joint
limits. As a QP "solver": with equalities ``x = A^+ b`` (the minimum-norm solution, the QP's
minimiser when ``P = I, q = 0`` as in the paper's eq. 11), else ``x = -P^+ q``; status
``optimal`` whenever an ``x`` was produced. Duals: ``y = -(A')^+ (P x + q)`` (least squares of
the stationarity condition), ``z`` and ``z_box`` zero.
"""

from __future__ import annotations

from functools import cache

import numpy as np

from ..native import compile_with
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
    kernels = ("pinv",)

    @classmethod
    def setting_names(cls) -> frozenset[str]:
        """None: the pseudo-inverse has no tolerance, limit or option to set."""
        return frozenset()

    def _solve(self, problem, warm_start):
        sol = BackendSolution(problem)
        P = np.ascontiguousarray(as_dense(problem.P), dtype=np.float64)
        q = np.ascontiguousarray(problem.q, dtype=np.float64)
        n = q.shape[0]
        if problem.A is not None and problem.A.shape[0] > 0:
            A = np.ascontiguousarray(as_dense(problem.A), dtype=np.float64)
            b = np.ascontiguousarray(problem.b, dtype=np.float64)
        else:
            A, b = np.zeros((0, n)), np.zeros(0)
        x, y = np.empty(n), np.empty(b.shape[0])
        try:
            pinv_kernel()(P, q, A, b, x, y)
        except np.linalg.LinAlgError as exc:
            return error_solution(problem, exc)
        sol.x, sol.y = x, y
        sol.z = np.zeros(0 if problem.G is None else problem.G.shape[0])
        sol.z_box = np.zeros(n if problem.lb is not None or problem.ub is not None else 0)
        sol.status = "optimal"
        sol.iterations = 0
        return sol


@cache
def pinv_kernel():
    """:func:`pinv_py` compiled: the one implementation the backend and the compiled engine call."""
    return compile_with(pinv_py, name="pinv")


def pinv_py(P, q, A, b, x, y):  # pragma: no cover - compiled
    """JMPI into ``x`` (n,) and ``y`` (me,): ``A = U S V'``, ``x = V S^+ U' b``, ``y = -U S^+ V'
    (P x + q)``; without equalities ``x = -P^+ q``. ``S^+`` drops ``s < max(A.shape) eps s_max``."""
    n, me = P.shape[0], A.shape[0]
    eps = np.finfo(np.float64).eps
    if me == 0:
        x[:] = np.linalg.lstsq(P, -q, rcond=n * eps)[0]
        return
    U, s, Vt = np.linalg.svd(A, full_matrices=False)
    cut = max(me, n) * eps * s[0]
    s_inv = np.zeros(s.shape[0])
    for i in range(s.shape[0]):
        if s[i] > cut:
            s_inv[i] = 1.0 / s[i]
    x[:] = Vt.T @ (s_inv * (U.T @ b))
    y[:] = -(U @ (s_inv * (Vt @ (P @ x + q))))
