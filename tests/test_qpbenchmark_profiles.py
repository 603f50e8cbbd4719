"""qpbenchmark's own profiles and success rule, checked against qpbenchmark's installed code.

Nothing here copies a number of qpbenchmark's: the expected keyword arguments,
tolerances and time limits come from a ``qpbenchmark.TestSet`` built in the
test (as its test sets build them), and the expected success flags from its
``Results.build_success_rate_df``.
"""

from __future__ import annotations

import shutil

import numpy as np
import pandas as pd
import pytest
import qpsolvers

from qpbench.backends import backend_names, get_backend
from qpbench.cli import main
from qpbench.formats import load_problems
from qpbench.harness.bench import BenchConfig, run_bench
from qpbench.profiles import get_profile, profile_names


def _test_set(qpb, runtime=None):
    """A qpbenchmark test set as its own test sets make one (its settings, its tolerances)."""

    class Empty(qpb.TestSet):
        title = description = "empty"
        sparse_only = False

        def __iter__(self):
            return iter(())

        def define_tolerances(self):
            if runtime is None:
                super().define_tolerances()
            else:  # as qpbenchmark's Maros-Meszaros test set does with 1000 s
                super().define_tolerances(runtime=runtime)

    return Empty()


def _routes():
    return sorted(n.split(":", 1)[1] for n in backend_names() if n.startswith("qpsolvers:"))


@pytest.mark.parametrize("runtime", [None, 1000.0])
def test_profiles_pass_qpbenchmarks_arguments_verbatim(qpb, runtime):
    test_set = _test_set(qpb, runtime)
    implemented = qpb.solver_settings.SolverSettings.is_implemented
    assert set(test_set.solver_settings) == {
        n.split(":", 1)[1] for n in profile_names() if n.startswith("qpbenchmark:")
    }
    for settings, tol in test_set.tolerances.items():
        profile = get_profile(f"qpbenchmark:{settings}")
        if runtime is not None:
            profile = profile.with_time_limit(runtime)
        assert (profile.tolerance.primal, profile.tolerance.dual, profile.tolerance.gap) == (
            tol.primal,
            tol.dual,
            tol.gap,
        )
        assert profile.time_limit == tol.runtime and profile.tolerance.rule == "qpbenchmark"
        for solver in _routes():
            if not implemented(solver):
                continue
            options = get_backend(f"qpsolvers:{solver}", profile).solver_options
            assert options == test_set.solver_settings[settings][solver], (settings, solver)


def test_the_solver_is_called_with_those_arguments(qpb, mm_dir, tmp_path, monkeypatch):
    """What qpsolvers' function for each solver (the one qpsolvers.solve_problem dispatches to)
    receives in a bench run under qpbenchmark:high_accuracy, beside initvals and verbose."""
    import qpsolvers

    table = qpsolvers.solve_problem.__globals__["solve_function"]
    calls = []

    def spy(solver):
        real = table[solver]

        def call(problem, initvals=None, verbose=False, **kwargs):
            assert verbose is False
            calls.append((solver, kwargs))
            return real(problem, initvals=initvals, verbose=verbose, **kwargs)

        return call

    for solver in ("osqp", "clarabel"):
        monkeypatch.setitem(table, solver, spy(solver))
    ps = load_problems(mm_dir / "HS21.mat")
    config = BenchConfig(
        backends=["qpsolvers:osqp", "qpsolvers:clarabel"],
        profile="qpbenchmark:high_accuracy",
        isolate="never",
        warmup=False,
    )
    run_bench(ps, config, tmp_path / "out.csv", references=[None])
    expected = _test_set(qpb).solver_settings["high_accuracy"]
    assert sorted(calls, key=lambda c: c[0]) == [
        ("clarabel", expected["clarabel"]),
        ("osqp", expected["osqp"]),
    ]


