"""Planar serial chain: forward kinematics, Jacobians and key points (paper sections 2.1, 2.2).

``theta[k]`` is the relative angle of joint k [rad]; link i's absolute angle is
``phi[i] = sum(theta[:i+1])``. Joint positions (eq. 1)::

    p[0] = 0,   p[i+1] = p[i] + l[i] [cos phi[i], sin phi[i]]

The end effector is ``p[n]``. A point ``x`` on link i has the Jacobian (eqs. 2, 7b) whose column
k <= i is ``[-(x - p[k])_y, (x - p[k])_x]`` and whose columns k > i are zero. A point on a link
is ``(link, frac)``: ``x = p[link] + frac * l[link] [cos phi, sin phi]`` (``frac = 1``: the next
joint). Vectorised numpy; :mod:`qpbench.control.build_kernel` repeats the maths compiled.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..exceptions import InputError

#: The kinds of key points (``[key_points] kind``; :class:`KeyPoints`).
KEY_POINT_KINDS = ("paper", "closest")


class PlanarArm:
    """A planar serial chain of revolute joints with link ``lengths`` (n,) [m], n >= 2."""

    def __init__(self, lengths):
        lengths = np.asarray(lengths, dtype=float)
        ok = (
            lengths.ndim == 1 and lengths.size >= 2 and np.all(np.isfinite(lengths) & (lengths > 0))
        )
        if not ok:
            raise InputError(
                f"a planar arm needs at least 2 finite link lengths > 0 [m], got {lengths.tolist()}",
                key="robot.link_lengths",
            )
        self.lengths = lengths
        self.n = lengths.size

    def absolute_angles(self, theta: np.ndarray) -> np.ndarray:
        """``phi[i] = sum(theta[:i+1])`` in [rad], shape (..., n)."""
        return np.cumsum(np.asarray(theta, dtype=float), axis=-1)

    def joint_positions(self, theta: np.ndarray) -> np.ndarray:
        """Positions of the base, the joints and the end effector [m], shape (..., n+1, 2), at
        joint angles ``theta`` of shape (..., n) [rad]."""
        phi = self.absolute_angles(theta)
        seg = self.lengths[:, None] * np.stack([np.cos(phi), np.sin(phi)], axis=-1)
        p = np.zeros((*phi.shape[:-1], self.n + 1, 2))
        np.cumsum(seg, axis=-2, out=p[..., 1:, :])
        return p

    def end_effector(self, theta: np.ndarray) -> np.ndarray:
        """End-effector position ``x = f(theta)`` (eq. 1) in [m], shape (2,)."""
        return self.joint_positions(theta)[-1]

    def points(self, theta: np.ndarray, links: np.ndarray, fracs: np.ndarray) -> np.ndarray:
        """Positions of points ``(links[j], fracs[j])`` in [m], shape (a, 2)."""
        links = np.asarray(links, dtype=int)
        fracs = np.asarray(fracs, dtype=float)
        phi = self.absolute_angles(theta)
        p = self.joint_positions(theta)
        d = np.stack([np.cos(phi[links]), np.sin(phi[links])], axis=1)
        return p[links] + (fracs * self.lengths[links])[:, None] * d

    def points_jacobians(
        self, theta: np.ndarray, links: np.ndarray, fracs: np.ndarray
    ) -> tuple[np.ndarray, np.ndarray]:
        """Positions (a, 2) in [m] and Jacobians (a, 2, n) in [m/rad] of points on links (eq. 7b)."""
        links = np.asarray(links, dtype=int)
        x = self.points(theta, links, fracs)
        p = self.joint_positions(theta)[:-1]  # joint k's position, (n, 2)
        rel = x[:, None, :] - p[None, :, :]  # (a, n, 2)
        mask = (np.arange(self.n)[None, :] <= links[:, None]).astype(float)  # (a, n)
        J = np.empty((x.shape[0], 2, self.n))
        J[:, 0, :] = -rel[:, :, 1] * mask
        J[:, 1, :] = rel[:, :, 0] * mask
        return x, J


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
    n: int, points_per_link: int = 1, include_joints: bool = True, radius: float = 0.0
) -> KeyPoints:
    """Key points of an n-link chain, link by link: ``points_per_link`` evenly spaced points on
    each link (fractions ``j / (m + 1)``) and, with ``include_joints``, the joints J2..Jn;
    ``radius`` [m]. One point per link, n = 4: the paper's A1..A7 (no end effector)."""
    if points_per_link < 0:
        raise InputError(f"must be >= 0, got {points_per_link}", key="key_points.points_per_link")
    links, fracs = [], []
    for i in range(n):
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
