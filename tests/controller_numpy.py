"""The numpy twin of the controller's compiled tick build (``qpbench/control/build_kernel.py``)
for the paper's key points: eq. 11 from the numpy kinematics and terms."""

from __future__ import annotations

import numpy as np

from qpbench.control.controller import TickArrays


def obstacle_rows(ctrl, obstacle, key_xy, key_J, t):
    """Velocity-damper rows (eqs. 8-10) of key points ``key_xy`` (a, 2) [m] with Jacobians
    ``key_J`` (a, 2, n) [m/rad] against ``obstacle`` at ``t`` [s]: ``G`` (a, m, n), ``h`` (a, m)
    and ``dist`` (a, m) [m], the key points' radius subtracted."""
    _, dist, u = obstacle.closest(key_xy, t)
    dist = dist - ctrl.key_points.radius
    G = -np.einsum("amk,akn->amn", u, key_J)
    h = ctrl.k * (dist - ctrl.d_safe) - u @ obstacle.velocity
    return G, h, dist


def numpy_arrays(ctrl, theta, t, kp, kd, soft: bool) -> TickArrays:
    """One tick's :class:`TickArrays` at ``theta`` [rad], ``t`` [s], ``kp`` [N/m], ``kd`` [N s/m]
    (rows key point major, as the compiled build)."""
    n, theta = ctrl.n, np.asarray(theta, dtype=float)
    ee, J = (x[0] for x in ctrl.arm.points_jacobians(theta, [n - 1], [1.0]))
    b0 = ctrl.task.impedance_reference(ee, t, kp, kd)
    lb, ub = ctrl.limits.escape_velocity_bounds(theta)
    if soft:  # 1/2 v^T v + rho/2 |J v - b0|^2
        P, q = np.eye(n) + ctrl.rho * J.T @ J, -ctrl.rho * J.T @ b0
    else:
        P, q = np.eye(n), np.zeros(n)
    key_xy, key_J = ctrl.arm.points_jacobians(theta, ctrl.key_points.links, ctrl.key_points.fracs)
    per = [obstacle_rows(ctrl, o, key_xy, key_J, t) for o in ctrl.obstacles]
    G, h, dist = np.zeros((0, n)), np.zeros(0), np.zeros(0)
    if per:
        G = np.concatenate([g for g, _, _ in per], axis=1).reshape(-1, n)
        h = np.concatenate([r for _, r, _ in per], axis=1).reshape(-1)
        dist = np.concatenate([d for _, _, d in per], axis=1).reshape(-1)
    return TickArrays(P, q, G, h, J, b0, lb, ub, ee, dist, ctrl.task.path(t))
