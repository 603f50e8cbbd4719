"""Backends ``qpsolvers:<name>``: every solver qpsolvers can drive, through ``qpsolvers.solve_problem``.

One class per solver, generated in a loop at import of this module and
registered as ``qpsolvers:<name>``. Classes exist for every solver in
:data:`qpsolvers.available_solvers` plus the solvers qpbench depends on
(:data:`EXPECTED_SOLVERS`, so that a missing one shows as unavailable); a
class is available exactly when qpsolvers lists its solver as available
(importing qpsolvers is all this module does at import).

Each call is stateless: qpsolvers builds the solver's problem anew (that is the
route this backend measures). ``warm_start`` is passed as ``initvals``.

Settings. The profile's ``eps_abs``, ``eps_rel``, ``max_iter`` and
``time_limit`` are translated to each solver's own option names by
:func:`native_settings`, following qpbenchmark's ``SolverSettings``
(``set_eps_abs``, ``set_eps_rel``, ``set_time_limit``; for ``high_accuracy``
also ``check_duality_gap`` for piqp/proxqp) plus iteration limits. OSQP gets
``polishing=True`` at ``eps_abs <= 1e-7`` (without it ADMM rarely reaches a
1e-9 residual). quadprog has no tolerance setting (it is exact up to
rounding). Settings given to the backend that are not one of the four generic
names are passed to the solver verbatim.

Matrices. Solvers that qpsolvers lists as sparse-only get CSC matrices from
us (qpsolvers would convert them too, with a warning); dense-only solvers
get dense ones (quadprog refuses sparse input). qpsolvers' warnings (non-optimal exit, ignored warm
start) are silenced: the status says it (except for daqp, whose wrapper
never warns: a ``catch_warnings`` block would cost a third of a DAQP solve
on the robot's QPs).

Statuses. qpsolvers reports ``found`` only; when ``found`` is True the status
is ``optimal``. When it is False, the status is read from the solver's own
report in ``Solution.extras`` where qpsolvers keeps one:

========= ==========================================================
clarabel  ``extras["status"]`` (``SolverStatus``)
osqp      ``extras["info"].status_val``
proxqp    ``extras["info"].status`` (``QPSolverOutput``)
piqp      ``extras["info"].status``
scs       ``extras["status_val"]``
========= ==========================================================

Other solvers (daqp, quadprog, highs, ...) keep no status there, so
``found=False`` becomes ``not_solved``. The raw status, when there is one, is
in ``extras["raw_status"]``.

Errors. :class:`qpsolvers.QPError` (qpsolvers' wrapping of solver failures,
e.g. quadprog's "P is not positive definite") and ``ValueError`` raised from
inside the solver call (what most solver bindings raise) become status
``error`` with the message in ``error``.
"""

from __future__ import annotations

import warnings

import numpy as np
import qpsolvers
import scipy.sparse as spa

from . import register
from ._common import generic_settings
from .base import Backend, BackendSolution

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


