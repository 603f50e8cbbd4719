"""The obstacle kinds: the table's layout, the compiled distance of every kind to a segment
against brute force (dense samples of the segment and of the shape's surface), finite
differences of its gradient, coal where installed and the planar kinds' distances as they
always were; the schemas' one-line errors; the body rule between ticks in 3-D."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import obstacles_numpy as planar_reference
import pytest
from scipy.spatial import cKDTree

from qpbench.exceptions import InputError, ScenarioError
from qpbench.robot import obstacles
from qpbench.robot.body import body_clearance, body_crossings
from qpbench.robot.obstacles.box import BoxObstacle
from qpbench.robot.obstacles.capsule import CapsuleObstacle
from qpbench.robot.obstacles.disk import DiskObstacle
from qpbench.robot.obstacles.line import LineObstacle
from qpbench.robot.obstacles.plane import PlaneObstacle
from qpbench.robot.obstacles.points import PointCloudObstacle
from qpbench.robot.obstacles.segment import SegmentObstacle
from qpbench.robot.obstacles.sphere import SphereObstacle

QUAT = np.array([0.9, 0.2, -0.3, 0.25]) / np.linalg.norm([0.9, 0.2, -0.3, 0.25])
SPATIAL = {
    "sphere": SphereObstacle("ball", [0.1, -0.05, 0.2], 0.12, velocity=[0.02, 0.0, -0.03]),
    "capsule": CapsuleObstacle("rod", [-0.2, 0.1, 0.0], [0.25, -0.1, 0.3], 0.06),
    "bar": CapsuleObstacle("bar", [-0.2, 0.1, 0.0], [0.25, -0.1, 0.3], velocity=[0.0, 0.05, 0.0]),
    "box": BoxObstacle("crate", [0.05, 0.0, 0.1], [0.15, 0.08, 0.2], QUAT, velocity=[0, 0, 0.04]),
    "plane": PlaneObstacle("floor", [0.0, 0.0, -0.1], [0.2, -0.3, 1.0]),
}
T = 0.5  # [s]: every obstacle has moved by half its velocity


def _segments(seed: int, count: int = 60, spread: float = 0.45, through=(0.0, 0.0, 0.15)):
    """Random segments (count, 3) [m] about the obstacles, every fifth a point, some parallel to
    the capsule's axis, every fourth through the point ``through`` [m]."""
    rng = np.random.default_rng(seed)
    a = rng.uniform(-spread, spread, (count, 3))
    b = a + rng.normal(0.0, 0.2, (count, 3))
    b[2::4] = 2 * np.asarray(through) - a[2::4]
    b[::5] = a[::5]
    axis = np.array([0.45, -0.2, 0.3])
    b[1::7] = a[1::7] + rng.uniform(-1, 1, (len(a[1::7]), 1)) * axis
    return a, b


def _signed_point_distance(obstacle, X, t):
    """Exact signed distance [m] of points ``X`` (k, 3) to a shape, from its own formula."""
    shift = t * obstacle.velocity3
    if isinstance(obstacle, SphereObstacle):
        return np.linalg.norm(X - obstacle.center - shift, axis=1) - obstacle.radius
    if isinstance(obstacle, CapsuleObstacle):
        a, e = obstacle.a + shift, obstacle.b - obstacle.a
        w = np.clip((X - a) @ e / (e @ e), 0.0, 1.0)
        return np.linalg.norm(X - a - w[:, None] * e, axis=1) - obstacle.radius
    if isinstance(obstacle, BoxObstacle):
        q = np.abs((X - obstacle.center - shift) @ obstacle.rotation()) - obstacle.half_extents
        outside = np.linalg.norm(np.maximum(q, 0.0), axis=1)
        return np.where(outside > 0, outside, np.max(np.minimum(q, 0.0), axis=1))
    return (X - obstacle.point - shift) @ obstacle.normal


