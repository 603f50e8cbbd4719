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


# ---------------------------------------------------------------- closest-point obstacle rows


def _closest_controller(name="moving_disk"):
    from qpbench.sim.scenario import load_scenario

    scenario = load_scenario(name, overrides={"key_points.kind": "closest"})
    return scenario, scenario.make_controller()


def test_closest_rows_are_the_gradient_of_the_capsule_clearance():
    """Each closest-point row is minus the gradient of its link's clearance (finite differences),
    its h the damper of that clearance, its distance the exact capsule clearance."""
    from qpbench.sim.scenario import load_scenario

    scenario = load_scenario(
        "moving_disk", overrides={"key_points.kind": "closest", "key_points.link_radius": 0.01}
    )
    ctrl = scenario.make_controller()
    rng = np.random.default_rng(3)
    for _ in range(5):
        theta, t = rng.uniform(-1.5, 1.5, 4), float(rng.uniform(0, 10))
        tick = ctrl.build(theta, t)
        G, h = tick.problem.G, tick.problem.h
        assert G.shape == (4, 4)  # one row per link against the one disk
        body = body_clearance(ctrl.arm, theta[None], [t], ctrl.obstacles, 0.01).d[0, :, 0]
        np.testing.assert_allclose(tick.distances[:, 0], body, atol=1e-12)
        eps = 1e-7
        for k in range(4):
            step = np.zeros(4)
            step[k] = eps
            up = body_clearance(ctrl.arm, (theta + step)[None], [t], ctrl.obstacles, 0.01)
            down = body_clearance(ctrl.arm, (theta - step)[None], [t], ctrl.obstacles, 0.01)
            grad = (up.d[0, :, 0] - down.d[0, :, 0]) / (2 * eps)
            np.testing.assert_allclose(-G[:, k], grad, atol=1e-5)
        disk = ctrl.obstacles[0]
        u = -G[:, :]  # noqa: F841 - rows checked above; h: k (d - d_safe) - u . velocity
        _, _, _, un = disk.closest_on_segments(
            ctrl.arm.joint_positions(theta)[:-1], ctrl.arm.joint_positions(theta)[1:], t
        )
        expect = ctrl.k * (body - ctrl.d_safe) - un[:, 0, :] @ disk.velocity
        np.testing.assert_allclose(h, expect, atol=1e-12)


def test_closest_rows_leave_out_the_end_effector_link_against_the_contact_surface():
    """narrow: the end effector presses into the lower line; its link has rows against the upper
    line only; every other link has rows against both. Paper key points keep every pair."""
    from qpbench.sim.scenario import load_scenario

    _, ctrl = _closest_controller("narrow")
    assert ctrl.exempt == [False, True]
    assert [(a, o) for a, o, _ in ctrl.obstacle_columns()] == [
        ("L1", "upper"),
        ("L1", "lower"),
        ("L2", "upper"),
        ("L2", "lower"),
        ("L3", "upper"),
        ("L3", "lower"),
        ("L4", "upper"),
    ]
    scenario = load_scenario("narrow", overrides={"key_points.kind": "closest"})
    tick = ctrl.build(scenario.theta0, 0.0)
    assert tick.problem.G.shape == (7, 4) and ctrl.n_rows == 7
    assert tick.distances[3, 1] == np.inf  # no row: the contact surface
    paper = load_scenario("narrow").make_controller()
    assert paper.n_rows == 14 and not paper.closest


def test_closest_is_settable_and_checked(tmp_path, capsys):
    from qpbench.cli import main
    from qpbench.exceptions import ScenarioError
    from qpbench.sim.scenario import load_scenario

    assert load_scenario("wall").make_key_points().kind == "paper"
    with pytest.raises(ScenarioError, match="key_points.kind"):
        load_scenario("wall", overrides={"key_points.kind": "nearest"})
    code = main(
        [
            "closed-loop",
            "--scenarios",
            "wall",
            "--backends",
            "daqp",
            "--out",
            str(tmp_path / "cl"),
            "--set",
            "key_points.kind=nearest",
        ]
    )
    assert code == 2 and not (tmp_path / "cl").exists()
    assert "key_points.kind" in capsys.readouterr().err


