"""The robot's surroundings: the contact surface and the obstacles (paper sections 2.1, 2.2, 4).

Contact surface: a line through ``point`` with unit normal ``normal``, the
direction in which the robot presses. Penetration ``delta = n . (x - point)``;
the force is a spring-damper acting only while penetrating (paper eq. 3 read
as the environment's law)::

    F = max(0, Kp_env delta + Kd_env deltadot)   if delta > 0, else 0     [N]

Obstacles: every obstacle kind gives, for each key point ``A``, one or more
obstacle points ``B`` (the closest point of an analytic shape, or each point
of a point cloud), the distance ``dist`` and the unit vector ``u`` from ``B``
to ``A`` (the gradient of ``dist`` with respect to ``A``). Every obstacle may
translate with a constant velocity ``velocity`` [m/s]; its position at time t
is its position at t = 0 plus ``velocity * t``. Adding a shape means adding one
class here with :meth:`Obstacle.closest` (numpy) and, for the compiled
per-tick build, a ``KERNEL_KIND`` code the kernel knows (the built-in four);
a shape without one makes the controller use its numpy path.

Distances of the ``line`` kind are signed (positive on the side ``normal``
points to): a wall is a half-plane, and a key point that crossed it is not
mistaken for one far away on the allowed side.
"""

from __future__ import annotations

import math

import numpy as np

from ..exceptions import InputError

__all__ = [
    "ContactSurface",
    "DiskObstacle",
    "LineObstacle",
    "Obstacle",
    "PointCloudObstacle",
    "SegmentObstacle",
    "OBSTACLE_KINDS",
]

#: Number of floats per obstacle point in the compiled kernel's table:
#: ``[kind, p0x, p0y, p1x, p1y, radius, vx, vy]``.
PRIMITIVE_WIDTH = 8


def _vec2(value, key: str) -> np.ndarray:
    arr = np.asarray(value, dtype=float)
    if arr.shape != (2,) or not np.all(np.isfinite(arr)):
        raise InputError(f"expected two finite numbers, got {value!r}", key=key)
    return arr


def _unit(value, key: str) -> np.ndarray:
    arr = _vec2(value, key)
    norm = math.hypot(arr[0], arr[1])
    if norm < 1e-12:
        raise InputError(f"a direction must not be zero, got {value!r}", key=key)
    return arr / norm


class ContactSurface:
    """A line the end effector presses on, with a spring-damper law (paper section 2.1, Figure 1).

    Args:
        point: A point of the surface in [m].
        normal: Direction the robot presses in (normalised here).
        stiffness: ``Kp_env`` in [N/m].
        damping: ``Kd_env`` in [N s/m].
        noise_std: Standard deviation of additive force-sensor noise in [N] (0: none).
        seed: Seed of the noise generator (same seed, same noise).
    """

    def __init__(
        self,
        point,
        normal,
        stiffness: float,
        damping: float,
        noise_std: float = 0.0,
        seed: int | None = 0,
    ):
        self.point = _vec2(point, "contact.point")
        self.normal = _unit(normal, "contact.normal")
        if not stiffness > 0:
            raise InputError(
                f"stiffness must be > 0 [N/m], got {stiffness}", key="contact.stiffness"
            )
        if not damping >= 0:
            raise InputError(f"damping must be >= 0 [N s/m], got {damping}", key="contact.damping")
        if not noise_std >= 0:
            raise InputError(
                f"noise_std must be >= 0 [N], got {noise_std}", key="contact.force_noise_std"
            )
        self.stiffness = float(stiffness)
        self.damping = float(damping)
        self.noise_std = float(noise_std)
        self.seed = seed
        self._rng = np.random.default_rng(seed)
        self._offset = float(self.normal @ self.point)

    def reset(self) -> None:
        """Restart the noise sequence from the seed."""
        self._rng = np.random.default_rng(self.seed)

    def penetration(self, x: np.ndarray) -> float:
        """``delta = n . (x - point)`` in [m] (positive inside the surface)."""
        return float(self.normal[0] * x[0] + self.normal[1] * x[1] - self._offset)

    def force(self, x: np.ndarray, xdot: np.ndarray) -> float:
        """Contact force magnitude along the normal in [N], as a sensor reads it (noise included).

        Args:
            x: End-effector position in [m].
            xdot: End-effector velocity in [m/s].
        """
        n0, n1 = self.normal
        delta = n0 * x[0] + n1 * x[1] - self._offset
        if delta > 0.0:
            f = self.stiffness * delta + self.damping * (n0 * xdot[0] + n1 * xdot[1])
            f = f if f > 0.0 else 0.0
        else:
            f = 0.0
        if self.noise_std > 0.0:
            f += self.noise()
        return f

    def noise(self) -> float:
        """One sample of the force-sensor noise in [N] (0.0 when ``noise_std`` is 0)."""
        if self.noise_std <= 0.0:
            return 0.0
        return self.noise_std * float(self._rng.standard_normal())


