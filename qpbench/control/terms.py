"""The pieces of the controller's QP (paper eq. 11) in numpy: the desired path ``x_d(t)``, the
impedance reference ``b0`` (eq. 4) and the escape-velocity bounds (eq. 11c), in ``dim`` task
axes; :mod:`qpbench.control.build_kernel` computes them and the obstacle rows compiled."""

from __future__ import annotations

import numpy as np

from ..exceptions import InputError
from .build_kernel import COSINE, POLYLINE, compiled_path


class CosinePath:
    """``x_d(t) = centre + amplitude * cos(omega t + phase)`` per axis (paper sections 4.2-4.5):
    ``centre``, ``amplitude`` [m], ``omega`` [rad/s], ``phase`` [rad], each of shape (dim,)."""

    def __init__(self, centre, amplitude, omega, phase=None):
        phase = np.zeros(len(centre)) if phase is None else phase
        cosine = np.concatenate([centre, amplitude, omega, phase]).astype(float)
        self.dim = len(centre)
        self.fields = (COSINE, cosine, np.zeros(2), np.zeros((2, self.dim)))

    def __call__(self, t: float) -> tuple[float, ...]:
        """``(x_d, xdot_d)`` at time t [s] as 2 dim numbers, in [m] and [m/s] (the compiled
        kernel's: :func:`~qpbench.control.build_kernel.compiled_path`)."""
        out = np.empty(2 * self.dim)
        compiled_path()(*self.fields, float(t), out)
        return tuple(out.tolist())


class PolylinePath(CosinePath):
    """A piecewise-linear ``x_d(t)`` through ``points`` (m, dim) [m] at increasing ``times``
    (m,) [s], m >= 2; it holds the last point after the end."""

    def __init__(self, times, points):
        self.times = np.asarray(times, dtype=float)
        self.points = np.asarray(points, dtype=float)
        if self.times.ndim != 1 or self.times.size < 2 or np.any(np.diff(self.times) <= 0):
            raise InputError(
                "polyline times must be >= 2 strictly increasing values [s]", key="path.times"
            )
        if self.points.ndim != 2 or self.points.shape[0] != self.times.size:
            raise InputError(
                f"polyline points must be {self.times.size} points, one per time",
                key="path.points",
            )
        self.dim = self.points.shape[1]
        self.fields = (POLYLINE, np.zeros(4 * self.dim), self.times, self.points)


class ImpedanceTask:
    """Position-force task as a task-space velocity reference (paper eqs. 3, 4, 11b)::

        b0 = xdot_d - Kd^-1 Kp (x - x_d) + Kd^-1 Fd n

    ``path(t) -> (x_d, xdot_d)`` components, ``normal`` the unit pressing direction (dim,),
    ``Fd`` [N]. At rest in contact the end effector sits ``Fd/Kp`` past ``x_d`` along ``n``.
    """

    def __init__(self, path, normal, desired_force: float):
        self.path = path
        self.normal = np.asarray(normal, dtype=float)
        self.desired_force = float(desired_force)

    def impedance_reference(self, x: np.ndarray, t: float, kp: float, kd: float) -> np.ndarray:
        """``b0`` (eq. 4) in [m/s] for end-effector position ``x`` [m] at time ``t`` [s]."""
        x_d, xdot_d = np.split(np.array(self.path(t)), 2)
        return xdot_d - (kp / kd) * (np.asarray(x) - x_d) + (self.desired_force / kd) * self.normal


class EscapeVelocityLimits:
    """Joint limits as velocity bounds (paper eq. 11c, escape-velocity form)::

        lb = max(alpha (theta_min - theta), v_min),   ub = min(v_max, alpha (theta_max - theta))

    ``theta_*`` [rad], ``v_*`` [rad/s], escape gain ``alpha`` [1/s]. With the plant
    ``theta += dt v`` and ``alpha dt < 1`` the angle never leaves its limits once inside.
    """

    def __init__(self, theta_min, theta_max, v_min, v_max, alpha: float):
        limits = (np.asarray(x, dtype=float) for x in (theta_min, theta_max, v_min, v_max))
        self.theta_min, self.theta_max, self.v_min, self.v_max = limits
        self.alpha = float(alpha)

    def escape_velocity_bounds(self, theta: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """``(lb, ub)`` in [rad/s] at joint angles ``theta`` [rad]."""
        theta = np.asarray(theta, dtype=float)
        lb = np.maximum(self.alpha * (self.theta_min - theta), self.v_min)
        ub = np.minimum(self.v_max, self.alpha * (self.theta_max - theta))
        return lb, ub
