"""The per-tick QP (paper eq. 11): an independent cvxpy model, finite-difference obstacle rows,
escape-velocity bounds, the compiled kernel against the numpy terms, the adaptive law."""

from __future__ import annotations

import tomllib

import cvxpy as cp
import numpy as np
import pytest
import qpsolvers
from controller_numpy import numpy_arrays

from qpbench.control.adaptive import AdaptiveImpedance
from qpbench.control.controller import Controller
from qpbench.control.terms import CosinePath, EscapeVelocityLimits, ImpedanceTask, PolylinePath
from qpbench.exceptions import ParamError
from qpbench.packed import PackedProblem
from qpbench.robot.kinematics import PlanarArm, default_key_points
from qpbench.robot.obstacles.disk import DiskObstacle
from qpbench.robot.obstacles.line import LineObstacle
from qpbench.robot.obstacles.points import PointCloudObstacle
from qpbench.robot.obstacles.segment import SegmentObstacle
from qpbench.sim.scenario import load_scenario

SCENARIOS = ("free", "wall", "adaptive", "narrow")

# clarabel through qpsolvers warns about dense input and about infeasible ticks (expected here)
pytestmark = pytest.mark.filterwarnings("ignore::UserWarning")


# -- an independent model of eq. 11, from the scenario's raw values ------------------
def fk(lengths, theta, link, frac):
    z = 0j
    phi = 0.0
    for i in range(link + 1):
        phi += theta[i]
        z += (frac if i == link else 1.0) * lengths[i] * np.exp(1j * phi)
    return np.array([z.real, z.imag])


def fd_jac(lengths, theta, link, frac, h=1e-7):
    cols = []
    for k in range(len(theta)):
        e = np.zeros(len(theta))
        e[k] = h
        cols.append(
            (fk(lengths, theta + e, link, frac) - fk(lengths, theta - e, link, frac)) / (2 * h)
        )
    return np.array(cols).T


def file_tables(sc):
    """The scenario file's tables as written (TOML read here, lists as arrays), not the model's."""

    def arrays(v):
        if isinstance(v, dict):
            return {k: arrays(x) for k, x in v.items()}
        if isinstance(v, list) and v and isinstance(v[0], dict):
            return [arrays(x) for x in v]
        return np.array(v, dtype=float) if isinstance(v, list) else v

    return arrays(tomllib.loads(sc.source))


def independent_qp(data, theta, t, kp, kd, formulation):
    """cvxpy problem of one tick written from the scenario file's numbers (not from our matrices)."""
    r, c, p = data["robot"], data["controller"], data["path"]
    L = r["link_lengths"]
    n = len(L)
    x = fk(L, theta, n - 1, 1.0)
    J = fd_jac(L, theta, n - 1, 1.0)
    xd = lambda s: p["centre"] + p["amplitude"] * np.cos(p["omega"] * s + p["phase"])  # noqa: E731
    x_d = xd(t)
    xdot_d = (xd(t + 1e-6) - xd(t - 1e-6)) / 2e-6
    nrm = data["contact"]["normal"] / np.linalg.norm(data["contact"]["normal"])
    b0 = xdot_d - kp / kd * (x - x_d) + c["desired_force"] / kd * nrm
    v = cp.Variable(n)
    cons = [
        v >= np.maximum(c["alpha"] * (r["theta_min"] - theta), r["velocity_min"]),
        v <= np.minimum(r["velocity_max"], c["alpha"] * (r["theta_max"] - theta)),
    ]
    # key points A1..A(2n-1): midpoints and the joints J2..Jn
    keys = []
    for i in range(n):
        keys.append((i, 0.5))
        if i < n - 1:
            keys.append((i, 1.0))
    for link, frac in keys:
        A = fk(L, theta, link, frac)
        JA = fd_jac(L, theta, link, frac)
        for o in data["obstacles"]:
            assert o["kind"] == "line"
            nn = o["normal"] / np.linalg.norm(o["normal"])
            dist = (A - o["point"] - o["velocity"] * t) @ nn
            # d/dt dist = nn . (J_A v - velocity) >= -k (dist - d_safe)
            cons.append(nn @ JA @ v - nn @ o["velocity"] >= -c["k"] * (dist - c["d_safe"]))
    if formulation == "paper":
        cons.append(J @ v == b0)
        obj = 0.5 * cp.sum_squares(v)
    else:
        obj = 0.5 * cp.sum_squares(v) + 0.5 * c["rho"] * cp.sum_squares(J @ v - b0)
    # constant the exported soft objective leaves out: rho/2 |b0|^2
    const = 0.5 * c["rho"] * float(b0 @ b0) if formulation == "soft" else 0.0
    return cp.Problem(cp.Minimize(obj), cons), const


