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

Two integrators compute the same thing: a numba-compiled loop (compiled on
first call, cached on disk) and a pure-numpy path (used when numba is absent
or not wanted). They agree to rounding (1e-12 and below).

The online backend calls the compiled loop through two thin per-tick
kernels that also return the tick's verdict: :func:`online_kernel` (the
problem's eight arrays, compiled for exactly one argument type) and
:func:`packed_kernel` (a :class:`qpbench.packed.PackedProblem`'s one buffer).
Both run the same compiled loop and give the same numbers bit for bit.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
import scipy.sparse as spa

from ..exceptions import ParamError, ProblemFormatError

#: Integration methods.
METHODS = ("euler", "semi-implicit")

#: Squarings in the trace-power bound of ``sigma_max(C)^2``.
_SQUARINGS = 5

#: Layout of the parameter block ``prm`` the kernels read (inputs) and fill (outputs).
PMIN, PMAX, SEMI, R_TOTAL, SUBSTEPS, SAFETY, MAX_STEPS, TOL, L1_CLIP = range(9)
PRIMAL, DUAL, COMPL, OBJ, RATIO, RATIO_MAX, SIG2 = range(9, 16)
#: Inputs of the per-tick kernel (:func:`online_kernel`): the residual bounds of
#: status ``optimal`` and the equality count of the state's split (-1: not checked);
#: and one more output of every kernel: the last call's step count or code (NaN: none yet).
OK_PRIMAL, OK_DUAL, STATE_ME, STEPS = range(16, 20)
#: Inputs of a fixed step: the ratio ``r = h / eps`` of one step the setting
#: asks for (0: none; then ``SUBSTEPS`` or the bound decides the count) and
#: whether to clamp a forced step to the stability bound (1) or not (0);
#: output: the step count the setting asked for (0 when the bound chose it).
R_STEP, CLAMP, NOMINAL = range(20, 23)
#: Output: what a fixed-duration call did against its setting (:data:`NOTES`).
NOTE = 23
PRM_SIZE = 24

#: ``prm[NOTE]`` values: nothing to say; the step was clamped to the bound (more
#: steps); no step is proven stable (``P`` not positive definite: the steps ran
#: as set); the steps the bound needs exceed ``MAX_STEPS`` (capped there: the
#: step stays above the bound).
NOTE_NONE, NOTE_CLAMPED, NOTE_UNPROVEN, NOTE_CAPPED = 0, 1, 2, 3

#: Kernel return codes besides a step count.
NO_STABLE_STEP = -1
SHAPE_MISMATCH = -2
#: Per-tick kernel only: the state is no longer finite.
DIVERGED = -3


# ---------------------------------------------------------------------------
# Problem and state
# ---------------------------------------------------------------------------
@dataclass
class DenseQP:
    """A QP as dense float64 arrays, absent parts replaced by neutral ones.

    Attributes:
        P: Cost matrix, shape (n, n).
        q: Cost vector, shape (n,).
        A, b: Equalities ``A v = b``, shapes (me, n), (me,); me may be 0.
        G, h: Inequalities ``G v <= h``, shapes (mi, n), (mi,); mi may be 0.
        lb, ub: Box, shape (n,), ``-inf`` / ``+inf`` where absent.
        has_box: Whether the problem had ``lb`` or ``ub``.
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


_EMPTY_CACHE: dict[tuple, np.ndarray] = {}


def _cached(key: tuple, make) -> np.ndarray:
    arr = _EMPTY_CACHE.get(key)
    if arr is None:
        arr = make()
        arr.flags.writeable = False
        _EMPTY_CACHE[key] = arr
    return arr


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


def dense_qp(problem) -> DenseQP:
    """The QP of a :class:`qpsolvers.Problem` as a :class:`DenseQP`.

    Raises:
        ProblemFormatError: inconsistent shapes (names the matrix).
    """
    P = _f64(problem.P, "P", 2)
    q = _f64(problem.q, "q", 1)
    n = q.shape[0]
    if P.shape != (n, n):
        raise ProblemFormatError(f"P has shape {P.shape}, expected ({n}, {n})", key="P")
    if problem.A is None:
        A = _cached(("A", n), lambda: np.zeros((0, n)))
        b = _cached(("v", 0), lambda: np.zeros(0))
    else:
        A = _f64(problem.A, "A", 2)
        b = _f64(problem.b, "b", 1)
        if A.shape[1] != n or b.shape[0] != A.shape[0]:
            raise ProblemFormatError(f"A {A.shape} and b {b.shape} do not fit n = {n}", key="A")
    if problem.G is None:
        G = _cached(("A", n), lambda: np.zeros((0, n)))
        h = _cached(("v", 0), lambda: np.zeros(0))
    else:
        G = _f64(problem.G, "G", 2)
        h = _f64(problem.h, "h", 1)
        if G.shape[1] != n or h.shape[0] != G.shape[0]:
            raise ProblemFormatError(f"G {G.shape} and h {h.shape} do not fit n = {n}", key="G")
    has_box = problem.lb is not None or problem.ub is not None
    if problem.lb is None:
        lb = _cached(("lb", n), lambda: np.full(n, -np.inf))
    else:
        lb = _f64(problem.lb, "lb", 1)
    if problem.ub is None:
        ub = _cached(("ub", n), lambda: np.full(n, np.inf))
    else:
        ub = _f64(problem.ub, "ub", 1)
    if lb.shape[0] != n or ub.shape[0] != n:
        raise ProblemFormatError(f"lb {lb.shape} / ub {ub.shape} do not fit n = {n}", key="lb")
    return DenseQP(P, q, A, b, G, h, lb, ub, has_box)


class NetworkState:
    """State of the network, stored as one vector ``xi = [v; l1; l2]``.

    Attributes:
        xi: The whole state, shape (n + me + mi,).
        v: Output (the joint-velocity command in the paper), shape (n,), [rad/s]
            (a view of ``xi``).
        l1: Equality dual state, shape (me,) (qpsolvers ``y = -l1``).
        l2: Inequality dual state, shape (mi,), >= 0 (qpsolvers ``z = l2``).
    """

    __slots__ = ("xi", "n", "me", "mi")

    def __init__(self, xi: np.ndarray, n: int, me: int, mi: int):
        if xi.shape != (n + me + mi,):
            raise ParamError(f"state of shape {xi.shape} does not hold n={n}, me={me}, mi={mi}", key="state")
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
        """A state for a problem of shape ``(n, me, mi)``: parts whose size
        changed restart at zero (all of it when ``n`` changes)."""
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
    def v(self, value) -> None:
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
    """What one call of :func:`integrate` did.

    Attributes:
        steps: Integration steps taken, or :data:`NO_STABLE_STEP` when ``P``
            is not positive definite and no step size is proven stable.
        primal_residual: ``max(|A v - b|, [G v - h]^+, [lb - v]^+, [v - ub]^+)``
            at the final state (inf-norm).
        dual_residual: ``|v - P_Omega(v - g)|_inf`` with
            ``g = P v + q - A^T l1 + G^T l2``: qpsolvers' dual residual with the
            ``z_box`` of :func:`duals`.
        complementarity: ``|l2 - max(l2 + G v - h, 0)|_inf`` (zero iff
            ``l2 >= 0``, ``G v <= h`` and ``l2_i (h - G v)_i = 0``).
        objective: ``1/2 v^T P v + q^T v`` at the final state.
        ratio: ``r = h / eps`` of one step.
        ratio_max: Stability bound on ``r`` (module docstring); a ``ratio``
            above it may diverge.
        sigma2_bound: Upper bound on ``sigma_max([A; G])^2`` used.
        nominal_steps: Steps the setting asked for (a forced count, or the
            duration over a fixed step); 0 when the bound chose the count.
            ``steps > nominal_steps > 0``: the step was clamped to the bound.

    ``ratio_max`` and ``sigma2_bound`` are NaN when a forced step was not
    checked against the bound, or was below a cheap lower estimate of it
    (then it is within the bound: see :func:`integrate`).
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
        """The step of the setting exceeded the stability bound and was shortened."""
        return self.steps > self.nominal_steps > 0


# ---------------------------------------------------------------------------
# Step bound
# ---------------------------------------------------------------------------
def p_eigen_range(P: np.ndarray) -> tuple[float, float]:
    """``(lambda_min, lambda_max)`` of the symmetric part of ``P``."""
    if P.shape[0] == 0:
        return 1.0, 1.0
    w = np.linalg.eigvalsh(0.5 * (P + P.T))
    return float(w[0]), float(w[-1])


def _ratio_max(pmin, pmax, sig2, semi):
    """Largest stable ``r = h/eps`` (see the module docstring); 0 if none."""
    if pmin <= 0.0:
        return 0.0
    if semi and pmin == pmax:
        return min(2.0 / pmax, 4.0 / (pmax + math.sqrt(pmax * pmax + 4.0 * sig2)))
    bound = 2.0 / pmax
    if sig2 > 0.0:
        bound = min(bound, pmin / sig2)
    return bound


def _gershgorin(P):
    """``(lower, upper, exact)``: Gershgorin bounds on the eigenvalues of ``(P + P^T) / 2``.

    ``exact`` when the symmetric part is diagonal (the bounds are then its
    smallest and largest diagonal entries, the eigenvalues themselves).
    """
    n = P.shape[0]
    lo = np.inf
    hi = -np.inf
    exact = True
    for i in range(n):
        radius = 0.0
        for j in range(n):
            if j != i:
                radius += abs(0.5 * (P[i, j] + P[j, i]))
        if radius != 0.0:
            exact = False
        lo = min(lo, P[i, i] - radius)
        hi = max(hi, P[i, i] + radius)
    if n == 0:
        return 1.0, 1.0, True
    return lo, hi, exact


def _frobenius2(A, G):
    """``|A|_F^2 + |G|_F^2 = tr(A^T A + G^T G)``: an upper bound on ``sigma_max([A; G])^2``."""
    t = 0.0
    for i in range(A.shape[0]):
        for j in range(A.shape[1]):
            t += A[i, j] * A[i, j]
    for i in range(G.shape[0]):
        for j in range(G.shape[1]):
            t += G[i, j] * G[i, j]
    return t


def _nominal_steps(r_total, r_step, substeps):
    """Steps a fixed-duration call takes before any clamp (0: the bound decides).

    ``r_step > 0``: the fewest steps of ratio at most ``r_step`` over
    ``r_total`` (a step of fixed length, whatever the duration; a duration a
    hair above a multiple of the step, from rounding, does not add a step);
    else ``substeps`` (0 for none).
    """
    if r_total <= 0.0:
        return 0
    if r_step > 0.0:
        return max(1, int(math.ceil(r_total / r_step - 1e-9)))
    return substeps


def _clamped_steps(r_total, r_max, at_least, max_steps):
    """The fewest steps (at least ``at_least``) of ratio ``<= r_max`` over ``r_total``, at most ``max_steps``."""
    need = r_total / r_max
    if not need < max_steps:  # also a tiny or zero bound (need inf or NaN)
        return int(max(at_least, max_steps))
    return max(at_least, int(math.ceil(need)))


def _sigma2_bound_numpy(A: np.ndarray, G: np.ndarray) -> float:
    """Upper bound on ``lambda_max(A^T A + G^T G)``: ``tr(B^(2^k))^(1/2^k)``."""
    B = A.T @ A + G.T @ G
    t = float(np.trace(B))
    if not t > 0.0:
        return 0.0
    logc = math.log(t)
    B = B / t
    for _ in range(_SQUARINGS):
        B = B @ B
        t = float(np.trace(B))
        if not t > 0.0:
            return 0.0
        logc = 2.0 * logc + math.log(t)
        B = B / t
    return math.exp(logc / 2.0**_SQUARINGS)


def stable_ratio(qp: DenseQP, method: str = "euler") -> float:
    """Largest stable ``r = h / eps`` of one integration step for ``qp``.

    Uses the eigenvalues of ``P`` and the trace-power bound of
    ``sigma_max([A; G])^2`` (module docstring). Returns 0 when ``P`` is not
    positive definite (no step size is proven stable then).
    """
    pmin, pmax = p_eigen_range(qp.P)
    return _ratio_max(pmin, pmax, _sigma2_bound_numpy(qp.A, qp.G), method == "semi-implicit")


def make_params(
    *,
    p_range: tuple[float, float],
    method: str = "euler",
    r_total: float = 0.0,
    substeps: int = 0,
    safety: float = 0.9,
    max_steps: int = 100_000,
    tol: float = -1.0,
    l1_clip: float | None = None,
    step_ratio: float = 0.0,
    clamp: bool = False,
) -> np.ndarray:
    """The parameter block ``prm`` of the kernels (see :func:`integrate`)."""
    if method not in METHODS:
        raise ParamError(f"unknown method '{method}' (choose from {', '.join(METHODS)})", key="method")
    prm = np.zeros(PRM_SIZE)
    prm[PMIN], prm[PMAX] = p_range
    prm[SEMI] = 1.0 if method == "semi-implicit" else 0.0
    prm[R_TOTAL] = r_total
    prm[SUBSTEPS] = substeps
    prm[SAFETY] = safety
    prm[MAX_STEPS] = max_steps
    prm[TOL] = tol
    prm[L1_CLIP] = np.inf if l1_clip is None else l1_clip
    prm[R_STEP] = step_ratio
    prm[CLAMP] = 1.0 if clamp else 0.0
    prm[OK_PRIMAL] = prm[OK_DUAL] = -1.0
    prm[STATE_ME] = -1.0
    prm[STEPS] = np.nan
    prm[NOTE] = NOTE_NONE
    return prm


# ---------------------------------------------------------------------------
# numpy integrator
# ---------------------------------------------------------------------------
def _integrate_numpy(P, q, A, b, G, h, lb, ub, xi, prm, sol):
    """Same contract as the compiled kernel (see :func:`kernel`)."""
    n, me, mi = q.shape[0], b.shape[0], h.shape[0]
    if (
        P.shape != (n, n) or A.shape != (me, n) or G.shape != (mi, n) or lb.shape != (n,)
        or ub.shape != (n,) or xi.shape != (n + me + mi,)
        or sol.shape[0] not in (0, 2 * n + me + mi, 3 * n + 2 * (me + mi))
    ):
        return SHAPE_MISMATCH
    v, l1, l2 = xi[:n], xi[n : n + me], xi[n + me :]
    semi = prm[SEMI] != 0.0
    r_total, l1_clip = prm[R_TOTAL], prm[L1_CLIP]
    nominal = _nominal_steps(r_total, prm[R_STEP], int(prm[SUBSTEPS]))
    forced = nominal > 0
    prm[NOMINAL] = nominal
    note = NOTE_NONE
    if forced:
        rmax = sig2 = np.nan
        nsteps = nominal
        if prm[CLAMP] != 0.0:
            # the bound only when the step may exceed it: below a cheap lower
            # estimate of it (Gershgorin for P, Frobenius for sigma_max^2) it cannot
            if n:
                S = 0.5 * (P + P.T)
                radius = np.abs(S).sum(axis=1) - np.abs(np.diag(S))
                glo, ghi = float((np.diag(S) - radius).min()), float((np.diag(S) + radius).max())
                exact = not radius.any()
            else:
                glo, ghi, exact = 1.0, 1.0, True
            low = _ratio_max(glo, ghi, float(np.sum(A * A) + np.sum(G * G)), semi)
            if not r_total / nominal <= prm[SAFETY] * low:
                pmin, pmax = (glo, ghi) if exact else p_eigen_range(P)
                sig2 = _sigma2_bound_numpy(A, G)
                rmax = _ratio_max(pmin, pmax, sig2, semi)
                if rmax <= 0.0:
                    note = NOTE_UNPROVEN
                elif r_total / nominal > prm[SAFETY] * rmax:
                    nsteps = _clamped_steps(r_total, prm[SAFETY] * rmax, nominal, prm[MAX_STEPS])
                    note = NOTE_CLAMPED
    else:
        sig2 = _sigma2_bound_numpy(A, G)
        rmax = _ratio_max(prm[PMIN], prm[PMAX], sig2, semi)
    prm[RATIO_MAX] = rmax
    prm[SIG2] = sig2
    if not forced and rmax <= 0.0:
        prm[RATIO] = 0.0
        prm[STEPS] = NO_STABLE_STEP
        return NO_STABLE_STEP
    if r_total > 0.0:
        if not forced:
            nsteps = _clamped_steps(r_total, prm[SAFETY] * rmax, 1, prm[MAX_STEPS])
        if nsteps >= prm[MAX_STEPS] and r_total / nsteps > prm[SAFETY] * rmax:
            note = NOTE_CAPPED
        r = r_total / nsteps
        check = False
    else:
        r = prm[SAFETY] * rmax
        nsteps = int(prm[MAX_STEPS])
        check = prm[TOL] >= 0.0
    prm[NOTE] = note
    tol = prm[TOL]
    prm[RATIO] = r
    Av = A @ v
    Gv = G @ v
    steps = 0
    while True:
        g = P @ v + q - A.T @ l1 + G.T @ l2
        if check or steps == nsteps:
            # np.max propagates NaN (a diverged state must not look converged)
            pr = np.max(np.concatenate([np.abs(Av - b), Gv - h, lb - v, v - ub, v * 0.0]))
            du = np.max(np.abs(v - np.minimum(np.maximum(v - g, lb), ub)), initial=0.0)
            if np.isnan(g).any():
                du = np.nan
            co = np.max(np.abs(l2 - np.maximum(l2 + Gv - h, 0.0)), initial=0.0)
            if steps == nsteps or (pr <= tol and du <= tol and co <= tol):
                break
        w = np.minimum(np.maximum(v - g, lb), ub)
        v += r * (w - v)
        if semi:
            Av = A @ v
            Gv = G @ v
        l1 += r * (b - Av)
        if l1_clip < np.inf:
            np.minimum(np.maximum(l1, -l1_clip, out=l1), l1_clip, out=l1)
        l2 += r * (np.maximum(l2 + Gv - h, 0.0) - l2)
        if not semi:
            Av = A @ v
            Gv = G @ v
        steps += 1
    prm[PRIMAL] = pr
    prm[DUAL] = du
    prm[COMPL] = co
    prm[OBJ] = 0.5 * float(v @ (P @ v)) + float(q @ v)
    prm[STEPS] = steps
    if sol.shape[0]:
        w = v - g
        if sol.shape[0] > 2 * n + me + mi:
            base = 2 * n + me + mi
            sol[base : base + n] = g
            sol[base + n : base + n + me] = Av
            sol[base + n + me :] = Gv
        sol[:n] = v
        sol[n : n + me] = -l1
        sol[n + me : n + me + mi] = l2
        sol[n + me + mi : 2 * n + me + mi] = w - np.minimum(np.maximum(w, lb), ub)
    return steps


# ---------------------------------------------------------------------------
# numba integrator (same algorithm, explicit loops; compiled on first call)
# ---------------------------------------------------------------------------
def _sigma2_bound_loops(A, G):  # pragma: no cover - runs compiled
    n = A.shape[1]
    B = np.zeros((n, n))
    for k in range(A.shape[0]):
        for i in range(n):
            for j in range(n):
                B[i, j] += A[k, i] * A[k, j]
    for k in range(G.shape[0]):
        for i in range(n):
            for j in range(n):
                B[i, j] += G[k, i] * G[k, j]
    t = 0.0
    for i in range(n):
        t += B[i, i]
    if not t > 0.0:
        return 0.0
    logc = math.log(t)
    for i in range(n):
        for j in range(n):
            B[i, j] /= t
    C = np.empty((n, n))
    for _ in range(_SQUARINGS):
        for i in range(n):
            for j in range(n):
                s = 0.0
                for k in range(n):
                    s += B[i, k] * B[k, j]
                C[i, j] = s
        t = 0.0
        for i in range(n):
            t += C[i, i]
        if not t > 0.0:
            return 0.0
        logc = 2.0 * logc + math.log(t)
        for i in range(n):
            for j in range(n):
                B[i, j] = C[i, j] / t
    return math.exp(logc / 2.0**_SQUARINGS)


def _matvec_off(M, xi, off, y):  # pragma: no cover - runs compiled
    """``y = M @ xi[off : off + M.shape[1]]``."""
    for i in range(M.shape[0]):
        s = 0.0
        for j in range(M.shape[1]):
            s += M[i, j] * xi[off + j]
        y[i] = s


def _grad_products(P, q, A, G, xi, g, Av, Gv, products):  # pragma: no cover - runs compiled
    """``g = P v + q - A^T l1 + G^T l2`` and, with ``products``, ``Av = A v``, ``Gv = G v``.

    Row by row: each row of ``A`` and ``G`` is read once for both its
    product with ``v`` and its share of ``g`` (the rows are contiguous).
    """
    n = P.shape[0]
    me = A.shape[0]
    mi = G.shape[0]
    for j in range(n):
        s = q[j]
        for k in range(n):
            s += P[j, k] * xi[k]
        g[j] = s
    for i in range(me):
        c = xi[n + i]
        s = 0.0
        for j in range(n):
            a = A[i, j]
            s += a * xi[j]
            g[j] -= a * c
        if products:
            Av[i] = s
    for i in range(mi):
        c = xi[n + me + i]
        s = 0.0
        for j in range(n):
            a = G[i, j]
            s += a * xi[j]
            g[j] += a * c
        if products:
            Gv[i] = s


def _step(P, q, A, b, G, h, lb, ub, xi, g, Av, Gv, r, semi, l1_clip):  # pragma: no cover - runs compiled
    """One step of ratio ``r`` from the state ``xi`` whose ``g`` (and ``Av``, ``Gv``) are given; refreshes them."""
    n = q.shape[0]
    me = b.shape[0]
    mi = h.shape[0]
    o1 = n
    o2 = n + me
    for j in range(n):
        w = min(max(xi[j] - g[j], lb[j]), ub[j])
        xi[j] += r * (w - xi[j])
    if semi:
        _matvec_jit(A, xi, 0, Av)
        _matvec_jit(G, xi, 0, Gv)
    for i in range(me):
        xi[o1 + i] += r * (b[i] - Av[i])
        if l1_clip < np.inf:
            xi[o1 + i] = min(max(xi[o1 + i], -l1_clip), l1_clip)
    for i in range(mi):
        xi[o2 + i] += r * (max(xi[o2 + i] + Gv[i] - h[i], 0.0) - xi[o2 + i])
    # the next step's g (and, for Euler, Av and Gv): one pass over each row
    _grad_products_jit(P, q, A, G, xi, g, Av, Gv, not semi)


def _residuals(b, h, lb, ub, xi, g, Av, Gv):  # pragma: no cover - runs compiled
    """``(primal, dual, complementarity)`` residuals of the state (see :class:`IntegrationResult`).

    Maxima that propagate NaN: a diverged state must not look converged.
    """
    n = lb.shape[0]
    me = b.shape[0]
    mi = h.shape[0]
    o2 = n + me
    pr = 0.0
    for i in range(me):
        e = abs(Av[i] - b[i])
        if e > pr or e != e:
            pr = e
    for i in range(mi):
        e = Gv[i] - h[i]
        if e > pr or e != e:
            pr = e
    for j in range(n):
        e = max(lb[j] - xi[j], xi[j] - ub[j])
        if e > pr or xi[j] != xi[j]:
            pr = e if xi[j] == xi[j] else xi[j]
    du = 0.0
    for j in range(n):
        e = abs(xi[j] - min(max(xi[j] - g[j], lb[j]), ub[j]))
        if e > du or g[j] != g[j] or xi[j] != xi[j]:
            du = e if (g[j] == g[j] and xi[j] == xi[j]) else np.nan
    co = 0.0
    for i in range(mi):
        e = abs(xi[o2 + i] - max(xi[o2 + i] + Gv[i] - h[i], 0.0))
        if e > co or xi[o2 + i] != xi[o2 + i] or Gv[i] != Gv[i]:
            co = e if (xi[o2 + i] == xi[o2 + i] and Gv[i] == Gv[i]) else np.nan
    return pr, du, co


def _integrate_loops(P, q, A, b, G, h, lb, ub, xi, prm, sol):  # pragma: no cover - runs compiled
    n = q.shape[0]
    me = b.shape[0]
    mi = h.shape[0]
    if (
        P.shape[0] != n or P.shape[1] != n or A.shape[0] != me or A.shape[1] != n
        or G.shape[0] != mi or G.shape[1] != n or lb.shape[0] != n or ub.shape[0] != n
        or xi.shape[0] != n + me + mi
        or (sol.shape[0] != 0 and sol.shape[0] != 2 * n + me + mi and sol.shape[0] != 3 * n + 2 * (me + mi))
    ):
        return SHAPE_MISMATCH
    o1 = n
    o2 = n + me
    semi = prm[SEMI] != 0.0
    r_total = prm[R_TOTAL]
    l1_clip = prm[L1_CLIP]
    tol = prm[TOL]
    nominal = _nominal_steps_jit(r_total, prm[R_STEP], int(prm[SUBSTEPS]))
    forced = nominal > 0
    prm[NOMINAL] = nominal
    nsteps = nominal
    note = NOTE_NONE
    if forced:
        rmax = np.nan
        sig2 = np.nan
        if prm[CLAMP] != 0.0:
            # the bound only when the step may exceed it: below a cheap lower
            # estimate of it (Gershgorin for P, Frobenius for sigma_max^2) it cannot
            glo, ghi, exact = _gershgorin_jit(P)
            low = _ratio_max_jit(glo, ghi, _frobenius2_jit(A, G), semi)
            if not r_total / nominal <= prm[SAFETY] * low:
                pmin = glo
                pmax = ghi
                if not exact:
                    w = np.linalg.eigvalsh(0.5 * (P + P.T))
                    pmin = w[0]
                    pmax = w[n - 1]
                # same logic as _integrate_numpy's (the numpy twin, kept apart on purpose: numba
                # compiles this one; tests/test_rnn.py checks both give the same steps and notes)
                sig2 = _sigma2_bound_jit(A, G)
                rmax = _ratio_max_jit(pmin, pmax, sig2, semi)
                if rmax <= 0.0:
                    note = NOTE_UNPROVEN
                elif r_total / nominal > prm[SAFETY] * rmax:
                    nsteps = _clamped_steps_jit(r_total, prm[SAFETY] * rmax, nominal, prm[MAX_STEPS])
                    note = NOTE_CLAMPED
    else:
        sig2 = _sigma2_bound_jit(A, G)
        rmax = _ratio_max_jit(prm[PMIN], prm[PMAX], sig2, semi)
    prm[RATIO_MAX] = rmax
    prm[SIG2] = sig2
    if not forced and rmax <= 0.0:
        prm[RATIO] = 0.0
        prm[STEPS] = NO_STABLE_STEP
        return NO_STABLE_STEP
    if r_total > 0.0:
        if not forced:
            nsteps = _clamped_steps_jit(r_total, prm[SAFETY] * rmax, 1, prm[MAX_STEPS])
        if nsteps >= prm[MAX_STEPS] and r_total / nsteps > prm[SAFETY] * rmax:
            note = NOTE_CAPPED
        r = r_total / nsteps
        check = False
    else:
        r = prm[SAFETY] * rmax
        nsteps = int(prm[MAX_STEPS])
        check = tol >= 0.0
    prm[NOTE] = note
    prm[RATIO] = r
    if sol.shape[0] >= 3 * n + 2 * (me + mi):
        # scratch space after the outputs (saves three allocations)
        base = 2 * n + me + mi
        g = sol[base : base + n]
        Av = sol[base + n : base + n + me]
        Gv = sol[base + n + me : base + n + me + mi]
    else:
        Av = np.empty(me)
        Gv = np.empty(mi)
        g = np.empty(n)
    # g = P v + q - A^T l1 + G^T l2, Av = A v, Gv = G v at the current state
    _grad_products_jit(P, q, A, G, xi, g, Av, Gv, True)
    if check:
        steps = 0
        while True:
            pr, du, co = _residuals_jit(b, h, lb, ub, xi, g, Av, Gv)
            if steps == nsteps or (pr <= tol and du <= tol and co <= tol):
                break
            _step_jit(P, q, A, b, G, h, lb, ub, xi, g, Av, Gv, r, semi, l1_clip)
            steps += 1
    else:
        # a fixed duration: a plain loop (the residuals once, at the end)
        for _ in range(nsteps):
            _step_jit(P, q, A, b, G, h, lb, ub, xi, g, Av, Gv, r, semi, l1_clip)
        steps = nsteps
        pr, du, co = _residuals_jit(b, h, lb, ub, xi, g, Av, Gv)
    prm[PRIMAL] = pr
    prm[DUAL] = du
    prm[COMPL] = co
    obj = 0.0
    for j in range(n):
        s = 0.0
        for k in range(n):
            s += P[j, k] * xi[k]
        obj += xi[j] * (0.5 * s + q[j])
    prm[OBJ] = obj
    prm[STEPS] = steps
    if sol.shape[0] != 0:
        for j in range(n):
            sol[j] = xi[j]
            w = xi[j] - g[j]
            sol[n + me + mi + j] = w - min(max(w, lb[j]), ub[j])
        for i in range(me):
            sol[n + i] = -xi[o1 + i]
        for i in range(mi):
            sol[n + me + i] = xi[o2 + i]
    return steps


def _online_tick_loops(P, q, A, b, G, h, lb, ub, xi, prm, sol):  # pragma: no cover - runs compiled
    """One call of the online network: :func:`_integrate_loops` plus its verdict.

    Returns ``4 * steps + 2 * note + ok`` (``ok``: primal residual and
    complementarity within ``prm[OK_PRIMAL]``, dual residual within
    ``prm[OK_DUAL]``; ``note``: the setting's step was clamped to the
    stability bound, or no step is proven stable, see :func:`step_note`), or
    :data:`SHAPE_MISMATCH` (also when the equality count is not the state's
    ``prm[STATE_ME]``), :data:`NO_STABLE_STEP` or :data:`DIVERGED`.
    """
    if prm[STATE_ME] >= 0.0 and b.shape[0] != prm[STATE_ME]:
        return SHAPE_MISMATCH
    steps = _integrate_jit(P, q, A, b, G, h, lb, ub, xi, prm, sol)
    if steps < 0:
        return steps
    obj = prm[OBJ]
    pr = prm[PRIMAL]
    if not (math.isfinite(obj) and math.isfinite(pr)):
        return DIVERGED
    ok = pr <= prm[OK_PRIMAL] and prm[DUAL] <= prm[OK_DUAL] and prm[COMPL] <= prm[OK_PRIMAL]
    return 4 * steps + (2 if prm[NOTE] != NOTE_NONE else 0) + (1 if ok else 0)


def _part_fits(off, size, length):  # pragma: no cover - runs compiled
    return off >= _HEADER and size >= 0 and off + size <= length


def _online_tick_packed_loops(buf, xi, prm, sol):  # pragma: no cover - runs compiled
    """:func:`_online_tick_loops` on a :class:`qpbench.packed.PackedProblem`'s buffer.

    Reads the header, checks that every part lies inside the buffer and that
    the sizes are the state's, and integrates on views of the buffer. A
    problem without ``lb`` or ``ub`` gives :data:`SHAPE_MISMATCH` (the general
    path handles it).
    """
    length = buf.shape[0]
    if length < _HEADER:
        return SHAPE_MISMATCH
    n = int(buf[0])
    me = int(buf[1])
    mi = int(buf[2])
    if n < 1 or me < 0 or mi < 0 or n + me + mi != xi.shape[0]:
        return SHAPE_MISMATCH
    oP = int(buf[3])
    oq = int(buf[4])
    oA = int(buf[5])
    ob = int(buf[6])
    oG = int(buf[7])
    oh = int(buf[8])
    olb = int(buf[9])
    oub = int(buf[10])
    if not (
        _part_fits_jit(oP, n * n, length) and _part_fits_jit(oq, n, length)
        and _part_fits_jit(olb, n, length) and _part_fits_jit(oub, n, length)
        and (me == 0 or (_part_fits_jit(oA, me * n, length) and _part_fits_jit(ob, me, length)))
        and (mi == 0 or (_part_fits_jit(oG, mi * n, length) and _part_fits_jit(oh, mi, length)))
    ):
        return SHAPE_MISMATCH
    if me == 0:
        oA = ob = _HEADER
    if mi == 0:
        oG = oh = _HEADER
    return _online_tick_jit(
        buf[oP : oP + n * n].reshape((n, n)), buf[oq : oq + n],
        buf[oA : oA + me * n].reshape((me, n)), buf[ob : ob + me],
        buf[oG : oG + mi * n].reshape((mi, n)), buf[oh : oh + mi],
        buf[olb : olb + n], buf[oub : oub + n], xi, prm, sol,
    )


# Names the compiled kernels call; bound to jitted functions by :func:`kernel`.
_sigma2_bound_jit = _sigma2_bound_loops
_ratio_max_jit = _ratio_max
_gershgorin_jit = _gershgorin
_frobenius2_jit = _frobenius2
_nominal_steps_jit = _nominal_steps
_clamped_steps_jit = _clamped_steps
_matvec_jit = _matvec_off
_grad_products_jit = _grad_products
_step_jit = _step
_residuals_jit = _residuals
_integrate_jit = _integrate_loops
_online_tick_jit = _online_tick_loops
_part_fits_jit = _part_fits
_COMPILED = None
_ONLINE = {}
_PACKED = None
_HEADER = 11  # qpbench.packed.HEADER (a test keeps them equal)


def numba_available() -> bool:
    """Whether numba can be imported here."""
    try:
        import numba  # noqa: F401
    except ImportError:
        return False
    return True


def kernel(use_numba: bool = True):
    """The integrator ``f(P, q, A, b, G, h, lb, ub, xi, prm, sol) -> steps``.

    ``xi`` (the state ``[v; l1; l2]``) is updated in place; ``prm`` holds the
    inputs ``PMIN .. L1_CLIP`` and receives the outputs ``PRIMAL .. SIG2``
    (index constants of this module); ``sol`` (length ``2n + me + mi``, or 0
    to skip) receives ``[x; y; z; z_box]`` as :func:`duals` defines them.
    Returns the step count, :data:`NO_STABLE_STEP` or :data:`SHAPE_MISMATCH`.
    The numba version is compiled on the first call of this function's result
    (and cached on disk); the numpy version computes the same numbers.
    """
    if not use_numba:
        return _integrate_numpy
    global _COMPILED, _sigma2_bound_jit, _ratio_max_jit, _matvec_jit, _grad_products_jit, _integrate_jit
    global _step_jit, _residuals_jit, _gershgorin_jit, _frobenius2_jit, _nominal_steps_jit, _clamped_steps_jit
    if _COMPILED is None:
        import numba

        jit = numba.njit(cache=True)
        inline = numba.njit(cache=True, inline="always")
        _sigma2_bound_jit = jit(_sigma2_bound_loops)
        _ratio_max_jit = jit(_ratio_max)
        _gershgorin_jit = inline(_gershgorin)
        _frobenius2_jit = inline(_frobenius2)
        _nominal_steps_jit = inline(_nominal_steps)
        _clamped_steps_jit = inline(_clamped_steps)
        # inlined into their callers (numba IR): a call costs more than these small products
        _matvec_jit = inline(_matvec_off)
        _grad_products_jit = inline(_grad_products)
        _step_jit = inline(_step)
        _residuals_jit = inline(_residuals)
        _COMPILED = _integrate_jit = inline(_integrate_loops)
    return _COMPILED


def online_kernel(strict: bool = True, inline: bool = False):
    """The per-tick kernel ``f(P, q, A, b, G, h, lb, ub, xi, prm, sol) -> code``.

    Same arguments as :func:`kernel`'s result, ``sol`` of length
    ``3 n + 2 (me + mi)``; returns :func:`_online_tick_loops`'s code. With
    ``strict`` it is compiled for exactly one argument type (C-contiguous,
    writable float64 arrays; ``P``, ``A``, ``G`` 2-D) and compiles nothing
    else: any other argument (``None``, a sparse matrix, a list, another
    dtype or layout) raises ``TypeError`` in numba's dispatcher, which is the
    whole type check of the online backend's per-tick path. Without
    ``strict`` it compiles for what it is given (the general path); with
    ``inline`` too, numba inlines it into a compiled caller
    (:func:`packed_kernel`). All compile the same code and give the same
    numbers.
    """
    fn = _ONLINE.get((strict, inline))
    if fn is None:
        import numba

        kernel(True)  # binds the integrator the tick calls
        if strict:
            a1 = numba.types.Array(numba.float64, 1, "C")
            a2 = numba.types.Array(numba.float64, 2, "C")
            sig = numba.int64(a2, a1, a2, a1, a2, a1, a1, a1, a1, a1, a1)
            fn = numba.njit(sig, cache=True)(_online_tick_loops)
        else:
            fn = numba.njit(cache=True, inline="always" if inline else "never")(_online_tick_loops)
        _ONLINE[(strict, inline)] = fn
    return fn


def packed_kernel():
    """The per-tick kernel on a packed buffer: ``f(buffer, xi, prm, sol) -> code``.

    Compiled for 1-D C-contiguous float64 arrays only. Returned is the
    compiled function's own entry point when numba exposes it: it skips the
    dispatcher's type matching (a quarter of a call's cost here), so every
    argument must be of that type. :class:`qpbench.packed.PackedProblem`
    guarantees it for its buffer (made by its checked constructor or by the
    controller, and never reassigned); the kernel checks the header against
    the buffer's length and the state before reading.
    """
    global _PACKED, _online_tick_jit, _part_fits_jit
    if _PACKED is None:
        import numba

        _online_tick_jit = online_kernel(strict=False, inline=True)
        _part_fits_jit = numba.njit(cache=True, inline="always")(_part_fits)
        a1 = numba.types.Array(numba.float64, 1, "C")
        disp = numba.njit(numba.int64(a1, a1, a1, a1), cache=True)(_online_tick_packed_loops)
        try:
            _PACKED = disp.overloads[disp.signatures[0]].entry_point
        except (AttributeError, KeyError, IndexError):  # pragma: no cover - another numba
            _PACKED = disp
    return _PACKED


# ---------------------------------------------------------------------------
# Public entry points
# ---------------------------------------------------------------------------
def integrate(
    qp: DenseQP,
    state: NetworkState,
    *,
    r_total: float = 0.0,
    substeps: int = 0,
    safety: float = 0.9,
    max_steps: int = 100_000,
    tol: float = -1.0,
    l1_clip: float | None = None,
    method: str = "euler",
    use_numba: bool = True,
    p_range: tuple[float, float] | None = None,
    step_ratio: float = 0.0,
    clamp: bool = True,
) -> IntegrationResult:
    """Integrate the network on ``qp`` from ``state`` (updated in place).

    Two modes:

    - fixed duration (``r_total = duration / eps > 0``): steps of ratio at
      most ``step_ratio`` (a fixed step ``h = step_ratio * eps``: their count
      follows the duration), else ``substeps`` equal steps, else (both 0)
      the fewest steps with ``r <= safety * ratio_max``. With ``clamp``, a
      forced step above ``safety * ratio_max`` is shortened to it (more
      steps; :attr:`IntegrationResult.clamped`); the bound is computed only
      when the step is above a cheap lower estimate of it (Gershgorin bounds
      of ``P``, ``|A|_F^2 + |G|_F^2`` for ``sigma_max^2``);
    - to convergence (``r_total <= 0``): steps of ``r = safety * ratio_max``
      until primal residual, dual residual and complementarity are all
      ``<= tol``, or ``max_steps`` steps.

    Args:
        qp: The problem (:func:`dense_qp`).
        state: Network state, updated in place; its shape must match ``qp``.
        r_total: Duration of the integration over ``eps`` (dimensionless).
        substeps: Forced number of steps of a fixed-duration integration.
        step_ratio: Ratio ``h / eps`` of one step of a fixed-duration
            integration (over ``substeps`` when both are given).
        safety: Fraction of the stability bound used for the step, in (0, 1].
        max_steps: Step budget of a convergence run.
        tol: Residual tolerance of a convergence run (negative: never stop early).
        l1_clip: Clip ``l1`` to ``[-l1_clip, l1_clip]`` after each step
            (anti-windup); ``None`` for no clip.
        method: ``"euler"`` or ``"semi-implicit"``.
        use_numba: Use the compiled loop (else the numpy path).
        p_range: ``(lambda_min, lambda_max)`` of ``P`` if known.
        clamp: Shorten a forced step above ``safety * ratio_max`` (more
            steps); ``False`` runs it as given (to study instability).

    Returns:
        An :class:`IntegrationResult` (``steps == NO_STABLE_STEP`` when ``P``
        is not positive definite and no step count was forced).
    """
    if state.shape != qp.shape:
        raise ParamError(f"state shape {state.shape} does not match problem {qp.shape}", key="state")
    prm = make_params(
        p_range=p_range if p_range is not None else p_eigen_range(qp.P), method=method,
        r_total=r_total, substeps=substeps, safety=safety, max_steps=max_steps, tol=tol,
        l1_clip=l1_clip, step_ratio=step_ratio, clamp=clamp,
    )
    steps = kernel(use_numba)(qp.P, qp.q, qp.A, qp.b, qp.G, qp.h, qp.lb, qp.ub, state.xi, prm, _NO_SOL)
    if steps == SHAPE_MISMATCH:  # pragma: no cover - dense_qp checked the shapes
        raise ProblemFormatError("inconsistent problem shapes", key="P")
    return result(prm)


def result(prm: np.ndarray) -> IntegrationResult:
    """The :class:`IntegrationResult` of the last kernel call on ``prm``."""
    return IntegrationResult(
        int(prm[STEPS]), float(prm[PRIMAL]), float(prm[DUAL]), float(prm[COMPL]), float(prm[OBJ]),
        float(prm[RATIO]), float(prm[RATIO_MAX]), float(prm[SIG2]), int(prm[NOMINAL]),
    )


def step_note(prm: np.ndarray) -> str | None:
    """What the last fixed-step call did against the setting, if anything (else ``None``).

    A forced step above ``safety * ratio_max`` was shortened (more steps),
    or no step size is proven stable (``P`` not positive definite) and the
    setting's steps ran as given.
    """
    note = prm[NOTE]
    nominal, steps = int(prm[NOMINAL]), int(prm[STEPS])
    if note == NOTE_CLAMPED:
        r_set = prm[R_TOTAL] / nominal
        return (
            f"step clamped to the stability bound: r = h/eps = {r_set:.3g} > {prm[SAFETY]:g} x {prm[RATIO_MAX]:.3g}; "
            f"{steps} steps instead of {nominal}"
        )
    if note == NOTE_UNPROVEN:
        return f"no step size is proven stable (P not positive definite); {steps} steps as set"
    if note == NOTE_CAPPED:
        return (
            f"step above the stability bound: r = h/eps = {prm[RATIO]:.3g} > {prm[SAFETY]:g} x {prm[RATIO_MAX]:.3g} "
            f"even at the step budget ({steps} steps, max_iter)"
        )
    return None


_NO_SOL = np.zeros(0)


def duals(qp: DenseQP, state: NetworkState):
    """qpsolvers duals ``(y, z, z_box)`` of a network state.

    ``y = -l1``, ``z = l2`` and ``z_box = w - P_Omega(w)`` with
    ``w = v - (P v + q + A^T y + G^T z)``: the part of ``w`` the projection
    cuts off. At an equilibrium (``v = P_Omega(w)``) this is the note's
    ``z_box = -(P v + q + A^T y + G^T z)``; away from it ``z_box`` keeps the
    signs qpsolvers requires (< 0 only at a lower bound, > 0 only at an upper
    one) and qpsolvers' dual residual equals ``|v - P_Omega(w)|_inf``.
    Absent parts give ``None``.
    """
    n, me, mi = qp.shape
    v, l1, l2 = state.v, state.l1, state.l2
    w = v - (qp.P @ v + qp.q - qp.A.T @ l1 + qp.G.T @ l2)
    z_box = w - np.minimum(np.maximum(w, qp.lb), qp.ub)
    return (-l1 if me else None), (l2.copy() if mi else None), (z_box if qp.has_box else None)
