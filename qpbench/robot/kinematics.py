"""The arm's kinematics as numpy functions of joint angles, and the points kept away from
obstacles (paper sections 2.1, 2.2): :class:`Arm` is a serial chain (:mod:`qpbench.robot.chain`:
its equations, points ``(link, frac)`` on links and their Jacobians, eqs. 1, 2, 7b);
:class:`PlanarArm` the paper's planar arm of link lengths, a chain of that kind.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..exceptions import InputError
from .chain import (
    ChainModel,
    forward_kinematics_np,
    planar_chain,
    points_jacobians_np,
    positions_many,
)


class Arm:
    """A serial chain of n revolute joints (:class:`~qpbench.robot.chain.ChainModel`) with
    positions and Jacobians of ``dim`` rows (2: planar, 3: spatial)."""

    def __init__(self, model: ChainModel):
        self.model = model
        self.n = model.n
        self.dim = model.dim
        #: Link lengths [m] (n,): joint to joint, the last to the end effector.
        self.lengths = model.lengths

    def joint_positions(self, theta: np.ndarray) -> np.ndarray:
        """Positions of the joints and the end effector [m], shape (..., n+1, dim), at joint
        angles ``theta`` of shape (..., n) [rad] (row 0: joint 0, fixed to the base)."""
        theta = np.asarray(theta, dtype=float)
        if theta.ndim == 2:  # a run's log: compiled, one configuration after another
            return positions_many(self.model, theta)[..., : self.dim]
        return forward_kinematics_np(self.model, theta).position[..., : self.dim]

    def end_effector(self, theta: np.ndarray) -> np.ndarray:
        """End-effector position ``x = f(theta)`` (eq. 1) in [m], shape (..., dim)."""
        return self.joint_positions(theta)[..., -1, :]

    def points(self, theta: np.ndarray, links: np.ndarray, fracs: np.ndarray) -> np.ndarray:
        """Positions of points ``(links[j], fracs[j])`` in [m], shape (a, dim)."""
        links = np.asarray(links, dtype=int)
        fracs = np.asarray(fracs, dtype=float)
        p = self.joint_positions(theta)
        return p[links] + fracs[:, None] * (p[links + 1] - p[links])

    def points_jacobians(
        self, theta: np.ndarray, links: np.ndarray, fracs: np.ndarray
    ) -> tuple[np.ndarray, np.ndarray]:
        """Positions (a, dim) in [m] and Jacobians (a, dim, n) in [m/rad] of points on links
        (eq. 7b)."""
        x, J = points_jacobians_np(self.model, theta, links, fracs)
        return x[:, : self.dim], J


class PlanarArm(Arm):
    """The planar arm of link ``lengths`` (n,) [m], n >= 2 (:func:`~qpbench.robot.chain.planar_chain`)."""

    def __init__(self, lengths):
        super().__init__(planar_chain(lengths))


@dataclass(frozen=True)
class KeyPoints:
    """Points of the robot kept away from obstacles (paper sections 2.2, 4.1).

    ``kind`` ``paper``: fixed points ``(links, fracs)`` named ``A1..Aa`` (:func:`default_key_points`);
    ``closest``: each link's point closest to each obstacle, found anew every tick (``L1..Ln``;
    ``fracs`` the midpoints, for pictures). Distances are from the link's surface: ``|A - B| -
    radius`` [m].
    """

    links: np.ndarray
    fracs: np.ndarray
    names: tuple[str, ...]
    radius: float = 0.0
    kind: str = "paper"

    def __len__(self) -> int:
        return int(self.links.size)


def default_key_points(
    n: int,
    points_per_link: int = 1,
    include_joints: bool = True,
    radius: float = 0.0,
    lengths=None,
) -> KeyPoints:
    """Key points of an n-link chain, link by link: ``points_per_link`` evenly spaced points on
    each link (fractions ``j / (m + 1)``) and, with ``include_joints``, the joints J2..Jn;
    ``radius`` [m]. With link ``lengths`` [m] (a spatial chain's, whose joints can share an
    origin), a link of zero length has none (its points are the previous link's end). One point
    per link, n = 4: the paper's A1..A7 (no end effector)."""
    if points_per_link < 0:
        raise InputError(f"must be >= 0, got {points_per_link}", key="key_points.points_per_link")
    links, fracs = [], []
    for i in range(n):
        if lengths is not None and lengths[i] < 1e-12:
            continue
        for j in range(1, points_per_link + 1):
            links.append(i)
            fracs.append(j / (points_per_link + 1))
        if include_joints and i < n - 1:
            links.append(i)
            fracs.append(1.0)
    if not links:
        raise InputError(
            "no key points: points_per_link = 0 and include_joints = false",
            key="key_points.points_per_link",
        )
    names = tuple(f"A{i + 1}" for i in range(len(links)))
    return KeyPoints(
        np.array(links, dtype=np.int64), np.array(fracs, dtype=float), names, float(radius)
    )


def closest_key_points(n: int, radius: float = 0.0) -> KeyPoints:
    """Closest-point key points of an n-link chain (one per link, ``L1..Ln``, the end effector's
    link included; ``radius`` [m])."""
    return KeyPoints(
        np.arange(n, dtype=np.int64),
        np.full(n, 0.5),
        tuple(f"L{i + 1}" for i in range(n)),
        float(radius),
        "closest",
    )
