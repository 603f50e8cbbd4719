"""Metrics: qpsolvers' residuals reused as is, objective with offset, success rule."""

from __future__ import annotations

import dataclasses
import math
import warnings

import numpy as np
import pytest
import qpsolvers

from qpbench.formats import ProblemRecord
from qpbench.metrics import evaluate, objective
from qpbench.profiles import PROFILES, Tolerance
from qpbench.reference import ReferenceSolution

TOL = PROFILES["default"].tolerance


def _solve(problem, solver="clarabel", **kw):
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        return qpsolvers.solve_problem(problem, solver=solver, **kw)


@pytest.mark.parametrize("solver", ["clarabel", "proxqp", "osqp"])
def test_metrics_equal_qpsolvers_functions(random_qp, solver):
    if solver not in qpsolvers.available_solvers:
        pytest.skip(f"{solver} not available")
    for i in range(5):
        p = random_qp(n=4 + i, n_ineq=3 + i, n_eq=2)
        sol = _solve(p, solver)
        m = evaluate(ProblemRecord(p, f"r{i}", offset=1.5), sol, None, TOL)
        assert m["primal_residual"] == sol.primal_residual()
        assert m["dual_residual"] == sol.dual_residual()
        assert m["duality_gap"] == sol.duality_gap()
        x = sol.x
        assert m["objective"] == pytest.approx(0.5 * x @ p.P @ x + p.q @ x + 1.5, rel=1e-14)
        assert m["found"] is True and m["status"] == "optimal"
        assert math.isnan(m["optimality_gap"]) and math.isnan(m["reference_objective"])


def test_objective_without_solution_obj(random_qp):
    p = random_qp()
    sol = _solve(p)
    sol.obj = None  # some solvers leave it empty
    rec = ProblemRecord(p, "x", offset=-3.0)
    assert evaluate(rec, sol, None, TOL)["objective"] == objective(rec, sol.x)
    assert objective(rec, np.zeros(4)) == -3.0


def test_missing_solution_and_missing_duals(random_qp):
    p = random_qp()
    rec = ProblemRecord(p, "x")
    m = evaluate(rec, None, None, TOL)
    assert m["success"] is False and m["primal_residual"] == math.inf and math.isnan(m["objective"])
    sol = _solve(p)
    nodual = dataclasses.replace(sol, z=None)
    m = evaluate(rec, nodual, None, TOL)
    assert m["dual_residual"] == math.inf == nodual.dual_residual()
    assert m["success"] is False and m["primal_residual"] == sol.primal_residual()


def test_constraint_violation_of_unfound_solution(random_qp):
    p = random_qp(n_eq=None, bounds=False)
    x = np.linalg.solve(p.P, -p.q)  # unconstrained minimiser, violates G x <= h in general
    sol = qpsolvers.Solution(p, found=False, x=x)
    m = evaluate(ProblemRecord(p, "pinv-like"), sol, None, TOL)
    assert m["primal_residual"] == math.inf  # qpsolvers: not found -> inf
    assert m["constraint_violation"] == pytest.approx(
        max(0.0, float(np.max(p.G @ x - p.h))), rel=1e-12
    )
    assert m["status"] == "not_solved" and m["success"] is False


def test_success_rule_with_optimal_reference(random_qp):
    p = random_qp()
    rec = ProblemRecord(p, "x", offset=10.0)
    sol = _solve(p, tol_gap_abs=1e-10, tol_gap_rel=1e-10, tol_feas=1e-10)
    f = objective(rec, sol.x)
    ref = ReferenceSolution("optimal", x=sol.x, objective=f)
    m = evaluate(rec, sol, ref, TOL)
    assert m["success"] is True and m["optimality_gap"] <= 1e-9
    # same residuals, but a reference 1e-3 lower: relative gap 1e-3/max(1,|f*|) fails the 1e-5 tolerance
    shifted = ReferenceSolution("optimal", objective=f - 1e-3 * max(1.0, abs(f)))
    m = evaluate(rec, sol, shifted, TOL)
    assert m["optimality_gap_signed"] == pytest.approx(
        1e-3 * max(1.0, abs(f)) / max(1.0, abs(f - 1e-3 * max(1.0, abs(f))))
    )
    assert m["optimality_gap_signed"] > 0 and m["success"] is False
    # an unknown reference adds no condition
    assert evaluate(rec, sol, ReferenceSolution("unknown"), TOL)["success"] is True
    # each residual threshold is applied on its own
    off = dataclasses.replace(sol, x=sol.x + 1e-4)
    r = {"primal": off.primal_residual(), "dual": off.dual_residual(), "gap": off.duality_gap()}
    assert min(r.values()) > 0
    loose = Tolerance(primal=2 * r["primal"], dual=2 * r["dual"], gap=2 * r["gap"], runtime=1.0)
    assert evaluate(rec, off, None, loose)["success"] is True
    for k in r:
        tight = dataclasses.replace(loose, **{k: r[k] / 2})
        assert evaluate(rec, off, None, tight)["success"] is False, k


