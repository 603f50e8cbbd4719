"""The step bound of the network's integrators and the parameter block of a call.

Euler is stable for ``r = h / eps < min(lambda_min(P) / sigma_max(C)^2,
2 / lambda_max(P))``; the semi-implicit method for about ``2 / sigma`` (see
:mod:`qpbench.rnn.network`). ``sigma_max(C)^2`` is bounded from above by a
trace power of ``A^T A + G^T G``. The small helpers here are called by the
numpy path and, compiled, by the kernels (:mod:`qpbench.rnn.kernels`).
"""

from __future__ import annotations

import math

import numpy as np

from ..exceptions import ParamError
from .layout import (
    _SQUARINGS,
    CLAMP,
    L1_CLIP,
    MAX_STEPS,
    METHODS,
    NOTE,
    NOTE_NONE,
    OK_DUAL,
    OK_PRIMAL,
    PMAX,
    PMIN,
    PRM_SIZE,
    R_STEP,
    R_TOTAL,
    SAFETY,
    SEMI,
    STATE_ME,
    STEPS,
    SUBSTEPS,
    TOL,
)
from .problem import DenseQP


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


# Keywords as in network.integrate (the public entry that passes them on); listed again here so
# the packed parameter vector can be built without going through a network state.
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
