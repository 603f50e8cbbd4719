"""The scaling study: generated arms, clouds, QP shapes, slope fits, and ``qpbench scaling`` end to end."""

from __future__ import annotations

import csv
import math

import numpy as np
import pytest

from qpbench.cli import main
from qpbench.harness.results import read_results
from qpbench.robot.kinematics import PlanarArm
from qpbench.scaling.report import crossing, extrapolated_crossing, first_above, fit_power_law
from qpbench.scaling.runner import COLUMNS
from qpbench.scaling.sizes import (
    DEFAULT_SIZES,
    REACH,
    THETA_LIMIT,
    Size,
    generate,
    generate_arm,
    min_key_point_distance,
    parse_sizes,
    qp_shape,
    scenario_toml,
    start_target,
    task,
)
from qpbench.sim.scenario import parse_scenario

LINKS = (4, 8, 16, 32, 64)


def _fd_jacobian(arm: PlanarArm, theta, links, fracs, h=1e-6) -> np.ndarray:
    """Central differences of the key points' forward kinematics, shape (a, 2, n)."""
    J = np.empty((len(links), 2, arm.n))
    for k in range(arm.n):
        e = np.zeros(arm.n)
        e[k] = h
        J[:, :, k] = (arm.points(theta + e, links, fracs) - arm.points(theta - e, links, fracs)) / (
            2 * h
        )
    return J


@pytest.mark.parametrize("n", LINKS)
def test_generated_arm_jacobians_match_finite_differences(n):
    gen = generate_arm(n, 2, start_target(), seed=3)
    kp = gen.key_points
    assert len(kp) == 3 * n - 1 == Size(n, 2, 1).key_points
    assert gen.arm.lengths.sum() == pytest.approx(REACH)
    _, J = gen.arm.points_jacobians(gen.theta0, kp.links, kp.fracs)
    np.testing.assert_allclose(J, _fd_jacobian(gen.arm, gen.theta0, kp.links, kp.fracs), atol=1e-8)
    # and at another state than the start
    theta = gen.theta0 + np.random.default_rng(n).uniform(-0.3, 0.3, n)
    _, J = gen.arm.points_jacobians(theta, kp.links, kp.fracs)
    np.testing.assert_allclose(J, _fd_jacobian(gen.arm, theta, kp.links, kp.fracs), atol=1e-8)


@pytest.mark.parametrize("n", LINKS)
def test_qp_obstacle_rows_are_minus_u_times_the_finite_difference_jacobian(n):
    size = Size(n, 2, 5)
    gen, cloud = generate(size, seed=1)
    controller = parse_scenario(scenario_toml(size, gen, cloud, 0.1)).make_controller()
    G = controller.build(gen.theta0, 0.0).problem.G
    kp = gen.key_points
    A = gen.key_point_positions()
    J = _fd_jacobian(gen.arm, gen.theta0, kp.links, kp.fracs)
    diff = A[:, None, :] - cloud.points[None, :, :]
    u = diff / np.linalg.norm(diff, axis=2, keepdims=True)
    expected = -np.einsum("amk,akn->amn", u, J).reshape(-1, n)
    np.testing.assert_allclose(G, expected, atol=1e-7)


@pytest.mark.parametrize("size", DEFAULT_SIZES, ids=lambda s: s.name)
def test_start_state_is_feasible(size):
    gen, cloud = generate(size)
    # every key point outside the cloud by d_safe and a margin
    assert (
        min_key_point_distance(gen.key_point_positions(), cloud.points)
        >= task()["controller"]["d_safe"] + 0.01
    )
    assert np.all(np.abs(gen.theta0) < THETA_LIMIT)
    # the end effector rests in contact: Fd / Kp past x_d(0) along the pressing direction
    np.testing.assert_allclose(gen.arm.end_effector(gen.theta0), start_target(), atol=1e-9)
    normal = np.array(task()["contact"]["normal"]) / np.hypot(*task()["contact"]["normal"])
    penetration = normal @ (gen.target - np.array(task()["path"]["centre"]))
    assert penetration == pytest.approx(
        task()["controller"]["desired_force"] / task()["controller"]["kp"]
    )
    # the cloud approaches the arm
    assert np.hypot(*cloud.velocity) == pytest.approx(0.1)


