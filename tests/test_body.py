"""The whole body: exact capsule clearances against brute force, the contact-surface exemption,
the closest-point obstacle rows, the body between ticks against dense sub-steps of the same
motion, and the verdict on the body in closed loop."""

from __future__ import annotations

import numpy as np
import pytest

from qpbench.robot.body import body_clearance, body_crossings, contact_obstacles, link_label
from qpbench.robot.environment import ContactSurface
from qpbench.robot.kinematics import PlanarArm
from qpbench.robot.obstacles.disk import DiskObstacle
from qpbench.robot.obstacles.line import LineObstacle
from qpbench.robot.obstacles.points import PointCloudObstacle
from qpbench.robot.obstacles.segment import SegmentObstacle

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


# ---------------------------------------------------------------- between ticks

DT = 1e-3
#: Sub-steps of an interval in the dense references below.
REFERENCE_STEPS = 1000


def _interval_states(theta_a, theta_b, t_a, steps=REFERENCE_STEPS):
    """Joint angles (steps + 1, n) [rad] and times (steps + 1,) [s] evenly over one interval."""
    s = np.arange(steps + 1) / steps
    return theta_a + s[:, None] * (theta_b - theta_a), t_a + s * DT


def _dense_first_inside(arm, theta_a, theta_b, t_a, obstacle, radius=0.0):
    """The independent reference of a crossing: the first of the interval's sub-steps at which a
    link is inside the obstacle [s] (``None``: at none)."""
    theta, t = _interval_states(theta_a, theta_b, t_a)
    d_min = body_clearance(arm, theta, t, [obstacle], radius).d_min
    rows = np.flatnonzero(d_min < 0.0)
    return float(t[rows[0]]) if rows.size else None


def _dense_side_change(arm, theta_a, theta_b, t_a, cloud):
    """The sub-step ``[t_j, t_j+1]`` [s] in which a cloud point first changes sides of a link
    while projecting within it (the reference of a point through a link of no thickness)."""
    theta, t = _interval_states(theta_a, theta_b, t_a)
    p = arm.joint_positions(theta)
    C = cloud.points[None] + t[:, None, None] * cloud.velocity  # (steps + 1, m, 2)
    first = None
    for i in range(arm.n):
        e = (p[:, i + 1] - p[:, i])[:, None, :]
        r = C - p[:, i, None, :]
        side = e[..., 0] * r[..., 1] - e[..., 1] * r[..., 0]
        along = np.einsum("smi,smi->sm", r, e) / np.einsum("smi,smi->sm", e, e)
        within = (along >= 0.0) & (along <= 1.0)
        change = (side[:-1] * side[1:] < 0) & within[:-1] & within[1:]
        rows = np.flatnonzero(change.any(axis=1))
        if rows.size and (first is None or rows[0] < first):
            first = rows[0]
    return None if first is None else (float(t[first]), float(t[first + 1]))


def _still(theta, ticks=20):
    """A log of an arm holding ``theta``: angles (ticks, n) [rad], times (ticks,) [s]."""
    return np.tile(theta, (ticks, 1)), np.arange(ticks) * DT


ARM = PlanarArm([0.3, 0.4, 0.15, 0.15])
#: Link 1 up the y axis to (0, 0.3), links 2-4 along +x to (0.7, 0.3).
BENT = np.array([np.pi / 2, -np.pi / 2, 0.0, 0.0])


@pytest.mark.parametrize("radius", [0.0, 0.01])
@pytest.mark.parametrize("gap,disk", [(0.010, 0.002), (0.0005, 0.0001), (0.03, 0.02)])
def test_a_fast_disk_through_a_link_between_ticks_is_found_when_it_went_in(radius, gap, disk):
    """A disk ``gap`` [m] short of link 2 at tick 10 and as far past it at tick 11: clear at every
    tick, inside between; found at the dense reference's first inside sub-step, to one sub-step."""
    theta, t = _still(BENT)
    speed = (2 * gap + 2 * disk + 2 * radius) / DT
    start = 0.3 - radius - disk - gap - 10 * DT * speed
    blob = DiskObstacle("blob", [0.2, start], disk, velocity=[0.0, speed])
    body = body_clearance(ARM, theta, t, [blob], radius)
    assert body.d_min.min() == pytest.approx(gap)  # clear at every tick by the gap
    found = body_crossings(ARM, theta, t, DT, [blob], radius, d_min=body.d_min)
    assert found.tick.tolist() == [10] and found.link.tolist() == [2]
    reference = _dense_first_inside(ARM, BENT, BENT, t[10], blob, radius)
    assert reference - DT / REFERENCE_STEPS <= found.t[0] <= reference + 1e-12


