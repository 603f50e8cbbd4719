"""Generated planar arms for the scaling study: n links, key points, a start in contact.

Link lengths sum to :data:`REACH` (the paper arm's 1.0 m): ``l_i = REACH w_i / sum(w)``, ``w_i``
uniform in [0.5, 1.5]. Key points: the paper's rule generalised (``p`` per link and the joints
J2..Jn, ``a = n p + n - 1``; ``p = 1``, ``n = 4``: A1..A7). The start puts the end effector at rest
in contact (paper eq. 4: ``x_d(0) + (Fd / Kp) n``), so the first QPs are feasible: a bent arc of
equal relative angles ``c`` (bisection on the reach, ``|c| <= 2 pi / n`` keeps the joints within
+-3 rad for n >= 4), turned onto the target by the first joint.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from ..exceptions import ParamError
from ..robot.kinematics import KeyPoints, PlanarArm, default_key_points

#: Sum of the link lengths of every generated arm in [m] (the paper arm's reach).
REACH = 1.0
#: Joint-angle limits in [rad] (the paper's, for every joint).
THETA_LIMIT = 3.0
#: Joint-velocity limits in [rad/s] (the paper's, for every joint).
VELOCITY_LIMIT = 1.0


@dataclass
class GeneratedArm:
    """An arm (lengths [m]), its key points, a start ``theta0`` [rad] in contact at ``target`` [m]."""

    arm: PlanarArm
    key_points: KeyPoints
    theta0: np.ndarray
    target: np.ndarray

    def key_point_positions(self, theta: np.ndarray | None = None) -> np.ndarray:
        """Key-point positions in [m], shape (a, 2), at ``theta`` (default ``theta0``)."""
        theta = self.theta0 if theta is None else theta
        return self.arm.points(theta, self.key_points.links, self.key_points.fracs)


def link_lengths(n: int, seed: int = 0, reach: float = REACH) -> np.ndarray:
    """Link lengths in [m] summing to ``reach``, ``l_i`` proportional to uniform [0.5, 1.5] draws."""
    rng = np.random.default_rng([int(seed), int(n), 7919])
    w = rng.uniform(0.5, 1.5, size=int(n))
    return reach * w / w.sum()


def _reach_at(lengths: np.ndarray, c: float) -> float:
    arm = PlanarArm(lengths)
    theta = np.full(lengths.size, c)
    theta[0] = 0.0
    return float(np.hypot(*arm.end_effector(theta)))


def bent_arm_angles(lengths: np.ndarray, target: np.ndarray) -> np.ndarray:
    """Joint angles [rad] of the bent arc reaching ``target`` [m] exactly (module docstring).

    Raises:
        ParamError: ``target`` is out of reach (farther than the arm's length
            or nearer than the tightest arc with ``|c| <= 2 pi / n``).
    """
    lengths = np.asarray(lengths, dtype=float)
    n = lengths.size
    target = np.asarray(target, dtype=float)
    dist = float(np.hypot(*target))
    lo, hi = 0.0, 2.0 * math.pi / n * 0.95
    if not _reach_at(lengths, hi) < dist < _reach_at(lengths, lo):
        raise ParamError(
            f"target {target.tolist()} m is out of reach of a bent {n}-link arm", key="target"
        )
    for _ in range(100):  # the reach falls monotonically as the arc bends on [0, 2 pi / n)
        mid = 0.5 * (lo + hi)
        if _reach_at(lengths, mid) > dist:
            lo = mid
        else:
            hi = mid
    theta = np.full(n, 0.5 * (lo + hi))
    theta[0] = 0.0
    ee = PlanarArm(lengths).end_effector(theta)
    theta[0] = math.atan2(target[1], target[0]) - math.atan2(ee[1], ee[0])
    theta[0] = math.remainder(theta[0], 2.0 * math.pi)
    return theta


def generate_arm(
    links: int, points_per_link: int, target: np.ndarray, seed: int = 0
) -> GeneratedArm:
    """The arm of ``links`` links with ``points_per_link`` key points per link besides the joints
    J2..Jn, lengths drawn from ``seed``, its end effector at ``target`` [m] (module docstring)."""
    lengths = link_lengths(links, seed)
    arm = PlanarArm(lengths)
    theta0 = bent_arm_angles(lengths, target)
    if np.any(np.abs(theta0) > THETA_LIMIT):
        raise ParamError(
            f"start angles {theta0.tolist()} leave the joint limits +-{THETA_LIMIT} rad",
            key="theta0",
        )
    key_points = default_key_points(links, points_per_link, include_joints=True)
    return GeneratedArm(arm, key_points, theta0, arm.end_effector(theta0))
