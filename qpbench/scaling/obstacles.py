"""Point-cloud obstacles beside a generated arm, approaching it (scaling study).

As in the paper (section 2.2, obstacles as key points ``B_j``; eqs. 8-10) every (key point, cloud
point) pair is one velocity-damper row, every tick: ``a`` key points and ``m`` points give ``a m``
rows (a fixed count, as a persistent solver needs). The cloud fills a disk of :data:`CLOUD_RADIUS`
on the outer side of the arm at its middle key point, ``d_safe + clearance`` away, and approaches
at ``speed`` [m/s]: its rows start inactive and become active within the first tenths of a second,
so the dumped ticks hold both.
"""

from __future__ import annotations

import math

import numpy as np

from ..robot.environment import PointCloudObstacle
from .arms import GeneratedArm

#: Radius of the disk the cloud's points fill, in [m].
CLOUD_RADIUS = 0.03


def cloud_points(m: int, seed: int = 0, radius: float = CLOUD_RADIUS) -> np.ndarray:
    """``m`` points uniform over a disk of ``radius`` [m] centred at 0, shape (m, 2); one point: the centre."""
    if m == 1:
        return np.zeros((1, 2))
    rng = np.random.default_rng([int(seed), int(m), 104729])
    r = radius * np.sqrt(rng.uniform(0.0, 1.0, m))
    a = rng.uniform(0.0, 2.0 * math.pi, m)
    return np.stack([r * np.cos(a), r * np.sin(a)], axis=1)


def min_key_point_distance(key_xy: np.ndarray, points: np.ndarray) -> float:
    """Smallest distance in [m] between key points (a, 2) and cloud points (m, 2)."""
    best = math.inf
    for chunk in np.array_split(points, max(1, points.shape[0] // 256)):
        d = np.sqrt(((key_xy[:, None, :] - chunk[None, :, :]) ** 2).sum(axis=2))
        best = min(best, float(d.min()))
    return best


def _outer_normal(gen: GeneratedArm, i: int) -> np.ndarray:
    """Unit normal at key point ``i`` pointing away from the chord base -> end effector."""
    xy = gen.key_point_positions()
    link = int(gen.key_points.links[i])
    phi = float(np.cumsum(gen.theta0)[link])
    normal = np.array([-math.sin(phi), math.cos(phi)])
    chord = gen.target / np.linalg.norm(gen.target)
    side = xy[i] - (xy[i] @ chord) * chord  # the key point's offset from the chord
    return normal if normal @ side >= 0 else -normal


def _clear_offset(
    xy: np.ndarray, anchor: np.ndarray, u: np.ndarray, pts: np.ndarray, want: float
) -> float:
    """Smallest offset along ``u`` (1 mm steps from the one that puts the cloud's point nearest
    the arm ``want`` away from ``anchor``) at which the arm clears the cloud by ``want``."""
    offset = want + float(np.max(-(pts @ u)))
    for _ in range(2000):
        if min_key_point_distance(xy, anchor + offset * u + pts) >= want:
            return offset
        offset += 0.001
    raise RuntimeError(
        "no clear place for the cloud"
    )  # pragma: no cover - 2 m of steps clear a 1 m arm


def place_cloud(
    gen: GeneratedArm,
    points: int,
    d_safe: float,
    seed: int = 0,
    clearance: float = 0.015,
    speed: float = 0.1,
) -> PointCloudObstacle:
    """A cloud of ``points`` points (drawn from ``seed``) beside ``gen`` at ``theta0``, every key
    point ``d_safe + clearance`` [m] from it: stepped outwards by 1 mm along the middle key point's
    outer (or inner) normal until the arm clears it, the side needing the smaller step; it moves
    towards the arm at ``speed`` [m/s]."""
    xy = gen.key_point_positions()
    i = len(gen.key_points) // 2
    u = _outer_normal(gen, i)
    pts = cloud_points(points, seed)
    want = d_safe + clearance
    offset, side = min(
        (_clear_offset(xy, xy[i], s * u, pts, want), k) for k, s in enumerate((1.0, -1.0))
    )
    u = u if side == 0 else -u
    return PointCloudObstacle("cloud", xy[i] + offset * u + pts, velocity=-speed * u)