def test_a_point_swept_by_a_zero_radius_link_is_found_where_it_changes_sides():
    """Link 4 turning at 3 rad/s over a point of a cloud: no thickness, so the point is never
    inside at a sample; it passes through the link between ticks 10 and 11."""
    v = np.array([0.0, 0.0, 0.0, 3.0])
    theta = BENT + np.arange(20)[:, None] * DT * v
    t = np.arange(20) * DT
    angle = 10.3 * DT * 3.0  # the link's angle 0.3 of the way from tick 10 to tick 11
    point = [0.55 + 0.1 * np.cos(angle), 0.3 + 0.1 * np.sin(angle)]
    cloud = PointCloudObstacle("cloud", [[0.3, 0.9], point])
    assert body_clearance(ARM, theta, t, [cloud]).d_min.min() >= 0.0
    found = body_crossings(ARM, theta, t, DT, [cloud], theta_end=theta[-1] + DT * v)
    assert found.tick.tolist() == [10] and found.link.tolist() == [4]
    lo, hi = _dense_side_change(ARM, theta[10], theta[11], t[10], cloud)
    assert lo <= found.t[0] <= hi
    assert found.t[0] == pytest.approx(10.3 * DT, abs=1e-9)


def test_a_moving_point_through_a_still_link():
    """A cloud point at 20 m/s through link 2, 10.13 and 9.87 mm from it at ticks 10 and 11."""
    theta, t = _still(BENT)
    cloud = PointCloudObstacle("cloud", [[0.2, 0.28987 - 10 * DT * 20.0]], velocity=[0.0, 20.0])
    found = body_crossings(ARM, theta, t, DT, [cloud])
    assert found.tick.tolist() == [10] and found.link.tolist() == [2]
    lo, hi = _dense_side_change(ARM, theta[10], theta[11], t[10], cloud)
    assert lo <= found.t[0] <= hi and found.t[0] == pytest.approx(10.5065 * DT, abs=1e-9)


def test_a_bar_through_a_link_and_a_link_dipping_into_a_wall_between_ticks():
    """A short bar flying through link 2; link 4 swinging so fast that its end dips 0.1 mm into
    a wall between two ticks at which it is 0.1 mm clear of it (a half-plane is never passed
    through, but it can be dipped into); both against the dense reference."""
    theta, t = _still(BENT)
    bar = SegmentObstacle("bar", [0.2, 0.28 - 10 * DT * 30], [0.2, 0.29 - 10 * DT * 30], [0, 30.0])
    found = body_crossings(ARM, theta, t, DT, [bar])
    assert found.tick.tolist() == [10] and found.link.tolist() == [2]
    reference = _dense_first_inside(ARM, BENT, BENT, t[10], bar)
    assert reference - DT / REFERENCE_STEPS <= found.t[0] <= reference + 1e-12
    # link 4 about J4 (0.55, 0.3) at 40 rad/s, symmetric about +x between ticks 10 and 11: its
    # end's arc bulges 0.15 (1 - cos 0.02) = 30 um beyond the chord at x = 0.55 + 0.15 cos 0.02
    v = np.array([0.0, 0.0, 0.0, 40.0])
    theta = BENT + (np.arange(20)[:, None] - 10.5) * DT * v
    x_chord = 0.55 + 0.15 * np.cos(0.02)
    wall = LineObstacle("wall", [x_chord + 2e-5, 0.0], [-1.0, 0.0])  # 20 um beyond the chord
    body = body_clearance(ARM, theta, t, [wall])
    assert body.d_min.min() > 0.0
    found = body_crossings(ARM, theta, t, DT, [wall], d_min=body.d_min)
    assert found.tick.tolist() == [10] and found.link.tolist() == [4]
    reference = _dense_first_inside(ARM, theta[10], theta[11], t[10], wall)
    assert reference - DT / REFERENCE_STEPS <= found.t[0] <= reference + 1e-12


