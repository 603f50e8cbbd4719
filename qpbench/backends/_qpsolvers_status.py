"""Statuses and iteration counts of the solvers qpbench drives through qpsolvers.

qpsolvers hands back each solver's own status in ``Solution.extras``; the
readers here map it to qpbench's statuses
(:data:`qpbench.backends.base.STATUSES`). Which solvers' statuses, as
qpsolvers passes them on, tell a primal-infeasible QP from an unbounded one:
:data:`CERTIFYING_SOLVERS` and, with the reason, :data:`NO_CERTIFICATE`
(the backends' ``certifies_infeasibility``). Used by :mod:`.qpsolvers_`.
"""

from __future__ import annotations

import numpy as np

_ndarray = np.ndarray


def _status_clarabel(extras) -> tuple[str, str | None]:
    from .clarabel_ import CLARABEL_STATUSES

    raw = extras.get("status")
    name = str(raw).split(".")[-1] if raw is not None else None
    return CLARABEL_STATUSES.get(name, "not_solved"), name


_ENUM_MAPS: dict[str, dict] = {}


def _enum_map(solver: str) -> dict:
    """Solver status value -> our status, built once per solver (hashing their enums is slow)."""
    if solver not in _ENUM_MAPS:
        if solver == "osqp":
            import osqp

            S = osqp.SolverStatus
            pairs = [
                (S.OSQP_SOLVED, "optimal"),
                (S.OSQP_PRIMAL_INFEASIBLE, "primal_infeasible"),
                (S.OSQP_DUAL_INFEASIBLE, "dual_infeasible"),
                (S.OSQP_MAX_ITER_REACHED, "max_iter"),
                (S.OSQP_TIME_LIMIT_REACHED, "time_limit"),
            ]
            _ENUM_MAPS[solver] = {int(k): v for k, v in pairs}
        elif solver == "proxqp":
            import proxsuite

            O = proxsuite.proxqp.QPSolverOutput
            _ENUM_MAPS[solver] = {
                O.PROXQP_SOLVED: "optimal",
                O.PROXQP_PRIMAL_INFEASIBLE: "primal_infeasible",
                O.PROXQP_DUAL_INFEASIBLE: "dual_infeasible",
                O.PROXQP_MAX_ITER_REACHED: "max_iter",
            }
        elif solver == "piqp":
            import piqp

            _ENUM_MAPS[solver] = {
                piqp.PIQP_SOLVED: "optimal",
                piqp.PIQP_PRIMAL_INFEASIBLE: "primal_infeasible",
                piqp.PIQP_DUAL_INFEASIBLE: "dual_infeasible",
                piqp.PIQP_MAX_ITER_REACHED: "max_iter",
                piqp.PIQP_NUMERICS: "error",
            }
    return _ENUM_MAPS[solver]


def _status_osqp(extras) -> tuple[str, str | None]:
    info = extras.get("info")
    if info is None:
        return "not_solved", None
    return _enum_map("osqp").get(int(info.status_val), "not_solved"), str(info.status)


def _status_proxqp(extras) -> tuple[str, str | None]:
    info = extras.get("info")
    if info is None:
        return "not_solved", None
    return _enum_map("proxqp").get(info.status, "not_solved"), None


def _status_piqp(extras) -> tuple[str, str | None]:
    info = extras.get("info")
    if info is None:
        return "not_solved", None
    return _enum_map("piqp").get(info.status, "not_solved"), None


def _status_scs(extras) -> tuple[str, str | None]:
    val = extras.get("status_val")
    if val is None:
        return "not_solved", None
    # SCS 3: 1 solved, -1 unbounded, -2 infeasible, -6/-7 the inaccurate ones.
    mapping = {1: "optimal", -1: "dual_infeasible", -2: "primal_infeasible"}
    return mapping.get(val, "not_solved"), f"{val} ({extras.get('status', '')})"


def _status_ecos(extras) -> tuple[str, str | None]:
    flag = extras.get("exitFlag")
    if flag is None:
        return "not_solved", None
    # ECOS: 0 optimal, 1 primal infeasible, 2 dual infeasible, -1 max iterations; others inaccurate/failed.
    mapping = {0: "optimal", 1: "primal_infeasible", 2: "dual_infeasible", -1: "max_iter"}
    return mapping.get(flag, "not_solved"), f"{flag} ({extras.get('infostring', '')})"