# ---------------------------------------------------------------- the shipped scenarios, in the loop


def test_disk_on_path_paper_drives_the_end_effector_through_the_disk():
    """The paper's key points never include the end effector: with an exact solver it passes
    through the disk's centre (t = pi s), 30 mm deep, every key point 10 mm clear."""
    from qpbench.sim.loop import simulate
    from qpbench.sim.scenario import load_scenario

    scenario = load_scenario("disk_on_path", overrides={"simulation.duration": 3.5})
    assert scenario.in_paper is False
    s = simulate(scenario, "daqp").summary
    assert s["verdict"] == "unsafe"
    assert s["verdict_reasons"].startswith(
        "link 4 (end effector) 30.0 mm inside disk 'blob' at 3.14 s"
    )
    assert s["min_body_distance"] == pytest.approx(-0.03, abs=1e-4)
    assert (s["min_body_distance_link"], s["min_body_distance_obstacle"]) == (4, "blob")
    assert s["key_point_rule"] == "held" and s["min_obstacle_distance"] > 0.0095


def test_disk_on_path_closest_keeps_the_body_out_and_the_task_goes_infeasible():
    """Closest-point rows: the end effector stops at the disk (body clear), the task runs into it,
    so the paper QP is infeasible there (soft fallback) and tracking is lost."""
    from qpbench.sim.loop import simulate
    from qpbench.sim.scenario import load_scenario

    scenario = load_scenario(
        "disk_on_path",
        overrides={"simulation.duration": 3.5, "key_points.kind": "closest"},
    )
    r = simulate(scenario, "daqp")
    s = r.summary
    assert s["key_points_kind"] == "closest"
    assert s["min_body_distance"] > 0.0095 and s["key_point_rule"] == "held"
    late = [iv for iv in s["infeasible_intervals"] if iv[0] > 1.0]
    assert late and s["fallback_ticks"] == s["infeasible_ticks"]
    assert s["verdict"] == "diverged"
    assert (r.log["d_body_min"] >= 0).all()


@pytest.mark.parametrize("kind", ["paper", "closest"])
def test_moving_disk(kind):
    """A disk crossing link 2 between key points: by 10 s the paper's key points let it 15+ mm
    into the link, every key point clear; closest-point rows keep the whole body d_safe away,
    the task held."""
    from qpbench.sim.loop import simulate
    from qpbench.sim.scenario import load_scenario

    scenario = load_scenario(
        "moving_disk", overrides={"simulation.duration": 10.0, "key_points.kind": kind}
    )
    assert scenario.in_paper is False and scenario.make_obstacles()[0].velocity.any()
    s = simulate(scenario, "daqp").summary
    assert s["key_point_rule"] == "held"
    if kind == "paper":
        assert s["verdict"] == "unsafe" and s["min_body_distance"] < -0.015
        assert (
            s["verdict_reasons"].startswith("link 2 ")
            and "inside disk 'blob'" in (s["verdict_reasons"])
        )
    else:
        assert s["verdict"] == "ok", s["verdict_reasons"]
        assert s["min_body_distance"] > 0.0095 and s["infeasible_intervals"] == [[0.0, 0.114]]


def test_closest_ticks_export_and_bench(tmp_path):
    """The dumped QPs of a closest-point run are a problem set the bench runs."""
    import pandas as pd

    from qpbench.cli import main
    from qpbench.formats import read_problem_set
    from qpbench.sim.loop import simulate
    from qpbench.sim.scenario import load_scenario

    scenario = load_scenario("narrow", overrides={"key_points.kind": "closest"})
    simulate(scenario, "daqp", duration=0.05, every=5, dump=tmp_path / "set")
    ps = read_problem_set(tmp_path / "set")
    assert len(ps) == 10 and all(rec.problem.G.shape == (7, 4) for rec in ps)
    assert ps.manifest["extra"]["scenario_overrides"] == {"key_points.kind": "closest"}
    code = main(
        ["bench", str(tmp_path / "set"), "--backends", "daqp", "--out", str(tmp_path / "b")]
    )
    assert code in (0, 1)
    rows = pd.read_csv(tmp_path / "b")
    assert len(rows) == 10 and set(rows["backend"]) == {"daqp"}
