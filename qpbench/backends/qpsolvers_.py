"""Backends ``qpsolvers:<name>``: every solver qpsolvers can drive, through its wrapper.

One stateless class per solver qpsolvers has or qpbench expects, generated at import; a call is
what :func:`qpsolvers.solve_problem` does (``warm_start`` as ``initvals``). Statuses: ``found``
-> ``optimal``, else the solver's report (:data:`STATUS_READERS`), else ``not_solved``.
"""

from __future__ import annotations

import warnings
from typing import ClassVar

import numpy as np
import qpsolvers

from . import register
from ._common import generic_settings, native_settings
from .base import Backend, error_solution, new_solution
from .clarabel_ import CLARABEL_STATUSES
from .clarabel_ import status_name as clarabel_status_name
from .osqp_ import OSQP_STATUSES, status_name
from .piqp_ import PIQP_STATUSES
from .proxqp_ import PROXQP_STATUSES

#: Each solver qpsolvers can drive: (algorithm family, Python distribution for the version column).
SOLVERS: dict[str, tuple[str, str | None]] = {
    "clarabel": ("interior point", "clarabel"),
    "copt": ("interior point", "coptpy"),
    "cvxopt": ("interior point", "cvxopt"),
    "daqp": ("active set (dual)", "daqp"),
    "ecos": ("interior point (SOCP)", "ecos"),
    "gurobi": ("interior point", "gurobipy"),
    "highs": ("active set", "highspy"),
    "hpipm": ("interior point", "hpipm_python"),
    "jaxopt_osqp": ("ADMM", "jaxopt"),
    "kvxopt": ("interior point", "kvxopt"),
    "mosek": ("interior point", "mosek"),
    "nppro": ("projection", None),
    "osqp": ("ADMM", "osqp"),
    "pdhcg": ("first-order primal-dual", None),
    "piqp": ("proximal interior point", "piqp"),
    "proxqp": ("augmented Lagrangian", "proxsuite"),
    "pyqpmad": ("active set (dual)", "pyqpmad"),
    "qpalm": ("proximal augmented Lagrangian", "qpalm"),
    "qpax": ("interior point", "qpax"),
    "qpoases": ("active set (online)", "qpoases"),
    "qpswift": ("interior point", "qpSWIFT"),
    "qtqp": ("interior point", None),
    "quadprog": ("active set (Goldfarb-Idnani)", "quadprog"),
    "scs": ("ADMM (conic)", "scs"),
    "sip": ("interior point", "sip-python"),
}


def _table_reader(read, table, text=lambda value, extras: str(value)) -> object:
    """A status reader: ``read(extras)`` is the solver's status (None: no report), ``table``
    maps it to ours, ``text(value, extras)`` is the raw status kept."""

    def reader(extras) -> tuple[str, str | None]:
        value = read(extras)
        if value is None:
            return "not_solved", None
        return table.get(value, "not_solved"), text(value, extras)

    return reader


def _info(read):
    """``read(extras["info"])``, None without an info."""
    return lambda e: None if e.get("info") is None else read(e["info"])


_INFO_NAME = _info(lambda info: info.status.name)


def _info_text(value, extras) -> str:
    return str(extras["info"].status)


#: Solver -> ``reader(extras) -> (status, raw status)``.
STATUS_READERS = {
    "clarabel": _table_reader(
        lambda e: None if e.get("status") is None else clarabel_status_name(e["status"]),
        CLARABEL_STATUSES,
    ),
    "osqp": _table_reader(_info(lambda i: status_name(i.status_val)), OSQP_STATUSES, _info_text),
    "proxqp": _table_reader(_INFO_NAME, PROXQP_STATUSES, _info_text),
    "piqp": _table_reader(_INFO_NAME, PIQP_STATUSES, _info_text),
    # SCS 3: 1 solved, -1 unbounded, -2 infeasible, -6/-7 the inaccurate ones.
    "scs": _table_reader(
        lambda e: e.get("status_val"),
        {1: "optimal", -1: "dual_infeasible", -2: "primal_infeasible"},
        lambda v, e: f"{v} ({e.get('status', '')})",
    ),
    # ECOS: 0 optimal, 1 primal infeasible, 2 dual infeasible, -1 max iterations.
    "ecos": _table_reader(
        lambda e: e.get("exitFlag"),
        {0: "optimal", 1: "primal_infeasible", 2: "dual_infeasible", -1: "max_iter"},
        lambda v, e: f"{v} ({e.get('infostring', '')})",
    ),
    # cvxopt's qp() says "optimal" or "unknown" (it certifies infeasibility for cone programs only).
    "cvxopt": _table_reader(
        lambda e: e.get("status"),
        {
            "optimal": "optimal",
            "primal infeasible": "primal_infeasible",
            "dual infeasible": "dual_infeasible",
        },
    ),
    "qpalm": _table_reader(
        _info(lambda info: str(info.status)),
        {
            "solved": "optimal",
            "primal infeasible": "primal_infeasible",
            "dual infeasible": "dual_infeasible",
            "maximum iterations reached": "max_iter",
            "time limit exceeded": "time_limit",
        },
    ),
    # Gurobi's model status codes; 4 (INF_OR_UNBD) says neither for sure.
    "gurobi": _table_reader(
        lambda e: e.get("status"),
        {
            2: "optimal",
            3: "primal_infeasible",
            5: "dual_infeasible",
            7: "max_iter",
            9: "time_limit",
        },
    ),
}


