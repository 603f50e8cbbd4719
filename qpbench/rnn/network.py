"""The projection network of the paper's eq. 15 for any QP in qpsolvers form.

For the QP ``min 1/2 v^T P v + q^T v  s.t.  A v = b, G v <= h, lb <= v <= ub``
the network's state is ``(v, l1, l2)`` and its gain ``eps`` [s] (eq. 15a-c,
with the objective's gradient ``P v + q`` where the paper prints a garbled
``thetadot / ||thetadot||^2``)::

    eps vdot  = -v + P_Omega(v - (P v + q - A^T l1 + G^T l2))      (15a)
    eps l1dot = b - A v                                              (15b)
    eps l2dot = -l2 + max(l2 + G v - h, 0)                           (15c)

``P_Omega`` clips to ``[lb, ub]`` (infinite where a bound is absent). At an
equilibrium the qpsolvers duals are ``y = -l1``, ``z = l2`` and
``z_box = -(P v + q + A^T y + G^T z)``.

Integration. Writing ``r = h / eps`` for a step of ``h`` seconds, explicit
Euler is ``xi <- xi + r * f(xi)``. Away from the kinks of the projections
the network is linear with matrix ``M = [[P, -C^T], [C, 0]]``,
``C = [A; -G]`` (rows of active inequalities), whose eigenvalues ``lam``
satisfy ``Re lam = u^H P u`` for a unit eigenvector ``(u, w)``. Euler is
stable when ``|1 - r lam| < 1`` for all of them, which holds when::

    r < min(lambda_min(P) / sigma_max(C)^2,  2 / lambda_max(P))

(complex eigenvalues have ``|u|^2 = 1/2`` and ``|lam| <= sigma_max(C)``;
real ones ``lam <= lambda_max(P)``). For the paper's ``P = I`` this is the
note's ``r sigma_max^2 < 1``. Taking every row of ``A`` and ``G`` in ``C``
bounds every active set (a subset of rows has a smaller ``sigma_max``); the
box is handled by the projection and adds decoupled modes with eigenvalue 1.
``sigma_max(C)^2`` is bounded from above without an eigen-decomposition by
``tr(B^(2^k))^(1/2^k)`` with ``B = A^T A + G^T G`` (``k = 5`` squarings of
an ``n x n`` matrix; at most ``rank(B)^(1/32)`` above the true value).

The ``semi-implicit`` method updates ``v`` first and feeds the new ``v`` to the
dual updates (symplectic Euler). For ``P = p I`` each singular value ``sigma``
of ``C`` gives the 2x2 step matrix ``[[1 - r p, r sigma], [-r sigma (1 - r p),
1 - r^2 sigma^2]]``, stable (Jury) when ``r p < 2`` and
``r < 4 / (p + sqrt(p^2 + 4 sigma^2))`` -- about ``2 / sigma`` instead of
Euler's ``1 / sigma^2``. For a ``P`` that is not a multiple of the identity the
semi-implicit method uses Euler's bound.

This module holds the problem, the state and the entry points; the integrator, its
parameter block and its step bound are :mod:`.kernels`.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import TYPE_CHECKING

import numpy as np
import scipy.sparse as spa

from ..exceptions import ParamError, ProblemFormatError
from .kernels import (  # noqa: F401 - also the network's names for its callers
    METHODS,
    SHAPE_MISMATCH,
    IntegrationResult,
    kernel,
    make_params,
    packed_kernel,
    result,
)

if TYPE_CHECKING:
    import qpsolvers


@dataclass
class DenseQP:
    """A QP as dense float64 arrays, absent parts replaced by neutral ones.

    ``A v = b`` and ``G v <= h`` may have no rows (``me``, ``mi`` = 0); ``lb``,
    ``ub`` are ``-inf`` / ``+inf`` where absent (``has_box``: the problem had one).
    """

    P: np.ndarray
    q: np.ndarray
    A: np.ndarray
    b: np.ndarray
    G: np.ndarray
    h: np.ndarray
    lb: np.ndarray
    ub: np.ndarray
    has_box: bool

    @property
    def shape(self) -> tuple[int, int, int]:
        """``(n, me, mi)``: variables, equalities, inequalities."""
        return self.q.shape[0], self.b.shape[0], self.h.shape[0]


_EMPTIES: dict = {}


def empty_rows(n: int) -> tuple[np.ndarray, np.ndarray]:
    """Cached ``(zeros((0, n)), zeros(0))``: no constraint rows.

    Writable like the rows a problem has (they hold nothing to protect): numba types a
    read-only array apart, so read-only empties would compile the integrator again for
    every combination of absent and present rows.
    """
    pair = _EMPTIES.get(n)
    if pair is None:
        pair = _EMPTIES[n] = (np.zeros((0, n)), np.zeros(0))
    return pair


def infinite(n: int, value: float) -> np.ndarray:
    """Cached read-only ``full(n, value)``: an absent bound."""
    arr = _EMPTIES.get((n, value))
    if arr is None:
        arr = _EMPTIES[(n, value)] = np.full(n, value)
        arr.flags.writeable = False
    return arr


def _rows(M, v, m_name: str, v_name: str, n: int) -> tuple[np.ndarray, np.ndarray]:
    """Constraint rows ``M x (=|<=) v`` as float64 arrays (:func:`empty_rows` when ``M`` is None)."""
    if M is None:
        return empty_rows(n)
    M = _f64(M, m_name, 2)
    v = _f64(v, v_name, 1)
    if M.shape[1] != n or v.shape[0] != M.shape[0]:
        raise ProblemFormatError(
            f"{m_name} {M.shape} and {v_name} {v.shape} do not fit n = {n}", key=m_name
        )
    return M, v


def _f64(a, name: str, ndim: int) -> np.ndarray:
    if spa.issparse(a):
        a = a.toarray()
    if type(a) is not np.ndarray or a.dtype != np.float64 or not a.flags.c_contiguous:
        a = np.ascontiguousarray(a, dtype=np.float64)
    if a.ndim != ndim:
        if ndim == 2 and a.ndim == 1:
            a = a.reshape(1, -1)
        elif ndim == 1 and a.ndim == 2 and 1 in a.shape:
            a = a.ravel()
        else:
            raise ProblemFormatError(f"'{name}' has {a.ndim} dimensions, expected {ndim}", key=name)
    return a


def dense_qp(problem: qpsolvers.Problem) -> DenseQP:
    """The QP of a :class:`qpsolvers.Problem` as a :class:`DenseQP`; ProblemFormatError names a bad part."""
    P = _f64(problem.P, "P", 2)
    q = _f64(problem.q, "q", 1)
    n = q.shape[0]
    if P.shape != (n, n):
        raise ProblemFormatError(f"P has shape {P.shape}, expected ({n}, {n})", key="P")
    A, b = _rows(problem.A, problem.b, "A", "b", n)
    G, h = _rows(problem.G, problem.h, "G", "h", n)
    has_box = problem.lb is not None or problem.ub is not None
    lb = infinite(n, -np.inf) if problem.lb is None else _f64(problem.lb, "lb", 1)
    ub = infinite(n, np.inf) if problem.ub is None else _f64(problem.ub, "ub", 1)
    if lb.shape[0] != n or ub.shape[0] != n:
        raise ProblemFormatError(f"lb {lb.shape} / ub {ub.shape} do not fit n = {n}", key="lb")
    return DenseQP(P, q, A, b, G, h, lb, ub, has_box)


class NetworkState:
    """State of the network, stored as one vector ``xi = [v; l1; l2]``.

    ``v``: the output (the paper's joint-velocity command [rad/s]); ``l1``: equality
    dual state (qpsolvers ``y = -l1``); ``l2``: inequality dual state, >= 0
    (qpsolvers ``z = l2``); all three views of ``xi``.
    """

    __slots__ = ("xi", "n", "me", "mi")

    def __init__(self, xi: np.ndarray, n: int, me: int, mi: int):
        if xi.shape != (n + me + mi,):
            raise ParamError(
                f"state of shape {xi.shape} does not hold n={n}, me={me}, mi={mi}", key="state"
            )
        self.xi = xi
        self.n, self.me, self.mi = n, me, mi

    @classmethod
    def cold(cls, n: int, me: int, mi: int, v0: np.ndarray | None = None) -> NetworkState:
        """All-zero state (``v = v0`` if given)."""
        xi = np.zeros(n + me + mi)
        if v0 is not None:
            xi[:n] = np.asarray(v0, dtype=np.float64).reshape(n)
        return cls(xi, n, me, mi)

    def resized(self, n: int, me: int, mi: int) -> NetworkState:
        """The state for shape ``(n, me, mi)``: parts whose size changed restart at zero."""
        if n != self.n:
            return NetworkState.cold(n, me, mi)
        new = NetworkState.cold(n, me, mi, self.v)
        if me == self.me:
            new.l1[:] = self.l1
        if mi == self.mi:
            new.l2[:] = self.l2
        return new

    @property
    def v(self) -> np.ndarray:
        return self.xi[: self.n]

    @v.setter
    def v(self, value: np.ndarray) -> None:
        self.xi[: self.n] = value

    @property
    def l1(self) -> np.ndarray:
        return self.xi[self.n : self.n + self.me]

    @property
    def l2(self) -> np.ndarray:
        return self.xi[self.n + self.me :]

    @property
    def shape(self) -> tuple[int, int, int]:
        return self.n, self.me, self.mi

    def copy(self) -> NetworkState:
        return NetworkState(self.xi.copy(), self.n, self.me, self.mi)

    def __repr__(self) -> str:
        return f"NetworkState(v={self.v!r}, l1={self.l1!r}, l2={self.l2!r})"


def p_eigen_range(P: np.ndarray) -> tuple[float, float]:
    """``(lambda_min, lambda_max)`` of the symmetric part of ``P``."""
    if P.shape[0] == 0:
        return 1.0, 1.0
    w = np.linalg.eigvalsh(0.5 * (P + P.T))
    return float(w[0]), float(w[-1])


def integrate(
    qp: DenseQP,
    state: NetworkState,
    *,
    use_numba: bool = True,
    p_range: tuple[float, float] | None = None,
    **settings,
) -> IntegrationResult:
    """Integrate the network on ``qp`` from ``state`` (updated in place).

    ``settings``: those of :func:`make_params` (``r_total`` is the duration
    over ``eps``); ``p_range`` defaults to the eigenvalues of ``P``.
    ``steps == NO_STABLE_STEP`` when ``P`` is not positive definite and no
    step count was forced.
    """
    if state.shape != qp.shape:
        raise ParamError(
            f"state shape {state.shape} does not match problem {qp.shape}", key="state"
        )
    prm = make_params(p_range=p_range or p_eigen_range(qp.P), **settings)
    steps = kernel(use_numba)(
        qp.P, qp.q, qp.A, qp.b, qp.G, qp.h, qp.lb, qp.ub, state.xi, prm, _NO_SOL
    )
    if steps == SHAPE_MISMATCH:  # pragma: no cover - dense_qp checked the shapes
        raise ProblemFormatError("inconsistent problem shapes", key="P")
    return result(prm)


_NO_SOL = np.zeros(0)