@pytest.mark.parametrize(
    "obstacle",
    [
        # a fast disk crossing link 4's line 0.1 mm beyond its end (0.7, 0.3)
        DiskObstacle("blob", [0.7 + 0.002 + 1e-4, 0.25 - 10 * DT * 10], 0.002, [0.0, 10.0]),
        # a fast point crossing it 1 um beyond the end
        PointCloudObstacle("cloud", [[0.7 + 1e-6, 0.29 - 10 * DT * 20]], velocity=[0.0, 20.0]),
        # a point sliding along link 2, 1 nm off it
        PointCloudObstacle("cloud", [[0.05, 0.3 - 1e-9]], velocity=[20.0, 0.0]),
        # a bar passing 10 um beyond link 4's end
        SegmentObstacle("bar", [0.70001, 0.29 - 0.2], [0.70001, 0.295 - 0.2], velocity=[0, 20.0]),
    ],
)
def test_near_misses_between_ticks_stay_clear(obstacle):
    theta, t = _still(BENT)
    body = body_clearance(ARM, theta, t, [obstacle])
    assert body.d_min.min() >= 0.0
    found = body_crossings(ARM, theta, t, DT, [obstacle], theta_end=BENT, d_min=body.d_min)
    assert found.tick.size == 0
    for k in range(len(t)):  # the dense reference agrees: clear throughout
        assert _dense_first_inside(ARM, BENT, BENT, t[k], obstacle) is None
        if isinstance(obstacle, PointCloudObstacle):
            assert _dense_side_change(ARM, BENT, BENT, t[k], obstacle) is None


def test_a_link_swinging_past_a_point_or_turning_back_before_it_misses_it():
    """Link 4 turning at 3 rad/s over a point 1 nm beyond its end; link 4 turning up to 0.1 um
    short of a point on it at tick 10, and back: clear."""
    v = np.array([0.0, 0.0, 0.0, 3.0])
    theta = BENT + np.arange(20)[:, None] * DT * v
    t = np.arange(20) * DT
    angle = 10.3 * DT * 3.0
    beyond = 0.15 + 1e-9
    cloud = PointCloudObstacle(
        "cloud", [[0.55 + beyond * np.cos(angle), 0.3 + beyond * np.sin(angle)]]
    )
    assert body_crossings(ARM, theta, t, DT, [cloud], theta_end=theta[-1] + DT * v).tick.size == 0
    swing = BENT + (10 - np.abs(np.arange(20) - 10))[:, None] * DT * v  # up to tick 10, then down
    turn = 10 * DT * 3.0
    tip = np.array([0.55 + 0.1 * np.cos(turn), 0.3 + 0.1 * np.sin(turn)])
    cloud = PointCloudObstacle("cloud", [tip + 1e-7 * np.array([-np.sin(turn), np.cos(turn)])])
    assert body_clearance(ARM, swing, t, [cloud]).d_min.min() == pytest.approx(1e-7, abs=1e-12)
    assert body_crossings(ARM, swing, t, DT, [cloud], theta_end=swing[-2]).tick.size == 0


def _small_fast_obstacle(kind, rng, near):
    """A small obstacle of ``kind`` passing ``near`` [m] at t = 10 ms at 5-40 m/s (a shape of a
    few mm); a line through ``near``, at up to 1 m/s."""
    speed = rng.uniform(5.0, 40.0) * _direction(rng)
    at = near + rng.uniform(-0.005, 0.005, 2)
    start = at - 10 * DT * speed
    if kind == "disk":
        return DiskObstacle("o", start, rng.uniform(5e-4, 5e-3), velocity=speed)
    if kind == "points":
        return PointCloudObstacle("o", start + rng.uniform(-0.003, 0.003, (3, 2)), velocity=speed)
    if kind == "segment":
        return SegmentObstacle(
            "o", start, start + rng.uniform(0.002, 0.01) * _direction(rng), speed
        )
    return LineObstacle("o", near, _direction(rng), velocity=rng.uniform(0, 1) * _direction(rng))


