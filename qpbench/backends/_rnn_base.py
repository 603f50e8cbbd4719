"""The shared part of the ``rnn`` backends: their settings and the network backend base class.

A helper of :mod:`qpbench.backends.rnn` (not a backend): the settings every
``rnn`` backend accepts (:data:`SETTING_NAMES`, checked by :func:`positive`),
and :class:`NetworkBackend`, which reads them, keeps the network's state
between calls and builds a solution from the integration's result. The
settings and the per-tick path are described in :mod:`qpbench.backends.rnn`.
"""

from __future__ import annotations

import math
from typing import ClassVar

import numpy as np

from ..exceptions import ParamError, ProblemFormatError
from ..rnn import network as nw
from .base import Backend, BackendSolution

_DEFAULTS = {
    "eps": 0.02,
    "dt": 1e-3,
    "substeps": None,
    "tick": 1e-3,
    "safety": 0.9,
    "l1_clip": None,
    "method": None,
    "use_numba": None,
    "max_iter": None,
    "tol": None,
}


#: Names of the settings the rnn backends accept (a scenario's ``[rnn]`` table).
SETTING_NAMES = tuple(_DEFAULTS)


def positive(
    key: str,
    value: object,
    integer: bool = False,
    allow_none: bool = False,
    upper: float | None = None,
) -> float | int | None:
    if value is None and allow_none:
        return None
    try:
        number = int(value) if integer else float(value)
    except (TypeError, ValueError):
        raise ParamError(f"{value!r} is not a number", key=key) from None
    if integer and number != value:
        raise ParamError(f"{value!r} is not an integer", key=key)
    if not (number > 0 and math.isfinite(number)) or (upper is not None and number > upper):
        bound = f" and <= {upper}" if upper is not None else ""
        raise ParamError(f"{value!r} must be finite, > 0{bound}", key=key)
    return number


