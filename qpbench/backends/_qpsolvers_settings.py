"""Settings of the ``qpsolvers:<name>`` backends (:mod:`qpbench.backends.qpsolvers_`).

Each solver's algorithm family and Python distribution, the translation of the
generic settings (``eps_abs``, ``eps_rel``, ``max_iter``, ``time_limit``) to the
solver's own option names (:func:`native_settings`, following qpbenchmark's
``SolverSettings``), and the solver's own defaults of the options qpbench adds
(:func:`solver_default_limits`).
"""

from __future__ import annotations

import numpy as np

__all__ = ["SOLVER_FAMILIES", "SOLVER_PACKAGES", "native_settings", "solver_default_limits"]

#: Algorithm family of each solver qpsolvers can drive.
SOLVER_FAMILIES: dict[str, str] = {
    "clarabel": "interior point",
    "copt": "interior point",
    "cvxopt": "interior point",
    "daqp": "active set (dual)",
    "ecos": "interior point (SOCP)",
    "gurobi": "interior point",
    "highs": "active set",
    "hpipm": "interior point",
    "jaxopt_osqp": "ADMM",
    "kvxopt": "interior point",
    "mosek": "interior point",
    "nppro": "projection",
    "osqp": "ADMM",
    "pdhcg": "first-order primal-dual",
    "piqp": "proximal interior point",
    "proxqp": "augmented Lagrangian",
    "pyqpmad": "active set (dual)",
    "qpalm": "proximal augmented Lagrangian",
    "qpax": "interior point",
    "qpoases": "active set (online)",
    "qpswift": "interior point",
    "qtqp": "interior point",
    "quadprog": "active set (Goldfarb-Idnani)",
    "scs": "ADMM (conic)",
    "sip": "interior point",
}

#: Python distribution of each solver (for the version column).
SOLVER_PACKAGES: dict[str, str] = {
    "clarabel": "clarabel",
    "copt": "coptpy",
    "cvxopt": "cvxopt",
    "daqp": "daqp",
    "ecos": "ecos",
    "gurobi": "gurobipy",
    "highs": "highspy",
    "hpipm": "hpipm_python",
    "jaxopt_osqp": "jaxopt",
    "kvxopt": "kvxopt",
    "mosek": "mosek",
    "osqp": "osqp",
    "piqp": "piqp",
    "proxqp": "proxsuite",
    "pyqpmad": "pyqpmad",
    "qpalm": "qpalm",
    "qpax": "qpax",
    "qpoases": "qpoases",
    "qpswift": "qpSWIFT",
    "quadprog": "quadprog",
    "scs": "scs",
    "sip": "sip-python",
}


def _clarabel(eps_abs, eps_rel, max_iter, time_limit):
    return {
        "tol_feas": eps_abs,
        "tol_gap_abs": eps_abs,
        "tol_gap_rel": eps_rel,
        "max_iter": min(max_iter, 2**32 - 1),
        "time_limit": time_limit,
    }


def _daqp(eps_abs, eps_rel, max_iter, time_limit):
    return {"primal_tol": eps_abs, "dual_tol": eps_abs, "iter_limit": max_iter}


def _highs(eps_abs, eps_rel, max_iter, time_limit):
    return {
        "primal_feasibility_tolerance": eps_abs,
        "dual_feasibility_tolerance": eps_abs,
        "time_limit": time_limit,
    }


def _osqp(eps_abs, eps_rel, max_iter, time_limit):
    settings = {
        "eps_abs": eps_abs,
        "eps_rel": eps_rel,
        "max_iter": max_iter,
        "time_limit": time_limit,
    }
    if eps_abs <= 1e-7:
        settings["polishing"] = True
    return settings


def _piqp_proxqp(eps_abs, eps_rel, max_iter, time_limit):
    settings = {
        "eps_abs": eps_abs,
        "eps_rel": eps_rel,
        "eps_duality_gap_abs": eps_abs,
        "eps_duality_gap_rel": eps_rel,
        "max_iter": max_iter,
    }
    if eps_abs <= 1e-7:
        settings["check_duality_gap"] = True
    return settings


def _scs(eps_abs, eps_rel, max_iter, time_limit):
    return {
        "eps_abs": eps_abs,
        "eps_rel": eps_rel,
        "max_iters": max_iter,
        "time_limit_secs": time_limit,
    }


