"""The whole body: exact clearance of the arm's link capsules to the obstacles.

Link i is the segment ``p[i] -> p[i+1]`` swollen by the link radius ``r`` (``[key_points]
link_radius``); its clearance to an obstacle is the exact signed distance of the segment to the
shape minus ``r`` [m] (``< 0``: inside, by that depth). A static ``line`` obstacle that is the
contact surface (:func:`contact_obstacles`) is exempt for the end effector's link, which presses
into it by design; the closest-point key points use the same exemption.
"""

from __future__ import annotations

from typing import NamedTuple

import numpy as np

from .environment import ContactSurface, LineObstacle, Obstacle
from .kinematics import PlanarArm

#: Tolerance of "the same line" (an obstacle recognised as the contact surface) [m, rad].
SAME_LINE_TOL = 1e-9


def contact_obstacles(obstacles: list[Obstacle], surface: ContactSurface) -> list[bool]:
    """For each obstacle: it is the contact surface (a static ``line`` through its point, free
    side against the pressing direction)."""
    return [
        isinstance(o, LineObstacle)
        and not np.any(o.velocity)
        and float(o.normal @ surface.normal) <= -1.0 + SAME_LINE_TOL
        and abs(float(o.normal @ (surface.point - o.point))) <= SAME_LINE_TOL
        for o in obstacles
    ]


def link_label(link: int, n: int) -> str:
    """``"link 4 (end effector)"`` for the last of ``n`` links (1-based ``link``), else ``"link 2"``."""
    return f"link {link} (end effector)" if link == n else f"link {link}"


class BodyClearance(NamedTuple):
    """Clearance ``d`` (T, n, o) [m] of every link to every obstacle per tick (``+inf`` where
    exempt); per tick its smallest ``d_min`` [m] (NaN without obstacles), that one's 1-based
    ``link`` (0 without) and ``obstacle`` index (-1 without)."""

    d: np.ndarray
    d_min: np.ndarray
    link: np.ndarray
    obstacle: np.ndarray


def body_clearance(
    arm: PlanarArm,
    theta: np.ndarray,
    t: np.ndarray,
    obstacles: list[Obstacle],
    radius: float = 0.0,
    exempt: list[bool] | None = None,
) -> BodyClearance:
    """Clearance of the arm's capsules of ``radius`` [m] at joint angles ``theta`` (T, n) [rad]
    and times ``t`` (T,) [s]; ``exempt``: per obstacle, the end effector's link is not judged."""
    theta = np.atleast_2d(np.asarray(theta, dtype=float))
    T, n = theta.shape
    t = np.broadcast_to(np.asarray(t, dtype=float), (T,))
    d = np.empty((T, n, len(obstacles)))
    if not obstacles or T == 0:
        none = np.zeros(T, dtype=np.int64)
        return BodyClearance(d, np.full(T, np.nan), none, none - 1)
    p = arm.joint_positions(theta)
    P0 = p[:, :-1].reshape(-1, 2)
    P1 = p[:, 1:].reshape(-1, 2)
    ts = np.repeat(t, n)
    for j, o in enumerate(obstacles):
        _, _, dist, _ = o.closest_on_segments(P0, P1, ts)
        d[:, :, j] = dist.min(axis=1).reshape(T, n) - radius
        if exempt is not None and exempt[j]:
            d[:, n - 1, j] = np.inf
    flat = d.reshape(T, -1)
    arg = np.argmin(np.where(np.isnan(flat), -np.inf, flat), axis=1)
    m = len(obstacles)
    return BodyClearance(d, flat[np.arange(T), arg], arg // m + 1, arg % m)
