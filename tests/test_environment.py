"""Contact surface and obstacles: force law, closest points (vs brute force), distance gradients."""

from __future__ import annotations

import numpy as np
import pytest

from qpbench.exceptions import InputError
from qpbench.robot.environment import ContactSurface
from qpbench.robot.obstacles.disk import DiskObstacle
from qpbench.robot.obstacles.line import LineObstacle
from qpbench.robot.obstacles.points import PointCloudObstacle
from qpbench.robot.obstacles.segment import SegmentObstacle


def penetration(surface, x) -> float:
    """``delta = n . (x - point)`` [m] (positive inside the surface)."""
    return float(surface.normal @ (np.asarray(x, dtype=float) - surface.point))


def contact_force(surface, x, xdot) -> float:
    """The contact force [N] a sensor reads (paper eq. 3 as the environment's law, noise
    included): the numpy oracle of the tick kernel's compiled force law."""
    n = surface.normal
    delta = penetration(surface, x)
    f = 0.0
    if delta > 0.0:
        f = max(0.0, surface.stiffness * delta + surface.damping * float(n @ np.asarray(xdot)))
    return f + surface.noise()


def test_contact_force_law():
    s = ContactSurface([0.4, 0.5], [1.0, -1.0], 5000.0, 50.0)
    n = np.array([1.0, -1.0]) / np.sqrt(2)
    np.testing.assert_allclose(s.normal, n)
    x0 = np.array([0.4, 0.5])
    assert contact_force(s, x0 - 0.01 * n, [0, 0]) == 0.0  # outside
    assert contact_force(s, x0 + 0.004 * n, [0, 0]) == pytest.approx(20.0)  # Kp_env * delta
    assert contact_force(s, x0 + 0.004 * n, 0.1 * n) == pytest.approx(25.0)  # + Kd_env * deltadot
    assert contact_force(s, x0 + 0.004 * n, -1.0 * n) == 0.0  # pulling out fast: never negative
    # tangential motion adds nothing
    t = np.array([n[1], -n[0]])
    assert contact_force(s, x0 + 0.004 * n, 3.0 * t) == pytest.approx(20.0)
    assert penetration(s, x0 + 0.004 * n) == pytest.approx(0.004)


def test_force_noise_is_seeded():
    a = ContactSurface([0, 0], [0, -1], 5000.0, 50.0, noise_std=0.5, seed=7)
    b = ContactSurface([0, 0], [0, -1], 5000.0, 50.0, noise_std=0.5, seed=7)
    fa = [contact_force(a, [0, -0.004], [0, 0]) for _ in range(2000)]
    fb = [contact_force(b, [0, -0.004], [0, 0]) for _ in range(2000)]
    assert fa == fb
    assert np.mean(fa) == pytest.approx(20.0, abs=0.05)
    assert np.std(fa) == pytest.approx(0.5, rel=0.1)
    a.reset()
    assert [contact_force(a, [0, -0.004], [0, 0]) for _ in range(3)] == fa[:3]


def brute_force_distance(sample_points, A):
    return np.min(np.linalg.norm(sample_points - A, axis=1))


OBSTACLES = [
    (
        SegmentObstacle("seg", [0.1, 0.2], [0.4, -0.1], velocity=[0.05, -0.02]),
        lambda t: np.linspace([0.1, 0.2], [0.4, -0.1], 20001) + np.array([0.05, -0.02]) * t,
    ),
    (
        DiskObstacle("disk", [0.3, 0.1], 0.07, velocity=[-0.1, 0.0]),
        lambda t: (
            np.array([0.3, 0.1])
            + np.array([-0.1, 0.0]) * t
            + 0.07 * np.stack([np.cos(a := np.linspace(0, 2 * np.pi, 40001)), np.sin(a)], axis=1)
        ),
    ),
]


@pytest.mark.parametrize("obstacle,samples", OBSTACLES, ids=["segment", "disk"])
def test_closest_point_matches_brute_force(obstacle, samples):
    rng = np.random.default_rng(3)
    A = rng.uniform(-0.3, 0.8, (40, 2))
    for t in (0.0, 1.5):
        B, dist, u = obstacle.closest(A, t)
        S = samples(t)
        for i in range(len(A)):
            d_ref = brute_force_distance(S, A[i])
            if (
                isinstance(obstacle, DiskObstacle)
                and np.linalg.norm(A[i] - obstacle.center - obstacle.velocity * t) < obstacle.radius
            ):
                continue  # inside the disk: distance is negative by design
            assert dist[i, 0] == pytest.approx(d_ref, abs=2e-5)
            # B is the closest point: on the shape, |A - B| = dist
            assert np.linalg.norm(A[i] - B[i, 0]) == pytest.approx(dist[i, 0], abs=1e-12)


@pytest.mark.parametrize(
    "obstacle",
    [
        LineObstacle("wall", [-0.05, 0.0], [1.0, 0.0], velocity=[0.1, 0.0]),
        LineObstacle("slanted", [0.0, 0.3], [1.0, -2.0]),
        SegmentObstacle("seg", [0.1, 0.2], [0.4, -0.1], velocity=[0.05, -0.02]),
        DiskObstacle("disk", [0.3, 0.1], 0.07),
        PointCloudObstacle("cloud", [[0.0, 0.5], [0.2, -0.3], [0.6, 0.6]], velocity=[0.0, 0.2]),
    ],
    ids=lambda o: o.name,
)
def test_u_is_the_distance_gradient_and_velocity_term(obstacle):
    """``u`` = d dist / dA (finite differences) and d dist/dt at fixed A = -u . Bdot."""
    rng = np.random.default_rng(5)
    A = rng.uniform(-0.3, 0.8, (25, 2))
    h = 1e-6
    _, dist, u = obstacle.closest(A, 0.7)
    for axis in range(2):
        e = np.zeros(2)
        e[axis] = h
        _, dp, _ = obstacle.closest(A + e, 0.7)
        _, dm, _ = obstacle.closest(A - e, 0.7)
        np.testing.assert_allclose((dp - dm) / (2 * h), u[:, :, axis], atol=1e-6)
    _, dp, _ = obstacle.closest(A, 0.7 + h)
    _, dm, _ = obstacle.closest(A, 0.7 - h)
    np.testing.assert_allclose((dp - dm) / (2 * h), -(u @ obstacle.velocity), atol=1e-6)
    assert dist.shape == (25, obstacle.n_points)


def test_line_distance_is_signed():
    wall = LineObstacle("wall", [-0.05, 0.0], [1.0, 0.0])
    _, d, _ = wall.closest(np.array([[0.1, 0.3], [-0.2, 0.0]]), 0.0)
    np.testing.assert_allclose(d[:, 0], [0.15, -0.15])


def test_obstacle_input_errors():
    with pytest.raises(InputError, match="normal"):
        LineObstacle("w", [0, 0], [0, 0])
    with pytest.raises(InputError, match="radius"):
        DiskObstacle("d", [0, 0], 0.0)
    with pytest.raises(InputError, match="points"):
        PointCloudObstacle("c", [[0, 0, 0]])
    with pytest.raises(InputError, match="stiffness"):
        ContactSurface([0, 0], [0, 1], 0.0, 1.0)
