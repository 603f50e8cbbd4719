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

The integrator itself is :mod:`.kernels` (compiled loops); this module is its
front, and the name every caller reads the network's names by.
"""

from __future__ import annotations

import math

import numpy as np

from ..exceptions import ParamError, ProblemFormatError
from .kernels import (  # noqa: F401 - also the names callers read as ``network.NAME``
    CLAMP,
    COMPL,
    DIVERGED,
    DUAL,
    L1_CLIP,
    MAX_STEPS,
    METHODS,
    NO_STABLE_STEP,
    NOMINAL,
    NOTE,
    NOTE_CAPPED,
    NOTE_CLAMPED,
    NOTE_NONE,
    NOTE_UNPROVEN,
    OBJ,
    OK_DUAL,
    OK_PRIMAL,
    PMAX,
    PMIN,
    PRIMAL,
    PRM_SIZE,
    R_STEP,
    R_TOTAL,
    RATIO,
    RATIO_MAX,
    SAFETY,
    SEMI,
    SHAPE_MISMATCH,
    SIG2,
    SQUARINGS,
    STATE_ME,
    STEPS,
    SUBSTEPS,
    TOL,
    kernel,
    numba_available,
    online_kernel,
    packed_kernel,
    ratio_max,
)
from .problem import DenseQP, IntegrationResult, NetworkState, dense_qp  # noqa: F401


def p_eigen_range(P: np.ndarray) -> tuple[float, float]:
    """``(lambda_min, lambda_max)`` of the symmetric part of ``P``."""
    if P.shape[0] == 0:
        return 1.0, 1.0
    w = np.linalg.eigvalsh(0.5 * (P + P.T))
    return float(w[0]), float(w[-1])


def sigma2_bound(A: np.ndarray, G: np.ndarray) -> float:
    """Upper bound on ``lambda_max(A^T A + G^T G)``: ``tr(B^(2^k))^(1/2^k)``."""
    B = A.T @ A + G.T @ G
    t = float(np.trace(B))
    if not t > 0.0:
        return 0.0
    logc = math.log(t)
    B = B / t
    for _ in range(SQUARINGS):
        B = B @ B
        t = float(np.trace(B))
        if not t > 0.0:
            return 0.0
        logc = 2.0 * logc + math.log(t)
        B = B / t
    return math.exp(logc / 2.0**SQUARINGS)


def stable_ratio(qp: DenseQP, method: str = "euler") -> float:
    """Largest stable ``r = h / eps`` of one step for ``qp``; 0 when ``P`` is not positive definite."""
    pmin, pmax = p_eigen_range(qp.P)
    return ratio_max(pmin, pmax, sigma2_bound(qp.A, qp.G), method == "semi-implicit")


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
    clamp: bool = True,
) -> np.ndarray:
    """The parameter block ``prm`` of the kernels.

    Two modes:

    - fixed duration (``r_total = duration / eps > 0``): steps of ratio at
      most ``step_ratio`` (a fixed step ``h = step_ratio * eps``), else
      ``substeps`` equal steps, else (both 0) the fewest steps with
      ``r <= safety * ratio_max``. With ``clamp``, a forced step above
      ``safety * ratio_max`` is shortened to it (more steps); the bound is
      computed only when the step is above a cheap lower estimate of it
      (Gershgorin bounds of ``P``, ``|A|_F^2 + |G|_F^2`` for ``sigma_max^2``);
    - to convergence (``r_total <= 0``): steps of ``r = safety * ratio_max``
      until primal residual, dual residual and complementarity are all
      ``<= tol``, or ``max_steps`` steps.

    ``p_range``: ``(lambda_min, lambda_max)`` of ``P``; ``safety`` in (0, 1];
    ``tol`` negative: never stop early; ``l1_clip``: clip ``l1`` to
    ``[-l1_clip, l1_clip]`` after each step (anti-windup); ``method``: one of
    :data:`METHODS`.
    """
    if method not in METHODS:
        raise ParamError(
            f"unknown method '{method}' (choose from {', '.join(METHODS)})", key="method"
        )
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


def result(prm: np.ndarray) -> IntegrationResult:
    """The :class:`IntegrationResult` of the last kernel call on ``prm``."""
    return IntegrationResult(
        int(prm[STEPS]),
        float(prm[PRIMAL]),
        float(prm[DUAL]),
        float(prm[COMPL]),
        float(prm[OBJ]),
        float(prm[RATIO]),
        float(prm[RATIO_MAX]),
        float(prm[SIG2]),
        int(prm[NOMINAL]),
    )


def step_note(prm: np.ndarray) -> str | None:
    """What the last fixed-step call did against the setting (:data:`NOTE`), or ``None``."""
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


def duals(qp: DenseQP, state: NetworkState) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
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
