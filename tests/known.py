"""QPs with a known optimal primal-dual solution, built backwards from a chosen KKT point.

:func:`random_kkt_problem` picks ``x*``, the multipliers and which constraints
are active, then sets the data so that the KKT conditions hold (qpsolvers'
sign convention)::

    P x* + q + A' y* + G' z* + z_box* = 0
    A x* = b
    G x* <= h,   z* >= 0,   z*_i (G x* - h)_i = 0
    lb <= x* <= ub,   z_box* < 0 where x*_i = lb_i, > 0 where x*_i = ub_i, 0 elsewhere

``P`` is positive definite (strongly convex), so ``x*`` is the unique
minimiser; the active constraint gradients are generically independent (at
most ``n`` of them are active), so the multipliers are unique too. Active
multipliers and inactive slacks are at least ``0.1`` in magnitude (strict
complementarity), which keeps the answer well defined for solvers at 1e-9.
"""

from __future__ import annotations

import numpy as np
import qpsolvers

from qpbench.exceptions import ParamError


def _check_kkt_counts(
    n: int, n_eq: int, n_ineq: int, n_active: int, n_active_bounds: int, with_bounds: bool
) -> None:
    """Reject counts :func:`random_kkt_problem` cannot build (a :class:`ParamError` naming the count)."""
    if min(n, n_eq, n_ineq, n_active, n_active_bounds) < 0 or n < 1:
        raise ParamError(f"counts must be non-negative and n >= 1 (n={n})", key="n")
    if n_active > n_ineq:
        raise ParamError(f"n_active={n_active} > n_ineq={n_ineq}", key="n_active")
    if n_eq + n_active + n_active_bounds > n:
        raise ParamError(
            f"n_eq + n_active + n_active_bounds = {n_eq + n_active + n_active_bounds} > n = {n}",
            key="n_active",
        )
    if n_active_bounds and not with_bounds:
        raise ParamError("n_active_bounds > 0 needs with_bounds=True", key="n_active_bounds")


def _bounds_around(
    rng: np.random.Generator, x: np.ndarray, n_active_bounds: int, z_box: np.ndarray
) -> tuple[np.ndarray, np.ndarray]:
    """Bounds ``lb < x < ub`` with ``n_active_bounds`` of them active at ``x`` (lower, upper, ...).

    Writes the active bounds' multipliers into ``z_box`` (negative at a lower
    bound, qpsolvers' sign).
    """
    n = x.shape[0]
    lb = x - rng.uniform(0.1, 1.0, n)
    ub = x + rng.uniform(0.1, 1.0, n)
    active = rng.choice(n, size=n_active_bounds, replace=False)
    for k, i in enumerate(active):
        if k % 2 == 0:
            lb[i] = x[i]
            z_box[i] = -rng.uniform(0.1, 1.0)
        else:
            ub[i] = x[i]
            z_box[i] = rng.uniform(0.1, 1.0)
    return lb, ub


def random_kkt_problem(
    rng: np.random.Generator,
    n: int,
    n_eq: int,
    n_ineq: int,
    n_active: int,
    with_bounds: bool = True,
    n_active_bounds: int | None = None,
    cond: float = 1e2,
) -> tuple[qpsolvers.Problem, np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """A random strongly convex QP and its optimal ``(x, y, z, z_box)``.

    Args:
        rng: Random generator (the result is a function of its state).
        n: Number of variables.
        n_eq: Number of equality rows ``A x = b``.
        n_ineq: Number of inequality rows ``G x <= h``.
        n_active: How many of the inequality rows are active at ``x*``.
        with_bounds: Add finite bounds ``lb <= x <= ub`` (else ``lb = ub = None``).
        n_active_bounds: How many bounds are active at ``x*`` (about half of
            them lower, half upper); default ``min(2, n - n_eq - n_active)``.
        cond: Ratio of largest to smallest eigenvalue of ``P``.

    Returns:
        ``(problem, x, y, z, z_box)``; ``y`` has ``n_eq`` entries, ``z``
        ``n_ineq``, ``z_box`` ``n`` (zeros when ``with_bounds`` is False).

    Raises:
        ParamError: the counts are negative or more than ``n`` constraints
            would be active.
    """
    if n_active_bounds is None:
        n_active_bounds = min(2, max(0, n - n_eq - n_active)) if with_bounds else 0
    _check_kkt_counts(n, n_eq, n_ineq, n_active, n_active_bounds, with_bounds)

    # Cost: P = Q diag(eigs) Q' with eigenvalues log-spaced in [1, cond].
    Q, _ = np.linalg.qr(rng.standard_normal((n, n)))
    eigs = np.logspace(0.0, np.log10(cond), n)
    P = (Q * eigs) @ Q.T
    P = 0.5 * (P + P.T)

    x = rng.uniform(-1.0, 1.0, n)

    A = rng.standard_normal((n_eq, n))
    b = A @ x
    y = rng.uniform(-1.0, 1.0, n_eq)

    G = rng.standard_normal((n_ineq, n))
    slack = np.zeros(n_ineq)
    slack[n_active:] = rng.uniform(0.1, 1.0, n_ineq - n_active)
    h = G @ x + slack
    z = np.zeros(n_ineq)
    z[:n_active] = rng.uniform(0.1, 1.0, n_active)
    # Shuffle rows so the active ones are not always first.
    perm = rng.permutation(n_ineq)
    G, h, z = G[perm], h[perm], z[perm]

    z_box = np.zeros(n)
    lb = ub = None
    if with_bounds:
        lb, ub = _bounds_around(rng, x, n_active_bounds, z_box)

    q = -(P @ x + A.T @ y + G.T @ z + z_box)
    problem = qpsolvers.Problem(
        P,
        q,
        G if n_ineq else None,
        h if n_ineq else None,
        A if n_eq else None,
        b if n_eq else None,
        lb,
        ub,
    )
    return problem, x, y, z, z_box


def robot_like_problem(rng: np.random.Generator, n_ineq: int | None = None) -> tuple:
    """A known-solution QP shaped like one control tick (paper eq. 11).

    ``n = 4`` joint velocities, 2 task equalities, 7-14 inequality rows
    (one or two active), bounds on every joint (one active), ``P`` close to
    the identity. Returns what :func:`random_kkt_problem` returns.
    """
    if n_ineq is None:
        n_ineq = int(rng.integers(7, 15))
    n_active = int(rng.integers(0, 2))
    return random_kkt_problem(rng, 4, 2, n_ineq, n_active, True, n_active_bounds=1, cond=10.0)