def _surface(obstacle, t, n=60000):
    """Points densely on the shape's surface at ``t`` [s] (a plane: its patch near the origin;
    a bar: its axis, 5,000 points)."""
    rng = np.random.default_rng(0)
    shift = t * obstacle.velocity3
    if isinstance(obstacle, PlaneObstacle):
        u = np.cross(obstacle.normal, [1.0, 0, 0])
        u /= np.linalg.norm(u)
        v = np.cross(obstacle.normal, u)
        g = np.linspace(-0.9, 0.9, 400)
        G = np.stack(np.meshgrid(g, g), -1).reshape(-1, 2)
        return obstacle.point + shift + G[:, :1] * u + G[:, 1:] * v
    if isinstance(obstacle, BoxObstacle):
        pts = rng.uniform(-1, 1, (n, 3))
        face = rng.integers(0, 3, n)
        pts[np.arange(n), face] = np.sign(pts[np.arange(n), face])
        return obstacle.center + shift + (pts * obstacle.half_extents) @ obstacle.rotation().T
    d = rng.normal(size=(n, 3))
    d /= np.linalg.norm(d, axis=1)[:, None]
    if isinstance(obstacle, SphereObstacle):
        return obstacle.center + shift + obstacle.radius * d
    a, e = obstacle.a + shift, obstacle.b - obstacle.a
    if obstacle.radius == 0.0:
        return a + np.linspace(0.0, 1.0, 5000)[:, None] * e
    # a capsule: its cylinder (directions across the axis) and its two half-spheres
    along = d @ e / (e @ e)
    across = d - along[:, None] * e
    across /= np.linalg.norm(across, axis=1)[:, None]
    w = rng.uniform(0, 1, (n, 1))
    cylinder = a + w * e + obstacle.radius * across
    caps = np.where((along < 0)[:, None], a, a + e) + obstacle.radius * d
    return np.vstack([cylinder, caps])


def _distance(obstacle, a, b, t):
    """The compiled distance of the obstacle's (one) row: ``(d, u, s)``."""
    fn = obstacles.compiled_segment_distance()
    u = np.empty(len(a))
    d, s = fn(obstacle.primitives()[0], np.asarray(a, float), np.asarray(b, float), t, u)
    return d, u, s


def test_the_table_keeps_the_planar_columns_and_codes():
    """The first eight columns and the four planar codes mean what the planar build reads; the
    3-D columns follow; a planar kind fills z = 0 and the identity orientation."""
    assert obstacles.OBSTACLE_COLUMNS[:8] == (
        "kind",
        "p0x",
        "p0y",
        "p1x",
        "p1y",
        "radius",
        "vx",
        "vy",
    )
    assert (obstacles.LINE, obstacles.SEGMENT, obstacles.DISK, obstacles.POINT) == (0, 1, 2, 3)
    assert len(obstacles.OBSTACLE_COLUMNS) == 18 and obstacles.OBSTACLE_COLUMNS[8:11] == (
        "p0z",
        "p1z",
        "vz",
    )
    rows = np.vstack(
        [
            LineObstacle("w", [-0.05, 0.1], [3.0, 4.0], velocity=[0.1, 0.2]).primitives(),
            SegmentObstacle("s", [0.1, 0.2], [0.4, -0.1], velocity=[0.05, -0.02]).primitives(),
            DiskObstacle("d", [0.3, 0.1], 0.07, velocity=[-0.1, 0.0]).primitives(),
            PointCloudObstacle("c", [[0.0, 0.5], [0.2, -0.3]], velocity=[0.0, 0.2]).primitives(),
        ]
    )
    planar = [
        [0, -0.05, 0.1, 0.6, 0.8, 0.0, 0.1, 0.2],
        [1, 0.1, 0.2, 0.4, -0.1, 0.0, 0.05, -0.02],
        [2, 0.3, 0.1, 0.0, 0.0, 0.07, -0.1, 0.0],
        [3, 0.0, 0.5, 0.0, 0.0, 0.0, 0.0, 0.2],
        [3, 0.2, -0.3, 0.0, 0.0, 0.0, 0.0, 0.2],
    ]
    np.testing.assert_array_equal(rows[:, :8], planar)
    np.testing.assert_array_equal(rows[:, 8:], np.tile([0.0] * 6 + [1.0, 0, 0, 0], (5, 1)))
    box = SPATIAL["box"].primitives()[0]
    assert box[obstacles.KIND] == obstacles.BOX and box[obstacles.VZ] == 0.04
    np.testing.assert_allclose(box[[obstacles.HX, obstacles.HY, obstacles.HZ]], [0.15, 0.08, 0.2])
    np.testing.assert_allclose(box[obstacles.QW : obstacles.QZ + 1], QUAT)


