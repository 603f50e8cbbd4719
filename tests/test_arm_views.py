"""A spatial arm drawn in two orthographic views: the projection, the views chosen, each 3-D
obstacle kind where its projection lies, the snapshot and animation of panda_table."""

from __future__ import annotations

from types import SimpleNamespace

import numpy as np
import pytest
from conftest import simulate_args
from PIL import Image

from qpbench.report.arm import animate, caption, draw_snapshot, views
from qpbench.robot.obstacles import make, project, trace
from qpbench.sim.log import theta_columns
from qpbench.sim.loop import simulate
from qpbench.sim.scenario import load_scenario

PNG = b"\x89PNG\r\n\x1a\n"


@pytest.fixture(scope="module")
def panda_run():
    scenario = load_scenario("panda_table").with_overrides(duration=0.4)
    return scenario, simulate(scenario, "daqp")


def test_projection_keeps_the_view_axes_in_order():
    p = np.array([[0.1, -0.2, 0.3], [1.0, 2.0, 3.0]])
    np.testing.assert_array_equal(project(p, ("x", "y")), [[0.1, -0.2], [1.0, 2.0]])
    np.testing.assert_array_equal(project(p, ("x", "z")), [[0.1, 0.3], [1.0, 3.0]])
    np.testing.assert_array_equal(project(p, ("z", "y")), [[0.3, -0.2], [3.0, 2.0]])
    # a planar point lies in z = 0
    np.testing.assert_array_equal(project([0.4, 0.5], ("y", "z")), [0.5, 0.0])


def test_captions_name_the_line_of_sight_of_a_right_handed_view():
    assert caption(("x", "y")) == "x-y view, seen along -z"  # from above
    assert caption(("x", "z")) == "x-z view, seen along +y"
    assert caption(("y", "z")) == "y-z view, seen along -x"


def test_trace_of_a_plane_on_a_view():
    # the table z = 0.2 (normal down): edge on from the side, face on from above
    point, normal = trace([0.5, 0.0, 0.2], [0.0, 0.0, -1.0], ("x", "z"))
    np.testing.assert_allclose(point, [0.0, 0.2])
    np.testing.assert_allclose(normal, [0.0, -1.0])
    assert trace([0.5, 0.0, 0.2], [0.0, 0.0, -1.0], ("x", "y")) is None
    # x + z = 1 seen along y: every point of the drawn line satisfies it
    point, normal = trace([1.0, 5.0, 0.0], [1.0, 0.0, 1.0], ("x", "z"))
    np.testing.assert_allclose(point.sum(), 1.0)
    np.testing.assert_allclose(normal, np.array([1.0, 1.0]) / np.sqrt(2))


def _stub(dim, normal):
    arm = SimpleNamespace(dim=dim)
    surface = SimpleNamespace(normal=np.asarray(normal, dtype=float))
    return SimpleNamespace(make_arm=lambda: arm, make_surface=lambda: surface)


@pytest.mark.parametrize(
    "dim, normal, expected",
    [
        (2, [0.0, -1.0], (("x", "y"),)),
        (3, [0.0, 0.0, -1.0], (("x", "y"), ("x", "z"))),  # a table: from above, from the side
        (3, [-1.0, 0.1, 0.0], (("y", "z"), ("x", "z"))),  # a wall ahead: face on, from the side
        (3, [0.2, 1.0, 0.3], (("x", "z"), ("y", "z"))),
    ],
)
def test_views_see_the_surface_face_on_then_edge_on(dim, normal, expected):
    assert views(_stub(dim, normal)) == expected


SPATIAL = {
    "plane": dict(point=[0.0, 0.0, 0.1], normal=[0.0, 0.0, 1.0]),
    "sphere": dict(center=[0.3, 0.1, 0.5], radius=0.1, velocity=[0.1, 0.0, -0.2]),
    "capsule": dict(a=[0.1, 0.0, 0.2], b=[0.4, 0.3, 0.6], radius=0.05),
    "box": dict(
        center=[0.2, -0.1, 0.4],
        half_extents=[0.1, 0.05, 0.2],
        quaternion=[np.cos(0.3), 0.0, np.sin(0.3), 0.0],
    ),
}


def _expected_extent(ob, t, plane) -> np.ndarray:
    """(lo, hi) (2, 2) [m] of the obstacle's orthographic shadow, from its own fields."""
    if ob.KIND == "sphere":
        c = project(ob.center + t * ob.velocity3, plane)
        return np.array([c - ob.radius, c + ob.radius])
    if ob.KIND == "capsule":
        ends = project(np.array([ob.a, ob.b]), plane)
        return np.array([ends.min(0) - ob.radius, ends.max(0) + ob.radius])
    corners = project(ob.corners(t), plane)
    return np.array([corners.min(0), corners.max(0)])