def _cvxopt(eps_abs, eps_rel, max_iter, time_limit):
    # qpbenchmark sets feastol only; the gap tolerances (defaults 1e-7 absolute, 1e-6 relative)
    # would stop cvxopt far from a 1e-9 answer.
    return {
        "feastol": eps_abs,
        "abstol": eps_abs,
        "reltol": max(eps_rel, eps_abs),
        "maxiters": max_iter,
    }


def _ecos(eps_abs, eps_rel, max_iter, time_limit):
    # qpbenchmark's (feastol only): tighter gap tolerances make ECOS's dual residual worse, not better.
    return {"feastol": eps_abs}


def _qpalm(eps_abs, eps_rel, max_iter, time_limit):
    return {
        "eps_abs": eps_abs,
        "eps_rel": eps_rel,
        "max_iter": max_iter,
        "time_limit": time_limit,
    }


def _gurobi(eps_abs, eps_rel, max_iter, time_limit):
    # qpbenchmark's; Gurobi refuses tolerances below 1e-9 (a GurobiError: status error at high_accuracy).
    return {"FeasibilityTol": eps_abs, "OptimalityTol": eps_abs, "TimeLimit": time_limit}


def _hpipm(eps_abs, eps_rel, max_iter, time_limit):
    return {
        "tol_dual_gap": eps_abs,
        "tol_eq": eps_abs,
        "tol_ineq": eps_abs,
        "tol_stat": eps_abs,
    }


def _qpswift(eps_abs, eps_rel, max_iter, time_limit):
    return {"RELTOL": eps_abs * np.sqrt(3.0)}


def _qpoases(eps_abs, eps_rel, max_iter, time_limit):
    return {"time_limit": time_limit}


def _sip(eps_abs, eps_rel, max_iter, time_limit):
    return {"eps_abs": eps_abs, "eps_rel": eps_rel, "time_limit": time_limit}


#: Each solver's translation of the generic settings to its own option names.
_NATIVE = {
    "clarabel": _clarabel,
    "daqp": _daqp,
    "highs": _highs,
    "osqp": _osqp,
    "piqp": _piqp_proxqp,
    "proxqp": _piqp_proxqp,
    "scs": _scs,
    "cvxopt": _cvxopt,
    "kvxopt": _cvxopt,
    "ecos": _ecos,
    "qpalm": _qpalm,
    "gurobi": _gurobi,
    "hpipm": _hpipm,
    "qpswift": _qpswift,
    "qpoases": _qpoases,
    "sip": _sip,
}


def native_settings(
    solver: str, eps_abs: float, eps_rel: float, max_iter: int, time_limit: float
) -> dict:
    """Solver options (qpsolvers keyword arguments) for the generic settings.

    Solvers without a translation (quadprog: no tolerance setting) get ``{}``.

    Args:
        solver: qpsolvers' name of the solver.
        eps_abs: Absolute tolerance on primal/dual residuals and gap.
        eps_rel: Relative tolerance.
        max_iter: Iteration limit.
        time_limit: Time limit in [s].
    """
    translate = _NATIVE.get(solver)
    if translate is None:
        return {}
    return translate(eps_abs, eps_rel, int(max_iter), time_limit)


def solver_default_limits(solver: str) -> dict | None:
    """The solver's own defaults (native names) of the options qpbench adds beyond qpbenchmark's.

    Read from the installed solver package; ``None`` when qpbench adds keys
    this function does not know the defaults of.
    """
    if solver == "clarabel":
        import clarabel

        s = clarabel.DefaultSettings()
        return {"max_iter": s.max_iter, "time_limit": s.time_limit}
    if solver == "daqp":
        import daqp

        return {"iter_limit": daqp.Model().settings["iter_limit"]}
    if solver == "osqp":
        import osqp
        import scipy.sparse as spa

        one = spa.csc_matrix(np.eye(1))
        o = osqp.OSQP()
        o.setup(one, np.zeros(1), one, -np.ones(1), np.ones(1), verbose=False)
        return {"max_iter": int(o.settings.max_iter), "polishing": bool(o.settings.polishing)}
    if solver == "piqp":
        import piqp

        return {"max_iter": piqp.DenseSolver().settings.max_iter}
    if solver == "proxqp":
        import proxsuite

        return {"max_iter": proxsuite.proxqp.dense.QP(1, 0, 0).settings.max_iter}
    if solver == "scs":
        # SCS's Python binding does not expose its defaults; 1e5 is SCS 3's documented max_iters.
        return {"max_iters": 100_000}
    if solver in ("highs", "quadprog"):
        return {}
    return None
