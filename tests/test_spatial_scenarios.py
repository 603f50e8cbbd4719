"""The shipped spatial scenarios ``panda_shelf`` (a Panda between a shelf's boards and side
panel) and ``iiwa_wall`` (an iiwa 14 by a wall, a box moving over its elbow) in the closed loop
with an exact solver: the body keeps d_safe from every obstacle, between ticks too, the joints
their limits, the force its target and the end effector its path; the logged distances against
an independent computation (planes exactly, the moving box by sampling each link); both engines;
and a scenario of ``[robot] kind = "urdf"`` on Panda's URDF against the preset's run."""

from __future__ import annotations

import re
from pathlib import Path

import numpy as np
import pytest
from test_chain import panda_urdf
from test_engines import engines_agree

from qpbench.robot.chain import forward_kinematics_np
from qpbench.sim.loop import simulate
from qpbench.sim.scenario import load_scenario

pytestmark = pytest.mark.filterwarnings("ignore::UserWarning")

#: Per scenario: its obstacles, each reached by some link (its rows bind), and the share of ticks
#: with some obstacle row within 0.1 mm of d_safe at least (the scenarios are tuned to it).
SCENARIOS = {
    "panda_shelf": (("board", "upper", "side"), 0.3),
    "iiwa_wall": (("wall", "box"), 0.3),
}
DATA = Path(__file__).parent / "data"


@pytest.fixture(scope="module")
def runs():
    """Each scenario's 20 s with DAQP on the compiled engine (a second or two each)."""
    return {name: simulate(name, "daqp", engine="compiled") for name in SCENARIOS}


def joints(log, n=7):
    return log[[f"theta_{i}" for i in range(n)]].to_numpy()


def distances(log, obstacle):
    cols = [c for c in log.columns if re.fullmatch(rf"d_L\d_{obstacle}", c)]
    return log[cols].to_numpy(), [int(c[3]) for c in cols]


@pytest.mark.parametrize("name", SCENARIOS)
def test_the_body_keeps_d_safe_the_limits_the_force_and_the_path(runs, name):
    sc, run = load_scenario(name), runs[name]
    log, s, c, arm = run.log, run.summary, sc.spec.controller, sc.make_arm()
    assert s["ticks"] == 20000 and s["verdict"] == "ok" and s["key_point_rule"] == "held"
    # infeasible only at the start, as the planar scenarios' (the task asks for force at once)
    bad = log["t"].to_numpy()[log["status"].to_numpy() != "optimal"]
    assert bad.size == s["infeasible_ticks"] and (bad < 0.01).all()
    obstacles, share = SCENARIOS[name]
    assert "d_L7_board" not in log  # the board pressed on: no row of the end effector's link
    near = np.zeros(len(log), dtype=bool)
    for obstacle in obstacles:
        d, _ = distances(log, obstacle)
        assert d.min() >= c.d_safe - 1e-4, obstacle  # within the velocity damper's lag
        assert d.min() <= c.d_safe + 1e-3, obstacle  # its rows are reached, not avoided by chance
        near |= (d < c.d_safe + 1e-4).any(axis=1)
    assert near.mean() >= share
    # the whole body, between ticks too (link capsules swept from tick to tick)
    assert s["body_crossings"] == 0 and s["min_body_distance"] >= c.d_safe - 1e-4
    theta, v = joints(log), log[[f"v_{i}" for i in range(7)]].to_numpy()
    assert (theta >= arm.model.q_min).all() and (theta <= arm.model.q_max).all()
    assert (np.abs(v) <= arm.model.v_max + 1e-12).all()
    after = log["t"].to_numpy() >= 2.0
    assert np.abs(log["force_error"].to_numpy()[after]).max() < 0.05  # N, of Fd = 20 N
    assert log["tracking_error"].to_numpy()[after].max() < 1e-5  # m, in the surface's plane
    # pressing down: the end effector Fd / Kp below x_d, and on x_d's ellipse in the plane
    ee = log[["ee_x", "ee_y", "ee_z"]].to_numpy()[after]
    xd = log[["xd_x", "xd_y", "xd_z"]].to_numpy()[after]
    np.testing.assert_allclose(ee[:, 2], xd[:, 2] - c.desired_force / c.kp, atol=1e-5)
    np.testing.assert_allclose(ee[:, :2], xd[:, :2], atol=1e-5)


def capsule_gaps(name, log, ticks, obstacle, samples=4001):
    """Each link capsule's clearance (ticks, 7) [m] to ``obstacle`` from the logged angles, by
    the file's numbers: a plane exactly (a segment's least signed distance is at an end), the
    box (axis-aligned) by the least distance of ``samples`` points along each link."""
    sc = load_scenario(name)
    radius, arm = sc.spec.key_points.link_radius, sc.make_arm()
    spec = next(o for o in sc.spec.obstacles if o.name == obstacle)
    out = np.empty((len(ticks), 7))
    for row, k in enumerate(ticks):
        t, p = log["t"].iloc[k], forward_kinematics_np(arm.model, joints(log.iloc[[k]])[0]).position
        for link in range(7):
            a, b = p[link], p[link + 1]
            if spec.kind == "plane":
                n = np.asarray(spec.normal) / np.linalg.norm(spec.normal)
                out[row, link] = min(n @ (a - spec.point), n @ (b - spec.point)) - radius
                continue
            x = a + np.linspace(0.0, 1.0, samples)[:, None] * (b - a)
            centre = np.asarray(spec.center) + t * np.asarray(spec.velocity)
            outside = np.maximum(np.abs(x - centre) - spec.half_extents, 0.0)
            out[row, link] = np.linalg.norm(outside, axis=1).min() - radius
    return out


@pytest.mark.parametrize("name", SCENARIOS)
def test_the_logged_distances_are_the_files_geometry(runs, name):
    """Every 500th tick and the ticks where each obstacle is nearest: the log's distances (the
    compiled build's) against the file's planes and the box moving at its velocity."""
    log = runs[name].log
    for obstacle in SCENARIOS[name][0]:
        d, links = distances(log, obstacle)
        ticks = sorted({*range(0, len(log), 500), *np.argmin(d, axis=0)})
        gaps = capsule_gaps(name, log, ticks, obstacle)[:, [i - 1 for i in links]]
        np.testing.assert_allclose(d[ticks], gaps, atol=1e-4, rtol=0)  # sampling: < 0.03 mm


@pytest.mark.parametrize("name", SCENARIOS)
def test_both_engines_give_the_same_run(name):
    assert engines_agree(name, "daqp", duration=1.0)["verdict"] == "ok"


def test_a_urdf_robot_runs_as_its_preset():
    """``tests/data/panda_urdf_shelf.toml``, ``panda_shelf`` with ``[robot] kind = "urdf"`` on
    example-robot-data's Panda URDF: the closed loop of the preset's chain, to rounding."""
    pytest.importorskip("pinocchio")
    file = DATA / "panda_urdf_shelf.toml"
    urdf = load_scenario(file, {"robot.file": str(panda_urdf())})
    assert urdf.spec.robot.kind == "urdf"
    a = simulate(urdf, "daqp", duration=3.0).log
    b = simulate("panda_shelf", "daqp", duration=3.0).log
    numbers = [c for c in b.columns if c.startswith(("theta_", "v_", "d_L", "ee_", "force"))]
    assert list(a.columns) == list(b.columns) and len(numbers) > 30
    np.testing.assert_allclose(a[numbers].to_numpy(), b[numbers].to_numpy(), atol=1e-8, rtol=0)
    assert (a["status"] == b["status"]).all()