@pytest.fixture(scope="module")
def runs():
    """States of a 3 s closed loop of each scenario (daqp or clarabel through qpsolvers)."""
    from qpbench.backends import backend_names
    from qpbench.sim.loop import simulate

    names = backend_names()
    backend = next(
        (b for b in ("qpsolvers:daqp", "qpsolvers:clarabel", "clarabel") if b in names), None
    )
    if backend is None:
        pytest.skip("no QP backend available")
    return {s: simulate(s, backend, duration=3.0).log for s in SCENARIOS}


@pytest.mark.parametrize("formulation", ["paper", "soft"])
@pytest.mark.parametrize("name", SCENARIOS)
def test_independent_cvxpy_model_has_the_same_optimum(runs, name, formulation):
    sc = load_scenario(name)
    ctrl = sc.make_controller()
    log = runs[name]
    n = ctrl.n
    ticks = [0, 60, 200, 700, 1300, 1500, 2200, 2999]
    if name == "narrow":
        ticks += [300, 545, 546, 1000]
    n_infeasible = n_active = 0
    for k in ticks:
        row = log.iloc[k]
        theta = row[[f"theta_{i}" for i in range(n)]].to_numpy(float)
        t, kp, kd = float(row["t"]), float(row["kp_hat"]), float(row["kd_hat"])
        problem = ctrl.build(theta, t, kp, kd, formulation).problem
        ref, const = independent_qp(file_tables(sc), theta, t, kp, kd, formulation)
        ref.solve(solver=cp.CLARABEL)
        sol = qpsolvers.solve_problem(
            problem, solver="clarabel", tol_gap_abs=1e-10, tol_gap_rel=1e-10, tol_feas=1e-10
        )
        if ref.status in ("infeasible", "infeasible_inaccurate"):
            assert formulation == "paper"
            assert not sol.found, f"{name} tick {k}: cvxpy infeasible, exported problem solved"
            n_infeasible += 1
            continue
        assert ref.status == "optimal", (name, k, ref.status)
        assert sol.found, f"{name} tick {k}: exported problem not solved, cvxpy optimal"
        obj = 0.5 * sol.x @ problem.P @ sol.x + problem.q @ sol.x
        assert obj + const == pytest.approx(ref.value, rel=1e-5, abs=1e-7), (name, k)
        np.testing.assert_allclose(
            sol.x, ref.variables()[0].value, atol=2e-5, err_msg=f"{name} tick {k}"
        )
        if problem.G is not None and np.any(problem.G @ sol.x > problem.h - 1e-7):
            n_active += 1
    if formulation == "paper":
        assert (
            n_infeasible >= 1
        )  # the paper formulation is infeasible at the start of every scenario
    if name in ("wall", "narrow"):
        assert n_active >= 1  # some sampled tick has an active obstacle row


# -- the compiled kernel against the numpy terms ---------------------------------------
def make_controller(obstacles, n=4, radius=0.0, path=None):
    arm = PlanarArm([0.3, 0.4, 0.15, 0.15][:n] if n <= 4 else np.linspace(0.1, 0.3, n))
    kps = default_key_points(n, 2, True, radius)
    path = path or CosinePath([0.4, 0.5], [0.1, 0.1], [0.5, 0.5], [0.1, -0.2])
    task = ImpedanceTask(path, np.array([1.0, -1.0]) / np.sqrt(2), 20.0)
    lim = EscapeVelocityLimits(-3 * np.ones(n), 3 * np.ones(n), -np.ones(n), np.ones(n), 8.0)
    return Controller(
        arm, kps, task, lim, obstacles, k=10.0, d_safe=0.01, rho=1e4, kp=5000.0, kd=50.0
    )