def native_settings(solver: str, eps_abs: float, eps_rel: float, max_iter: int, time_limit: float) -> dict:
    """Solver options (qpsolvers keyword arguments) for the generic settings.

    Args:
        solver: qpsolvers' name of the solver.
        eps_abs: Absolute tolerance on primal/dual residuals and gap.
        eps_rel: Relative tolerance.
        max_iter: Iteration limit.
        time_limit: Time limit in [s].
    """
    max_iter = int(max_iter)
    if solver == "clarabel":
        return {"tol_feas": eps_abs, "tol_gap_abs": eps_abs, "tol_gap_rel": eps_rel,
                "max_iter": min(max_iter, 2**32 - 1), "time_limit": time_limit}
    if solver == "daqp":
        return {"primal_tol": eps_abs, "dual_tol": eps_abs, "iter_limit": max_iter}
    if solver == "highs":
        return {"primal_feasibility_tolerance": eps_abs, "dual_feasibility_tolerance": eps_abs,
                "time_limit": time_limit}
    if solver == "osqp":
        settings = {"eps_abs": eps_abs, "eps_rel": eps_rel, "max_iter": max_iter, "time_limit": time_limit}
        if eps_abs <= 1e-7:
            settings["polishing"] = True
        return settings
    if solver in ("piqp", "proxqp"):
        settings = {"eps_abs": eps_abs, "eps_rel": eps_rel, "eps_duality_gap_abs": eps_abs,
                    "eps_duality_gap_rel": eps_rel, "max_iter": max_iter}
        if eps_abs <= 1e-7:
            settings["check_duality_gap"] = True
        return settings
    if solver == "scs":
        return {"eps_abs": eps_abs, "eps_rel": eps_rel, "max_iters": max_iter, "time_limit_secs": time_limit}
    if solver in ("cvxopt", "kvxopt", "ecos"):
        return {"feastol": eps_abs}
    if solver == "qpalm":
        return {"eps_abs": eps_abs, "eps_rel": eps_rel, "max_iter": max_iter, "time_limit": time_limit}
    if solver == "gurobi":
        return {"FeasibilityTol": eps_abs, "OptimalityTol": eps_abs, "TimeLimit": time_limit}
    if solver == "hpipm":
        return {"tol_dual_gap": eps_abs, "tol_eq": eps_abs, "tol_ineq": eps_abs, "tol_stat": eps_abs}
    if solver == "qpswift":
        return {"RELTOL": eps_abs * np.sqrt(3.0)}
    if solver == "qpoases":
        return {"time_limit": time_limit}
    if solver == "sip":
        return {"eps_abs": eps_abs, "eps_rel": eps_rel, "time_limit": time_limit}
    return {}


# -- statuses ------------------------------------------------------------------

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
            pairs = [(S.OSQP_SOLVED, "optimal"), (S.OSQP_PRIMAL_INFEASIBLE, "primal_infeasible"),
                     (S.OSQP_DUAL_INFEASIBLE, "dual_infeasible"), (S.OSQP_MAX_ITER_REACHED, "max_iter"),
                     (S.OSQP_TIME_LIMIT_REACHED, "time_limit")]
            _ENUM_MAPS[solver] = {int(k): v for k, v in pairs}
        elif solver == "proxqp":
            import proxsuite

            O = proxsuite.proxqp.QPSolverOutput
            _ENUM_MAPS[solver] = {O.PROXQP_SOLVED: "optimal", O.PROXQP_PRIMAL_INFEASIBLE: "primal_infeasible",
                                  O.PROXQP_DUAL_INFEASIBLE: "dual_infeasible",
                                  O.PROXQP_MAX_ITER_REACHED: "max_iter"}
        elif solver == "piqp":
            import piqp

            _ENUM_MAPS[solver] = {piqp.PIQP_SOLVED: "optimal", piqp.PIQP_PRIMAL_INFEASIBLE: "primal_infeasible",
                                  piqp.PIQP_DUAL_INFEASIBLE: "dual_infeasible",
                                  piqp.PIQP_MAX_ITER_REACHED: "max_iter", piqp.PIQP_NUMERICS: "error"}
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


_STATUS_READERS = {
    "clarabel": _status_clarabel,
    "osqp": _status_osqp,
    "proxqp": _status_proxqp,
    "piqp": _status_piqp,
    "scs": _status_scs,
}


def _iterations(solver: str, extras: dict) -> int | None:
    """Iteration count where qpsolvers keeps it."""
    try:
        if solver in ("osqp", "proxqp", "piqp"):
            return int(extras["info"].iter)
        if solver == "scs":
            return int(extras["iter"])
        if solver == "quadprog":
            return int(np.ravel(extras["iterations"])[0])
    except (KeyError, AttributeError, TypeError, IndexError):
        return None
    return None


def _sparse_problem(problem: qpsolvers.Problem) -> qpsolvers.Problem:
    """Same problem with CSC matrices (for solvers that only take sparse input)."""
    P, q, G, h, A, b, lb, ub = problem.unpack()
    return qpsolvers.Problem(
        spa.csc_matrix(P),
        q,
        None if G is None else spa.csc_matrix(G),
        h,
        None if A is None else spa.csc_matrix(A),
        b,
        lb,
        ub,
    )


#: Solvers whose qpsolvers wrapper does not warn on a normal solve (no
#: ``warnings.catch_warnings`` around them: it costs microseconds).
_SILENT_SOLVERS = frozenset({"daqp"})


