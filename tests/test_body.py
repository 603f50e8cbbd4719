"""The whole body: exact capsule clearances against brute force, the contact-surface exemption,
the closest-point obstacle rows, and the verdict on the body in closed loop."""

from __future__ import annotations

import numpy as np
import pytest

from qpbench.robot.body import body_clearance, contact_obstacles, link_label
from qpbench.robot.environment import (
    ContactSurface,
    DiskObstacle,
    LineObstacle,
    PointCloudObstacle,
    SegmentObstacle,
)
from qpbench.robot.kinematics import PlanarArm

SAMPLES = 4001

OBSTACLES = {
    "line": LineObstacle("wall", [-0.05, 0.1], [1.0, 0.2]),
    "line_moving": LineObstacle("wall", [0.3, 0.0], [-1.0, 0.0], velocity=[-0.04, 0.0]),
    "segment": SegmentObstacle("bar", [0.1, 0.3], [0.5, 0.45]),
    "segment_moving": SegmentObstacle("bar", [0.0, 0.8], [0.4, 0.2], velocity=[0.03, -0.02]),
    "disk": DiskObstacle("blob", [0.35, 0.45], 0.12),
    "disk_moving": DiskObstacle("blob", [0.5, 0.1], 0.1, velocity=[-0.04, 0.03]),
    "points": PointCloudObstacle("cloud", [[0.2, 0.5], [0.45, 0.3], [0.0, 0.7]]),
    "points_moving": PointCloudObstacle(
        "cloud", [[0.2, 0.5], [0.45, 0.3], [0.0, 0.7]], velocity=[0.02, -0.05]
    ),
}


def _brute(arm, theta, t, obstacle, radius):
    """Per link: the smallest point distance over SAMPLES points of the link [m], radius subtracted."""
    n = arm.n
    fracs = np.linspace(0.0, 1.0, SAMPLES)
    out = np.empty(n)
    for i in range(n):
        pts = arm.points(theta, np.full(SAMPLES, i), fracs)
        _, dist, _ = obstacle.closest(pts, t)
        if isinstance(obstacle, SegmentObstacle):  # unsigned point-to-segment distance
            dist = np.abs(dist)
        out[i] = dist.min() - radius
    return out


def _configurations(seed=0, count=40):
    rng = np.random.default_rng(seed)
    return rng.uniform(-2.0, 2.0, (count, 4)), rng.uniform(0.0, 5.0, count)


@pytest.mark.parametrize("name", sorted(OBSTACLES))
@pytest.mark.parametrize("radius", [0.0, 0.02])
def test_capsule_clearance_matches_dense_sampling(name, radius):
    """Every obstacle kind, moving or not, with and without a link radius: the exact clearance
    is the minimum over dense samples of each link (to the sampling step), never above it."""
    arm = PlanarArm([0.3, 0.4, 0.15, 0.15])
    obstacle = OBSTACLES[name]
    theta, t = _configurations()
    body = body_clearance(arm, theta, t, [obstacle], radius)
    step = arm.lengths.max() / (SAMPLES - 1)
    crossed = 0
    for k in range(len(t)):
        brute = _brute(arm, theta[k], t[k], obstacle, radius)
        exact = body.d[k, :, 0]
        if isinstance(obstacle, SegmentObstacle):
            # a link crossing the bar has a negative clearance (its depth); the samples see 0
            crossing = exact < -radius
            crossed += int(crossing.sum())
            np.testing.assert_allclose(exact[~crossing], brute[~crossing], atol=step)
            np.testing.assert_allclose(brute[crossing], -radius, atol=step)
        else:
            np.testing.assert_allclose(exact, brute, atol=step)
            assert np.all(exact <= brute + 1e-12)
    assert body.d.shape == (len(t), 4, 1)
    assert np.all(body.d_min == body.d.min(axis=(1, 2)))


