"""The network's integrator with numpy array operations: the test oracle of the compiled loops.

Same contract and the same numbers (to rounding, 1e-12 and below) as
:func:`qpbench.rnn.kernels.kernel`'s result; written apart from the loops on purpose,
as the reference they are checked against.
"""

from __future__ import annotations

import math

import numpy as np

from qpbench.rnn.kernels import (
    CLAMP,
    COMPL,
    DUAL,
    L1_CLIP,
    MAX_STEPS,
    NO_STABLE_STEP,
    NOMINAL,
    NOTE,
    NOTE_CAPPED,
    NOTE_CLAMPED,
    NOTE_NONE,
    NOTE_UNPROVEN,
    OBJ,
    PMAX,
    PMIN,
    PRIMAL,
    R_STEP,
    R_TOTAL,
    RATIO,
    RATIO_MAX,
    SAFETY,
    SEMI,
    SHAPE_MISMATCH,
    SIG2,
    SQUARINGS,
    STEPS,
    SUBSTEPS,
    TOL,
    clamped_steps,
    nominal_steps,
    ratio_max,
)
from qpbench.rnn.network import DenseQP, NetworkState, p_eigen_range


def integrate(P, q, A, b, G, h, lb, ub, xi, prm, sol):
    n, me, mi = q.shape[0], b.shape[0], h.shape[0]
    if (
        P.shape != (n, n)
        or A.shape != (me, n)
        or G.shape != (mi, n)
        or lb.shape != (n,)
        or ub.shape != (n,)
        or xi.shape != (n + me + mi,)
        or sol.shape[0] not in (0, 2 * n + me + mi, 3 * n + 2 * (me + mi))
    ):
        return SHAPE_MISMATCH
    v, l1, l2 = xi[:n], xi[n : n + me], xi[n + me :]
    semi = prm[SEMI] != 0.0
    r_total, l1_clip = prm[R_TOTAL], prm[L1_CLIP]
    nominal = nominal_steps(r_total, prm[R_STEP], int(prm[SUBSTEPS]))
    forced = nominal > 0
    prm[NOMINAL] = nominal
    nsteps, rmax, sig2, note = _step_bound(P, A, G, prm, nominal, semi)
    prm[RATIO_MAX] = rmax
    prm[SIG2] = sig2
    # the step-count logic is the compiled loop's (qpbench/rnn/kernels.py:_integrate_loops),
    # line for line on purpose: the twin must choose the same steps and notes
    if not forced and rmax <= 0.0:
        prm[RATIO] = 0.0
        prm[STEPS] = NO_STABLE_STEP
        return NO_STABLE_STEP
    if r_total > 0.0:
        if not forced:
            nsteps = clamped_steps(r_total, prm[SAFETY] * rmax, 1, prm[MAX_STEPS])
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
        _fill_solution(sol, v, l1, l2, g, Av, Gv, lb, ub)
    return steps


def _step_bound(P, A, G, prm, nominal, semi):
    """``(steps, ratio_max, sigma_max^2 bound, note)`` before the steps: the bound where it is needed.

    A forced step count (``nominal > 0``) needs the bound only when its step
    may exceed it: below a cheap lower estimate of it (Gershgorin for ``P``,
    Frobenius for ``sigma_max^2``) it cannot, and ``ratio_max`` stays NaN.
    """
    n = P.shape[0]
    r_total = prm[R_TOTAL]
    note = NOTE_NONE
    if nominal <= 0:
        sig2 = sigma2_bound(A, G)
        return 0, ratio_max(prm[PMIN], prm[PMAX], sig2, semi), sig2, note
    rmax = sig2 = np.nan
    nsteps = nominal
    if prm[CLAMP] != 0.0:
        if n:
            S = 0.5 * (P + P.T)
            radius = np.abs(S).sum(axis=1) - np.abs(np.diag(S))
            glo, ghi = float((np.diag(S) - radius).min()), float((np.diag(S) + radius).max())
            exact = not radius.any()
        else:
            glo, ghi, exact = 1.0, 1.0, True
        low = ratio_max(glo, ghi, float(np.sum(A * A) + np.sum(G * G)), semi)
        if not r_total / nominal <= prm[SAFETY] * low:
            pmin, pmax = (glo, ghi) if exact else p_eigen_range(P)
            sig2 = sigma2_bound(A, G)
            rmax = ratio_max(pmin, pmax, sig2, semi)
            if rmax <= 0.0:
                note = NOTE_UNPROVEN
            elif r_total / nominal > prm[SAFETY] * rmax:
                nsteps = clamped_steps(r_total, prm[SAFETY] * rmax, nominal, prm[MAX_STEPS])
                note = NOTE_CLAMPED
    return nsteps, rmax, sig2, note


def _fill_solution(sol, v, l1, l2, g, Av, Gv, lb, ub):
    """``sol = [x; y; z; z_box]`` (and ``[g; Av; Gv]`` after it when long enough): see :func:`duals`."""
    n, me, mi = v.shape[0], l1.shape[0], l2.shape[0]
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
