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
first call, cached on disk; :mod:`.kernels`) and a pure-numpy path (used when
numba is absent or not wanted; :mod:`.integrate_numpy`). They agree to
rounding (1e-12 and below).

This module is the network's front: the entry points (:func:`integrate`,
:func:`duals`) and, under their usual names, the pieces the other modules of
this package hold: the parameter block's layout (:mod:`.layout`), the problem
and state (:mod:`.problem`), the step bound (:mod:`.step_bound`) and the
kernels (:mod:`.kernels`).

The online backend calls the compiled loop through two thin per-tick
kernels that also return the tick's verdict: :func:`online_kernel` (the
problem's eight arrays, compiled for exactly one argument type) and
:func:`packed_kernel` (a :class:`qpbench.packed.PackedProblem`'s one buffer).
Both run the same compiled loop and give the same numbers bit for bit.
"""

from __future__ import annotations

import numpy as np

from ..exceptions import ParamError, ProblemFormatError
from .kernels import (  # noqa: F401 - the network's names, read through this module
    _HEADER,
    kernel,
    numba_available,
    online_kernel,
    packed_kernel,
)

# The layout's names re-exported one by one (the list repeats kernels.py's): callers read the
# network's slots as ``network.NAME``, and this list says which names that covers.
from .layout import (  # noqa: F401 - the network's names, read through this module
    _SQUARINGS,
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
    STATE_ME,
    STEPS,
    SUBSTEPS,
    TOL,
)
from .problem import (  # noqa: F401 - the network's names, read through this module
    DenseQP,
    IntegrationResult,
    NetworkState,
    dense_qp,
)
from .step_bound import (  # noqa: F401 - the network's names, read through this module
    _sigma2_bound_numpy,
    make_params,
    p_eigen_range,
    stable_ratio,
)


# The keywords repeat step_bound.make_params' on purpose: this is the public entry, whose signature
# documents each setting with its default; it passes them on to make_params unchanged.
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
        raise ParamError(
            f"state shape {state.shape} does not match problem {qp.shape}", key="state"
        )
    prm = make_params(
        p_range=p_range if p_range is not None else p_eigen_range(qp.P),
        method=method,
        r_total=r_total,
        substeps=substeps,
        safety=safety,
        max_steps=max_steps,
        tol=tol,
        l1_clip=l1_clip,
        step_ratio=step_ratio,
        clamp=clamp,
    )
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