ALL_KINDS = [
    LineObstacle("wall", [-0.05, 0.0], [1.0, 0.0], velocity=[0.02, 0.0]),
    SegmentObstacle("bar", [0.1, 0.1], [0.3, 0.25], velocity=[0.0, -0.05]),
    DiskObstacle("ball", [0.5, 0.0], 0.05, velocity=[0.1, 0.1]),
    PointCloudObstacle("cloud", [[0.0, 0.3], [0.2, 0.5], [0.7, -0.2]], velocity=[-0.03, 0.0]),
]


@pytest.mark.parametrize("formulation", ["paper", "soft"])
@pytest.mark.parametrize("n", [2, 4, 7])
def test_compiled_build_equals_numpy_terms(formulation, n):
    rng = np.random.default_rng(n)
    ctrl = make_controller(ALL_KINDS, n=n, radius=0.01)
    assert ctrl.n_rows == len(ctrl.key_points) * 6
    for _ in range(20):
        theta = rng.uniform(-3, 3, n)
        t = rng.uniform(0, 10)
        a = ctrl.build(theta, t, 4500.0, 70.0, formulation)
        b = numpy_arrays(ctrl, theta, t, 4500.0, 70.0, formulation == "soft")
        twin = ctrl.make_problem(b, formulation == "soft")
        for f in ("P", "q", "G", "h", "A", "b", "lb", "ub"):
            x, y = getattr(a.problem, f), getattr(twin, f)
            assert (x is None) == (y is None)
            if x is not None:
                np.testing.assert_allclose(x, y, rtol=1e-12, atol=1e-9, err_msg=f)
        np.testing.assert_allclose(a.distances, b.dist.reshape(a.distances.shape), atol=1e-14)
        np.testing.assert_allclose(a.ee, b.ee, atol=1e-15)
        assert isinstance(a.problem.P, np.ndarray) and a.problem.P.shape == (n, n)
        assert a.problem.G.shape == (ctrl.n_rows, n)  # fixed row count


def test_problem_shapes_and_formulations():
    ctrl = make_controller([])
    tick = ctrl.build(np.array([1.57, -0.628, -0.524, -0.524]), 0.0)
    p = tick.problem
    np.testing.assert_array_equal(p.P, np.eye(4))
    np.testing.assert_array_equal(p.q, np.zeros(4))
    assert p.G is None and p.h is None
    np.testing.assert_array_equal(p.A, tick.J)
    soft = ctrl.build(np.array([1.57, -0.628, -0.524, -0.524]), 0.0, formulation="soft").problem
    np.testing.assert_allclose(soft.P, np.eye(4) + 1e4 * tick.J.T @ tick.J)
    np.testing.assert_allclose(soft.q, -1e4 * tick.J.T @ tick.b0)
    assert soft.A is None and soft.b is None
    with pytest.raises(ParamError, match="formulation"):
        ctrl.build(np.zeros(4), 0.0, formulation="hard")
    with pytest.raises(ParamError, match="theta"):
        ctrl.build(np.zeros(3), 0.0)
    # successive builds never share arrays
    q1 = ctrl.build(np.zeros(4), 0.0).problem
    q2 = ctrl.build(np.ones(4), 0.0).problem
    assert not np.shares_memory(q1.A, q2.A) and not np.shares_memory(q1.lb, q2.lb)


