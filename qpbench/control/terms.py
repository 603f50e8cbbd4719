"""The pieces of the controller's QP (paper eq. 11) in numpy: the desired path ``x_d(t)``, the
impedance reference ``b0`` (eq. 4), the escape-velocity bounds (eq. 11c) and the obstacles'
velocity-damper rows (eqs. 8-10); :mod:`qpbench.control.build_kernel` computes the same compiled."""

from __future__ import annotations

import numpy as np

from ..exceptions import InputError
from ..robot.environment import Obstacle
from .build_kernel import COSINE, POLYLINE, compiled_path


class CosinePath:
    """``x_d(t) = centre + amplitude * cos(omega t + phase)`` per axis (paper sections 4.2-4.5):
    ``centre``, ``amplitude`` [m], ``omega`` [rad/s], ``phase`` [rad], each of shape (2,)."""

    def __init__(self, centre, amplitude, omega, phase=(0.0, 0.0)):
        cosine = np.concatenate([centre, amplitude, omega, phase]).astype(float)
        self.fields = (COSINE, cosine, np.zeros(2), np.zeros((2, 2)))

    def __call__(self, t: float) -> tuple[float, float, float, float]:
        """``(x_d_x, x_d_y, xdot_d_x, xdot_d_y)`` at time t [s], in [m] and [m/s] (the compiled
        kernel's: :func:`~qpbench.control.build_kernel.compiled_path`)."""
        out = np.empty(4)
        compiled_path()(*self.fields, float(t), out)
        return tuple(out.tolist())


class PolylinePath(CosinePath):
    """A piecewise-linear ``x_d(t)`` through ``points`` (m, 2) [m] at increasing ``times`` (m,)
    [s], m >= 2; it holds the last point after the end."""

    def __init__(self, times, points):
        self.times = np.asarray(times, dtype=float)
        self.points = np.asarray(points, dtype=float)
        if self.times.ndim != 1 or self.times.size < 2 or np.any(np.diff(self.times) <= 0):
            raise InputError(
                "polyline times must be >= 2 strictly increasing values [s]", key="path.times"
            )
        if self.points.shape != (self.times.size, 2):
            raise InputError(
                f"polyline points must be {self.times.size} [x, y] pairs", key="path.points"
            )
        self.fields = (POLYLINE, np.zeros(8), self.times, self.points)


class ImpedanceTask:
    """Position-force task as a task-space velocity reference (paper eqs. 3, 4, 11b)::

        b0 = xdot_d - Kd^-1 Kp (x - x_d) + Kd^-1 Fd n

    ``path(t) -> (x_d, xdot_d)`` components, ``normal`` the unit pressing direction, ``Fd`` [N].
    At rest in contact the end effector sits ``Fd/Kp`` past ``x_d`` along ``n``.
    """

    def __init__(self, path, normal, desired_force: float):
        self.path = path
        self.normal = np.asarray(normal, dtype=float)
        self.desired_force = float(desired_force)

    def impedance_reference(self, x: np.ndarray, t: float, kp: float, kd: float) -> np.ndarray:
        """``b0`` (eq. 4) in [m/s] for end-effector position ``x`` [m] at time ``t`` [s]."""
        xdx, xdy, vdx, vdy = self.path(t)
        x_d = np.array([xdx, xdy])
        xdot_d = np.array([vdx, vdy])
        return xdot_d - (kp / kd) * (np.asarray(x) - x_d) + (self.desired_force / kd) * self.normal


class EscapeVelocityLimits:
    """Joint limits as velocity bounds (paper eq. 11c, escape-velocity form)::

        lb = max(alpha (theta_min - theta), v_min),   ub = min(v_max, alpha (theta_max - theta))

    ``theta_*`` [rad], ``v_*`` [rad/s], escape gain ``alpha`` [1/s]. With the plant
    ``theta += dt v`` and ``alpha dt < 1`` the angle never leaves its limits once inside.
    """

    def __init__(self, theta_min, theta_max, v_min, v_max, alpha: float):
        self.theta_min = np.asarray(theta_min, dtype=float)
        self.theta_max = np.asarray(theta_max, dtype=float)
        self.v_min = np.asarray(v_min, dtype=float)
        self.v_max = np.asarray(v_max, dtype=float)
        self.alpha = float(alpha)

    def escape_velocity_bounds(self, theta: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """``(lb, ub)`` in [rad/s] at joint angles ``theta`` [rad]."""
        theta = np.asarray(theta, dtype=float)
        lb = np.maximum(self.alpha * (self.theta_min - theta), self.v_min)
        ub = np.minimum(self.v_max, self.alpha * (self.theta_max - theta))
        return lb, ub


def closest_rows(
    obstacle: Obstacle, k: float, d_safe: float, joints: np.ndarray, t: float, radius: float = 0.0
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Velocity-damper rows (eqs. 8-10) keeping each link's point closest to each point of
    ``obstacle`` (key points of kind ``closest``) ``d_safe`` [m] away at ``t`` [s].

    For key point ``A_i`` and obstacle point ``B_j`` with ``u = (A_i - B_j)/|A_i - B_j|``::

        d/dt dist = u . (J_Ai v - Bdot_j) >= -k (dist - d_safe)
        =>  G row = -u^T J_Ai,   h = k (dist - d_safe) - u . Bdot_j

    Damper gain ``k`` [1/s]; ``joints``: base, joints and end effector (n+1, 2) [m]; ``radius``
    [m]. Returns ``G`` (n*m, n), ``h`` (n*m,) and ``dist`` (n, m) [m] to the link's capsule,
    link major (the paper's key points: :mod:`qpbench.control.build_kernel`).
    """
    n = joints.shape[0] - 1
    A, _, dist, u = obstacle.closest_on_segments(joints[:-1], joints[1:], t)
    dist = dist - radius
    m = dist.shape[1]
    rel = A[:, :, None, :] - joints[None, None, :-1, :]  # (n links, m, n joints, 2)
    mask = (np.arange(n)[None, :] <= np.arange(n)[:, None]).astype(float)[:, None, :]
    J = np.stack([-rel[..., 1] * mask, rel[..., 0] * mask], axis=2)  # (n, m, 2, n)
    G = -np.einsum("lmk,lmkn->lmn", u, J).reshape(n * m, n)
    h = (k * (dist - d_safe) - u @ obstacle.velocity).reshape(n * m)
    return G, h, dist
