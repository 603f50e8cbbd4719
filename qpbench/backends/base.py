"""The backend interface: one small class per solver route.

A backend turns a :class:`qpsolvers.Problem` into a :class:`BackendSolution`. Duals follow
qpsolvers' sign convention::

    P x + q + A^T y + G^T z + z_box = 0,   z >= 0,
    z_box < 0 where the lower bound is active, > 0 where the upper bound is.
"""

from __future__ import annotations

import gc
import time
from dataclasses import dataclass
from typing import ClassVar

import numpy as np
import qpsolvers

from ..profiles import Profile, get_profile
from ..statuses import describe_exception


@dataclass
class BackendSolution(qpsolvers.Solution):
    """A :class:`qpsolvers.Solution` plus ``status`` (:data:`qpbench.statuses.STATUSES`), the
    solver's own ``solver_time_s`` [s] and ``error``; ``obj`` is computed from ``x`` if unset."""

    status: str = "not_solved"
    iterations: int | None = None
    solver_time_s: float | None = None
    backend: str = ""
    error: str | None = None
    _obj = None  # what the obj property stores (not a field)

    def __getattr__(self, name: str):  # the default extras of an instance made by new_solution
        if name == "extras":
            extras = self.extras = {}
            return extras
        raise AttributeError(f"{type(self).__name__!r} object has no attribute {name!r}")


def _get_obj(self) -> float | None:
    obj = self._obj
    if obj is None and self.x is not None and self.problem is not None:
        obj = self._obj = objective(self.problem, self.x)
    return obj


def _set_obj(self, value) -> None:
    self._obj = value


# The dataclass __init__ assigns ``self.obj = obj``, which the property stores as ``_obj``.
BackendSolution.obj = property(_get_obj, _set_obj, doc="Primal objective at ``x``.")


def new_solution(
    problem: qpsolvers.Problem, status: str, extras: dict, cls: type = BackendSolution
) -> BackendSolution:
    """A :class:`BackendSolution` (or ``cls``) without the dataclass ``__init__``."""
    sol = _new(cls)
    sol.problem = problem
    sol.status = status
    sol.extras = extras
    return sol


_new = object.__new__


class _Duals:
    """``y``, ``z`` and ``z_box`` of a :class:`ViewSolution`, put into the instance on the
    first read of any (a non-data descriptor: later reads do not call it)."""

    def __set_name__(self, owner, name: str):
        self.name = name

    def __get__(self, sol, owner=None):
        if sol is None:
            return self
        d = sol.__dict__
        out = d.get("_out")  # None: no solution
        _, sy, sz, sb = d["_slices"] if out is not None else _NO_SLICES
        if "y" not in d:
            d["y"] = None if sy is None else out[sy]
        if "z" not in d:
            d["z"] = None if sz is None else out[sz]
        if "z_box" not in d:
            d["z_box"] = None if sb is None else out[sb]
        return d[self.name]


_NO_SLICES = (None, None, None, None)


class ViewSolution(BackendSolution):
    """A solution whose ``x``, ``y``, ``z``, ``z_box`` are views of ``_out`` at ``_slices``
    (``None``: absent), the duals made on first read (a closed loop reads only ``x``)."""

    y = _Duals()
    z = _Duals()
    z_box = _Duals()


def error_solution(problem: qpsolvers.Problem, exc: BaseException) -> BackendSolution:
    """Status ``error`` naming ``exc`` (a failure the solver raised on this problem)."""
    return BackendSolution(problem, status="error", error=describe_exception(exc))