@pytest.mark.parametrize("formulation", ["paper", "soft"])
@pytest.mark.parametrize("obstacles", [[], ALL_KINDS[:2]], ids=["none", "two"])
def test_fast_problem_equals_qpsolvers_constructor(formulation, obstacles):
    """The problem built without Problem.__init__'s checks is what the constructor makes."""
    ctrl = make_controller(obstacles)
    p = ctrl.build(np.array([1.0, -0.5, 0.3, -0.2]), 0.4, formulation=formulation).problem
    ref = qpsolvers.Problem(p.P, p.q, p.G, p.h, p.A, p.b, p.lb, p.ub)
    assert isinstance(p, PackedProblem) and set(vars(p)) - {"buffer"} == set(vars(ref))
    # the header the kernel wrote describes the same problem (checked constructor)
    unpacked = PackedProblem(p.buffer)
    for key, value in vars(ref).items():
        for mine in (getattr(p, key), getattr(unpacked, key)):
            assert (mine is None) == (value is None), key
            if value is not None:
                assert (
                    type(mine) is type(value)
                    and mine.dtype == value.dtype
                    and mine.shape == value.shape
                ), key
                assert mine.flags.c_contiguous and np.shares_memory(mine, p.buffer), key
                np.testing.assert_array_equal(mine, value)
    p.check_constraints()
    assert p.has_sparse is False


def test_impedance_reference_equilibrium():
    """At x = x_d + Fd/Kp n (at rest on the path) b0 equals xdot_d (eq. 4)."""
    ctrl = make_controller([])
    task = ctrl.task
    xdx, xdy, vdx, vdy = task.path(1.3)
    x = np.array([xdx, xdy]) + 20.0 / 5000.0 * task.normal
    np.testing.assert_allclose(
        task.impedance_reference(x, 1.3, 5000.0, 50.0), [vdx, vdy], atol=1e-14
    )


# -- obstacle rows against finite differences of the distance --------------------------
@pytest.mark.parametrize("obstacle", ALL_KINDS, ids=lambda o: o.name)
def test_obstacle_rows_are_distance_derivatives(obstacle):
    """-G_r v = d dist_r/dtheta . v, and h_r = k (dist_r - d_safe) + d dist_r/dt (moving obstacle)."""
    ctrl = make_controller([obstacle])
    rng = np.random.default_rng(11)
    h = 1e-6
    checked = 0
    for _ in range(20):
        theta = rng.uniform(-3, 3, 4)
        t = rng.uniform(0, 5)
        v = rng.standard_normal(4)
        tick = ctrl.build(theta, t)
        d = tick.distances.reshape(-1)
        dp = ctrl.build(theta + h * v, t).distances.reshape(-1)
        dm = ctrl.build(theta - h * v, t).distances.reshape(-1)
        dtp = ctrl.build(theta, t + h).distances.reshape(-1)
        dtm = ctrl.build(theta, t - h).distances.reshape(-1)
        ok = d > 1e-3  # away from the kink of |A - B| at 0
        np.testing.assert_allclose((-tick.problem.G @ v)[ok], ((dp - dm) / (2 * h))[ok], atol=1e-6)
        np.testing.assert_allclose(
            tick.problem.h[ok], (10.0 * (d - 0.01) + (dtp - dtm) / (2 * h))[ok], atol=1e-6
        )
        checked += ok.sum()
    assert checked > 50


# -- escape-velocity bounds -------------------------------------------------------------
def test_escape_velocity_bounds_keep_theta_inside_limits():
    """Any v within [lb, ub] applied with dt = 1 ms keeps theta in its limits (alpha dt < 1)."""
    rng = np.random.default_rng(0)
    n = 5
    lo, hi = -np.array([3.0, 1.0, 2.0, 0.5, 2.5]), np.array([3.0, 2.0, 0.3, 0.5, 2.5])
    lim = EscapeVelocityLimits(lo, hi, -np.ones(n), np.ones(n), 8.0)
    theta = hi - 1e-3  # start next to the upper limits
    dt = 1e-3
    for step in range(60_000):
        lb, ub = lim.escape_velocity_bounds(theta)
        assert np.all(lb <= 0) and np.all(ub >= 0) and np.all(lb >= -1) and np.all(ub <= 1)
        # random commands, pushed to a bound half the time
        v = rng.uniform(lb, ub)
        push = rng.random(n) < 0.5
        v[push] = np.where(rng.random(push.sum()) < 0.5, lb[push], ub[push])
        theta = theta + dt * v
        assert np.all(theta >= lo) and np.all(theta <= hi), step
    # and the compiled build gives the same bounds
    ctrl = make_controller([])
    th = rng.uniform(-3, 3, 4)
    p = ctrl.build(th, 0.0).problem
    lb, ub = ctrl.limits.escape_velocity_bounds(th)
    np.testing.assert_array_equal(p.lb, lb)
    np.testing.assert_array_equal(p.ub, ub)