@pytest.mark.parametrize("ref_status", ["primal_infeasible", "dual_infeasible"])
def test_success_rule_with_infeasible_reference(random_qp, ref_status):
    from qpbench.backends.base import BackendSolution

    p = random_qp()
    rec = ProblemRecord(p, "x")
    ref = ReferenceSolution(ref_status)
    right = BackendSolution(p, found=False, status=ref_status)
    assert evaluate(rec, right, ref, TOL)["success"] is True
    other = "dual_infeasible" if ref_status == "primal_infeasible" else "primal_infeasible"
    assert (
        evaluate(rec, BackendSolution(p, found=False, status=other), ref, TOL)["success"] is False
    )
    # a "solution" to an infeasible problem is a failure, however small its residuals look
    sol = _solve(p)
    wrong = BackendSolution(
        p, found=True, status="optimal", x=sol.x, y=sol.y, z=sol.z, z_box=sol.z_box
    )
    assert evaluate(rec, wrong, ref, TOL)["success"] is False


def test_constraint_violation_of_a_deliberately_infeasible_point():
    from qpbench.metrics import constraint_violation

    # x = (3, -2) on: x0 <= 1, x1 <= 1 (G x <= h); x0 + x1 = 0 (A x = b); -1 <= x <= (2, 0.5)
    p = qpsolvers.Problem(
        np.eye(2),
        np.zeros(2),
        G=np.eye(2),
        h=np.ones(2),
        A=np.array([[1.0, 1.0]]),
        b=np.array([0.0]),
        lb=np.array([-1.0, -1.0]),
        ub=np.array([2.0, 0.5]),
    )
    x = np.array([3.0, -2.0])
    v = constraint_violation(p, x)
    # G x - h = (2, -3); A x - b = 1; lb - x = (-4, 1), x - ub = (1, -2.5)
    assert v == {
        "violation_ineq": 2.0,
        "violation_eq": 1.0,
        "violation_box": 1.0,
        "constraint_violation": 2.0,
    }
    # in evaluate, whether found or not; equal to qpsolvers' primal residual of a found solution
    for found in (False, True):
        m = evaluate(ProblemRecord(p, "bad"), qpsolvers.Solution(p, found=found, x=x), None, TOL)
        assert m["constraint_violation"] == 2.0 and m["violation_eq"] == 1.0
    assert qpsolvers.Solution(p, found=True, x=x).primal_residual() == 2.0
    # a feasible point violates nothing; no x: NaN; a problem without constraints: 0
    assert constraint_violation(p, np.array([0.5, -0.5]))["constraint_violation"] == 0.0
    assert all(math.isnan(val) for val in constraint_violation(p, None).values())
    assert (
        constraint_violation(qpsolvers.Problem(np.eye(2), np.zeros(2)), x)["constraint_violation"]
        == 0.0
    )
    # infinite bounds are no constraint
    p_inf = qpsolvers.Problem(
        np.eye(2), np.zeros(2), lb=np.array([-np.inf, 0.0]), ub=np.array([np.inf, np.inf])
    )
    assert constraint_violation(p_inf, x)["violation_box"] == 2.0


def test_constraint_violation_equals_qpsolvers_primal_residual(random_qp):
    from qpbench.metrics import constraint_violation

    rng = np.random.default_rng(3)
    for _ in range(20):
        p = random_qp()
        x = 3 * rng.standard_normal(p.q.shape[0])
        expected = qpsolvers.Solution(p, found=True, x=x).primal_residual()
        assert constraint_violation(p, x)["constraint_violation"] == pytest.approx(
            expected, rel=1e-14, abs=1e-15
        )


# ------------------------------------------------------------ per-tick metrics are the CSV's columns


def test_evaluate_returns_every_metric_column_in_order(random_qp):
    from qpbench.metrics import metric_columns

    problem = random_qp()
    record = ProblemRecord(problem, "p")
    m = evaluate(record, _solve(problem), None, TOL)
    assert list(m) == ["status", "found", *metric_columns(), "optimality_gap_signed", "success"]


def test_a_metric_added_here_is_a_column_of_qpbench_bench(tmp_path, monkeypatch):
    """One function registered in metrics: bench writes it as a column, after the other metrics."""
    import faulty_backends as fb
    import pandas as pd

    from qpbench import metrics
    from qpbench.cli import main
    from qpbench.harness.results import bench_columns as columns

    monkeypatch.setattr(metrics, "PER_TICK_METRICS", dict(metrics.PER_TICK_METRICS))

    @metrics.per_tick_metric
    def kkt_residual(tick):
        """The largest of the residuals and the duality gap, read from the metrics before it."""
        v = tick.values
        return max(v["primal_residual"], v["dual_residual"], abs(v["duality_gap"]))

    assert columns()[columns().index("violation_box") + 1] == "kkt_residual"
    folder = fb.write_tick_set(tmp_path / "set", 3)
    out = tmp_path / "rows.csv"
    assert main(["-q", "bench", str(folder), "--backends", "daqp,pinv", "--out", str(out)]) in (
        0,
        1,
    )
    rows = pd.read_csv(out)
    assert list(rows.columns) == list(columns())
    expected = rows[["primal_residual", "dual_residual", "duality_gap"]].abs().max(axis=1)
    np.testing.assert_allclose(rows["kkt_residual"], expected)
    assert (rows["backend"] == "pinv").any() and np.isfinite(rows["kkt_residual"]).any()
    # a metric of an existing name is refused, a re-registered one keeps its place
    with pytest.raises(ValueError, match="dual_residual"):
        metrics.per_tick_metric(lambda tick: 0.0, columns=("dual_residual", "x"))
    metrics.per_tick_metric(kkt_residual)
    assert metrics.metric_columns().count("kkt_residual") == 1