@pytest.mark.parametrize(
    "size", [s for s in DEFAULT_SIZES if not s.spatial], ids=lambda s: s.name
)  # the spatial ones: tests/test_scaling_spatial.py
def test_tick_qp_shapes_follow_the_formula_and_v0_is_feasible(size):
    gen, cloud = generate(size)
    scenario = parse_scenario(scenario_toml(size, gen, cloud, 0.1), f"{size.name}.toml")
    problem = scenario.make_controller().build(scenario.spec.robot.theta0, 0.0).problem
    shape = qp_shape(size)
    assert problem.P.shape == (shape["n"], shape["n"])
    assert problem.A.shape == (shape["m_eq"], shape["n"])
    assert (
        problem.G.shape
        == (shape["m_ineq"], shape["n"])
        == (size.key_points * size.cloud_points, size.links)
    )
    assert problem.lb.shape == problem.ub.shape == (size.links,)
    # v = 0 satisfies every obstacle row and bound at the start; the task asks for the path's speed only
    assert np.all(problem.h > 0)
    assert np.all(problem.lb < 0) and np.all(problem.ub > 0)
    assert np.hypot(*problem.b) == pytest.approx(0.05 * math.sqrt(2), rel=1e-6)


def test_generation_is_deterministic_in_the_seed():
    a, ca = generate(Size(16, 2, 100), seed=5)
    b, cb = generate(Size(16, 2, 100), seed=5)
    c, cc = generate(Size(16, 2, 100), seed=6)
    np.testing.assert_array_equal(a.theta0, b.theta0)
    np.testing.assert_array_equal(ca.points, cb.points)
    assert not np.array_equal(a.arm.lengths, c.arm.lengths)
    assert not np.array_equal(ca.points, cc.points)


def test_the_smallest_size_is_the_papers_4_by_7():
    shape = qp_shape(DEFAULT_SIZES[0])
    assert (shape["n"], shape["m_ineq"]) == (4, 7)
    assert max(qp_shape(s)["m_ineq"] for s in DEFAULT_SIZES) >= 3000


def test_fit_recovers_a_known_slope():
    rng = np.random.default_rng(0)
    s = np.repeat(np.geomspace(4, 4000, 8), 3)
    t = 2e-6 * s**1.7 * np.exp(rng.normal(0, 0.05, s.size))
    fit = fit_power_law(s, t)
    assert abs(fit.slope - 1.7) < 3 * fit.slope_se
    assert 0 < fit.slope_se < 0.05
    exact = fit_power_law([1, 10, 100], [3.0, 30.0, 300.0])
    assert exact.slope == pytest.approx(1.0) and exact.slope_se == pytest.approx(0.0, abs=1e-12)
    assert exact.predict(1000) == pytest.approx(3000.0)
    two = fit_power_law([1, 10], [1.0, 100.0])
    assert two.slope == pytest.approx(2.0) and math.isnan(two.slope_se)
    assert math.isnan(fit_power_law([5], [1.0]).slope)


def test_crossings():
    sizes = [1, 10, 100, 1000]
    assert crossing(sizes, [1, 2, 4, 8], [5, 3, 3, 3]) == 100
    assert crossing(sizes, [1, 2, 4, 8], [5, 3, 5, 9]) is None
    assert first_above(sizes, [0.1, 2, 0.5, 3], 1.0) == 1000
    a = fit_power_law([1, 10, 100], [1, 10, 100])  # slope 1
    b = fit_power_law([1, 10, 100], [100, 100, 100])  # flat at 100
    assert extrapolated_crossing(a, b) == pytest.approx(100.0)


def test_parse_sizes():
    assert parse_sizes("default") == list(DEFAULT_SIZES)
    assert [s.axis for s in parse_sizes("n4-p1-m10,n5-p3-m7")] == ["cloud", "arm"]
    assert parse_sizes("n5-p3-m7")[0].key_points == 5 * 3 + 4
    for bad in ("n1-p1-m1", "x4-p1-m1", "n4-p0-m1", "n4-p1", "n4-p1-m10,n4-p1-m10"):
        with pytest.raises(Exception) as exc:
            parse_sizes(bad)
        assert exc.value.exit_code == 2