def _iter_quadprog(extras: dict) -> int:
    it = extras["iterations"]  # quadprog's (iterations, active-set changes)
    return int(it.item(0) if type(it) is _ndarray else np.ravel(it)[0])


#: Solver -> ``reader(extras) -> iterations`` for the solvers whose count qpsolvers keeps.
ITERATION_READERS = {
    **dict.fromkeys(("osqp", "proxqp", "piqp", "qpalm"), lambda e: int(e["info"].iter)),
    **dict.fromkeys(("scs", "ecos"), lambda e: int(e["iter"])),
    "quadprog": _iter_quadprog,
    "cvxopt": lambda e: int(e["iterations"]),
}


def iterations(solver: str, extras: dict) -> int | None:
    """Iteration count where qpsolvers keeps it."""
    reader = ITERATION_READERS.get(solver)
    if reader is None:
        return None
    try:
        return reader(extras)
    except (KeyError, AttributeError, TypeError, IndexError):
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


def silence_wrapper_warnings(solver: str) -> None:
    """Ignore, from now on in this process, the warnings of qpsolvers' wrapper of ``solver``
    and of its conversions (the status says what they would)."""
    warnings.filterwarnings("ignore", module=rf"qpsolvers\.solvers\.{solver}_\Z")
    warnings.filterwarnings("ignore", module=r"qpsolvers\.conversions\.")
    if solver == "osqp":  # osqp 1.x: qpsolvers calls solve() without raise_error
        warnings.filterwarnings(
            "ignore", "The default value of raise_error will change", PendingDeprecationWarning
        )


#: Exception classes of solver packages (by name) that are solver failures, not bugs.
_SOLVER_ERRORS = frozenset({"GurobiError"})

_ndarray = np.ndarray
_F64 = np.dtype(np.float64)
_solve_problem = qpsolvers.solve_problem
_QPError = qpsolvers.QPError


def solver_function(solver: str):
    """qpsolvers' function for ``solver``: the entry of ``solve_problem``'s dispatch table."""
    table = getattr(_solve_problem, "__globals__", {}).get("solve_function")
    function = table.get(solver) if isinstance(table, dict) else None
    if function is not None:
        return function

    def through_solve_problem(problem, initvals=None, verbose=False, **kwargs):
        return _solve_problem(problem, solver, initvals, verbose, **kwargs)

    return through_solve_problem


def _float_array(v):
    if v is None or (type(v) is _ndarray and v.dtype == _F64):
        return v
    return np.asarray(v, dtype=float)


#: Solvers whose qpsolvers wrapper hands its answer back as float64 arrays (others converted).
FLOAT64_WRAPPERS = frozenset(
    "cvxopt daqp ecos gurobi highs osqp piqp proxqp qpalm quadprog scs".split()
)