class Backend:
    """Base class of every backend: set the class attributes and implement :meth:`_solve`
    (docs/architecture.md, "Adding things").

    Attributes:
        name: Registry key, e.g. ``"osqp"`` or ``"qpsolvers:daqp"``.
        package: Python distribution whose version is reported; ``module``: the module needed.
        online: Its own controller state (``rnn``): its ``x`` applied whatever the status.
        risky: Run in a worker with a deadline under ``--isolate auto``.
        scenario_table: Scenario table passed as settings by a closed loop (``"rnn"``).
        certifies_infeasibility: Tells primal from dual infeasibility (``None``: undeclared).
        sparse: Takes scipy.sparse matrices; the others get problems up to
            :data:`qpbench.memory.DENSE_MAX_ENTRIES` only.
        kernels: The numba kernel groups (:data:`qpbench.jit.KERNELS`) it runs.
        noise_floor: The loop without a solver: never ranked, not in ``all``, no bench.
    """

    name: ClassVar[str] = ""
    family: ClassVar[str] = ""
    package: ClassVar[str | None] = None
    module: ClassVar[str | None] = None
    online: ClassVar[bool] = False
    risky: ClassVar[bool] = False
    scenario_table: ClassVar[str | None] = None
    certifies_infeasibility: ClassVar[bool | None] = None
    infeasibility_note: ClassVar[str] = ""
    sparse: ClassVar[bool] = False
    kernels: ClassVar[tuple[str, ...]] = ()
    noise_floor: ClassVar[bool] = False

    def __init__(self, profile: str | Profile = "default", **settings):
        self.profile = get_profile(profile)
        self.settings = dict(settings)

    @classmethod
    def setting_names(cls) -> frozenset[str] | None:
        """The settings ``--set`` may give, or ``None``: any key is passed on."""
        return None

    @classmethod
    def unavailable_reason(cls) -> str | None:
        """``None`` when the backend can run here, else why not (default: :attr:`module` imports)."""
        if cls.module is None:
            return None
        try:
            __import__(cls.module)  # like an import statement (honours import hooks)
        except ImportError as exc:
            return f"cannot import {cls.module} ({exc})"
        return None

    @classmethod
    def version(cls) -> str | None:
        """Version of the package behind the backend, if known."""
        from ..formats import package_versions

        return None if cls.package is None else package_versions((cls.package,))[cls.package]

    def solve(
        self, problem: qpsolvers.Problem, warm_start: np.ndarray | None = None
    ) -> BackendSolution:
        """Solve ``problem`` (``warm_start``: a primal guess, shape (n,)); ``found`` iff
        ``optimal``. Solver failures are statuses; an exception escaping here is a bug."""
        sol = self._solve(problem, warm_start)
        sol.backend = self.name
        sol.found = sol.status == "optimal"
        return sol

    def _solve(
        self, problem: qpsolvers.Problem, warm_start: np.ndarray | None
    ) -> BackendSolution:  # pragma: no cover - abstract
        raise NotImplementedError

    def reset(self) -> None:
        """Forget every state kept between calls (persistent solver, warm start)."""

    def fresh(self) -> Backend:
        """A new instance with this one's profile and settings, sharing no state."""
        return type(self)(profile=self.profile, **self.settings)

    def __repr__(self) -> str:
        return f"<{type(self).__name__} {self.name!r} profile={self.profile.name}>"


def objective(problem: qpsolvers.Problem, x: np.ndarray) -> float:
    """Primal objective ``1/2 x^T P x + q^T x`` (plus no constant)."""
    return float(0.5 * x @ (problem.P @ x) + problem.q @ x)


class PersistentBackend(Backend):
    """A backend keeping its solver between calls (:meth:`reset` builds the state): a failure
    :meth:`_attempt` raises (:attr:`errors`, :attr:`error_names`) is ``error`` and drops it."""

    certifies_infeasibility = True
    errors: ClassVar[tuple[type[BaseException], ...]] = (ValueError,)
    #: Exception classes of the solver's package, by name (the package is imported lazily).
    error_names: ClassVar[frozenset[str]] = frozenset()

    def __init__(self, profile: str | Profile = "default", **settings):
        super().__init__(profile, **settings)
        self.reset()

    def reset(self) -> None:
        self._solver = self._layout = None  # the kept solver object and its data layout

    def _solve(self, problem, warm_start):
        try:
            return self._attempt(problem, warm_start)
        except BaseException as exc:
            if not isinstance(exc, self.errors) and type(exc).__name__ not in self.error_names:
                raise
            self.reset()
            return error_solution(problem, exc)

    def _attempt(
        self, problem: qpsolvers.Problem, warm_start: np.ndarray | None
    ) -> BackendSolution:  # pragma: no cover - abstract
        raise NotImplementedError


#: The fields of an answer read inside the clock (:func:`timed_call`).
ANSWER_FIELDS = ("x", "y", "z", "z_box")


def timed_call(
    backend: Backend, problem: qpsolvers.Problem, warm_start: np.ndarray | None = None
) -> tuple[BackendSolution, int]:
    """``(solution, time [ns])`` of ``backend.solve(problem, warm_start)``, the one definition
    of a solve's time from Python: the call and the read of :data:`ANSWER_FIELDS`, gc off."""
    enabled = gc.isenabled()
    gc.disable()
    try:
        t0 = time.perf_counter_ns()
        solution = backend.solve(problem, warm_start)
        if solution is not None:  # materialises the fields a backend defers
            for name in ANSWER_FIELDS:
                getattr(solution, name, None)
        t1 = time.perf_counter_ns()
    finally:
        if enabled:
            gc.enable()
    return solution, t1 - t0