def _rows(path):
    with open(path, newline="") as fh:
        return list(csv.DictReader(fh))


def test_command_end_to_end_on_the_two_smallest_sizes(tmp_path, capsys):
    out = tmp_path / "scaling"
    args = [
        "scaling",
        "--backends",
        "daqp,clarabel",
        "--sizes",
        "n4-p1-m1,n4-p1-m10",
        "--out",
        str(out),
        "--duration",
        "0.05",
        "--every",
        "10",
        "--repeat",
        "1",
        "-q",
    ]
    assert main(args) == 0
    rows = _rows(out / "scaling.csv")
    assert tuple(rows[0]) == COLUMNS
    assert {(r["size"], r["backend"]) for r in rows} == {
        (s, b) for s in ("n4-p1-m1", "n4-p1-m10") for b in ("daqp", "clarabel")
    }
    for r in rows:
        assert r["status"] == "measured" and r["problems"] == "5"
        assert float(r["success_rate"]) == 1.0
        assert 0 < float(r["time_median_s"]) <= float(r["time_p99_s"])
        assert float(r["gap_max"]) < 1e-6
        assert 0 < float(r["build_median_s"]) < 1.0
        assert r["m_ineq"] == str(7 * int(r["cloud_points"]))
    bench = _rows(out / "bench" / "n4-p1-m10.csv")
    assert len(bench) == 10 and {r["m_ineq"] for r in bench} == {"70"}
    text = (out / "scaling.md").read_text()
    assert "## Slopes" in text and "| daqp | dense |" in text and "1 ms" in text
    assert (out / "scaling.png").stat().st_size > 0
    # each size is a scenario file of its own
    assert parse_scenario((out / "scenarios" / "n4-p1-m10.toml").read_text()).name == "n4-p1-m10"

    # an existing output is refused; --resume runs nothing new; a half-written line is repaired
    assert main(args) == 2
    assert "exists" in capsys.readouterr().err
    before = (out / "scaling.csv").read_bytes()
    assert main(args + ["--resume"]) == 0
    assert (out / "scaling.csv").read_bytes() == before
    with open(out / "scaling.csv", "ab") as fh:
        fh.write(b"n4-p1-m100,cloud,4")
    assert len(read_results(out / "scaling.csv", repair=True, columns=COLUMNS).rows) == 4
    assert (out / "scaling.csv").read_bytes() == before

    # qpbench report renders the same folder
    report = tmp_path / "report"
    assert main(["report", str(out), "--out", str(report), "-q"]) == 0
    assert (report / "scaling.md").read_text() == text


def test_dense_backends_skip_above_the_limit_with_a_reason(tmp_path):
    out = tmp_path / "s"
    assert (
        main(
            [
                "scaling",
                "--backends",
                "daqp,clarabel",
                "--sizes",
                "n4-p1-m1",
                "--out",
                str(out),
                "--duration",
                "0.02",
                "--every",
                "10",
                "--repeat",
                "1",
                "--dense-limit",
                "10",
                "-q",
            ]
        )
        == 0
    )
    rows = {r["backend"]: r for r in _rows(out / "scaling.csv")}
    assert rows["daqp"]["status"] == "skipped" and "dense-only" in rows["daqp"]["skip_reason"]
    assert rows["clarabel"]["status"] == "measured"
    assert "skipped: dense-only" in (out / "scaling.md").read_text()


@pytest.mark.parametrize(
    "extra, key",
    [
        (["--sizes", "n1-p1-m1"], "--sizes"),
        (["--every", "0"], "--every"),
        (["--backends", "osqq"], "osqq"),
    ],
)
def test_bad_input_is_one_line_and_writes_nothing(tmp_path, capsys, extra, key):
    out = tmp_path / "s"
    argv = ["scaling", "--backends", "daqp", "--out", str(out), *extra]
    assert main(argv) == 2
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1 and key in err
    assert not out.exists()
