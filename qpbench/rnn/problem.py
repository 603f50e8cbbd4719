"""The network's problem and state: a QP as dense C-contiguous arrays, the state ``(v, l1, l2)``."""

from __future__ import annotations

from dataclasses import dataclass
from typing import TYPE_CHECKING

import numpy as np
import scipy.sparse as spa

from ..exceptions import ParamError, ProblemFormatError

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
    """The QP of a :class:`qpsolvers.Problem` as a :class:`DenseQP`.

    Raises:
        ProblemFormatError: inconsistent shapes (names the matrix).
    """
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


@dataclass
class IntegrationResult:
    """What one call of :func:`qpbench.rnn.network.integrate` did.

    ``steps``: taken, or ``NO_STABLE_STEP``. Residuals at the final state (inf-norms):
    primal ``max(|A v - b|, [G v - h]^+, [lb - v]^+, [v - ub]^+)``; dual
    ``|v - P_Omega(v - g)|_inf`` with ``g = P v + q - A^T l1 + G^T l2`` (qpsolvers' with
    the ``z_box`` of ``duals``); complementarity ``|l2 - max(l2 + G v - h, 0)|_inf`` (zero
    iff ``l2 >= 0``, ``G v <= h`` and ``l2_i (h - G v)_i = 0``). ``ratio``: ``r = h / eps``
    of one step; ``ratio_max``: its stability bound, ``sigma2_bound``: the bound on
    ``sigma_max([A; G])^2`` used, both NaN when a forced step was not checked against the
    bound or was below a cheap lower estimate of it. ``nominal_steps``: steps the setting
    asked for (0 when the bound chose the count).
    """

    steps: int
    primal_residual: float
    dual_residual: float
    complementarity: float
    objective: float
    ratio: float
    ratio_max: float
    sigma2_bound: float
    nominal_steps: int = 0

    @property
    def clamped(self) -> bool:
        """The setting's step exceeded the stability bound and was shortened."""
        return self.steps > self.nominal_steps > 0
