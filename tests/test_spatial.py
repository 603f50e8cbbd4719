"""The paper's controller on a spatial arm (the shipped ``panda_table``): one tick's QP against an
independent cvxpy model (the scenario file's numbers, Franka's Denavit-Hartenberg table and
finite-difference Jacobians), the closed loop with an exact solver, the scenario's
checks across keys and the command line (both engines: tests/test_engines.py)."""

from __future__ import annotations

import re

import cvxpy as cp
import numpy as np
import pytest
import qpsolvers
from test_controller import file_tables

from qpbench.cli import main
from qpbench.exceptions import ScenarioError
from qpbench.sim.loop import simulate
from qpbench.sim.scenario import load_scenario, scenario_path

pytestmark = pytest.mark.filterwarnings("ignore::UserWarning")

#: Franka Emika Panda, Craig's modified DH rows of joints 1-7 and the flange: a [m], d [m],
#: alpha [rad] (Franka's documentation), written here apart from the package's preset.
A = (0.0, 0.0, 0.0, 0.0825, -0.0825, 0.0, 0.088, 0.0)
D = (0.333, 0.0, 0.316, 0.0, 0.384, 0.0, 0.0, 0.107)
ALPHA = (0.0, -np.pi / 2, np.pi / 2, np.pi / 2, -np.pi / 2, np.pi / 2, np.pi / 2, 0.0)


def origins(q) -> np.ndarray:
    """Joint origins 1-7 and the flange (8, 3) [m] by homogeneous transforms."""
    T, out = np.eye(4), []
    for i in range(8):
        ca, sa = np.cos(ALPHA[i]), np.sin(ALPHA[i])
        qi = q[i] if i < 7 else 0.0
        cq, sq = np.cos(qi), np.sin(qi)
        T = T @ np.array(
            [
                [cq, -sq, 0.0, A[i]],
                [sq * ca, cq * ca, -sa, -sa * D[i]],
                [sq * sa, cq * sa, ca, ca * D[i]],
                [0.0, 0.0, 0.0, 1.0],
            ]
        )
        out.append(T[:3, 3].copy())
    return np.array(out)


def fd(f, q, h=1e-7) -> np.ndarray:
    cols = [(f(q + h * e) - f(q - h * e)) / (2 * h) for e in np.eye(len(q))]
    return np.array(cols).T


def independent_qp(data, q, t, kp, kd):
    """cvxpy model of one tick of eq. 11 on the Panda from the file's numbers: the task (3 rows),
    the escape-velocity bounds from Panda's published limits, and one velocity-damper row per
    link (its point closest to the ball, kept on the link while it moves)."""
    c, p, o = data["controller"], data["path"], data["obstacles"][0]
    radius = data["key_points"]["link_radius"]
    q_min = np.array([-2.8973, -1.7628, -2.8973, -3.0718, -2.8973, -0.0175, -2.8973])
    q_max = np.array([2.8973, 1.7628, 2.8973, -0.0698, 2.8973, 3.7525, 2.8973])
    v_max = np.array([2.1750, 2.1750, 2.1750, 2.1750, 2.6100, 2.6100, 2.6100])
    xd = lambda s: p["centre"] + p["amplitude"] * np.cos(p["omega"] * s + p["phase"])  # noqa: E731
    xdot_d = (xd(t + 1e-6) - xd(t - 1e-6)) / 2e-6
    normal = data["contact"]["normal"] / np.linalg.norm(data["contact"]["normal"])
    x = origins(q)[-1]
    b0 = xdot_d - kp / kd * (x - xd(t)) + c["desired_force"] / kd * normal
    v = cp.Variable(7)
    cons = [
        origin_jac(q, 7) @ v == b0,
        v >= np.maximum(c["alpha"] * (q_min - q), -v_max),
        v <= np.minimum(v_max, c["alpha"] * (q_max - q)),
    ]
    P = origins(q)
    dists = []
    for link in range(7):  # link i: joint i+1 to joint i+2 (the last: to the flange)
        a, b = P[link], P[link + 1]
        e = b - a
        s = 0.0 if e @ e == 0 else np.clip((o["center"] - a) @ e / (e @ e), 0.0, 1.0)
        point = lambda qq, L=link, s=s: (1 - s) * origins(qq)[L] + s * origins(qq)[L + 1]  # noqa: E731
        gap = point(q) - o["center"]
        d = np.linalg.norm(gap) - o["radius"] - radius
        u = gap / np.linalg.norm(gap)
        cons.append(u @ fd(point, q) @ v >= -c["k"] * (d - c["d_safe"]))
        dists.append(d)
    return cp.Problem(cp.Minimize(0.5 * cp.sum_squares(v)), cons), np.array(dists)


def origin_jac(q, i):
    return fd(lambda qq: origins(qq)[i], q)


@pytest.fixture(scope="module")
def run():
    """The shipped panda_table, 20 s with DAQP on the compiled engine."""
    return simulate("panda_table", "daqp", engine="compiled")


