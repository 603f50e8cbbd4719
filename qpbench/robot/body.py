"""The whole body: exact clearance of the arm's link capsules to the obstacles.

The arm is a chain of capsules: link i is the segment from joint ``p[i]`` to
``p[i+1]`` (the last one ends at the end effector) swollen by the link radius
``r`` (``[key_points] link_radius``). The clearance of link i to an obstacle is
the exact signed distance of its segment to the obstacle's shape
(:meth:`qpbench.robot.environment.Obstacle.closest_on_segments`) minus ``r``
[m]: ``< 0`` means the capsule is inside the obstacle, by that depth. The
smallest over the obstacle's points is the link's clearance to it.

The contact surface is the task, not an obstacle: a ``line`` obstacle that
is the contact surface (the same line, its free side against the pressing
direction, as the lower line of ``narrow``) is exempt for the end effector's
link, which presses into it by design; every other link is judged against it
(:func:`contact_obstacles`). The controller's closest-point obstacle rows
(``[key_points] kind = "closest"``) use the same exemption.
"""

from __future__ import annotations

import numpy as np

from .environment import ContactSurface, LineObstacle, Obstacle
from .kinematics import PlanarArm

__all__ = ["BodyClearance", "body_clearance", "contact_obstacles", "link_label"]

#: Tolerance of "the same line" when an obstacle is recognised as the contact surface [m, rad].
SAME_LINE_TOL = 1e-9


def contact_obstacles(obstacles: list[Obstacle], surface: ContactSurface) -> list[bool]:
    """For each obstacle: it is the contact surface (a static ``line`` through the surface's
    point whose free side faces against the pressing direction ``surface.normal``)."""
    out = []
    for o in obstacles:
        same = (
            isinstance(o, LineObstacle)
            and not np.any(o.velocity)
            and float(o.normal @ surface.normal) <= -1.0 + SAME_LINE_TOL
            and abs(float(o.normal @ (surface.point - o.point))) <= SAME_LINE_TOL
        )
        out.append(bool(same))
    return out


def link_label(link: int, n: int) -> str:
    """``"link 4 (end effector)"`` for the last of ``n`` links (1-based ``link``), else ``"link 2"``."""
    return f"link {link} (end effector)" if link == n else f"link {link}"


class BodyClearance:
    """Clearance of every link to every obstacle at a series of ticks.

    Attributes:
        d: ``(T, n, o)`` signed clearance [m] of link i to obstacle j at tick k
            (``+inf`` where exempt: the end effector's link against the contact surface).
        d_min: ``(T,)`` the smallest over links and obstacles [m] (``nan`` without obstacles).
        link: ``(T,)`` the 1-based link of ``d_min`` (0 without obstacles).
        obstacle: ``(T,)`` index of its obstacle (-1 without obstacles).
    """

    def __init__(self, d: np.ndarray):
        self.d = d
        T, n, o = d.shape
        if o == 0 or T == 0:
            self.d_min = np.full(T, np.nan)
            self.link = np.zeros(T, dtype=np.int64)
            self.obstacle = np.full(T, -1, dtype=np.int64)
            return
        flat = d.reshape(T, n * o)
        filled = np.where(np.isnan(flat), -np.inf, flat)
        arg = np.argmin(filled, axis=1)
        self.d_min = flat[np.arange(T), arg]
        self.link = arg // o + 1
        self.obstacle = arg % o


def body_clearance(
    arm: PlanarArm,
    theta: np.ndarray,
    t: np.ndarray,
    obstacles: list[Obstacle],
    radius: float = 0.0,
    exempt: list[bool] | None = None,
) -> BodyClearance:
    """Clearance of the arm's capsules at joint angles ``theta`` (T, n) [rad] and times ``t`` (T,) [s].

    Args:
        arm: The robot.
        theta: Joint angles per tick [rad].
        t: The ticks' times [s] (moving obstacles' positions).
        obstacles: The obstacles.
        radius: Link radius [m].
        exempt: Per obstacle, the end effector's link is not judged against it
            (:func:`contact_obstacles`).
    """
    theta = np.atleast_2d(np.asarray(theta, dtype=float))
    T, n = theta.shape
    t = np.broadcast_to(np.asarray(t, dtype=float), (T,))
    d = np.empty((T, n, len(obstacles)))
    if not obstacles or T == 0:
        return BodyClearance(d)
    phi = np.cumsum(theta, axis=1)
    seg = arm.lengths[None, :, None] * np.stack([np.cos(phi), np.sin(phi)], axis=2)
    p = np.zeros((T, n + 1, 2))
    np.cumsum(seg, axis=1, out=p[:, 1:])
    P0 = p[:, :-1].reshape(-1, 2)
    P1 = p[:, 1:].reshape(-1, 2)
    ts = np.repeat(t, n)
    for j, o in enumerate(obstacles):
        _, _, dist, _ = o.closest_on_segments(P0, P1, ts)
        d[:, :, j] = dist.min(axis=1).reshape(T, n) - radius
        if exempt is not None and exempt[j]:
            d[:, n - 1, j] = np.inf
    return BodyClearance(d)