class NetworkBackend(Backend):
    """Shared settings, state handling and solution building."""

    family: ClassVar[str] = "recurrent neural network"
    package: ClassVar[str | None] = "qpbench"
    #: A closed loop applies ``x`` of an online backend whatever its status.
    online: ClassVar[bool] = False
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
        self.eps = positive("eps", s["eps"])
        self.dt = positive("dt", s["dt"])
        self.substeps = positive("substeps", s["substeps"], integer=True, allow_none=True)
        self.tick = positive("tick", s["tick"])
        self.safety = positive("safety", s["safety"], upper=1.0)
        self.l1_clip = positive("l1_clip", s["l1_clip"], allow_none=True)
        if s["method"] is None:
            s["method"] = self.default_method
        if s["method"] not in nw.METHODS:
            raise ParamError(
                f"unknown method {s['method']!r} (choose from {', '.join(nw.METHODS)})",
                key="method",
            )
        self.method = s["method"]
        if s["use_numba"] is None:
            self.use_numba = nw.numba_available()
        elif s["use_numba"] in (True, False):
            if s["use_numba"] and not nw.numba_available():
                raise ParamError("numba is not installed", key="use_numba")
            self.use_numba = bool(s["use_numba"])
        else:
            raise ParamError(f"{s['use_numba']!r} is not true or false", key="use_numba")
        self.max_iter = positive(
            "max_iter",
            self.profile.max_iter if s["max_iter"] is None else s["max_iter"],
            integer=True,
        )
        self.tol = positive("tol", self.profile.eps_abs if s["tol"] is None else s["tol"])
        self._p_key: bytes | None = None
        self._prm = nw.make_params(
            p_range=(1.0, 1.0),
            method=self.method,
            r_total=self._r_total(),
            safety=self.safety,
            max_steps=self.max_iter,
            tol=self._stop_tol(),
            l1_clip=self.l1_clip,
            step_ratio=self.tick / (self.substeps * self.eps) if self.substeps else 0.0,
            clamp=True,
        )
        self._kernel = None
        # A call is "optimal" when its residuals meet the profile's success
        # thresholds (and the stop tolerance, when it is tighter).
        self._ok_primal = max(self.tol, self.profile.tolerance.primal)
        self._ok_dual = max(self.tol, self.profile.tolerance.dual)
        self._prm[nw.OK_PRIMAL] = self._ok_primal
        self._prm[nw.OK_DUAL] = self._ok_dual
        self.state = None

    @property
    def state(self) -> nw.NetworkState | None:
        """The network's state ``(v, l1, l2)``, or ``None`` (the next call starts cold)."""
        return self._state

    @state.setter
    def state(self, st: nw.NetworkState | None) -> None:
        self._state = st
        self._prm[nw.STATE_ME] = -1.0 if st is None else st.me
        self._state_changed()

    def _state_changed(self) -> None:
        """Hook: the state object was replaced (or dropped)."""

    def _r_total(self) -> float:
        """``duration / eps`` of one call; 0 to integrate to convergence."""
        raise NotImplementedError

    def _stop_tol(self) -> float:
        """Residual tolerance that ends a call early (negative: never)."""
        raise NotImplementedError

    def reset(self) -> None:
        """Forget the network state (the next call starts cold)."""
        self.state = None
        self._prm[nw.STEPS] = np.nan

    @property
    def last(self) -> nw.IntegrationResult | None:
        """What the last call's integration did (``None`` before any call or after :meth:`reset`)."""
        p = self._prm
        if math.isnan(p[nw.STEPS]):
            return None
        return nw.result(p)

    def _diverged(self, problem, steps: int) -> BackendSolution:
        """The answer of a call whose state is no longer finite (the state is dropped)."""
        self.state = None
        prm = self._prm
        return BackendSolution(
            problem=problem,
            status="error",
            iterations=steps,
            error=f"FloatingPointError: network state diverged (r = {prm[nw.RATIO]:.3g}, "
            + (
                f"stable below {prm[nw.RATIO_MAX]:.3g})"
                if math.isfinite(prm[nw.RATIO_MAX])
                else "below a lower estimate of the stability bound)"
            ),
        )

    # -- the call ---------------------------------------------------------
    def _run(self, problem, warm_start) -> BackendSolution:
        if self._kernel is None:
            self._kernel = nw.kernel(self.use_numba)
        P, q, A, b = problem.P, problem.q, problem.A, problem.b
        G, h, lb, ub = problem.G, problem.h, problem.lb, problem.ub
        # Inline, not _common.dense_f64_parts: only the types that choose the route are
        # tested here, and the tick pays no extra call.
        if (
            not self.use_numba
            or type(P) is not np.ndarray
            or (A is not None and type(A) is not np.ndarray)
            or (G is not None and type(G) is not np.ndarray)
        ):
            qp = nw.dense_qp(problem)  # checks and converts (sparse, lists, shapes)
            P, q, A, b, G, h, lb, ub = qp.P, qp.q, qp.A, qp.b, qp.G, qp.h, qp.lb, qp.ub
        else:
            n = q.shape[0]
            if A is None:
                A, b = empty_rows(n)
            if G is None:
                G, h = empty_rows(n)
            if lb is None:
                lb = infinite(n, -np.inf)
            if ub is None:
                ub = infinite(n, np.inf)
        n, me, mi = q.shape[0], b.shape[0], h.shape[0]
        st = self.state
        if st is None:
            st = self.state = nw.NetworkState.cold(n, me, mi, warm_start)
        elif st.n != n or st.me != me or st.mi != mi:
            st = self.state = st.resized(n, me, mi)
        prm = self._prm
        key = P.tobytes()
        if key != self._p_key:
            prm[nw.PMIN], prm[nw.PMAX] = nw.p_eigen_range(np.asarray(P, dtype=np.float64))
            self._p_key = key
        sol = np.empty(3 * n + 2 * (me + mi))  # outputs, then scratch
        steps = self._kernel(P, q, A, b, G, h, lb, ub, st.xi, prm, sol)
        if steps == nw.SHAPE_MISMATCH:
            nw.dense_qp(problem)  # raises ProblemFormatError naming the matrix
            raise ProblemFormatError("inconsistent problem shapes", key="P")  # pragma: no cover
        if steps == nw.NO_STABLE_STEP:
            return BackendSolution(
                problem=problem,
                status="error",
                iterations=0,
                error=f"ParamError: P is not positive definite (lambda_min {prm[nw.PMIN]:.3g}); "
                "no step size of the network is proven stable",
            )
        obj = prm.item(nw.OBJ)
        if not math.isfinite(obj) or not math.isfinite(prm.item(nw.PRIMAL)):
            return self._diverged(problem, steps)
        ok = (
            prm.item(nw.PRIMAL) <= self._ok_primal
            and prm.item(nw.DUAL) <= self._ok_dual
            and prm.item(nw.COMPL) <= self._ok_primal
        )
        return BackendSolution(
            problem=problem,
            x=sol[:n],
            y=sol[n : n + me] if me else None,
            z=sol[n + me : n + me + mi] if mi else None,
            z_box=sol[n + me + mi : 2 * n + me + mi]
            if (problem.lb is not None or problem.ub is not None)
            else None,
            obj=obj if self._kernel_obj else None,
            status="optimal" if ok else "max_iter",
            iterations=steps,
            error=nw.step_note(prm),
        )


_EMPTIES: dict = {}


def empty_rows(n: int) -> tuple[np.ndarray, np.ndarray]:
    """Cached ``(zeros((0, n)), zeros(0))``: no rows.

    Writable, as the arrays of rows a problem has (they hold no element to protect): numba
    types a read-only array apart, so read-only empties would compile the integrator once
    more for every combination of absent and present rows.
    """
    pair = _EMPTIES.get(n)
    if pair is None:
        pair = _EMPTIES[n] = (np.zeros((0, n)), np.zeros(0))
    return pair


def infinite(n: int, value: float) -> np.ndarray:
    key = (n, value)
    arr = _EMPTIES.get(key)
    if arr is None:
        arr = np.full(n, value)
        arr.flags.writeable = False
        _EMPTIES[key] = arr
    return arr