PLANAR = [
    (LineObstacle("w", [-0.05, 0.1], [1.0, 0.2], velocity=[0.1, 0.0]), "line"),
    (SegmentObstacle("s", [0.1, 0.2], [0.4, -0.1], velocity=[0.05, -0.02]), "segment"),
    (DiskObstacle("d", [0.3, 0.1], 0.07, velocity=[-0.1, 0.0]), "disk"),
    (PointCloudObstacle("c", [[0.0, 0.5], [0.2, -0.3], [0.3, 0.1]], velocity=[0.0, 0.2]), "points"),
]


@pytest.mark.parametrize("obstacle,kind", PLANAR, ids=[k for _, k in PLANAR])
def test_planar_kinds_give_the_distances_they_always_gave(obstacle, kind):
    """The planar kinds through the shared 3-D geometry give the planar formulas' closest
    points, distances and directions (crossing bars, centres on links and points included),
    for 2-D and for 3-D inputs in z = 0."""
    rng = np.random.default_rng(7)
    P0 = rng.uniform(-0.3, 0.7, (300, 2))
    P1 = P0 + rng.normal(0.0, 0.3, (300, 2))
    P1[::9] = P0[::9]
    P0[3], P1[3] = [0.3 - 0.1 * 0.7, 0.0], [0.3 - 0.1 * 0.7, 0.3]  # through the disk's centre
    shift = T * obstacle.velocity
    if kind == "line":
        A, d, u = planar_reference.line(obstacle.point + shift, obstacle.normal, P0, P1)
    elif kind == "segment":
        A, d, u = planar_reference.segment(obstacle.a + shift, obstacle.b + shift, P0, P1)
    elif kind == "disk":
        A, d, u = planar_reference.disk(obstacle.center + shift, obstacle.radius, P0, P1)
    else:
        A, d, u = planar_reference.points(obstacle.points + shift, P0, P1)
    got_A, _, got_d, got_u = obstacle.closest_on_segments(P0, P1, T)
    np.testing.assert_allclose(got_d, d, rtol=0, atol=1e-14)
    np.testing.assert_allclose(got_u, u, rtol=0, atol=1e-14)
    np.testing.assert_allclose(got_A, A, rtol=0, atol=1e-14)
    if kind == "segment":
        assert (d < 0).any()  # crossing bars were tested
    zeros = np.zeros((len(P0), 1))
    _, _, d3, u3 = obstacle.closest_on_segments(np.hstack([P0, zeros]), np.hstack([P1, zeros]), T)
    np.testing.assert_array_equal(d3, got_d)
    np.testing.assert_array_equal(u3[..., :2], got_u)
    assert not np.any(u3[..., 2])


@pytest.mark.parametrize("name", sorted(SPATIAL))
def test_spatial_distance_against_brute_force(name):
    """Against dense samples of the segment (2,001) and of the surface (60,000 points, the sign
    from the shape's inside): the signed distance to within the samples' spacing; and exactly
    (to rounding) the least of the shape's own point distance over the segment's samples,
    attained at the returned ``s``, with the closest point on the obstacle at ``-d`` along
    ``u``."""
    obstacle = SPATIAL[name]
    tree = cKDTree(_surface(obstacle, T), balanced_tree=False, compact_nodes=False)
    fracs = np.linspace(0.0, 1.0, 2001)
    a, b = _segments(1)
    inside_seen = False
    for k in range(len(a)):
        X = a[k] + fracs[:, None] * (b[k] - a[k])
        d, u, s = _distance(obstacle, a[k], b[k], T)
        exact = _signed_point_distance(obstacle, X, T)
        sampled = tree.query(X)[0] * np.sign(exact)
        inside_seen |= d < 0
        assert d == pytest.approx(sampled.min(), abs=4e-3)
        assert d <= exact.min() + 1e-12
        x = a[k] + s * (b[k] - a[k])
        assert _signed_point_distance(obstacle, x[None], T)[0] == pytest.approx(d, abs=1e-12)
        assert np.linalg.norm(u) == pytest.approx(1.0)
        if d > 1e-9 and name != "plane":  # the obstacle's point nearest x, at d along -u
            assert _signed_point_distance(obstacle, (x - d * u)[None], T)[0] == pytest.approx(
                0.0, abs=1e-9
            )
    assert inside_seen or name in ("bar", "plane")


