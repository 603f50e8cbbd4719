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
    """A :class:`qpsolvers.Solution` plus what a benchmark needs to know.

    ``status`` is one of :data:`qpbench.statuses.STATUSES`; ``solver_time_s`` [s] is the time
    the solver reports itself; ``error`` holds the exception when ``status == "error"``.
    ``obj`` is the solver's objective, or ``1/2 x'Px + q'x`` computed from ``x`` on first read.
    """

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
    """A :class:`BackendSolution` (or subclass ``cls``), every other field at its default:
    the per-tick constructor of the fast backends, without the dataclass ``__init__``."""
    sol = _new(cls)
    sol.problem = problem
    sol.status = status
    sol.extras = extras
    return sol


_new = object.__new__


class _Duals:
    """``y``, ``z`` and ``z_box`` of a :class:`ViewSolution`, made on the first read of any.

    A non-data descriptor: the first read puts all three views into the instance, where
    later reads (and assigned values) are found without calling this.
    """

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
    """A solution whose ``x`` is a view of one output vector ``_out`` and whose ``y``, ``z``,
    ``z_box`` are views made on the first read of any (a closed loop reads only ``x``):
    ``_slices`` says where ``x``, ``y``, ``z``, ``z_box`` lie in ``_out`` (``None``: absent)."""

    y = _Duals()
    z = _Duals()
    z_box = _Duals()


def error_solution(problem: qpsolvers.Problem, exc: BaseException) -> BackendSolution:
    """Status ``error`` naming ``exc`` (a failure the solver raised on this problem)."""
    return BackendSolution(problem, status="error", error=describe_exception(exc))


class Backend:
    """Base class of every backend: set the class attributes and implement :meth:`_solve`.

    Attributes:
        name: Registry key, e.g. ``"osqp"`` or ``"qpsolvers:daqp"``.
        package: Python distribution whose version is reported (or ``None``).
        module: Python module the backend needs (unavailable when it does not import).
        online: True for a backend that is its own controller state (the ``rnn`` network):
            a closed loop applies its ``x`` whatever the status, with no fallback, and
            passes the time between records as ``dt``.
        risky: Run in a worker process with a deadline under ``--isolate auto`` (it was
            seen to hang in native code).
        scenario_table: Scenario table whose values a closed loop passes as settings
            (``"rnn"``), or ``None``.
        certifies_infeasibility: Whether the backend tells a primal-infeasible QP from an
            unbounded one by a certificate (``None``: not declared); when it cannot,
            :attr:`infeasibility_note` says why.
        sparse: Hands scipy.sparse matrices to its solver as they are; the others make them
            dense, so the bench gives them problems up to
            :data:`qpbench.memory.DENSE_MAX_ENTRIES` only.
        kernels: The numba kernel groups (:data:`qpbench.jit.KERNELS`) the backend runs,
            compiled or loaded before anything is timed.
        noise_floor: Not a solver but the loop without one (``null``): measured beside the
            candidates in every closed-loop run set, never ranked, left out of ``all`` and
            refused by the per-tick bench.
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
        """The settings the backend accepts (``--set`` keys are checked against them), or
        ``None`` when it cannot tell (every key is passed on)."""
        return None

    @classmethod
    def unavailable_reason(cls) -> str | None:
        """``None`` when the backend can run here, else why not (by default: whether
        :attr:`module` imports; imported here, never at module import)."""
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
        """Solve ``problem`` (``warm_start``: an optional primal guess of shape (n,)).

        ``found`` is True only for status ``optimal``. Solver failures are statuses, not
        exceptions; an exception escaping here is a bug (the harness records it as ``error``).
        """
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
        """A new instance with this one's profile and settings, sharing no state with it
        (``--repeat`` times several, :mod:`qpbench.harness.guard`)."""
        return type(self)(profile=self.profile, **self.settings)

    def __repr__(self) -> str:
        return f"<{type(self).__name__} {self.name!r} profile={self.profile.name}>"


def objective(problem: qpsolvers.Problem, x: np.ndarray) -> float:
    """Primal objective ``1/2 x^T P x + q^T x`` (plus no constant)."""
    return float(0.5 * x @ (problem.P @ x) + problem.q @ x)


class PersistentBackend(Backend):
    """A backend keeping its solver between calls: the constructor calls :meth:`reset` (which
    builds the state), and a failure of the solver raised by :meth:`_attempt` (an instance of
    :attr:`errors`, or of a class named in :attr:`error_names`) is status ``error`` and drops
    the state."""

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
    """``(solution, time [ns])`` of ``backend.solve(problem, warm_start)``: the one definition
    of a solve's time from Python. Inside the clock (``CLOCK_MONOTONIC``, the compiled engine's
    too): the call and the reading of the answer's :data:`ANSWER_FIELDS` (a backend deferring
    its duals pays for them); the garbage collector is off while it runs."""
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