def _status_cvxopt(extras) -> tuple[str, str | None]:
    raw = extras.get("status")
    if raw is None:
        return "not_solved", None
    # cvxopt's qp() says "optimal" or "unknown" (it certifies infeasibility for LPs/cone programs only).
    mapping = {
        "optimal": "optimal",
        "primal infeasible": "primal_infeasible",
        "dual infeasible": "dual_infeasible",
    }
    return mapping.get(raw, "not_solved"), str(raw)


def _status_qpalm(extras) -> tuple[str, str | None]:
    info = extras.get("info")
    if info is None:
        return "not_solved", None
    raw = str(info.status)
    mapping = {
        "solved": "optimal",
        "primal infeasible": "primal_infeasible",
        "dual infeasible": "dual_infeasible",
        "maximum iterations reached": "max_iter",
        "time limit exceeded": "time_limit",
    }
    return mapping.get(raw, "not_solved"), raw


def _status_gurobi(extras) -> tuple[str, str | None]:
    code = extras.get("status")
    if code is None:
        return "not_solved", None
    # Gurobi's model status codes: 2 OPTIMAL, 3 INFEASIBLE, 5 UNBOUNDED, 7 ITERATION_LIMIT, 9 TIME_LIMIT;
    # 4 INF_OR_UNBD says neither for sure.
    mapping = {
        2: "optimal",
        3: "primal_infeasible",
        5: "dual_infeasible",
        7: "max_iter",
        9: "time_limit",
    }
    return mapping.get(code, "not_solved"), str(code)


#: Solver -> ``reader(extras) -> (status, raw status)``.
STATUS_READERS = {
    "clarabel": _status_clarabel,
    "osqp": _status_osqp,
    "proxqp": _status_proxqp,
    "piqp": _status_piqp,
    "scs": _status_scs,
    "ecos": _status_ecos,
    "cvxopt": _status_cvxopt,
    "qpalm": _status_qpalm,
    "gurobi": _status_gurobi,
}


def _iter_info(extras: dict) -> int:
    return int(extras["info"].iter)


def _iter_iter(extras: dict) -> int:
    return int(extras["iter"])


def _iter_quadprog(extras: dict) -> int:
    it = extras["iterations"]  # quadprog's (iterations, active-set changes)
    return int(it.item(0)) if type(it) is _ndarray and it.ndim == 1 else int(np.ravel(it)[0])


def _iter_cvxopt(extras: dict) -> int:
    return int(extras["iterations"])


#: Solver -> ``reader(extras) -> iterations`` (raises KeyError, AttributeError, TypeError or
#: IndexError when ``extras`` lacks it), for the solvers whose count qpsolvers keeps.
ITERATION_READERS = {
    "osqp": _iter_info,
    "proxqp": _iter_info,
    "piqp": _iter_info,
    "scs": _iter_iter,
    "quadprog": _iter_quadprog,
    "ecos": _iter_iter,
    "cvxopt": _iter_cvxopt,
    "qpalm": _iter_info,
}

#: Solvers whose iteration count qpsolvers keeps in ``extras``.
ITERATION_SOLVERS = frozenset(ITERATION_READERS)

_ITERATION_ERRORS = (KeyError, AttributeError, TypeError, IndexError)


def iterations(solver: str, extras: dict) -> int | None:
    """Iteration count where qpsolvers keeps it."""
    reader = ITERATION_READERS.get(solver)
    if reader is None:
        return None
    try:
        return reader(extras)
    except _ITERATION_ERRORS:
        return None


#: Solvers whose status, as qpsolvers hands it back, tells primal from dual infeasibility.
CERTIFYING_SOLVERS = ("clarabel", "osqp", "piqp", "proxqp", "qpalm", "scs")

#: Why the other solvers cannot tell, through qpsolvers.
NO_CERTIFICATE = {
    "daqp": "qpsolvers drops DAQP's exit flag: found=False only",
    "highs": "qpsolvers keeps no HiGHS model status: found=False only; on the unbounded "
    "problem HiGHS 1.16 even reports kOptimal with x2 = 1e7 and a dual residual of 1",
    "quadprog": "quadprog raises 'no solution' without saying why (and needs P > 0)",
    "cvxopt": "cvxopt's qp() certifies nothing: 'domain error' on the infeasible problem, "
    "'Rank(A) < p or Rank([P; A; G]) < n' on the unbounded one",
    "ecos": "ECOS finds the infeasible problem (exit flag 1) but qpsolvers' ECOS route needs P > 0 "
    "(Cholesky of P): the unbounded problem is an error",
    "gurobi": "Gurobi's presolve says INF_OR_UNBD (status 4) on both (DualReductions=0 would tell)",
}