def _direction(rng):
    a = rng.uniform(0.0, 2 * np.pi)
    return np.array([np.cos(a), np.sin(a)])


@pytest.mark.parametrize("kind", ["disk", "line", "points", "segment"])
def test_random_fast_motions_against_the_dense_reference(kind):
    """Joint speeds of 30 rad/s (sd) and a small obstacle of each kind flying through the arm
    at 5-40 m/s (a wall: across the arc of a link's end), radius 0 and 1 mm: every interval the dense
    reference finds inside (or a cloud point through a link) while the link was clear at both
    ticks is found, no later than the reference; at every time found, the link is inside (or,
    without thickness, on the point) to 1e-9 m; the same with the samples' clearance given."""
    rng = np.random.default_rng(7)
    checked = found_total = 0
    for trial in range(24):
        radius = (0.0, 0.001)[trial % 2]
        v = rng.normal(0.0, 30.0, (20, 4))
        theta = rng.uniform(-2, 2, 4) + np.vstack([np.zeros(4), np.cumsum(v[:-1] * DT, 0)])
        t = np.arange(20) * DT
        end = theta[-1] + DT * v[-1]
        link = rng.integers(0, 4)
        p = ARM.joint_positions(theta[10])
        near = p[link] + rng.uniform(0, 1) * (p[link + 1] - p[link])
        obstacle = _small_fast_obstacle(kind, rng, near)
        if kind == "line":  # a wall along the chord of the link end's arc, ticks 10 to 11
            half = ARM.joint_positions(theta[10] + 0.5 * DT * v[10])[link + 1]
            a, b = p[link + 1], ARM.joint_positions(theta[11])[link + 1]
            out = np.array([a[1] - b[1], b[0] - a[0]]) / np.linalg.norm(b - a)
            bulge = float(out @ (half - (a + b) / 2))  # how far the arc reaches past its chord
            out *= np.sign(bulge)
            wall = (a + b) / 2 + rng.uniform(0.0, 2.0) * abs(bulge) * out
            obstacle = LineObstacle("o", wall, -out)
        body = body_clearance(ARM, theta, t, [obstacle], radius)
        found = body_crossings(ARM, theta, t, DT, [obstacle], radius, theta_end=end)
        again = body_crossings(
            ARM, theta, t, DT, [obstacle], radius, theta_end=end, d_min=body.d_min
        )
        for a, b in zip(found, again):
            np.testing.assert_array_equal(a, b)
        at = dict(zip(found.tick.tolist(), zip(found.t.tolist(), found.link.tolist())))
        ends = np.vstack([theta[1:], end])
        for k in range(20):
            states, times = _interval_states(theta[k], ends[k], t[k])
            d = body_clearance(ARM, states, times, [obstacle], radius).d[:, :, 0]
            clear = (d[0] >= 0) & (d[-1] >= 0)
            inside = np.flatnonzero(((d < -1e-9) & clear).any(axis=1))
            first = times[inside[0]] if inside.size else None
            if kind == "points" and radius == 0.0:
                change = _dense_side_change(ARM, theta[k], ends[k], t[k], obstacle)
                first = None if change is None else change[1]
            if first is not None:
                checked += 1
                assert k in at and at[k][0] <= first + 1e-12, (trial, k, first)
            if k in at:
                found_total += 1
                tf, i = at[k]
                state = theta[k] + (tf - t[k]) / DT * (ends[k] - theta[k])
                depth = body_clearance(ARM, state[None], [tf], [obstacle], radius).d
                assert depth[0, i - 1, 0] <= 1e-9, (trial, k)
    assert found_total >= checked >= 5