@pytest.mark.parametrize("name", sorted(SPATIAL))
def test_spatial_gradient_is_the_finite_difference(name):
    """``u`` is the derivative of the distance in the segment's translation, and ``-u . v`` its
    derivative in time (where the distance is smooth: outside, and inside a smooth shape)."""
    obstacle = SPATIAL[name]
    a, b = _segments(2)
    h, checked = 1e-6, 0
    for k in range(len(a)):
        d, u, _ = _distance(obstacle, a[k], b[k], T)
        if abs(d) < 1e-4 or (name == "box" and d < 0):  # the deepest point of a box: a kink
            continue
        fd = np.empty(3)
        for i in range(3):
            e = np.eye(3)[i] * h
            fd[i] = (
                _distance(obstacle, a[k] + e, b[k] + e, T)[0]
                - _distance(obstacle, a[k] - e, b[k] - e, T)[0]
            ) / (2 * h)
        np.testing.assert_allclose(fd, u, atol=2e-6)
        dt = (
            _distance(obstacle, a[k], b[k], T + h)[0] - _distance(obstacle, a[k], b[k], T - h)[0]
        ) / (2 * h)
        assert dt == pytest.approx(-u @ obstacle.velocity3, abs=2e-6)
        checked += 1
    assert checked >= 30


def test_a_segment_inside_a_box_reports_its_deepest_point():
    """A segment through an axis-aligned box: minus the depth of its deepest point (the centre,
    nearest the thin faces), ``u`` that face's outward normal."""
    box = BoxObstacle("b", [0.0, 0.0, 0.0], [0.3, 0.1, 0.2])
    d, u, s = _distance(box, [-0.5, 0.02, 0.0], [0.5, 0.02, 0.0], 0.0)
    assert d == pytest.approx(-0.08)
    np.testing.assert_allclose(u, [0.0, 1.0, 0.0])
    assert abs(-0.5 + s) <= 0.3 - 0.08 + 1e-12  # a point of depth 0.08
    d, u, s = _distance(box, [0.1, 0.0, 0.05], [0.1, 0.0, 0.05], 0.0)  # a point inside
    assert d == pytest.approx(-0.1) and s == 0.0
    np.testing.assert_allclose(np.abs(u), [0.0, 1.0, 0.0])


def test_parallel_and_crossing_axes():
    """A segment parallel to a capsule's axis, overlapping it: the gap between the lines; axes
    that meet: minus the radius, ``u`` a unit normal of the segment."""
    rod = CapsuleObstacle("rod", [0.0, 0.0, 0.0], [1.0, 0.0, 0.0], 0.05)
    d, u, s = _distance(rod, [0.5, 0.3, 0.0], [1.5, 0.3, 0.0], 0.0)
    assert d == pytest.approx(0.25) and 0.0 <= s <= 0.5
    np.testing.assert_allclose(u, [0.0, 1.0, 0.0], atol=1e-12)
    d, u, s = _distance(rod, [0.5, -0.2, 0.0], [0.5, 0.2, 0.0], 0.0)
    assert d == pytest.approx(-0.05) and s == pytest.approx(0.5)
    assert np.linalg.norm(u) == pytest.approx(1.0) and u @ [0.0, 0.4, 0.0] == pytest.approx(0.0)


def test_two_or_three_entries_give_the_same_distance():
    """A 2-D segment is the 3-D one in z = 0."""
    for obstacle in SPATIAL.values():
        d2, u2, s2 = _distance(obstacle, [0.3, -0.2], [0.1, 0.4], T)
        d3, u3, s3 = _distance(obstacle, [0.3, -0.2, 0.0], [0.1, 0.4, 0.0], T)
        assert (d2, s2) == (d3, s3) and np.array_equal(u2, u3[:2])


