"""The robot's surroundings: the contact surface (paper sections 2.1, 4); the obstacles live in
:mod:`qpbench.robot.obstacles`, one module per kind.

Contact surface: a line (planar arm) or a plane (spatial arm) through ``point`` with unit
normal ``normal`` (the pressing direction); penetration ``delta = n . (x - point)``; a
spring-damper force while penetrating (paper eq. 3 read as the environment's law; computed by
:mod:`qpbench.sim.tick_kernel`)::

    F = max(0, Kp_env delta + Kd_env deltadot)   if delta > 0, else 0     [N]
"""

from __future__ import annotations

import math

import numpy as np

from ..exceptions import InputError


def _vector(value, key: str) -> np.ndarray:
    arr = np.asarray(value, dtype=float)
    if arr.shape not in ((2,), (3,)) or not np.all(np.isfinite(arr)):
        raise InputError(f"expected two or three finite numbers, got {value!r}", key=key)
    return arr


def _not_negative(value, key: str, unit: str, strict: bool = False) -> float:
    """``value`` as a float if ``>= 0`` (``> 0`` when ``strict``), else an :class:`InputError`."""
    if not (value > 0 if strict else value >= 0):
        raise InputError(f"must be {'>' if strict else '>='} 0 {unit}, got {value}", key=key)
    return float(value)


def _unit(value, key: str) -> np.ndarray:
    arr = _vector(value, key)
    norm = math.hypot(*arr)
    if norm < 1e-12:
        raise InputError(f"a direction must not be zero, got {value!r}", key=key)
    return arr / norm


class ContactSurface:
    """A line or plane the end effector presses on (paper section 2.1, Figure 1): ``point`` [m],
    pressing ``normal`` (normalised here; both of the arm's dim, 2 or 3), ``stiffness``
    ``Kp_env`` [N/m], ``damping`` ``Kd_env`` [N s/m], force-sensor noise ``noise_std`` [N] drawn from ``seed``."""

    def __init__(
        self,
        point,
        normal,
        stiffness: float,
        damping: float,
        noise_std: float = 0.0,
        seed: int | None = 0,
    ):
        self.point = _vector(point, "contact.point")
        self.normal = _unit(normal, "contact.normal")
        self.stiffness = _not_negative(stiffness, "contact.stiffness", "[N/m]", strict=True)
        self.damping = _not_negative(damping, "contact.damping", "[N s/m]")
        self.noise_std = _not_negative(noise_std, "contact.force_noise_std", "[N]")
        self.seed = seed
        self.reset()

    def reset(self) -> None:
        """Restart the noise sequence from the seed."""
        self._rng = np.random.default_rng(self.seed)

    def noise(self) -> float:
        """One sample of the force-sensor noise in [N] (0.0 when ``noise_std`` is 0)."""
        if self.noise_std <= 0.0:
            return 0.0
        return self.noise_std * float(self._rng.standard_normal())