class Obstacle:
    """Base class of the obstacle kinds.

    Attributes:
        name: Label used in log columns (``d_A2_wall``).
        velocity: Constant translation velocity in [m/s], shape (2,).
        n_points: Obstacle points ``B_j`` per key point (1 for analytic shapes).
    """

    KIND: str = ""
    #: Code of the shape in the controller's compiled kernel (None: numpy path only).
    KERNEL_KIND: int | None = None
    n_points: int = 1

    def __init__(self, name: str, velocity=(0.0, 0.0)):
        self.name = str(name)
        self.velocity = _vec2(velocity, f"obstacles.{name}.velocity")

    def closest(self, A: np.ndarray, t: float) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Obstacle points nearest to key points ``A`` (a, 2) at time ``t`` [s].

        Returns:
            ``B`` (a, m, 2) in [m], ``dist`` (a, m) in [m], ``u`` (a, m, 2), the
            unit vector from ``B`` to ``A`` (zero where ``dist`` is 0).
        """
        raise NotImplementedError

    def primitives(self) -> np.ndarray:
        """Rows ``[kind, p0x, p0y, p1x, p1y, radius, vx, vy]`` (m, 8) of the compiled kernel, at t = 0."""
        raise NotImplementedError

    @staticmethod
    def _from_diff(diff: np.ndarray, radius: float = 0.0):
        dist = np.sqrt(np.einsum("...i,...i->...", diff, diff))
        safe = np.where(dist > 0, dist, 1.0)
        u = np.where(dist[..., None] > 0, diff / safe[..., None], 0.0)
        return dist - radius, u


class LineObstacle(Obstacle):
    """An infinite line (a wall), the half-plane ``normal . (x - point) < 0`` being forbidden.

    Args:
        point: A point on the line at t = 0 in [m].
        normal: Unit normal pointing to the free side (normalised here).
    """

    KIND = "line"
    KERNEL_KIND = 0

    def __init__(self, name: str, point, normal, velocity=(0.0, 0.0)):
        super().__init__(name, velocity)
        self.point = _vec2(point, f"obstacles.{name}.point")
        self.normal = _unit(normal, f"obstacles.{name}.normal")

    def closest(self, A: np.ndarray, t: float) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        A = np.asarray(A, dtype=float)
        p = self.point + self.velocity * t
        dist = (A - p) @ self.normal  # signed
        B = A - dist[:, None] * self.normal
        u = np.broadcast_to(self.normal, A.shape).copy()
        return B[:, None, :], dist[:, None], u[:, None, :]

    def primitives(self) -> np.ndarray:
        return np.array([[self.KERNEL_KIND, *self.point, *self.normal, 0.0, *self.velocity]])


# The obstacle classes share one shape (KIND, KERNEL_KIND, __init__, closest, primitives) on
# purpose: one class per obstacle kind, each with its own geometry, so that adding a kind
# touches one class; the repeated lines are that protocol, not shared logic.
class SegmentObstacle(Obstacle):
    """A segment from ``a`` to ``b`` (a thin bar)."""

    KIND = "segment"
    KERNEL_KIND = 1

    def __init__(self, name: str, a, b, velocity=(0.0, 0.0)):
        super().__init__(name, velocity)
        self.a = _vec2(a, f"obstacles.{name}.a")
        self.b = _vec2(b, f"obstacles.{name}.b")
        if np.allclose(self.a, self.b):
            raise InputError("segment end points must differ", key=f"obstacles.{name}.b")

    def closest(self, A: np.ndarray, t: float) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        A = np.asarray(A, dtype=float)
        a = self.a + self.velocity * t
        ab = self.b - self.a
        s = np.clip(((A - a) @ ab) / (ab @ ab), 0.0, 1.0)
        B = a + s[:, None] * ab
        dist, u = self._from_diff(A - B)
        return B[:, None, :], dist[:, None], u[:, None, :]

    def primitives(self) -> np.ndarray:
        return np.array([[self.KERNEL_KIND, *self.a, *self.b, 0.0, *self.velocity]])


class DiskObstacle(Obstacle):
    """A disk of centre ``center`` and radius ``radius`` in [m]."""

    KIND = "disk"
    KERNEL_KIND = 2

    def __init__(self, name: str, center, radius: float, velocity=(0.0, 0.0)):
        super().__init__(name, velocity)
        self.center = _vec2(center, f"obstacles.{name}.center")
        if not radius > 0:
            raise InputError(
                f"radius must be > 0 [m], got {radius}", key=f"obstacles.{name}.radius"
            )
        self.radius = float(radius)

    def closest(self, A: np.ndarray, t: float) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        A = np.asarray(A, dtype=float)
        c = self.center + self.velocity * t
        dist, u = self._from_diff(A - c, self.radius)
        B = c + self.radius * u
        return B[:, None, :], dist[:, None], u[:, None, :]

    def primitives(self) -> np.ndarray:
        return np.array([[self.KERNEL_KIND, *self.center, 0.0, 0.0, self.radius, *self.velocity]])


class PointCloudObstacle(Obstacle):
    """A set of points ``B_1..B_m`` in [m] (paper section 2.2: obstacles as key points)."""

    KIND = "points"
    KERNEL_KIND = 3

    def __init__(self, name: str, points, velocity=(0.0, 0.0)):
        super().__init__(name, velocity)
        pts = np.asarray(points, dtype=float)
        if pts.ndim != 2 or pts.shape[1] != 2 or pts.shape[0] < 1 or not np.all(np.isfinite(pts)):
            raise InputError(
                f"expected a list of [x, y] points, got {points!r}", key=f"obstacles.{name}.points"
            )
        self.points = pts
        self.n_points = pts.shape[0]

    def closest(self, A: np.ndarray, t: float) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        A = np.asarray(A, dtype=float)
        B = np.broadcast_to(self.points + self.velocity * t, (A.shape[0], self.n_points, 2)).copy()
        dist, u = self._from_diff(A[:, None, :] - B)
        return B, dist, u

    def primitives(self) -> np.ndarray:
        m = self.n_points
        rows = np.zeros((m, PRIMITIVE_WIDTH))
        rows[:, 0] = self.KERNEL_KIND
        rows[:, 1:3] = self.points
        rows[:, 6:8] = self.velocity
        return rows


#: Obstacle kind name (as written in scenario files) -> class.
OBSTACLE_KINDS: dict[str, type[Obstacle]] = {
    cls.KIND: cls for cls in (LineObstacle, SegmentObstacle, DiskObstacle, PointCloudObstacle)
}