def test_a_tick_of_the_spatial_qp_is_the_independent_models(run):
    sc = load_scenario("panda_table")
    ctrl, log, data = sc.make_controller(), run.log, file_tables(sc)
    active = np.flatnonzero(log["z_max"].to_numpy() > 1e-9)
    assert active.size > 100  # the ball's row binds in the run
    ticks = [0, 500, 1500, *active[:: max(1, active.size // 6)][:6]]
    for k in ticks:
        row = log.iloc[k]
        q = row[[f"theta_{i}" for i in range(7)]].to_numpy(float)
        t, kp, kd = float(row["t"]), float(row["kp_hat"]), float(row["kd_hat"])
        tick = ctrl.build(q, t, kp, kd)
        ref, dists = independent_qp(data, q, t, kp, kd)
        ref.solve(solver=cp.CLARABEL)
        assert ref.status == "optimal", (k, ref.status)
        np.testing.assert_allclose(tick.distances[:, 0], dists, atol=1e-12)
        np.testing.assert_allclose(tick.ee, origins(q)[-1], atol=1e-12)
        x = qpsolvers.solve_problem(tick.problem, solver="daqp").x
        np.testing.assert_allclose(x, ref.variables()[0].value, atol=2e-6, rtol=0)


def test_panda_table_holds_d_safe_the_limits_the_force_and_the_path(run):
    sc, log, s = load_scenario("panda_table"), run.log, run.summary
    assert s["engine"] == "compiled" and s["ticks"] == 20000
    assert s["status_counts"] == {"optimal": 20000}
    c, arm = sc.spec.controller, sc.make_arm()
    # every guarded element (each link's closest point) keeps d_safe, within the damper's lag
    d = log[[col for col in log.columns if re.fullmatch(r"d_L\d_ball", col)]].to_numpy()
    assert d.min() >= c.d_safe - 1e-4
    assert d.min() <= c.d_safe + 1e-3  # the ball's row was reached, not avoided by chance
    assert s["body_crossings"] == 0
    theta = log[[f"theta_{i}" for i in range(7)]].to_numpy()
    assert (theta >= arm.model.q_min).all() and (theta <= arm.model.q_max).all()
    v = log[[f"v_{i}" for i in range(7)]].to_numpy()
    assert (np.abs(v) <= arm.model.v_max + 1e-12).all()
    after = log["t"].to_numpy() >= 2.0
    assert np.abs(log["force_error"].to_numpy()[after]).max() < 0.05  # N, of Fd = 20 N
    assert log["tracking_error"].to_numpy()[after].max() < 1e-5  # m, in the table's plane
    # the end effector on the table, Fd / Kp below x_d along the normal (z down)
    ee_z, xd_z = log["ee_z"].to_numpy()[after], log["xd_z"].to_numpy()[after]
    np.testing.assert_allclose(ee_z, xd_z - c.desired_force / c.kp, atol=1e-5)
    radius = np.hypot(log["ee_x"].to_numpy()[after] - 0.5, log["ee_y"].to_numpy()[after])
    np.testing.assert_allclose(radius, 0.1, atol=1e-5)
    assert s["verdict"] == "ok" and s["key_point_rule"] == "held"


def _edited(tmp_path, old, new):
    text = scenario_path("panda_table").read_text()
    assert re.search(old, text, flags=re.M), old
    f = tmp_path / "x.toml"
    f.write_text(re.sub(old, new, text, count=1, flags=re.M))
    return f


DISK = 'kind = "disk"\nname = "ball"\ncenter = [0.2, 0.1]\nradius = 0.05'
NARROW = "theta_max = [1.0, 1.0, 1.0, -0.1, 1.0, 2.0, 1.0]"


@pytest.mark.parametrize(
    ("old", "new", "key", "message"),
    [
        (r"^theta0 = \[0.0, ", "theta0 = [", "robot.theta0", "expected 7 values"),
        (r"^theta0 = \[0.0,", "theta0 = [3.0,", "robot.theta0", "outside"),
        (r'^kind = "panda"', 'kind = "ur5"', "robot.kind", "expected one of: planar, panda"),
        (r'^kind = "panda"', 'kind = "panda"\nlink_lengths = [0.3]', "robot.link_lengths", "unknown key"),
        (r"^normal = \[0.0, 0.0, -1.0\]", "normal = [0.0, -1.0]", "contact.normal", "expected 3 numbers"),
        (r"^omega = \[0.5, 0.5, 0.0\]", "omega = [0.5, 0.5]", "path.omega", "expected 3 numbers"),
        (r'^kind = "sphere"\nname = "ball"\ncenter = .*\nradius = .*', DISK, "obstacles[0].kind",
         "a spatial arm takes the spatial kinds only"),
        (r"^theta0 = .*$", "theta0 = [0.0, 0.5, 0.0, -1.9, 0.0, 2.3, 0.7]\n" + NARROW,
         "robot.theta0", "outside"),
    ],
)  # fmt: skip
def test_the_spatial_scenario_is_checked_across_keys(tmp_path, old, new, key, message):
    with pytest.raises(ScenarioError) as err:
        load_scenario(_edited(tmp_path, old, new))
    assert err.value.key == key and message in str(err.value), str(err.value)
    assert "\n" not in str(err.value)


def test_a_planar_scenario_refuses_a_spatial_kind_and_vectors_of_three(tmp_path):
    text = scenario_path("wall").read_text()
    f = tmp_path / "w.toml"
    f.write_text(text.replace("point = [0.4, 0.5]", "point = [0.4, 0.5, 0.0]"))
    with pytest.raises(ScenarioError, match=r"contact.point.*expected 2 numbers"):
        load_scenario(f)


def test_a_preset_may_override_its_limits():
    sc = load_scenario("panda_table", {"robot.velocity_max": [1.0] * 7})
    ctrl = sc.make_controller()
    np.testing.assert_array_equal(ctrl.model.v_max, np.ones(7))
    np.testing.assert_array_equal(ctrl.model.v_min, -np.ones(7))
    np.testing.assert_array_equal(ctrl.model.theta_max[3], -0.0698)  # Panda's own


def test_simulate_runs_the_spatial_scenario(tmp_path):
    out = tmp_path / "log.csv"
    code = main(
        ["simulate", "--scenario", "panda_table", "--backend", "daqp", "--duration", "3",
         "--log", str(out), "--summary", "-"]
    )  # fmt: skip
    assert code == 0
    log = out.read_text().splitlines()[0].split(",")
    assert {"ee_z", "xd_z", "y_2"} <= set(log)
