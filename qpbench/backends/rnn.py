"""Backends ``rnn``, ``rnn-tuned`` and ``rnn-converged``: the paper's recurrent neural network
(eq. 15, :mod:`qpbench.rnn.network`).

Settings: :data:`SETTING_NAMES` (a scenario's ``[rnn]`` table). A step above ``safety`` times
the stability bound of the call's QP is shortened to it and ``error`` says so.
"""

from __future__ import annotations

import math
from typing import TYPE_CHECKING, ClassVar

import numpy as np

from ..exceptions import ParamError
from ..packed import PackedProblem
from ..rnn import kernels as nk
from ..rnn import network as nw
from . import register
from .base import Backend, BackendSolution, ViewSolution

if TYPE_CHECKING:
    import qpsolvers

_DEFAULTS = {
    "eps": 0.02,  # gain of eq. 15 [s] (the paper's); rnn only
    "dt": 1e-3,  # time integrated per call [s] (one control tick); rnn only
    "substeps": None,  # steps per `tick` (a fixed step h = tick / substeps, dt / h steps a
    # call, rounded up); None: the fewest steps with h / eps <= safety * bound
    "tick": 1e-3,  # [s]
    "safety": 0.9,  # fraction of the stability bound per step, in (0, 1]
    "l1_clip": None,  # clip l1 to +-l1_clip after every step (anti-windup)
    "method": None,  # euler (default of rnn) or semi-implicit (of rnn-converged)
    "use_numba": None,  # compiled loops (None: when numba is installed) or the same in Python
    "max_iter": None,  # step budget of rnn-converged (None: the profile's)
    "tol": None,  # residual tolerance of rnn-converged (None: the profile's eps_abs)
}

#: Names of the settings the rnn backends accept (a scenario's ``[rnn]`` table).
SETTING_NAMES = tuple(_DEFAULTS)

#: A setting that works in the closed loop of every shipped scenario (the paper's ``eps``
#: does not): 20 semi-implicit steps per 1 ms, ``l1`` clipped (anti-windup).
WORKING_SETTINGS = {"eps": 1e-4, "substeps": 20, "method": "semi-implicit", "l1_clip": 10.0}


def _positive(key: str, value: object, integer: bool = False, upper: float = math.inf):
    """``value`` if a finite number in ``(0, upper]`` (``integer``: an integer); ``None`` kept."""
    if value is None and _DEFAULTS[key] is None:
        return None
    try:
        number = int(value) if integer else float(value)
    except (TypeError, ValueError):
        raise ParamError(f"{value!r} is not a number", key=key) from None
    if integer and number != value:
        raise ParamError(f"{value!r} is not an integer", key=key)
    if not (0 < number <= upper and math.isfinite(number)):
        bound = f" and <= {upper}" if upper < math.inf else ""
        raise ParamError(f"{value!r} must be finite, > 0{bound}", key=key)
    return number


