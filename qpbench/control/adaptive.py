"""Adaptive interaction coefficients (paper section 4.4).

The controller estimates the environment's ``W = [Kp_hat; Kd_hat]`` from the measured force::

    Wdot = -K_in eta (Fd - F),     eta = [n . (x - x_d); n . (xdot - xdot_d)]

``K_in = diag(gain_kp, gain_kd)``; ``eta`` is projected on the pressing direction ``n`` so
``W`` stays two scalars. Explicit Euler at the control period; the estimates are kept at or
above ``kp_min``, ``kd_min`` (``b0`` divides by ``Kd``).
"""

from __future__ import annotations

from typing import TYPE_CHECKING

if TYPE_CHECKING:
    import numpy as np


class AdaptiveImpedance:
    """Online estimate of ``Kp`` [N/m], ``Kd`` [N s/m] from ``kp0``, ``kd0`` (paper: 4000, 80),
    ``gain = K_in`` diagonal (paper: (500, 20)), unit ``normal`` and ``Fd`` [N]."""

    def __init__(
        self,
        kp0: float,
        kd0: float,
        gain,
        normal,
        desired_force: float,
        kp_min: float,
        kd_min: float,
    ):
        self.kp0 = float(kp0)
        self.kd0 = float(kd0)
        self.gain_kp = float(gain[0])
        self.gain_kd = float(gain[1])
        self.nx = float(normal[0])
        self.ny = float(normal[1])
        self.desired_force = float(desired_force)
        self.kp_min = float(kp_min)
        self.kd_min = float(kd_min)
        self.reset()

    def reset(self) -> None:
        """Back to the initial estimates."""
        self.kp = self.kp0
        self.kd = self.kd0

    def update(
        self,
        dt: float,
        x: np.ndarray,
        x_d: np.ndarray,
        xdot: np.ndarray,
        xdot_d: np.ndarray,
        force: float,
    ) -> tuple[float, float]:
        """One Euler step over ``dt`` [s] from positions [m], velocities [m/s] and the measured
        force [N]; returns the new ``(Kp_hat, Kd_hat)``."""
        nx, ny = self.nx, self.ny
        eta_p = nx * (x[0] - x_d[0]) + ny * (x[1] - x_d[1])
        eta_d = nx * (xdot[0] - xdot_d[0]) + ny * (xdot[1] - xdot_d[1])
        ef = self.desired_force - force
        kp = self.kp - dt * self.gain_kp * eta_p * ef
        kd = self.kd - dt * self.gain_kd * eta_d * ef
        self.kp = kp if kp > self.kp_min else self.kp_min
        self.kd = kd if kd > self.kd_min else self.kd_min
        return self.kp, self.kd