class QpsolversBackend(Backend):
    """A solver driven through qpsolvers (stateless); subclasses set ``solver``."""

    solver: str = ""

    #: Solvers whose wrapper hands unknown keywords to the solver's settings, as the direct
    #: backend does: the keywords the wrapper takes without listing them in its signature.
    SAME_SETTINGS_AS: ClassVar[dict[str, tuple[str, ...]]] = {
        "clarabel": (),  # setattr on DefaultSettings (an unknown name raises)
        "daqp": (),  # keywords of daqp.solve
        "osqp": ("raise_error",),  # OSQP.setup; raise_error goes to OSQP.solve
        "piqp": (),  # setattr on the settings (an unknown name is silently dropped)
    }

    def __init__(self, profile="default", **settings):
        super().__init__(profile, **settings)
        solver = self.solver
        sparse, dense = qpsolvers.sparse_solvers, qpsolvers.dense_solvers
        self._dense_only = solver in dense and solver not in sparse
        self._reader = STATUS_READERS.get(solver)
        self._float64_wrapper = solver in FLOAT64_WRAPPERS
        silence_wrapper_warnings(solver)
        generic, native = generic_settings(self)
        given = self.profile.solver_options
        #: The solver's options, as passed to qpsolvers (do not modify).
        if given is not None:
            self.solver_options = {**given.get(solver, {}), **self.settings}
        else:
            self.solver_options = {**native_settings(solver, **generic), **native}
        # solve_problem passes verbose (default False) to the wrapper
        self._call_options = {"verbose": False, **self.solver_options}
        self._function = solver_function(solver)

    @classmethod
    def unavailable_reason(cls) -> str | None:
        if cls.solver in qpsolvers.available_solvers:
            return None
        how = (
            "pip install 'qpbench[all-solvers]'"
            if cls.solver in OPTIONAL_SOLVERS
            else f"pip install qpsolvers[{cls.solver}] or the solver's package"
        )
        return f"qpsolvers does not find solver '{cls.solver}' ({how})"

    @classmethod
    def setting_names(cls) -> frozenset[str] | None:
        """For the solvers of :data:`SAME_SETTINGS_AS`: the direct backend's names plus the
        keywords of qpsolvers' ``<solver>_solve_problem``; ``None`` for the others."""
        import importlib
        import inspect

        from . import backend_class

        extra = cls.SAME_SETTINGS_AS.get(cls.solver)
        if extra is None:
            return None
        module = importlib.import_module(f"qpsolvers.solvers.{cls.solver}_")
        function = getattr(module, f"{cls.solver}_solve_problem")
        named = {
            name
            for name, p in inspect.signature(function).parameters.items()
            if p.kind in (p.POSITIONAL_OR_KEYWORD, p.KEYWORD_ONLY)
        } - {"problem", "initvals"}
        return backend_class(cls.solver).setting_names() | named | frozenset(extra)

    def _solve(self, problem, warm_start):
        solved = problem  # a sparse-only wrapper makes dense matrices sparse itself
        if self._dense_only:
            P, G, A = problem.P, problem.G, problem.A
            if (  # type tests first: Problem.has_sparse costs more
                not (
                    type(P) is _ndarray
                    and (G is None or type(G) is _ndarray)
                    and (A is None or type(A) is _ndarray)
                )
                and problem.has_sparse
            ):
                solved = qpsolvers.Problem(*problem.unpack_as_dense())
        try:
            solved.check_constraints()
            result = self._function(solved, initvals=warm_start, **self._call_options)
        except Exception as exc:
            if (
                not isinstance(exc, (_QPError, ValueError))
                and type(exc).__name__ not in _SOLVER_ERRORS
            ):
                raise
            return error_solution(problem, exc)
        extras = result.extras
        sol = new_solution(problem, "optimal", {} if extras is None else extras)
        x, y, z, z_box = result.x, result.y, result.z, result.z_box
        if not self._float64_wrapper:  # clarabel's duals are lists
            x, y, z, z_box = map(_float_array, (x, y, z, z_box))
        sol.x, sol.y, sol.z, sol.z_box = x, y, z, z_box
        sol._obj = result.obj
        sol.build_time = result.build_time
        sol.solver_time_s = result.solve_time
        sol.iterations = iterations(self.solver, sol.extras)
        if result.found:
            return sol
        # found nothing: the status from the solver's own report, no x unless finite
        status, raw = "not_solved", None
        if self._reader is not None:
            extras = sol.extras
            status, raw = self._reader(extras)
            if status == "optimal":
                status = "not_solved"  # the solver says solved but qpsolvers does not agree
            if raw is not None:
                sol.extras = dict(extras, raw_status=raw)
        sol.status = status
        if sol.x is not None and not np.all(np.isfinite(sol.x)):
            sol.x = None
        return sol


def _make_class(solver: str) -> type[QpsolversBackend]:
    family, package = SOLVERS.get(solver, ("unknown", None))
    cls = type(
        f"Qpsolvers_{solver}",
        (QpsolversBackend,),
        {
            "name": f"qpsolvers:{solver}",
            "family": family,
            "package": package,
            "solver": solver,
            "certifies_infeasibility": True
            if solver in CERTIFYING_SOLVERS
            else (False if solver in NO_CERTIFICATE else None),
            "infeasibility_note": NO_CERTIFICATE.get(solver, ""),
            # qpsolvers hands sparse matrices to a solver with a sparse API as they are
            "sparse": solver in qpsolvers.sparse_solvers,
            "__module__": __name__,
            "__doc__": f"``{solver}`` through qpsolvers (see :mod:`{__name__}`).",
        },
    )
    return register(cls)


#: Solvers qpbench installs with itself (listed even when qpsolvers does not find them).
EXPECTED_SOLVERS = ("clarabel", "daqp", "highs", "osqp", "piqp", "proxqp", "quadprog", "scs")

#: Solvers of the ``all-solvers`` extra (listed even when not installed, with how to install them).
OPTIONAL_SOLVERS = ("cvxopt", "ecos", "gurobi", "qpalm")

#: The generated classes, by qpsolvers' solver name.
BACKENDS: dict[str, type[QpsolversBackend]] = {
    solver: _make_class(solver)
    for solver in sorted(
        set(EXPECTED_SOLVERS) | set(OPTIONAL_SOLVERS) | set(qpsolvers.available_solvers)
    )
}
