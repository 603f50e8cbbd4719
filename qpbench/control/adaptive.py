"""Adaptive interaction coefficients (paper section 4.4).

The controller does not know the environment's ``Kp, Kd``; it estimates
``W = [Kp_hat; Kd_hat]`` from the measured force with the paper's law::

    Wdot = -K_in eta (Fd - F),     eta = [n . (x - x_d); n . (xdot - xdot_d)]

``K_in = diag(gain_kp, gain_kd)`` scales the two parts; ``eta`` is projected
on the pressing direction ``n`` so that ``W`` stays two scalars (the paper
writes vectors without saying how they reduce). Integrated with explicit
Euler at the control period. In steady contact ``n . xdot`` is about zero, so
``Kd_hat`` is not identifiable: only ``Kp_hat`` moves.

The estimates are kept at or above ``kp_min``, ``kd_min`` (``b0`` divides by
``Kd``).
"""

from __future__ import annotations

from typing import TYPE_CHECKING

if TYPE_CHECKING:
    import numpy as np

__all__ = ["AdaptiveImpedance"]


class AdaptiveImpedance:
    """Online estimate of ``Kp``, ``Kd`` (paper section 4.4).

    Args:
        kp0: Initial ``Kp_hat`` in [N/m] (paper: 4000).
        kd0: Initial ``Kd_hat`` in [N s/m] (paper: 80).
        gain: ``K_in`` diagonal ``(gain_kp, gain_kd)`` (paper: (500, 20)).
        normal: Pressing direction (unit), shape (2,).
        desired_force: ``Fd`` in [N].
        kp_min, kd_min: Lower clamps of the estimates.
    """

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
        """One Euler step of ``Wdot = -K_in eta (Fd - F)`` over ``dt`` [s]; returns the new ``(Kp_hat, Kd_hat)``.

        Args:
            dt: Step in [s].
            x, x_d: End-effector and desired positions in [m].
            xdot, xdot_d: End-effector and desired velocities in [m/s].
            force: Measured contact force in [N].
        """
        nx, ny = self.nx, self.ny
        eta_p = nx * (x[0] - x_d[0]) + ny * (x[1] - x_d[1])
        eta_d = nx * (xdot[0] - xdot_d[0]) + ny * (xdot[1] - xdot_d[1])
        ef = self.desired_force - force
        kp = self.kp - dt * self.gain_kp * eta_p * ef
        kd = self.kd - dt * self.gain_kd * eta_d * ef
        self.kp = kp if kp > self.kp_min else self.kp_min
        self.kd = kd if kd > self.kd_min else self.kd_min
        return self.kp, self.kd
