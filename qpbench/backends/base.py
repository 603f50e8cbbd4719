"""The backend interface: one small class per solver route.

A backend turns a :class:`qpsolvers.Problem` into a :class:`BackendSolution`
(a :class:`qpsolvers.Solution` with a few extras). Duals follow qpsolvers'
sign convention::

    P x + q + A^T y + G^T z + z_box = 0,   z >= 0,
    z_box < 0 where the lower bound is active, > 0 where the upper bound is.

A backend may keep state between calls (a controller solves a sequence of
problems, tick after tick): :meth:`Backend.solve` may update a persistent
solver object and warm-start from the previous answer; :meth:`Backend.reset`
forgets all of that.
"""

from __future__ import annotations

import time
from dataclasses import dataclass
from typing import ClassVar

import numpy as np
import qpsolvers

from ..profiles import Profile, get_profile
from ..statuses import STATUSES  # noqa: F401 - the vocabulary lives in qpbench.statuses; re-exported for backends


@dataclass
class BackendSolution(qpsolvers.Solution):
    """A :class:`qpsolvers.Solution` plus what a benchmark needs to know.

    Attributes:
        status: One of :data:`STATUSES`.
        iterations: Iterations (or integration steps) the solver reports, if any.
        solver_time_s: Solve time the solver itself reports, in [s], if any.
        wall_time_s: Wall time of the whole :meth:`Backend.solve` call in [s].
        backend: Name of the backend that produced it.
        error: Exception type and message when ``status == "error"``.

    ``obj`` is the solver's objective when the backend sets one; otherwise it
    is computed from ``x`` on first read (``1/2 x'Px + q'x``, no constant
    term) and kept: a closed loop that never reads it does not pay for it.
    """

    status: str = "not_solved"
    iterations: int | None = None
    solver_time_s: float | None = None
    wall_time_s: float | None = None
    backend: str = ""
    error: str | None = None

    def __getattr__(self, name: str):
        # Only for attributes not set: an instance made without __init__ (a
        # backend's per-tick path sets just the fields it has) gets the
        # defaults here. Fields with a plain default are class attributes.
        if name == "extras":
            extras = self.extras = {}
            return extras
        if name == "_obj":
            return None
        raise AttributeError(f"{type(self).__name__!r} object has no attribute {name!r}")


def _get_obj(self) -> float | None:
    obj = self._obj
    if obj is None and self.x is not None and self.problem is not None:
        obj = self._obj = objective(self.problem, self.x)
    return obj


def _set_obj(self, value) -> None:
    self._obj = value


# The dataclass __init__ assigns ``self.obj = obj``, which the property stores
# as ``_obj`` (a plain attribute: no ``__dict__`` access on the hot path).
BackendSolution.obj = property(
    _get_obj,
    _set_obj,
    doc="Primal objective at ``x`` (computed on first read when the solver gave none).",
)


class Backend:
    """Base class of every backend.

    Subclasses set the class attributes and implement :meth:`_solve`.

    Attributes:
        name: Registry key, e.g. ``"osqp"`` or ``"qpsolvers:daqp"``.
        family: Algorithm family, e.g. ``"ADMM"``, ``"interior point"``.
        package: Python distribution whose version is reported (or ``None``).
        module: Python module the backend needs; it is unavailable when that
            module does not import (or ``None``: always available).
        profile: The settings profile in force.
        settings: Extra solver settings given by the user (override the profile).
        online: True for a backend that is its own controller state (the
            ``rnn`` network): a closed loop applies its ``x`` whatever the
            status, with no fallback, and the harness gives it the time between
            records as ``dt``.
        risky: True for a backend the harness runs in a worker process with a
            deadline under ``--isolate auto`` (it was seen to hang in native code).
        scenario_table: Name of the scenario table whose values a closed loop
            passes as settings when it builds the backend by name (``"rnn"``
            for the network backends: the scenario's ``[rnn]`` table), or
            ``None``.
        certifies_infeasibility: True when the backend tells a primal-infeasible
            QP (status ``primal_infeasible``) and an unbounded one
            (``dual_infeasible``) apart from a certificate; False when it cannot
            (then :attr:`infeasibility_note` says why); ``None``: not declared.
        infeasibility_note: Why the backend cannot certify infeasibility.
        sparse: True for a backend that hands scipy.sparse matrices to its solver as
            they are; the others make them dense, so the bench gives them problems
            up to :data:`qpbench.memory.DENSE_MAX_ENTRIES` only (a larger one is a
            ``skipped`` row).
        kernels: The numba kernel groups the backend runs (names of
            :data:`qpbench.jit.KERNELS`, e.g. ``("network",)``): a command
            compiles or loads them before timing anything, and only those of
            the backends it runs.

    ``--repeat`` times a problem on several instances of a backend fed the same
    problems (:mod:`qpbench.harness.timing`); :meth:`fresh` makes them.
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

    def __init__(self, profile: str | Profile = "default", **settings):
        self.profile = get_profile(profile)
        self.settings = dict(settings)

    @classmethod
    def setting_names(cls) -> frozenset[str] | None:
        """Names of the settings the backend accepts (``--set BACKEND.KEY=VALUE`` is checked
        against them before any solve), or ``None`` when it cannot tell (every key is passed on)."""
        return None

    # -- availability -----------------------------------------------------
    @classmethod
    def unavailable_reason(cls) -> str | None:
        """``None`` when the backend can run here, else why it cannot.

        By default: whether :attr:`module` (the solver's Python module, if the
        backend names one) imports. Imported here, never at module import.
        """
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
        if cls.package is None:
            return None
        from importlib.metadata import PackageNotFoundError, version

        try:
            return version(cls.package)
        except PackageNotFoundError:
            return None

    # -- solving ----------------------------------------------------------
    def solve(
        self, problem: qpsolvers.Problem, warm_start: np.ndarray | None = None
    ) -> BackendSolution:
        """Solve ``problem``; fill x, y, z, z_box, found, obj, status and times.

        Args:
            problem: The QP in qpsolvers form.
            warm_start: Optional primal initial guess of shape (n,).

        Returns:
            The solution. ``found`` is True only for status ``optimal``;
            ``obj`` is the solver's or, when it gave none, computed from
            ``x`` on first read.
            Solver failures are statuses, not exceptions; an exception
            escaping here is a bug (the harness records it as ``error``).
        """
        start = _perf_ns()
        sol = self._solve(problem, warm_start)
        sol.wall_time_s = (_perf_ns() - start) * 1e-9
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
        """A new instance with this one's profile and settings, in the reset state.

        It must not share any state with this one: the two, fed the same problems,
        give the same answers. Override when the constructor takes more than
        ``(profile, **settings)``.
        """
        return type(self)(profile=self.profile, **self.settings)

    def __repr__(self) -> str:
        return f"<{type(self).__name__} {self.name!r} profile={self.profile.name}>"


_perf_ns = time.perf_counter_ns


def objective(problem: qpsolvers.Problem, x: np.ndarray) -> float:
    """Primal objective ``1/2 x^T P x + q^T x`` (plus no constant)."""
    P = problem.P
    Px = P @ x
    return float(0.5 * x @ Px + problem.q @ x)