@pytest.mark.parametrize("name", sorted(OBSTACLES))
def test_swept_distance_bound_is_below_the_sweep(name):
    """Each kind's bound on a segment swept with linearly moving ends is at most the smallest
    clearance over 2001 segments of the sweep (where it is positive, for a bar); the line's is
    that smallest clearance."""
    obstacle = OBSTACLES[name]
    rng = np.random.default_rng(11)
    s = 200
    P0a = rng.uniform(-0.2, 0.7, (s, 2))
    P1a = P0a + rng.uniform(-0.3, 0.3, (s, 2))
    scale = rng.choice([1e-4, 1e-2, 0.3], s)[:, None]
    P0b = P0a + scale * rng.normal(size=(s, 2))
    P1b = P1a + scale * rng.normal(size=(s, 2))
    t = rng.uniform(0.0, 2.0, s)
    bound = obstacle.swept_distance_bound(P0a, P1a, P0b, P1b, t)
    lam = np.linspace(0.0, 1.0, 2001)
    least = np.full(s, np.inf)
    for x in lam:
        dist = obstacle.closest_on_segments((1 - x) * P0a + x * P0b, (1 - x) * P1a + x * P1b, t)[2]
        least = np.minimum(least, dist.min(axis=1))
    # where positive, a bound; a segment's crossing depth is not bounded (only said: <= 0)
    assert np.all(bound <= np.maximum(least, 0.0) + 1e-12)
    if not isinstance(obstacle, SegmentObstacle):
        assert np.all(bound <= least + 1e-12)
    assert (bound > 0).any() and (least > 0).any() and (least < 0).any() != ("points" in name)
    if isinstance(obstacle, LineObstacle):
        np.testing.assert_allclose(bound, least, atol=1e-15)


# ---------------------------------------------------------------- between ticks, in the loop


def _wide_free(tmp_path, obstacles: str):
    """``free`` with joint speed limits of 50 rad/s (so that the pseudo-inverse keeps them) and
    ``obstacles`` (TOML) instead of none: a scenario file in ``tmp_path``."""
    import re

    from qpbench.sim.scenario import shipped_dir

    text = (shipped_dir() / "free.toml").read_text()
    for key, value in (("velocity_min", -50.0), ("velocity_max", 50.0)):
        text = re.sub(rf"^{key} = .*$", f"{key} = {[value] * 4}", text, flags=re.M)
    text = text.replace("obstacles = []", f"obstacles = {obstacles}", 1)
    path = tmp_path / "crossed.toml"
    path.write_text(text)
    return path


def _pinv_ticks(tmp_path, ticks=(200, 201)):
    """The pseudo-inverse's joint angles at ``ticks`` of the wide ``free`` (it ignores obstacles:
    the same with any)."""
    from qpbench.sim.log import theta_columns
    from qpbench.sim.loop import simulate
    from qpbench.sim.scenario import load_scenario

    log = simulate(load_scenario(_wide_free(tmp_path, "[]")), "pinv", duration=0.21).log
    assert log["v_0"].abs().max() < 50.0
    return [log[theta_columns(4)].to_numpy()[k] for k in ticks]


def _simulate_json(tmp_path, scenario, capsys):
    import json

    from conftest import simulate_args

    from qpbench.cli import main

    out = tmp_path / "s.json"
    code = main([*simulate_args(str(scenario), "pinv", "0.25"), "--summary", str(out)])
    err = capsys.readouterr().err
    assert out.exists(), err
    return code, json.loads(out.read_text())