class NetworkBackend(Backend):
    """Shared settings, state and solutions: ``online`` integrates ``dt`` a call, else to ``tol``."""

    family: ClassVar[str] = "recurrent neural network"
    package: ClassVar[str | None] = "qpbench"
    #: A closed loop builds the network with the scenario's ``[rnn]`` table.
    scenario_table: ClassVar[str | None] = "rnn"
    kernels: ClassVar[tuple[str, ...]] = ("network",)
    certifies_infeasibility = False
    infeasibility_note = (
        "the network's state moves towards the projection; no certificate, only no convergence"
    )
    #: Integration method unless the ``method`` setting says otherwise.
    default_method: ClassVar[str] = "euler"
    #: Whether ``obj`` is the kernel's (else computed from ``x`` on first read).
    _kernel_obj: ClassVar[bool] = True

    @classmethod
    def setting_names(cls) -> frozenset[str]:
        return frozenset(_DEFAULTS)

    def __init__(self, profile="default", **settings):
        super().__init__(profile, **settings)
        unknown = sorted(set(settings) - set(_DEFAULTS))
        if unknown:
            raise ParamError(
                f"unknown setting '{unknown[0]}' for backend '{self.name}' "
                f"(allowed: {', '.join(_DEFAULTS)})",
                key=unknown[0],
            )
        s = {**_DEFAULTS, **settings}
        self.eps, self.dt, self.tick = (_positive(k, s[k]) for k in ("eps", "dt", "tick"))
        self.safety = _positive("safety", s["safety"], upper=1.0)
        self.substeps = _positive("substeps", s["substeps"], integer=True)
        self.l1_clip = _positive("l1_clip", s["l1_clip"])
        self.method = self.default_method if s["method"] is None else s["method"]
        use = s["use_numba"]
        if use not in (None, True, False):
            raise ParamError(f"{use!r} is not true or false", key="use_numba")
        if use and not nk.numba_available():
            raise ParamError("numba is not installed", key="use_numba")
        self.use_numba = nk.numba_available() if use is None else bool(use)
        max_iter = self.profile.max_iter if s["max_iter"] is None else s["max_iter"]
        self.max_iter = _positive("max_iter", max_iter, integer=True)
        self.tol = _positive("tol", self.profile.eps_abs if s["tol"] is None else s["tol"])
        self._p_key: bytes | None = None
        self._prm = nk.make_params(
            p_range=(1.0, 1.0),
            method=self.method,
            r_total=self.dt / self.eps if self.online else 0.0,
            safety=self.safety,
            max_steps=self.max_iter,
            tol=-1.0 if self.online else self.tol,
            l1_clip=self.l1_clip,
            step_ratio=self.tick / (self.substeps * self.eps) if self.substeps else 0.0,
        )
        # "optimal": the residuals within the profile's success thresholds (or a looser tol)
        self._prm[nk.OK_PRIMAL] = max(self.tol, self.profile.tolerance.primal)
        self._prm[nk.OK_DUAL] = max(self.tol, self.profile.tolerance.dual)
        self.state = None

    @property
    def state(self) -> nw.NetworkState | None:
        """The network's state ``(v, l1, l2)``, or ``None`` (the next call starts cold)."""
        return self._state

    @state.setter
    def state(self, st: nw.NetworkState | None) -> None:
        self._state = st
        self._prm[nk.STATE_ME] = -1.0 if st is None else st.me
        self._state_changed()

    def _state_changed(self) -> None:
        """Hook: the state object was replaced (or dropped)."""

    def reset(self) -> None:
        """Forget the network state (the next call starts cold)."""
        self.state = None
        self._prm[nk.STEPS] = np.nan

    @property
    def last(self) -> nw.IntegrationResult | None:
        """What the last call's integration did (``None`` before any call or after :meth:`reset`)."""
        return None if math.isnan(self._prm[nk.STEPS]) else nk.result(self._prm)

    def _set_p(self, P: np.ndarray) -> None:
        """The eigenvalue range of ``P`` into the parameter block, when ``P`` changed."""
        key = P.tobytes()
        if key != self._p_key:
            self._prm[nk.PMIN], self._prm[nk.PMAX] = nw.p_eigen_range(P)
            self._p_key = key

    def _diverged(self, problem, steps: int) -> BackendSolution:
        """The answer of a call whose state is no longer finite (the state is dropped)."""
        self.state = None
        prm = self._prm
        bound = (
            f"stable below {prm[nk.RATIO_MAX]:.3g})"
            if math.isfinite(prm[nk.RATIO_MAX])
            else "below a lower estimate of the stability bound)"
        )
        return BackendSolution(
            problem=problem,
            status="error",
            iterations=steps,
            error=f"FloatingPointError: network state diverged (r = {prm[nk.RATIO]:.3g}, {bound}",
        )

    def _solve(self, problem, warm_start) -> BackendSolution:
        """The general path: convert ``problem`` (or not: the kernel checks), integrate."""
        p = problem
        if self.use_numba and type(p.P) is _ndarray and {type(p.A), type(p.G)} <= _DENSE:
            n = p.q.shape[0]
            A, b = nw.empty_rows(n) if p.A is None else (p.A, p.b)
            G, h = nw.empty_rows(n) if p.G is None else (p.G, p.h)
            lb = nw.infinite(n, -np.inf) if p.lb is None else p.lb
            ub = nw.infinite(n, np.inf) if p.ub is None else p.ub
            args = (p.P, p.q, A, b, G, h, lb, ub)
        else:
            qp = nw.dense_qp(problem)  # converts and checks (sparse, lists, shapes)
            args = (qp.P, qp.q, qp.A, qp.b, qp.G, qp.h, qp.lb, qp.ub)
        n, me, mi = args[1].shape[0], args[3].shape[0], args[5].shape[0]
        st = self.state
        if st is None:
            st = self.state = nw.NetworkState.cold(n, me, mi, warm_start)
        elif st.shape != (n, me, mi):
            st = self.state = st.resized(n, me, mi)
        self._set_p(np.asarray(args[0], dtype=np.float64))
        prm = self._prm
        sol = np.empty(3 * n + 2 * (me + mi))  # outputs, then scratch
        steps = nk.kernel(self.use_numba)(*args, st.xi, prm, sol)
        if steps == nk.SHAPE_MISMATCH:
            nw.dense_qp(problem)  # raises ProblemFormatError naming the part
        if steps == nk.NO_STABLE_STEP:
            return BackendSolution(
                problem=problem,
                status="error",
                iterations=0,
                error=f"ParamError: P is not positive definite (lambda_min {prm[nk.PMIN]:.3g}); "
                "no step size of the network is proven stable",
            )
        obj = prm.item(nk.OBJ)
        if not math.isfinite(obj) or not math.isfinite(prm.item(nk.PRIMAL)):
            return self._diverged(problem, steps)
        has_box = p.lb is not None or p.ub is not None
        ok = (
            prm.item(nk.PRIMAL) <= prm.item(nk.OK_PRIMAL)
            and prm.item(nk.DUAL) <= prm.item(nk.OK_DUAL)
            and prm.item(nk.COMPL) <= prm.item(nk.OK_PRIMAL)
        )
        return BackendSolution(
            problem=problem,
            x=sol[:n],
            y=sol[n : n + me] if me else None,
            z=sol[n + me : n + me + mi] if mi else None,
            z_box=sol[n + me + mi : 2 * n + me + mi] if has_box else None,
            obj=obj if self._kernel_obj else None,
            status="optimal" if ok else "max_iter",
            iterations=steps,
            error=nk.step_note(prm),
        )