def _coal_pose(R, t):
    import coal

    return coal.Transform3s(np.asarray(R, float), np.asarray(t, float))


def _axis_frame(a, b):
    """A rotation whose z axis runs from ``a`` to ``b``."""
    z = (np.asarray(b) - a) / np.linalg.norm(np.asarray(b) - a)
    x = np.cross(z, [1.0, 0, 0] if abs(z[0]) < 0.9 else [0, 1.0, 0])
    x /= np.linalg.norm(x)
    return np.stack([x, np.cross(z, x), z], axis=1)


@pytest.mark.parametrize("name", ["sphere", "capsule", "bar", "box"])
def test_distance_to_a_link_capsule_agrees_with_coal(name):
    """A link capsule (radius 2 cm) against sphere, capsule and box: the distance minus the
    link's radius is coal's (where apart by at least 1 mm)."""
    coal = pytest.importorskip("coal")
    obstacle, r_link = SPATIAL[name], 0.02
    shift = T * obstacle.velocity3
    if isinstance(obstacle, SphereObstacle):
        shape, pose = coal.Sphere(obstacle.radius), _coal_pose(np.eye(3), obstacle.center + shift)
    elif isinstance(obstacle, CapsuleObstacle):
        length = np.linalg.norm(obstacle.b - obstacle.a)
        shape = coal.Capsule(max(obstacle.radius, 1e-12), length)
        pose = _coal_pose(
            _axis_frame(obstacle.a, obstacle.b), (obstacle.a + obstacle.b) / 2 + shift
        )
    else:
        shape = coal.Box(*(2 * obstacle.half_extents))
        pose = _coal_pose(obstacle.rotation(), obstacle.center + shift)
    a, b = _segments(3, count=80, spread=0.6)
    compared = 0
    for k in range(len(a)):
        if np.linalg.norm(b[k] - a[k]) < 1e-6:
            link, link_pose = coal.Sphere(r_link), _coal_pose(np.eye(3), a[k])
        else:
            link = coal.Capsule(r_link, np.linalg.norm(b[k] - a[k]))
            link_pose = _coal_pose(_axis_frame(a[k], b[k]), (a[k] + b[k]) / 2)
        result = coal.DistanceResult()
        coal.distance(shape, pose, link, link_pose, coal.DistanceRequest(), result)
        d = _distance(obstacle, a[k], b[k], T)[0] - r_link
        if d > 1e-3:
            assert d == pytest.approx(result.min_distance, abs=1e-6), k
            compared += 1
        else:
            assert result.min_distance <= 1e-3 + 1e-6
    assert compared >= 20


# ---------------------------------------------------------------- schemas


def _scenario_with(tmp_path, obstacle: str):
    from qpbench.sim.scenario import parse_scenario

    shipped = Path(obstacles.__file__).parents[2] / "data" / "scenarios" / "free.toml"
    text = shipped.read_text().replace("obstacles = []", f"obstacles = [{obstacle}]")
    return parse_scenario(text, tmp_path / "x.toml")


@pytest.mark.parametrize(
    "obstacle,key,message",
    [
        (
            '{kind = "disk", name = "b", center = [0.9, 0.9], radius = 0.0}',
            "radius",
            "must be > 0",
        ),
        (
            '{kind = "disk", name = "b", center = [0.9, 0.9], radius = 0.1, colour = "red"}',
            "colour",
            "unknown key (expected one of: kind, name, velocity, center, radius)",
        ),
        ('{kind = "segment", name = "s", a = [0.0, 0.0]}', "b", "missing key"),
        (
            '{kind = "disk", name = "b", center = [true, 0.9], radius = 0.1}',
            "center",
            "2 finite numbers",
        ),
        ('{kind = "points", name = "c", points = [[0.0, 1.0, 2.0]]}', "points", "[x, y] points"),
        (
            '{kind = "disk", name = "", center = [0.9, 0.9], radius = 0.1}',
            "name",
            "at least 1 character",
        ),
        (
            '{kind = "sphere", name = "s", center = [0.9, 0.9, 0.0], radius = 0.1}',
            "kind",
            "planar arm takes the planar kinds",
        ),
        (
            '{kind = "box", name = "s", center = [0.9, 0.9, 0.0], half_extents = [0.1, -0.1, 0.1]}',
            "half_extents[1]",
            "must be > 0",
        ),
        ('{kind = "cube", name = "s"}', "kind", "expected one of: box, capsule, disk"),
    ],
)
def test_schema_errors_are_one_line_naming_file_and_key(tmp_path, obstacle, key, message):
    with pytest.raises(ScenarioError) as err:
        _scenario_with(tmp_path, obstacle)
    text = str(err.value)
    assert err.value.key == f"obstacles[0].{key}" and str(tmp_path / "x.toml") in text
    assert message in text and "\n" not in text, text