# -- paths and the adaptive law ------------------------------------------------------------
def test_paths():
    c = CosinePath([0.4, 0.5], [0.1, 0.1], [0.5, 0.5])
    x, y, vx, vy = c(2.0)
    assert x == pytest.approx(0.4 + 0.1 * np.cos(1.0)) and vx == pytest.approx(-0.05 * np.sin(1.0))
    p = PolylinePath([0.0, 1.0, 3.0], [[0, 0], [1, 0], [1, 2]])
    assert p(0.5) == pytest.approx((0.5, 0.0, 1.0, 0.0))
    assert p(2.0) == pytest.approx((1.0, 1.0, 0.0, 1.0))
    assert p(5.0) == (1.0, 2.0, 0.0, 0.0)


def test_adaptive_law_moves_kp_hat_towards_the_truth():
    """In steady contact with Kp_hat < Kp_env the force exceeds Fd and Kp_hat grows (section 4.4)."""
    n = np.array([0.0, -1.0])
    est = AdaptiveImpedance(4000.0, 80.0, (500.0, 20.0), n, 20.0, 100.0, 1.0)
    kp_env = 5000.0
    x_d = np.array([0.8, -0.15])
    for _ in range(2000):
        x = x_d + 20.0 / est.kp * n  # the controller's equilibrium for its estimate
        force = kp_env * 20.0 / est.kp
        est.update(1e-3, x, x_d, np.zeros(2), np.zeros(2), force)
    assert 4000.0 < est.kp < 5000.0
    assert est.kd == 80.0  # n . xdot = 0: Kd_hat does not move
    fast = AdaptiveImpedance(4000.0, 80.0, (5e4, 20.0), n, 20.0, 100.0, 1.0)
    for _ in range(5000):
        x = x_d + 20.0 / fast.kp * n
        fast.update(1e-3, x, x_d, np.zeros(2), np.zeros(2), kp_env * 20.0 / fast.kp)
    assert fast.kp == pytest.approx(5000.0, rel=0.01)
    fast.reset()
    assert fast.kp == 4000.0


def test_adaptive_law_is_the_same_along_the_normal_of_a_spatial_arm():
    """In 3-D the law reads only the components along ``n``: a planar contact embedded in z = 0,
    any tangential offset and velocity added, gives the planar estimates step for step."""
    rng = np.random.default_rng(3)
    n2 = np.array([1.0, -1.0]) / np.sqrt(2.0)
    n3 = np.array([n2[0], n2[1], 0.0])
    planar = AdaptiveImpedance(4000.0, 80.0, (5e4, 20.0), n2, 20.0, 100.0, 1.0)
    spatial = AdaptiveImpedance(4000.0, 80.0, (5e4, 20.0), n3, 20.0, 100.0, 1.0)
    assert spatial.law().size == planar.law().size + 1
    for _ in range(200):
        x, xd, v, vd = rng.normal(size=(4, 2)) * 1e-3
        force = 20.0 + rng.normal()
        free = np.array([-n2[1], n2[0], 1.0]) * rng.normal(size=3)[:, None]  # tangential
        lift = lambda p: np.append(p, 0.0)  # noqa: E731
        want = planar.update(1e-3, x, xd, v, vd, force)
        got = spatial.update(1e-3, lift(x) + free[0], lift(xd), lift(v) + free[1], lift(vd), force)
        assert got == pytest.approx(want, rel=1e-12)
    assert planar.kp != 4000.0 and planar.kd != 80.0