class TickSolution(ViewSolution):
    """The online network's answer to one tick: ``_out`` is the kernel's ``[x; y; z; z_box]``."""


@register
class RNNOnline(NetworkBackend):
    """The network integrated for ``dt`` per call (the paper's use). Per-tick path once a call
    has set up the state: :func:`~qpbench.rnn.kernels.packed_kernel` or
    :func:`~qpbench.rnn.kernels.online_kernel`; what they refuse goes to :meth:`_solve`."""

    name = "rnn"
    online = True
    _kernel_obj = False

    def _state_changed(self) -> None:
        """Arm the per-tick path for the state's shape (disarm without a state)."""
        st = self._state
        if st is None or not self.use_numba:
            self._fast = None
            return
        n, me, mi = st.shape
        slices = (
            slice(0, n),
            slice(n, n + me) if me else None,
            slice(n + me, n + me + mi) if mi else None,
            slice(n + me + mi, 2 * n + me + mi),
        )
        # the strict kernel takes arrays only: absent parts (None) go to the general path
        strict = nk.online_kernel() if me and mi else None
        # P's eigenvalues are read by the kernel only when it picks the sub-steps itself
        needs_p = self.substeps is None
        size = 3 * n + 2 * (me + mi)
        self._fast = (needs_p, nk.packed_kernel(), st.xi, self._prm, size, slices, strict)

    def solve(
        self, problem: qpsolvers.Problem, warm_start: np.ndarray | None = None
    ) -> BackendSolution:
        """One tick of integration; see :meth:`Backend.solve` (same fields)."""
        if self._fast is None:  # first call, odd input: the general path sets up the state
            return Backend.solve(self, problem, warm_start)
        needs_p, packed, xi, prm, size, slices, strict = self._fast
        if needs_p:
            P = problem.P
            if type(P) is not _ndarray or P.dtype != _f64:
                packed = strict = None
            else:
                self._set_p(P)
        out = _alloc(size)
        if type(problem) is _Packed and packed is not None:
            code = packed(problem.buffer, xi, prm, out)
        elif strict is None:
            code = nk.SHAPE_MISMATCH
        else:
            p = problem
            try:
                code = strict(p.P, p.q, p.A, p.b, p.G, p.h, p.lb, p.ub, xi, prm, out)
            except TypeError:  # numba's dispatcher: not the one argument type compiled
                code = nk.SHAPE_MISMATCH
        if code < 0:
            if code != nk.DIVERGED:  # refused before touching the state: the general path
                return Backend.solve(self, problem, warm_start)
            sol = self._diverged(problem, int(prm[nk.STEPS]))
            sol.backend, sol.found = self.name, False
            return sol
        sol = _new(TickSolution)
        sol.problem = problem
        sol.x = out[slices[0]]
        sol._out = out
        sol._slices = slices
        sol.iterations = code >> 2
        if code & 2:  # the step was clamped to the bound (or none is proven stable)
            sol.error = nk.step_note(prm)
        if code & 1:
            sol.status, sol.found = "optimal", True
        else:
            sol.status, sol.found = "max_iter", False
        sol.backend = self.name
        return sol


_ndarray = np.ndarray
_DENSE = {np.ndarray, type(None)}
_f64 = np.dtype(np.float64)
_alloc = np.empty
_new = object.__new__
_Packed = PackedProblem


@register
class RNNConverged(NetworkBackend):
    """The network integrated from the previous call's state until its KKT residuals are
    within ``tol``, or ``max_iter`` steps (status ``max_iter``)."""

    name = "rnn-converged"
    default_method = "semi-implicit"

    def _solve(self, problem, warm_start):
        st = self.state
        if warm_start is not None and st is not None and st.n == np.size(warm_start):
            st.v = np.asarray(warm_start, dtype=np.float64).reshape(-1)
        return super()._solve(problem, warm_start)


@register
class RNNTuned(RNNOnline):
    """The online network with :data:`WORKING_SETTINGS`, ignoring a scenario's ``[rnn]`` table."""

    name = "rnn-tuned"
    scenario_table = None

    def __init__(self, profile="default", **settings):
        super().__init__(profile, **{**WORKING_SETTINGS, **settings})