def test_schemas_are_discriminated_by_kind_and_fill_defaults(tmp_path):
    from pydantic import TypeAdapter

    from qpbench.sim.scenario_schema import ObstacleTable

    box = TypeAdapter(ObstacleTable).validate_python(
        {"kind": "box", "name": "b", "center": [0, 0, 1], "half_extents": [1, 2, 3]}
    )
    assert type(box).__name__ == "BoxSchema" and box.quaternion == (1.0, 0.0, 0.0, 0.0)
    assert box.velocity == (0.0, 0.0, 0.0)
    sc = _scenario_with(tmp_path, '{kind = "disk", name = "b", center = [0.9, 0.9], radius = 0.1}')
    assert tuple(sc.spec.obstacles[0].velocity) == (0.0, 0.0)
    assert sorted(obstacles.kinds()) == [
        "box",
        "capsule",
        "disk",
        "line",
        "plane",
        "points",
        "segment",
        "sphere",
    ]


def test_objects_check_themselves():
    """Made directly, a kind checks its fields by its schema and its geometry itself, naming
    ``obstacles.<name>.<key>``."""
    with pytest.raises(InputError) as err:
        SphereObstacle("s", [0.0, 0.0], 0.1)
    assert err.value.key == "obstacles.s.center" and "3 finite numbers" in str(err.value)
    with pytest.raises(InputError, match="obstacles.b.quaternion"):
        BoxObstacle("b", [0, 0, 0], [0.1, 0.1, 0.1], [0, 0, 0, 0])
    with pytest.raises(InputError, match="obstacles.r.b"):
        CapsuleObstacle("r", [0, 0, 0], [0, 0, 0], 0.1)
    with pytest.raises(InputError, match="obstacles.p.normal"):
        PlaneObstacle("p", [0, 0, 0], [0, 0, 0])


def test_every_kind_draws_itself_in_a_planar_and_a_side_view():
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, axes = plt.subplots(1, 2)
    limits = ((-1.0, 1.0), (-1.0, 1.0))
    every = [o for o, _ in PLANAR] + list(SPATIAL.values())
    for ax, plane in zip(axes, [("x", "y"), ("x", "z")]):
        for o in every:
            o.draw(ax, 0.3, plane=plane, limits=limits)
            assert o.view_points(plane).shape[1] == 2
    drawn = len(axes[0].patches) + len(axes[0].lines) + len(axes[0].collections)
    assert drawn >= len(every)  # each kind left a mark in the planar view
    plt.close(fig)


# ---------------------------------------------------------------- the body rule in 3-D


class SpatialChain:
    """A chain of revolute joints turning alternately about z and y, each link along its
    frame's x: joint positions (T, n + 1, 3) [m]."""

    def __init__(self, lengths):
        self.lengths = np.asarray(lengths, dtype=float)
        self.n = len(self.lengths)
        self.dim = 3

    def joint_positions(self, theta):
        theta = np.atleast_2d(theta)
        R = np.tile(np.eye(3), (len(theta), 1, 1))
        p = np.zeros((len(theta), self.n + 1, 3))
        for i in range(self.n):
            c, s = np.cos(theta[:, i]), np.sin(theta[:, i])
            turn = np.zeros((len(theta), 3, 3))
            a, b = (0, 1) if i % 2 == 0 else (2, 0)  # about z, then about y
            turn[:, a, a] = turn[:, b, b] = c
            turn[:, b, a], turn[:, a, b] = s, -s
            turn[:, 3 - a - b, 3 - a - b] = 1.0
            R = R @ turn
            p[:, i + 1] = p[:, i] + R[:, :, 0] * self.lengths[i]
        return p