class QpsolversBackend(Backend):
    """A solver driven through :func:`qpsolvers.solve_problem` (stateless).

    Subclasses set ``solver`` (qpsolvers' name); see the module docstring.
    """

    solver: str = ""

    def __init__(self, profile="default", **settings):
        super().__init__(profile, **settings)
        self._cached_options: dict | None = None

    @classmethod
    def unavailable_reason(cls) -> str | None:
        if cls.solver in qpsolvers.available_solvers:
            return None
        return (
            f"qpsolvers does not find solver '{cls.solver}' "
            f"(pip install qpsolvers[{cls.solver}] or the solver's package)"
        )

    def _options(self) -> dict:
        """Solver options (computed once per instance)."""
        if self._cached_options is None:
            generic, native = generic_settings(self)
            options = native_settings(self.solver, **generic)
            options.update(native)
            self._cached_options = options
        return dict(self._cached_options)

    def _call(self, problem, warm_start, options):
        try:
            return qpsolvers.solve_problem(problem, solver=self.solver, initvals=warm_start, **options), None
        except (qpsolvers.QPError, ValueError) as exc:
            return None, f"{type(exc).__name__}: {exc}"

    def _solve(self, problem, warm_start):
        options = self._options()
        sparse_only = self.solver in qpsolvers.sparse_solvers and self.solver not in qpsolvers.dense_solvers
        dense_only = self.solver in qpsolvers.dense_solvers and self.solver not in qpsolvers.sparse_solvers
        solved_problem = problem
        if sparse_only and not problem.has_sparse:
            solved_problem = _sparse_problem(problem)
        elif dense_only and problem.has_sparse:
            solved_problem = qpsolvers.Problem(*problem.unpack_as_dense())
        if self.solver in _SILENT_SOLVERS:
            result, error = self._call(solved_problem, warm_start, options)
        else:
            with warnings.catch_warnings():
                warnings.simplefilter("ignore")
                result, error = self._call(solved_problem, warm_start, options)
        sol = BackendSolution(problem)
        if result is None:
            sol.status = "error"
            sol.error = error
            return sol
        sol.extras = result.extras
        # Some qpsolvers wrappers (clarabel) hand duals back as Python lists.
        sol.x, sol.y, sol.z, sol.z_box = (
            None if v is None else np.asarray(v, dtype=float)
            for v in (result.x, result.y, result.z, result.z_box)
        )
        sol.obj = result.obj
        sol.build_time = result.build_time
        sol.solver_time_s = result.solve_time
        sol.iterations = _iterations(self.solver, result.extras or {})
        reader = _STATUS_READERS.get(self.solver)
        raw = None
        if reader is not None:
            status, raw = reader(result.extras or {})
        else:
            status = "optimal" if result.found else "not_solved"
        if result.found:
            status = "optimal"
        elif status == "optimal":
            status = "not_solved"  # the solver says solved but qpsolvers does not agree
        if raw is None and status != "optimal" and reader is not None and "info" in (result.extras or {}):
            raw = str(getattr(result.extras["info"], "status", None))
        if raw is not None:
            sol.extras = dict(sol.extras or {}, raw_status=raw)
        sol.status = status
        if status != "optimal" and sol.x is not None and not np.all(np.isfinite(sol.x)):
            sol.x = None
        return sol


def _make_class(solver: str) -> type[QpsolversBackend]:
    cls = type(
        f"Qpsolvers_{solver}",
        (QpsolversBackend,),
        {
            "name": f"qpsolvers:{solver}",
            "family": SOLVER_FAMILIES.get(solver, "unknown"),
            "package": SOLVER_PACKAGES.get(solver),
            "solver": solver,
            "__module__": __name__,
            "__doc__": f"``{solver}`` through qpsolvers.solve_problem (see :mod:`{__name__}`).",
        },
    )
    return register(cls)


#: Solvers qpbench installs with itself (listed even when qpsolvers does not find them).
EXPECTED_SOLVERS = ("clarabel", "daqp", "highs", "osqp", "piqp", "proxqp", "quadprog", "scs")

#: The generated classes, by qpsolvers' solver name.
BACKENDS: dict[str, type[QpsolversBackend]] = {
    solver: _make_class(solver)
    for solver in sorted(set(EXPECTED_SOLVERS) | set(qpsolvers.available_solvers))
}


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