def test_configurations_reach_inside_every_shape():
    """The random configurations above do test penetration: some links are inside each shape."""
    arm = PlanarArm([0.3, 0.4, 0.15, 0.15])
    theta, t = _configurations()
    for name, obstacle in OBSTACLES.items():
        if isinstance(obstacle, PointCloudObstacle):
            continue  # a cloud point has no inside
        d = body_clearance(arm, theta, t, [obstacle]).d
        assert (d < 0).any() and (d > 0).any(), name


def test_crossing_bar_depth_is_the_shortest_way_out():
    """A link crossing a bar: minus the smallest distance of an end of one to the other."""
    bar = SegmentObstacle("bar", [0.3, -0.1], [0.3, 0.5])
    A, B, dist, u = bar.closest_on_segments(np.array([[0.0, 0.0]]), np.array([[1.0, 0.0]]), 0.0)
    assert dist[0, 0] == pytest.approx(-0.1)  # the bar's end (0.3, -0.1) is 0.1 below the link
    np.testing.assert_allclose(A[0, 0], [0.3, 0.0])
    np.testing.assert_allclose(B[0, 0], [0.3, -0.1])
    np.testing.assert_allclose(u[0, 0], [0.0, -1.0])  # the link comes free moving down
    # moved 0.1 down, the link touches the bar's end: distance 0, continuous
    _, _, dist, _ = bar.closest_on_segments(np.array([[0.0, -0.1]]), np.array([[1.0, -0.1]]), 0.0)
    assert dist[0, 0] == pytest.approx(0.0, abs=1e-15)


def test_body_clearance_names_the_closest_link_and_obstacle():
    arm = PlanarArm([0.3, 0.4, 0.15, 0.15])
    theta = np.array([[np.pi / 2, -np.pi / 2, 0.0, 0.0]])  # up 0.3, then along +x to x = 0.7
    disk = DiskObstacle("blob", [0.7, 0.3], 0.03)  # centred on the end effector
    wall = LineObstacle("wall", [-0.05, 0.0], [1.0, 0.0])
    body = body_clearance(arm, theta, [0.0], [wall, disk], radius=0.0)
    assert body.d_min[0] == pytest.approx(-0.03)
    assert body.link[0] == 4 and body.obstacle[0] == 1
    assert body.d[0, 0, 0] == pytest.approx(0.05)  # link 1 is on x = 0, 0.05 from the wall
    assert link_label(4, 4) == "link 4 (end effector)" and link_label(2, 4) == "link 2"
    empty = body_clearance(arm, theta, [0.0], [])
    assert np.isnan(empty.d_min[0]) and empty.link[0] == 0


def test_the_contact_surface_is_exempt_for_the_end_effector_link_only():
    """narrow's lower line is the contact surface: its end effector's link is not judged against
    it, every other link is; a parallel line elsewhere, or one facing the other way, is an obstacle."""
    surface = ContactSurface([0.8, -0.15], [0.0, -1.0], 5000.0, 50.0)
    lower = LineObstacle("lower", [0.0, -0.15], [0.0, 1.0])
    upper = LineObstacle("upper", [0.0, 0.15], [0.0, -1.0])
    shifted = LineObstacle("shifted", [0.0, -0.14], [0.0, 1.0])
    moving = LineObstacle("moving", [0.0, -0.15], [0.0, 1.0], velocity=[0.0, 0.01])
    disk = DiskObstacle("d", [0.8, -0.15], 0.01)
    assert contact_obstacles([lower, upper, shifted, moving, disk], surface) == [
        True,
        False,
        False,
        False,
        False,
    ]
    arm = PlanarArm([0.3, 0.4, 0.15, 0.15])
    theta = np.array([[0.0, 0.0, -0.5, 0.4]])
    body = body_clearance(arm, theta, [0.0], [lower], exempt=[True])
    assert body.d[0, 3, 0] == np.inf
    plain = body_clearance(arm, theta, [0.0], [lower])
    np.testing.assert_array_equal(body.d[0, :3, 0], plain.d[0, :3, 0])