DT = 1e-3
CHAIN = SpatialChain([0.3, 0.4, 0.2])
POSE = np.array([0.4, -0.6, 0.5])


def _dense_first_inside(theta_a, theta_b, t_a, obstacle, radius, steps=1000):
    s = np.arange(steps + 1) / steps
    theta, t = theta_a + s[:, None] * (theta_b - theta_a), t_a + s * DT
    d = body_clearance(CHAIN, theta, t, [obstacle], radius).d_min
    rows = np.flatnonzero(d < 0.0)
    return float(t[rows[0]]) if rows.size else None


@pytest.mark.parametrize("radius", [0.0, 0.01])
def test_a_fast_sphere_through_a_spatial_link_between_ticks(radius):
    """A 3 mm ball crossing link 2 of a still 3-D chain between ticks 5 and 6, clear at both:
    found at the dense reference's first inside sub-step, to one sub-step; 1 mm further off
    its path, it passes by and nothing is found."""
    theta, t = np.tile(POSE, (12, 1)), np.arange(12) * DT
    p = CHAIN.joint_positions(POSE)[0]
    mid, e = (p[1] + p[2]) / 2, p[2] - p[1]
    across = np.cross(e, [0.0, 0.0, 1.0])
    across /= np.linalg.norm(across)
    gap, ball = 0.004, 0.003
    speed = 2 * (gap + ball + radius) / DT
    start = mid - across * (gap + ball + radius + 5.0 * DT * speed)
    sphere = SphereObstacle("ball", start, ball, velocity=speed * across)
    body = body_clearance(CHAIN, theta, t, [sphere], radius)
    assert body.d_min.min() == pytest.approx(gap, abs=1e-9)
    found = body_crossings(CHAIN, theta, t, DT, [sphere], radius, d_min=body.d_min)
    assert found.tick.tolist() == [5] and found.link.tolist() == [2]
    reference = _dense_first_inside(POSE, POSE, t[5], sphere, radius)
    assert reference - DT / 1000 <= found.t[0] <= reference + 1e-12
    normal = np.cross(e, across) / np.linalg.norm(np.cross(e, across))
    aside = SphereObstacle(
        "ball", start + normal * (ball + radius + 1e-3), ball, velocity=speed * across
    )
    assert body_crossings(CHAIN, theta, t, DT, [aside], radius).tick.size == 0


def test_a_turning_link_through_a_box_corner_and_a_bar_between_ticks():
    """The chain turning fast: its last link sweeps through a box's corner and across a bar (a
    capsule of radius 0, never inside at any instant: only passing through shows it), between
    ticks at which it is clear of both."""
    v = np.array([0.0, 0.0, 40.0])  # [rad/s]: the last link turns 0.04 rad a tick
    theta = POSE + np.arange(10)[:, None] * DT * v
    t = np.arange(10) * DT
    p_mid = CHAIN.joint_positions(POSE + 4.5 * DT * v)[0]  # half way from tick 4 to tick 5
    tip, base = p_mid[3], p_mid[2]
    side = np.cross(tip - base, CHAIN.joint_positions(POSE + 5 * DT * v)[0][3] - tip)
    side /= np.linalg.norm(side)
    bar = CapsuleObstacle(
        "bar", tip - 0.05 * (tip - base) - 0.1 * side, tip - 0.05 * (tip - base) + 0.1 * side
    )
    found = body_crossings(CHAIN, theta, t, DT, [bar])
    assert found.tick.tolist() == [4] and found.link.tolist() == [3]
    assert body_clearance(CHAIN, theta, t, [bar]).d_min.min() > 0
    corner = tip - 0.02 * (tip - base) / np.linalg.norm(tip - base)
    box = BoxObstacle("crate", corner, [1e-4, 2e-4, 1e-4], QUAT)  # 2 cm from the tip
    found = body_crossings(CHAIN, theta, t, DT, [box])
    body = body_clearance(CHAIN, theta, t, [box])
    assert body.d_min.min() > 0 and found.tick.tolist() == [4] and found.link.tolist() == [3]
