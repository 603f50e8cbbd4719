"""The scaling study's spatial sizes: the presets and generated chains, their start, balls and
tick QPs (convex, feasible at the start, solved with small residuals), and a short run."""

from __future__ import annotations

import csv

import numpy as np
import pytest
import qpsolvers

from qpbench.cli import main
from qpbench.robot.body import body_clearance
from qpbench.robot.chain import forward_kinematics_np
from qpbench.robot.presets import make_chain, modified_dh
from qpbench.scaling.sizes import (
    CLEARANCE,
    DEFAULT_SIZES,
    Size,
    parse_sizes,
    qp_shape,
    start_target,
)
from qpbench.scaling.spatial import (
    REACH,
    chain_of,
    dh_rows,
    generated_chain,
    scenario_file,
    task,
)
from qpbench.sim.scenario import parse_scenario

SPATIAL = ("panda-m4", "iiwa14-m4", "chain14-m4", "chain28-m4")


def test_default_grid_holds_the_spatial_sizes():
    spatial = [s for s in DEFAULT_SIZES if s.axis == "spatial"]
    assert [s.name for s in spatial] == list(SPATIAL)
    assert [qp_shape(s) for s in spatial] == [
        {"n": n, "m_eq": 3, "m_ineq": 4 * n} for n in (7, 7, 14, 28)
    ]
    assert parse_sizes("chain20-m3,iiwa14-m2") == [
        Size(20, 1, 3, "spatial", "chain"),
        Size(7, 1, 2, "spatial", "iiwa14"),
    ]
    assert [s.axis for s in parse_sizes("n4-p1-m10,panda-m4")] == ["cloud", "spatial"]


@pytest.mark.parametrize("n", [14, 28])
def test_generated_chain_alternates_its_axes_and_keeps_the_reach(n):
    chain = generated_chain(n)
    data = forward_kinematics_np(chain, np.zeros(n))
    w = data.axis  # world axes at q = 0: each perpendicular to the next, joint 1 vertical
    assert np.allclose(w[0], [0, 0, 1])
    assert np.allclose(np.einsum("ij,ij->i", w[:-1], w[1:]), 0.0, atol=1e-12)
    assert chain.lengths[:-1].sum() == pytest.approx(REACH)
    assert np.all(chain.q_max > 0) and np.allclose(chain.q_min, -chain.q_max)


def test_dh_rows_of_the_panda_make_the_preset():
    """``kind = "dh"`` is the presets' own construction: the Panda's published rows give it."""
    from qpbench.robot.presets import PANDA_DH, PANDA_LIMITS

    rows = dict(zip(("a", "d", "alpha"), PANDA_DH, strict=True))
    chain, preset = make_chain("dh", **rows, **PANDA_LIMITS), make_chain("panda")
    q = np.random.default_rng(3).uniform(-1, 1, 7)
    a, b = forward_kinematics_np(chain, q), forward_kinematics_np(preset, q)
    assert np.array_equal(a.position, b.position) and np.array_equal(a.rotation, b.rotation)
    assert np.array_equal(modified_dh(*PANDA_DH)[0], modified_dh(*rows.values())[0])


def test_dh_rows_of_unequal_lengths_are_refused():
    rows = dh_rows(4)
    rows["alpha"] = rows["alpha"][:-1]
    with pytest.raises(Exception, match="n \\+ 1 values each"):
        make_chain("dh", **rows)


@pytest.mark.parametrize("name", SPATIAL)
def test_spatial_size_starts_in_contact_with_valid_qps(name, tmp_path):
    [size] = parse_sizes(name)
    text = scenario_file(size, 0, 0.1)
    scenario = parse_scenario(text, tmp_path / f"{name}.toml")
    chain, theta0 = scenario.make_arm().model, scenario.theta0
    assert np.allclose(chain.rotation, chain_of(size).rotation, atol=1e-12)
    assert np.all((theta0 > chain.q_min) & (theta0 < chain.q_max))
    ee = forward_kinematics_np(chain, theta0).position[-1]
    assert np.allclose(ee, start_target(task()), atol=1e-9)  # 4 mm into the table, paper eq. 4
    obstacles, radius = scenario.make_obstacles(), scenario.spec.key_points.link_radius
    body = body_clearance(scenario.make_arm(), theta0, 0.0, obstacles, radius)
    d_safe = scenario.spec.controller.d_safe
    assert d_safe + CLEARANCE <= np.nanmin(body.d) < d_safe + CLEARANCE + 0.002
    problem = scenario.make_controller().build(theta0, 0.0).problem
    P, G, h, A = (np.array(getattr(problem, k), dtype=float) for k in "PGhA")
    shape = qp_shape(size)
    assert P.shape == (shape["n"],) * 2 and A.shape == (shape["m_eq"], shape["n"])
    assert G.shape == (shape["m_ineq"], shape["n"])
    assert np.linalg.eigvalsh((P + P.T) / 2).min() >= -1e-9 * np.abs(P).max()  # convex
    assert np.all(h > 0)  # the balls outside d_safe: v = 0 keeps every obstacle row
    lb, ub = np.asarray(problem.lb), np.asarray(problem.ub)
    # the least-norm point of the equality rows keeps the bounds and the obstacle rows
    v = np.linalg.lstsq(A, np.asarray(problem.b), rcond=None)[0]
    assert np.all((lb <= v) & (v <= ub)) and np.all(G @ v <= h)  # feasible at the start
    dense = qpsolvers.Problem(P, problem.q, G, h, A, problem.b, lb, ub)
    solution = qpsolvers.solve_problem(dense, solver="daqp")
    assert solution.found
    assert solution.primal_residual() < 1e-9 and solution.dual_residual() < 1e-9
    assert abs(solution.duality_gap()) < 1e-8


def test_scaling_command_on_the_panda(tmp_path):
    out = tmp_path / "scaling"
    args = ["scaling", "--backends", "daqp", "--sizes", "panda-m4", "--out", str(out)]
    assert main([*args, "--duration", "0.05", "--every", "10", "--repeat", "1", "-q"]) == 0
    with open(out / "scaling.csv", newline="") as fh:
        [row] = list(csv.DictReader(fh))
    assert (row["axis"], row["robot"], row["n"], row["m_eq"], row["m_ineq"]) == (
        "spatial",
        "panda",
        "7",
        "3",
        "28",
    )
    assert row["status"] == "measured" and float(row["success_rate"]) == 1.0
    with open(out / "bench" / "panda-m4.csv", newline="") as fh:
        bench = list(csv.DictReader(fh))
    assert len(bench) == 5 and {(r["n"], r["m_eq"], r["m_ineq"]) for r in bench} == {
        ("7", "3", "28")
    }
    assert "spatial axis" in (out / "scaling.md").read_text()