@pytest.mark.parametrize("plane", [("x", "y"), ("x", "z"), ("y", "z")])
@pytest.mark.parametrize("kind", sorted(SPATIAL))
def test_each_spatial_kind_draws_its_shadow_where_it_projects(kind, plane):
    from qpbench.report import style

    plt = style.pyplot()
    ob = make({"kind": kind, "name": kind, **SPATIAL[kind]})
    fig, ax = plt.subplots()
    limits = ((-1.0, 1.0), (-1.0, 1.0))
    t = 0.5
    ob.draw(ax, t, plane=plane, limits=limits)
    if kind == "plane":  # z = 0.1: a line from the side, nothing seen face on
        lines = [line for line in ax.lines if line.get_label() == "plane"]
        if "z" not in plane:
            assert not lines and not ax.patches
        else:
            (line,) = lines
            xy = line.get_xydata()
            assert np.allclose(xy[:, plane.index("z")], 0.1)
    else:
        (patch,) = ax.patches
        xy = patch.get_xy()
        # a ring of 48 points has its extremes on the axes: the shadow's extent is exact
        np.testing.assert_allclose([xy.min(0), xy.max(0)], _expected_extent(ob, t, plane))
    plt.close(fig)


def test_panda_snapshot_has_two_views_with_the_ball_and_the_table(panda_run, tmp_path, monkeypatch):
    from conftest import figures_closed, legends_over_data

    scenario, run = panda_run
    figures = figures_closed(monkeypatch)
    out = draw_snapshot(scenario, run.log, tmp_path / "panda.png", backend="daqp")
    assert out.stat().st_size > 0 and out.read_bytes()[:8] == PNG
    (fig,) = figures
    top, side, distance = fig.axes
    assert (top.get_xlabel(), top.get_ylabel()) == ("x [m]", "y [m]")
    assert (side.get_xlabel(), side.get_ylabel()) == ("x [m]", "z [m]")
    assert top.get_aspect() == side.get_aspect() == 1.0
    assert top.get_xlim() == side.get_xlim()  # the views line up along x
    assert distance.get_xlabel() == "t [s]"
    ball = scenario.make_obstacles()[0]
    for ax, plane in ((top, ("x", "y")), (side, ("x", "z"))):
        (shadow,) = [p for p in ax.patches if p.get_label() == "ball"]
        xy = shadow.get_xy()
        c = project(ball.center, plane)
        np.testing.assert_allclose([xy.min(0), xy.max(0)], [c - 0.05, c + 0.05], atol=1e-4)
        # the links' capsules: every joint of the last pose inside their shadow
        (capsules,) = [p for p in ax.patches if "capsules" in str(p.get_label())]
        q = run.log[theta_columns(7)].to_numpy()[-1]
        joints = project(scenario.make_arm().joint_positions(q), plane)
        assert capsules.get_path().contains_points(joints, radius=1e-9).all()
    # the table z = 0.2 drawn edge on from the side only
    table = [line for line in side.lines if line.get_label() == "contact surface"]
    assert len(table) == 1 and np.allclose(table[0].get_ydata(), 0.2)
    assert not [line for line in top.lines if line.get_label() == "contact surface"]
    # the desired circle drawn from above as the log has it
    (desired,) = [line for line in top.lines if line.get_label() == "desired end-effector path"]
    np.testing.assert_allclose(desired.get_xydata(), run.log[["xd_x", "xd_y"]].to_numpy())
    assert legends_over_data(fig) == []


def test_panda_animation_draws_both_views_per_frame(panda_run, tmp_path, monkeypatch):
    from conftest import figures_closed

    scenario, run = panda_run
    figures = figures_closed(monkeypatch)
    out = animate(scenario, run.log, tmp_path / "panda.gif", fps=10, speed=0.2, backend="daqp")
    with Image.open(out) as img:
        assert img.format == "GIF" and img.n_frames == 20  # 0.4 s at 0.2 s per second, 10 fps
    (fig,) = figures
    top, side = fig.axes
    assert "t =" in top.get_title(loc="left")
    # the last frame's arm: its joints projected on each view
    q = run.log[theta_columns(7)].to_numpy()[(len(run.log) - 1) // 20 * 20]
    joints = scenario.make_arm().joint_positions(q)
    for ax, plane in ((top, ("x", "y")), (side, ("x", "z"))):
        arm_line = next(line for line in ax.lines if line.get_marker() == "o")
        np.testing.assert_allclose(arm_line.get_xydata(), project(joints, plane))


def test_simulate_draws_a_spatial_arm(tmp_path):
    from qpbench.cli import main

    png, gif = tmp_path / "p.png", tmp_path / "p.gif"
    options = ("--snapshot", str(png), "--animate", str(gif), "--fps", "10", "--speed", "0.5")
    assert main(["-q", *simulate_args("panda_table", "daqp", "0.2", *options)]) == 0
    assert png.read_bytes()[:8] == PNG
    with Image.open(gif) as img:
        assert img.n_frames == 4  # 0.2 s at 0.5 simulated s per second and 10 fps
        assert img.size[0] > img.size[1]  # two views side by side
