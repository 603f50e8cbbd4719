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


#: Each solver's option names for the generic settings, as qpbenchmark's ``SolverSettings``
#: sets them plus iteration limits: native name -> the generic key whose value it takes, or a
#: function of the generic values (``e``: eps_abs, ``r``: eps_rel, ``k``: max_iter, ``t``:
#: time_limit) where the value is derived.
_NATIVE: dict[str, dict[str, object]] = {
    "clarabel": {
        "tol_feas": "eps_abs",
        "tol_gap_abs": "eps_abs",
        "tol_gap_rel": "eps_rel",
        "max_iter": lambda e, r, k, t: min(k, 2**32 - 1),  # Clarabel's u32
        "time_limit": "time_limit",
    },
    "daqp": {"primal_tol": "eps_abs", "dual_tol": "eps_abs", "iter_limit": "max_iter"},
    "highs": {
        "primal_feasibility_tolerance": "eps_abs",
        "dual_feasibility_tolerance": "eps_abs",
        "time_limit": "time_limit",
    },
    "osqp": {
        "eps_abs": "eps_abs",
        "eps_rel": "eps_rel",
        "max_iter": "max_iter",
        "time_limit": "time_limit",
    },
    "piqp": {
        "eps_abs": "eps_abs",
        "eps_rel": "eps_rel",
        "eps_duality_gap_abs": "eps_abs",
        "eps_duality_gap_rel": "eps_rel",
        "max_iter": "max_iter",
    },
    "scs": {
        "eps_abs": "eps_abs",
        "eps_rel": "eps_rel",
        "max_iters": "max_iter",
        "time_limit_secs": "time_limit",
    },
    # qpbenchmark sets feastol only; the gap tolerances (defaults 1e-7 absolute, 1e-6 relative)
    # would stop cvxopt far from a 1e-9 answer.
    "cvxopt": {
        "feastol": "eps_abs",
        "abstol": "eps_abs",
        "reltol": lambda e, r, k, t: max(r, e),
        "maxiters": "max_iter",
    },
    # qpbenchmark's (feastol only): tighter gap tolerances make ECOS's dual residual worse, not better.
    "ecos": {"feastol": "eps_abs"},
    "qpalm": {
        "eps_abs": "eps_abs",
        "eps_rel": "eps_rel",
        "max_iter": "max_iter",
        "time_limit": "time_limit",
    },
    # qpbenchmark's; Gurobi refuses tolerances below 1e-9 (a GurobiError: status error; high_accuracy asks 1e-9).
    "gurobi": {"FeasibilityTol": "eps_abs", "OptimalityTol": "eps_abs", "TimeLimit": "time_limit"},
    "hpipm": {
        "tol_dual_gap": "eps_abs",
        "tol_eq": "eps_abs",
        "tol_ineq": "eps_abs",
        "tol_stat": "eps_abs",
    },
    "qpswift": {"RELTOL": lambda e, r, k, t: e * np.sqrt(3.0)},
    "qpoases": {"time_limit": "time_limit"},
    "sip": {"eps_abs": "eps_abs", "eps_rel": "eps_rel", "time_limit": "time_limit"},
}
_NATIVE["proxqp"] = _NATIVE["piqp"]
_NATIVE["kvxopt"] = _NATIVE["cvxopt"]

#: Options added at ``eps_abs <= 1e-7`` (the ``high_accuracy`` profile): OSQP's polishing (ADMM
#: alone seldom reaches a 1e-9 residual; the polishing step, a solve of the KKT system of the
#: guessed active set, does), PIQP's and ProxQP's duality-gap test.
_HIGH_ACCURACY = {
    "osqp": {"polishing": True},
    "piqp": {"check_duality_gap": True},
    "proxqp": {"check_duality_gap": True},
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
    names = _NATIVE.get(solver)
    if names is None:
        return {}
    generic = {
        "eps_abs": eps_abs,
        "eps_rel": eps_rel,
        "max_iter": int(max_iter),
        "time_limit": time_limit,
    }
    args = tuple(generic.values())
    settings = {
        name: generic[key] if type(key) is str else key(*args) for name, key in names.items()
    }
    if eps_abs <= 1e-7:
        settings.update(_HIGH_ACCURACY.get(solver, {}))
    return settings


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
