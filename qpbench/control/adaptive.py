"""Adaptive interaction coefficients (paper section 4.4).

The controller estimates the environment's ``W = [Kp_hat; Kd_hat]`` from the measured force::

    Wdot = -K_in eta (Fd - F),     eta = [n . (x - x_d); n . (xdot - xdot_d)]

``K_in = diag(gain_kp, gain_kd)``; ``eta`` is projected on the pressing direction ``n`` (the
impedance acts along it, the task tracks in the other directions), so ``W`` stays two scalars
on a planar or a spatial arm. Explicit Euler at the control period; the estimates are kept at
or above ``kp_min``, ``kd_min`` (``b0`` divides by ``Kd``).
"""

from __future__ import annotations

from functools import cache

import numpy as np


class AdaptiveImpedance:
    """Online estimate of ``Kp`` [N/m], ``Kd`` [N s/m] from ``kp0``, ``kd0`` (paper: 4000, 80),
    ``gain = K_in`` diagonal (paper: (500, 20)), unit ``normal`` (the arm's dim) and ``Fd`` [N]."""

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
        self.kp0, self.kd0 = float(kp0), float(kd0)
        self._law = np.array([*gain, desired_force, kp_min, kd_min, *normal], dtype=float)
        self.reset()

    def reset(self) -> None:
        """Back to the initial estimates."""
        self.kp, self.kd = self.kp0, self.kd0

    def update(
        self,
        dt: float,
        x: np.ndarray,
        x_d: np.ndarray,
        xdot: np.ndarray,
        xdot_d: np.ndarray,
        force: float,
    ) -> tuple[float, float]:
        """One Euler step over ``dt`` [s] from positions [m], velocities [m/s] (the arm's dim) and
        the measured force [N]; returns the new ``(Kp_hat, Kd_hat)`` (the compiled law
        :func:`adapt_py`)."""
        sensed = np.concatenate([x, xdot]).astype(float)
        xd = np.concatenate([x_d, xdot_d]).astype(float)
        gains = np.array([self.kp, self.kd])
        compiled_law()(self.law(), float(dt), sensed, xd, float(force), gains)
        self.kp, self.kd = float(gains[0]), float(gains[1])
        return self.kp, self.kd

    def law(self):
        """The law's constants as :func:`adapt_py` reads them: ``K_in`` (2), ``Fd``, ``kp_min``,
        ``kd_min``, then ``n`` (the arm's dim)."""
        return self._law.copy()


@cache
def compiled_law():
    """:func:`adapt_py`, compiled (or loaded from numba's cache) on the first call."""
    from ..native import compile_with

    return compile_with(adapt_py, name="adapt")


def adapt_py(law, dt, sensed, xd, force, gains):  # pragma: no cover - compiled
    """One Euler step of the law over ``dt`` [s]: ``gains = [Kp_hat, Kd_hat]`` updated in place
    from the sensed ``[x, xdot]`` and desired ``[x_d, xdot_d]`` (2 dim,) [m, m/s] and the
    measured ``force`` [N]; ``law`` of :meth:`AdaptiveImpedance.law`."""
    dim = law.shape[0] - 5
    eta_p = eta_d = 0.0
    for i in range(dim):
        eta_p += law[5 + i] * (sensed[i] - xd[i])
        eta_d += law[5 + i] * (sensed[dim + i] - xd[dim + i])
    ef = law[2] - force
    kp = gains[0] - dt * law[0] * eta_p * ef
    kd = gains[1] - dt * law[1] * eta_d * ef
    gains[0] = kp if kp > law[3] else law[3]
    gains[1] = kd if kd > law[4] else law[4]