def _qpbenchmark_success(qpb, rows: pd.DataFrame, tol) -> pd.Series:
    """qpbenchmark's own success flags of our rows: one 'solver' per row, rates of 0 or 100."""
    results = qpb.Results.__new__(qpb.Results)
    results.df = pd.DataFrame(
        {
            "problem": rows["problem"],
            "solver": rows["backend"] + "|" + rows["problem"],
            "settings": "s",
            "runtime": rows["wall_time_min_s"],
            "found": rows["found"].astype(bool),
            "primal_residual": rows["primal_residual"].astype(float),
            "dual_residual": rows["dual_residual"].astype(float),
            "duality_gap": rows["duality_gap"].astype(float),
        }
    )
    rates = results.build_success_rate_df({"s": tol.primal}, {"s": tol.dual}, {"s": tol.gap})["s"]
    return (rows["backend"] + "|" + rows["problem"]).map(rates) == 100.0


@pytest.mark.parametrize(
    "profile", ["high_accuracy", "qpbenchmark:high_accuracy", "qpbenchmark:mid_accuracy"]
)
def test_reference_none_and_qpbenchmark_profiles_succeed_by_qpbenchmarks_rule(
    qpb, mm_dir, tmp_path, profile
):
    folder = tmp_path / "mm"
    shutil.copytree(mm_dir, folder, ignore=shutil.ignore_patterns("reference-*"))
    out = tmp_path / "out.csv"
    backends = ",".join(
        b
        for b in ("qpsolvers:osqp", "qpsolvers:scs", "qpsolvers:proxqp", "osqp", "clarabel")
        if b.split(":")[-1] in qpsolvers.available_solvers
    )
    code = main(
        [
            "-q",
            "bench",
            str(folder),
            "--backends",
            backends,
            "--profile",
            profile,
            "--reference",
            "none",
            "--out",
            str(out),
            "--no-warmup",
        ]
    )
    assert code in (0, 1)
    rows = pd.read_csv(out)
    assert rows["reference_status"].isna().all() and rows["optimality_gap"].isna().all()
    assert not list(folder.glob("reference-*"))  # no reference computed
    theirs = _qpbenchmark_success(qpb, rows, get_profile(profile).tolerance)
    assert (rows["success"].astype(bool) == theirs).all()
    # not vacuous: some rows succeed and, under these tolerances, some do not
    assert theirs.any()
    if profile.endswith("high_accuracy"):
        assert not theirs.all()


def test_qpbenchmark_rule_is_strict_where_qpbenchs_is_not():
    """A residual exactly at the threshold: qpbenchmark's rule (strict) fails it, qpbench's passes it."""
    from qpbench.formats import ProblemRecord
    from qpbench.metrics import evaluate

    problem = qpsolvers.Problem(np.eye(1), np.zeros(1), A=np.ones((1, 1)), b=np.ones(1))
    sol = qpsolvers.Solution(
        problem, found=True, x=np.array([1.0 - 1e-6]), y=np.array([-(1.0 - 1e-6)])
    )
    record = ProblemRecord(problem, "p")
    tol = get_profile("default").tolerance
    primal = sol.primal_residual()
    at = type(tol)(primal, 1.0, 1.0, 10.0)
    assert evaluate(record, sol, None, at)["success"]
    assert not evaluate(record, sol, None, type(tol)(primal, 1.0, 1.0, 10.0, rule="qpbenchmark"))[
        "success"
    ]


def test_time_limit_replaces_qpbenchmarks_in_the_solver_arguments(qpb):
    profile = get_profile("qpbenchmark:low_accuracy").with_time_limit(3.0)
    assert profile.time_limit == 3.0 and profile.tolerance.runtime == 3.0
    assert profile.solver_options == {
        s: dict(v)
        for s, v in (
            (s, _test_set(qpb, 3.0).solver_settings["low_accuracy"][s])
            for s in qpb.solver_settings.SolverSettings.IMPLEMENTED_SOLVERS
        )
    }
    assert np.isfinite(profile.reference_time_limit)
