"""Backends ``qpsolvers:<name>``: every solver qpsolvers can drive, through ``qpsolvers.solve_problem``.

One class per solver, generated in a loop at import of this module and
registered as ``qpsolvers:<name>``. Classes exist for every solver in
:data:`qpsolvers.available_solvers` plus the solvers qpbench depends on
(:data:`EXPECTED_SOLVERS`, so that a missing one shows as unavailable) and
those of the ``all-solvers`` extra (:data:`OPTIONAL_SOLVERS`: qpalm, ecos,
cvxopt, gurobi with gurobipy's size-limited licence, which prints a
"Restricted license" line at its first model); a class is available exactly
when qpsolvers lists its solver as available (importing qpsolvers is all this
module does at import).

Each call is stateless: qpsolvers builds the solver's problem anew (that is the
route this backend measures). ``warm_start`` is passed as ``initvals``. The
call is what :func:`qpsolvers.solve_problem` does (``check_constraints``,
then qpsolvers' function for the solver with the same keywords), minus its
dispatch (:func:`_wrapper`).

Settings. Under a qpbenchmark profile (``qpbenchmark:<settings>``) the
options are the keyword arguments qpbenchmark's runner passes for the solver,
verbatim, plus the backend's own settings (``--set``). Otherwise the profile's
``eps_abs``, ``eps_rel``, ``max_iter`` and
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
get dense ones (quadprog's wrapper refuses sparse input).

Warnings. qpsolvers' wrappers warn on a failed solve and on an ignored warm
start; the status says it. Constructing a ``qpsolvers:<name>`` backend adds
a filter that ignores the warnings of qpsolvers' wrapper module for that
solver (``qpsolvers.solvers.<name>_``) in this process
(:func:`silence_wrapper_warnings`): free per call, where a
``warnings.catch_warnings`` block around every call costs a noticeable
fraction of a fast solve.

Per-call cost. The options are computed once per instance, the results of
the solvers whose wrappers hand back float64 arrays (:data:`FLOAT64_WRAPPERS`)
are taken as given (the others are checked and converted), and a
solver's status table is read only when qpsolvers says ``found=False``: the
backend costs what :func:`qpsolvers.solve_problem` costs plus building the
:class:`BackendSolution` (``bench/backend_overhead.py``).

Statuses. qpsolvers reports ``found`` only; when ``found`` is True the status
is ``optimal``. When it is False, the status is read from the solver's own
report in ``Solution.extras`` where qpsolvers keeps one:

========= ==========================================================
clarabel  ``extras["status"]`` (``SolverStatus``)
osqp      ``extras["info"].status_val``
proxqp    ``extras["info"].status`` (``QPSolverOutput``)
piqp      ``extras["info"].status``
scs       ``extras["status_val"]``
ecos      ``extras["exitFlag"]``
cvxopt    ``extras["status"]`` (``qp()`` says ``optimal`` or ``unknown``)
qpalm     ``extras["info"].status``
gurobi    ``extras["status"]`` (model status code)
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
from typing import ClassVar

import numpy as np
import qpsolvers
import scipy.sparse as spa

from . import register
from ._common import generic_settings
from ._qpsolvers_settings import (
    SOLVER_FAMILIES,
    SOLVER_PACKAGES,
    native_settings,
    solver_default_limits,  # noqa: F401 - imported from here by callers and tests
)
from ._qpsolvers_status import (
    CERTIFYING_SOLVERS,
    ITERATION_READERS,
    NO_CERTIFICATE,
    STATUS_READERS,
)
from .base import Backend, BackendSolution, _perf_ns


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


def silence_wrapper_warnings(solver: str) -> None:
    """Ignore the warnings of qpsolvers' wrapper module of ``solver`` from now on, in this process.

    qpsolvers' wrappers warn on a failed solve and on an ignored ``initvals``;
    the backend reports both as its status. A filter on the wrapper's module
    (``qpsolvers.solvers.<solver>_``) costs nothing per call, where a
    ``warnings.catch_warnings`` block around each call costs a noticeable
    fraction of a DAQP solve through qpsolvers. Adding it again moves it to the
    front of the filter list (idempotent). Warnings a solver's own package
    raises on qpsolvers' normal calls (:data:`_SOLVER_WARNINGS`) are ignored too.
    """
    warnings.filterwarnings("ignore", module=rf"qpsolvers\.solvers\.{solver}_\Z")
    for message, category in _SOLVER_WARNINGS.get(solver, ()):
        warnings.filterwarnings("ignore", message=message, category=category)


#: Warnings of a solver's own package on every call qpsolvers makes (message regex, category).
_SOLVER_WARNINGS = {
    # osqp 1.x: qpsolvers calls solve() without raise_error.
    "osqp": (("The default value of raise_error will change", PendingDeprecationWarning),),
}


#: Exception classes of solver packages (by name) that are solver failures, not bugs.
_SOLVER_ERRORS = frozenset({"GurobiError"})

_ndarray = np.ndarray
_new = object.__new__
_solve_problem = qpsolvers.solve_problem
_QPError = qpsolvers.QPError


def _wrapper(solver: str):
    """qpsolvers' function for ``solver``: the entry of the table :func:`qpsolvers.solve_problem`
    dispatches through (read from its globals: the table's module moved between qpsolvers
    4.4 and 4.13), called as ``solve_problem`` calls it. Without that table (another
    qpsolvers), ``solve_problem`` itself. Calling it directly saves ``solve_problem``'s frame
    and keyword repacking, which ``python bench/backend_overhead.py`` shows on the fastest
    routes (the routes' ratio to ``solve_problem``)."""
    table = getattr(_solve_problem, "__globals__", {}).get("solve_function")
    wrapper = table.get(solver) if isinstance(table, dict) else None
    if wrapper is not None:
        return wrapper

    def through_solve_problem(problem, initvals=None, verbose=False, **kwargs):
        return _solve_problem(problem, solver, initvals, verbose, **kwargs)

    return through_solve_problem


def _float_array(v):
    if v is None or (type(v) is _ndarray and v.dtype == _F64):
        return v
    return np.asarray(v, dtype=float)


_F64 = np.dtype(np.float64)

#: Solvers whose qpsolvers wrapper hands ``x``, ``y``, ``z`` and ``z_box`` back as float64
#: arrays (or None): their results are taken as given, without the four type checks (a share
#: of the fastest routes' call: ``python bench/backend_overhead.py``). tests/test_backends.py
#: checks it of every installed one through qpsolvers.solve_problem itself, so a qpsolvers
#: release that changes a wrapper fails there;
#: any other solver's results (clarabel's duals are lists) are checked and converted.
FLOAT64_WRAPPERS = frozenset(
    {
        "cvxopt",
        "daqp",
        "ecos",
        "gurobi",
        "highs",
        "osqp",
        "piqp",
        "proxqp",
        "qpalm",
        "quadprog",
        "scs",
    }
)
_ITERATION_ERRORS = (KeyError, AttributeError, TypeError, IndexError)


class QpsolversBackend(Backend):
    """A solver driven through :func:`qpsolvers.solve_problem` (stateless).

    Subclasses set ``solver`` (qpsolvers' name); see the module docstring.
    """

    solver: str = ""

    def __init__(self, profile="default", **settings):
        super().__init__(profile, **settings)
        solver = self.solver
        self._sparse_only = (
            solver in qpsolvers.sparse_solvers and solver not in qpsolvers.dense_solvers
        )
        self._dense_only = (
            solver in qpsolvers.dense_solvers and solver not in qpsolvers.sparse_solvers
        )
        self._reader = STATUS_READERS.get(solver)
        self._iterations = ITERATION_READERS.get(solver)
        self._float64_wrapper = solver in FLOAT64_WRAPPERS
        silence_wrapper_warnings(solver)
        self._solver_options = self._build_options()
        # The keywords of every call: solve_problem passes verbose (default False) to the wrapper.
        self._call_options = {"verbose": False, **self._solver_options}
        self._wrapper = _wrapper(solver)

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

    #: Solvers whose qpsolvers wrapper hands every keyword it does not take itself to the
    #: solver's own settings, as the direct backend named here does: (that backend, keywords
    #: the wrapper takes without listing them in its signature).
    SAME_SETTINGS_AS: ClassVar[dict[str, tuple[str, tuple[str, ...]]]] = {
        "clarabel": ("clarabel", ()),  # setattr on DefaultSettings (an unknown name raises)
        "daqp": ("daqp", ()),  # keywords of daqp.solve
        "osqp": ("osqp", ("raise_error",)),  # OSQP.setup; raise_error goes to OSQP.solve
        "piqp": ("piqp", ()),  # setattr on the settings (an unknown name is silently dropped)
    }

    @classmethod
    def setting_names(cls) -> frozenset[str] | None:
        """For the solvers of :data:`SAME_SETTINGS_AS`: the direct backend's names, plus the
        keywords of qpsolvers' ``<solver>_solve_problem`` (``backend`` of piqp). For the other
        solvers ``None`` (every key is passed on): qpsolvers hands them their keywords each
        in its own way (the arguments of ``proxsuite.proxqp.dense.solve``, HiGHS'
        ``setOptionValue``, quadprog's ``solve_qp``, ...), and no list of the solver's own
        settings tells which keys the route accepts."""
        import importlib
        import inspect

        from . import backend_class

        same = cls.SAME_SETTINGS_AS.get(cls.solver)
        if same is None:
            return None
        direct, extra = same
        module = importlib.import_module(f"qpsolvers.solvers.{cls.solver}_")
        wrapper = getattr(module, f"{cls.solver}_solve_problem")
        named = {
            name
            for name, p in inspect.signature(wrapper).parameters.items()
            if p.kind in (p.POSITIONAL_OR_KEYWORD, p.KEYWORD_ONLY)
        } - {"problem", "initvals"}
        return backend_class(direct).setting_names() | named | frozenset(extra)

    def _options(self) -> dict:
        """Solver options, as passed to :func:`qpsolvers.solve_problem` (computed at construction;
        do not modify)."""
        return self._solver_options

    def _build_options(self) -> dict:
        generic, native = generic_settings(self)
        given = self.profile.solver_options
        if given is not None:  # qpbenchmark's arguments, verbatim (qpbench.profiles)
            options = dict(given.get(self.solver, {}))
            options.update({k: v for k, v in self.settings.items()})
        else:
            options = native_settings(self.solver, **generic)
            options.update(native)
        return options

    def solve(self, problem, warm_start=None) -> BackendSolution:
        """One solve through qpsolvers; see :meth:`Backend.solve` (same fields). Timed here
        rather than around a ``_solve``: one Python call less per solve."""
        start = _perf_ns()
        solved = problem
        if self._sparse_only:
            if not problem.has_sparse:
                solved = _sparse_problem(problem)
        elif self._dense_only:
            P, G, A = problem.P, problem.G, problem.A
            if (
                not (
                    type(P) is _ndarray
                    and (G is None or type(G) is _ndarray)
                    and (A is None or type(A) is _ndarray)
                )
                and problem.has_sparse
            ):
                solved = qpsolvers.Problem(*problem.unpack_as_dense())
        try:
            # What qpsolvers.solve_problem does, without its dispatch: the same check, then
            # the same wrapper with the same keywords (verbose=False among them).
            solved.check_constraints()
            result = self._wrapper(solved, initvals=warm_start, **self._call_options)
        except (_QPError, ValueError) as exc:
            return self._finish(_error(problem, exc), start)
        except Exception as exc:
            if type(exc).__name__ not in _SOLVER_ERRORS:
                raise
            return self._finish(_error(problem, exc), start)
        # Without __init__ (BackendSolution's defaults are class attributes): a microsecond less per call.
        sol = _new(BackendSolution)
        sol.problem = problem
        extras = result.extras
        if extras is None:
            extras = {}
        sol.extras = extras
        x, y, z, z_box = result.x, result.y, result.z, result.z_box
        if not self._float64_wrapper:
            # Some qpsolvers wrappers (clarabel) hand duals back as Python lists. The float64
            # descriptor of a fresh array is numpy's singleton: tested by identity, and anything
            # else (lists, other dtypes, an equal descriptor that is another object) converted.
            if not (
                (x is None or (type(x) is _ndarray and x.dtype is _F64))
                and (y is None or (type(y) is _ndarray and y.dtype is _F64))
                and (z is None or (type(z) is _ndarray and z.dtype is _F64))
                and (z_box is None or (type(z_box) is _ndarray and z_box.dtype is _F64))
            ):
                x, y, z, z_box = map(_float_array, (x, y, z, z_box))
        sol.x = x
        sol.y = y
        sol.z = z
        sol.z_box = z_box
        sol._obj = result.obj
        sol.build_time = result.build_time
        sol.solver_time_s = result.solve_time
        read_iterations = self._iterations
        if read_iterations is not None:  # otherwise the class default, None
            try:
                sol.iterations = read_iterations(extras)
            except _ITERATION_ERRORS:
                pass
        if result.found:
            sol.status = "optimal"
            sol.found = True
            sol.backend = self.name
            sol.wall_time_s = (_perf_ns() - start) * 1e-9
            return sol
        return self._finish(self._not_found(sol, extras), start)

    def _not_found(self, sol: BackendSolution, extras: dict) -> BackendSolution:
        """``sol`` of a solve qpsolvers says found nothing: the status from the solver's own
        report (:data:`STATUS_READERS`), its raw value in the extras, no ``x`` unless finite."""
        reader = self._reader
        raw = None
        if reader is not None:
            status, raw = reader(extras)
            if status == "optimal":
                status = "not_solved"  # the solver says solved but qpsolvers does not agree
            if raw is None and "info" in extras:
                raw = str(getattr(extras["info"], "status", None))
        else:
            status = "not_solved"
        if raw is not None:
            sol.extras = dict(extras, raw_status=raw)
        sol.status = status
        if sol.x is not None and not np.all(np.isfinite(sol.x)):
            sol.x = None
        return sol

    def _finish(self, sol: BackendSolution, start: int) -> BackendSolution:
        """What :meth:`Backend.solve` adds: ``found``, the backend's name, the wall time since ``start``."""
        sol.found = sol.status == "optimal"
        sol.backend = self.name
        sol.wall_time_s = (_perf_ns() - start) * 1e-9
        return sol


def _error(problem, exc: BaseException) -> BackendSolution:
    return BackendSolution(problem, status="error", error=f"{type(exc).__name__}: {exc}")


def _make_class(solver: str) -> type[QpsolversBackend]:
    cls = type(
        f"Qpsolvers_{solver}",
        (QpsolversBackend,),
        {
            "name": f"qpsolvers:{solver}",
            "family": SOLVER_FAMILIES.get(solver, "unknown"),
            "package": SOLVER_PACKAGES.get(solver),
            "solver": solver,
            "certifies_infeasibility": True
            if solver in CERTIFYING_SOLVERS
            else (False if solver in NO_CERTIFICATE else None),
            "infeasibility_note": NO_CERTIFICATE.get(solver, ""),
            # qpsolvers hands sparse matrices to a solver with a sparse API as they are
            "sparse": solver in qpsolvers.sparse_solvers,
            "__module__": __name__,
            "__doc__": f"``{solver}`` through qpsolvers.solve_problem (see :mod:`{__name__}`).",
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
