"""The projection network of the paper's eq. 15 for ``min 1/2 v^T P v + q^T v  s.t.  A v = b,
G v <= h, lb <= v <= ub``: state ``(v, l1, l2)``, gain ``eps`` [s], the objective's gradient
``P v + q`` where the paper prints a garbled ``thetadot / ||thetadot||^2``::

    eps vdot  = -v + P_Omega(v - (P v + q - A^T l1 + G^T l2))      (15a)
    eps l1dot = b - A v                                              (15b)
    eps l2dot = -l2 + max(l2 + G v - h, 0)                           (15c)

``P_Omega`` clips to ``[lb, ub]``; at an equilibrium ``y = -l1``, ``z = l2``, ``z_box = -(P v
+ q + A^T y + G^T z)``. The steps ``xi <- xi + r f(xi)`` of ratio ``r = h / eps`` (``h`` [s]),
Euler or semi-implicit (``v`` first), are in :mod:`.kernels`.
"""

from __future__ import annotations

from dataclasses import dataclass
from functools import cache
from typing import TYPE_CHECKING

import numpy as np
import scipy.sparse as spa

from ..exceptions import ProblemFormatError
from .kernels import IntegrationResult, kernel, make_params, result

if TYPE_CHECKING:
    import qpsolvers


@dataclass
class DenseQP:
    """A QP as dense float64 arrays: no rows, infinite bounds where absent (``has_box``)."""

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
        return self.q.shape[0], self.b.shape[0], self.h.shape[0]


@cache
def empty_rows(n: int) -> tuple[np.ndarray, np.ndarray]:
    """No constraint rows (writable: numba compiles a read-only array type apart)."""
    return np.zeros((0, n)), np.zeros(0)


@cache
def infinite(n: int, value: float) -> np.ndarray:
    """Read-only ``full(n, value)``: an absent bound."""
    arr = np.full(n, value)
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
    """``a`` as a C-contiguous float64 array of ``ndim`` dimensions (a vector as a row)."""
    a = np.ascontiguousarray(a.toarray() if spa.issparse(a) else a, dtype=np.float64)
    if a.ndim == ndim:
        return a
    if ndim == 2 and a.ndim == 1:
        return a.reshape(1, -1)
    if ndim == 1 and a.ndim == 2 and 1 in a.shape:
        return a.ravel()
    raise ProblemFormatError(f"'{name}' has {a.ndim} dimensions, expected {ndim}", key=name)


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
    """State of the network, one vector ``xi = [v; l1; l2]`` of which ``v`` (the output, the
    paper's joint velocities [rad/s]), ``l1`` (``y = -l1``) and ``l2`` (``z = l2``) are views."""

    __slots__ = ("xi", "n", "me", "mi", "shape", "l1", "l2")

    def __init__(self, xi: np.ndarray, n: int, me: int, mi: int):
        self.xi = xi
        self.n, self.me, self.mi = n, me, mi
        self.shape = (n, me, mi)
        self.l1 = xi[n : n + me]
        self.l2 = xi[n + me :]

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

    def copy(self) -> NetworkState:
        return NetworkState(self.xi.copy(), self.n, self.me, self.mi)


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
    """Integrate the network on ``qp`` from ``state`` (updated in place); ``settings``: those
    of :func:`make_params`; ``p_range`` defaults to the eigenvalues of ``P``."""
    prm = make_params(p_range=p_range or p_eigen_range(qp.P), **settings)
    kernel(use_numba)(qp.P, qp.q, qp.A, qp.b, qp.G, qp.h, qp.lb, qp.ub, state.xi, prm, np.zeros(0))
    return result(prm)