def test_pinv_with_a_small_fast_disk_through_link_2_between_ticks_is_unsafe(tmp_path, capsys):
    """A 2 mm disk 10 mm short of link 2 at tick 200 and 10 mm past it at tick 201: the body is
    clear at every tick, the run is unsafe, exit 1, the crossing time that of the dense
    reference of the same motion."""
    a, b = _pinv_ticks(tmp_path)
    p = ARM.joint_positions(a)
    e = p[2] - p[1]
    normal = np.array([-e[1], e[0]]) / np.linalg.norm(e)
    radius, gap = 0.002, 0.010
    velocity = normal * (2 * gap + 2 * radius) / DT
    centre = (p[1] + p[2]) / 2 - normal * (gap + radius) - velocity * 0.2
    disk = DiskObstacle("bullet", centre, radius, velocity)
    toml = (
        f'[{{kind = "disk", name = "bullet", center = {centre.tolist()}, radius = {radius}, '
        f"velocity = {velocity.tolist()}}}]"
    )
    code, s = _simulate_json(tmp_path, _wide_free(tmp_path, toml), capsys)
    assert code == 1 and s["verdict"] == "unsafe"
    assert 0.0095 < s["min_body_distance"] < 0.0105  # clear at every tick
    assert s["body_crossings"] == 1 and s["body_crossing_link"] == 2
    assert s["body_crossing_obstacle"] == "bullet"
    reference = _dense_first_inside(ARM, a, b, 0.2, disk)
    assert reference - DT / REFERENCE_STEPS <= s["body_crossing_t"] <= reference + 1e-12
    assert s["verdict_reasons"].startswith(
        f"link 2 inside disk 'bullet' at {s['body_crossing_t']:.4f} s, between two ticks clear of it"
    )


def test_pinv_sweeping_link_2_over_a_point_is_unsafe(tmp_path, capsys):
    """A point of a cloud on link 2 (radius 0) 0.3737 of the way from tick 200 to 201: a link
    without thickness is never inside at a tick; the run is unsafe, exit 1, at the time the
    point changes sides in the dense reference."""
    a, b = _pinv_ticks(tmp_path)
    between = ARM.joint_positions(a + 0.3737 * (b - a))
    point = (between[1] + between[2]) / 2
    cloud = PointCloudObstacle("cloud", [point, [-0.5, -0.5]])
    toml = f'[{{kind = "points", name = "cloud", points = {cloud.points.tolist()}, velocity = [0, 0]}}]'
    code, s = _simulate_json(tmp_path, _wide_free(tmp_path, toml), capsys)
    assert code == 1 and s["verdict"] == "unsafe"
    assert s["min_body_distance"] >= 0.0  # never inside at a tick
    assert s["body_crossings"] >= 1 and s["body_crossing_link"] == 2
    lo, hi = _dense_side_change(ARM, a, b, 0.2, cloud)
    assert lo <= s["body_crossing_t"] <= hi
    assert s["body_crossing_t"] == pytest.approx(0.2 + 0.3737 * DT, abs=2e-6)
    assert "link 2 inside points 'cloud' at 0.2004 s, between two ticks" in s["verdict_reasons"]


def _shipped_daqp_verdicts():
    """The shipped run's verdict of DAQP on each scenario (``results/closed_loop.csv``)."""
    from pathlib import Path

    import pandas as pd

    rows = pd.read_csv(Path(__file__).resolve().parents[1] / "results" / "closed_loop.csv")
    daqp = rows[(rows["backend"] == "daqp") & (rows["formulation"] == "paper")]
    return dict(zip(daqp["scenario"], daqp["verdict"]))


@pytest.mark.parametrize("name", ["wall", "narrow"])
def test_shipped_scenarios_with_daqp_have_no_crossing(name):
    """The first 3 s of two shipped scenarios: no crossing between ticks, the verdict as shipped."""
    from qpbench.sim.loop import simulate
    from qpbench.sim.scenario import load_scenario

    s = simulate(load_scenario(name), "daqp", duration=3.0).summary
    assert s["body_crossings"] == 0 and s["body_crossing_t"] is None
    assert s["verdict"] == _shipped_daqp_verdicts()[name] == "ok"


@pytest.mark.slow
def test_shipped_runs_with_daqp_keep_their_verdicts():
    """Every scenario of the shipped run, 20 s with DAQP: the verdicts of
    ``results/closed_loop.csv``, no crossing between ticks."""
    from qpbench.sim.loop import simulate
    from qpbench.sim.scenario import load_scenario

    shipped = _shipped_daqp_verdicts()
    assert len(shipped) == 8
    for name, verdict in shipped.items():
        s = simulate(load_scenario(name), "daqp").summary
        assert (s["verdict"], s["body_crossings"]) == (verdict, 0), (name, s["verdict_reasons"])
