"""Our metrics agree with qpbenchmark's own run of the same Parquet problems.

Problems: the first 60 problems of the shipped ``problems/wall`` set (the
13 primal-infeasible ticks at its start, then 47 optimal ones), written with
pandas as a bare qpbenchmark Parquet file (the ``ProblemList`` columns only).
Both programs read that same file:

- qpbenchmark: a :class:`qpbenchmark.ParquetTestSet` subclass run by
  :func:`qpbenchmark.run` in this process, its rows taken from
  :class:`qpbenchmark.Results` (``found``, ``primal_residual``,
  ``dual_residual``, ``duality_gap``, computed by qpsolvers on the solution it got);
- qpbench: ``qpsolvers:<name>`` backends in ``independent`` mode, through
  :func:`qpbench.harness.bench.run_bench` (the function behind ``qpbench bench``)
  or the CLI itself, rows read back from the CSV.

Solvers: every solver both can drive here (qpsolvers finds it, qpbenchmark
has settings for it, qpbench has an available ``qpsolvers:<name>`` backend).

Settings, two honest ways:

1. ``test_same_solver_calls_same_metrics``: qpbenchmark's own named settings
   ``low_accuracy``, ``mid_accuracy``, ``high_accuracy`` (its ``default``, the
   solvers' own defaults judged at tolerance 1, has no qpbench profile). Our
   backend gets qpbenchmark's keyword arguments verbatim as settings; the keys
   qpbench adds on its own (iteration limits, Clarabel's time limit, OSQP's
   polishing) are set to the solver's own default, read from the installed
   solver package. The test first checks that the backend's options then
   equal qpbenchmark's arguments plus those defaults, key for key: both sides
   make the same ``qpsolvers.solve_problem`` call. The solution is then the
   same, so the residuals may differ by rounding only (qpbenchmark evaluates
   sparse-only solvers' residuals on the CSC copy it solved, we on the dense
   problem): ``|a - b| <= 1e-12 max(|a|, |b|) + 16 eps s`` with ``s`` the
   largest finite magnitude in the problem's data (dimensionless, as the data).
   ``found`` must be equal, and so must qpbenchmark's success rule (found and
   each residual below the settings' tolerance) evaluated on either side's rows,
   per row and as :meth:`qpbenchmark.Results.build_success_rate_df`'s rates.
2. ``test_cli_profile_against_qpbenchmark_settings``: the CLI ``qpbench bench
   --profile P`` as a user runs it, against qpbenchmark run with settings built
   by its own API from P's numbers (``set_eps_abs``, ``set_eps_rel``,
   ``set_time_limit`` and ``check_duality_gap`` for piqp/proxqp, as its named
   settings do). qpbenchmark's keys must appear in our options with the same
   values. A solver whose options differ from qpbenchmark's in nothing but
   limits (iteration/time limits that a converging solve never reaches) makes
   the same run and must agree as above; a solver given something more
   (OSQP's polishing at ``eps_abs <= 1e-7``) makes another run, and where
   both found a solution the residuals agree to the profile's tolerance.

Our ``success`` column adds two things to qpbenchmark's rule (see
:mod:`qpbench.metrics`): the optimality gap against the reference, and
"reporting infeasibility of an infeasible problem is a success". On problems
whose reference is optimal, our success implies qpbenchmark's.
"""

from __future__ import annotations

import math
import sys
import warnings
from dataclasses import replace
from pathlib import Path

import numpy as np
import pandas as pd
import pytest

from qpbench.backends import get_backend
from qpbench.cli import main
from qpbench.formats import load_problems
from qpbench.harness.bench import BenchConfig, run_bench
from qpbench.profiles import get_profile
from qpbench.reference import reference_solutions

ROOT = Path(__file__).resolve().parents[1]
# bench/qpbenchmark_agreement.py runs this comparison on whole sets: its constants, the solvers
# both programs drive, the data scale and qpbenchmark's success rule are used here as they are there
sys.path.insert(0, str(ROOT / "bench"))
from qpbenchmark_agreement import (  # noqa: E402
    EPS,
    LIMIT_KEYS,
    METRICS,
    NAMED_SETTINGS,
    common_solvers,
    data_scale,
    qpbenchmark_success,
    side,
)

SHIPPED_SET = ROOT / "problems" / "wall" / "problems.parquet"
#: Problems taken from the start of the shipped set.
COUNT = 60
#: Relative agreement of residuals evaluated on the same solution.
RTOL_SAME = 1e-12


# ---------------------------------------------------------------- helpers


def solver_default_limits(solver: str) -> dict | None:
    """The solver's own defaults (native names, read from the installed package) of the options
    qpbench adds beyond qpbenchmark's; ``None`` when this function does not know them."""
    if solver == "clarabel":
        import clarabel

        s = clarabel.DefaultSettings()
        return {"max_iter": s.max_iter, "time_limit": s.time_limit}
    if solver == "daqp":
        import daqp

        return {"iter_limit": daqp.Model().settings["iter_limit"]}
    if solver == "osqp":
        import osqp
        import scipy.sparse as spa

        one = spa.csc_matrix(np.eye(1))
        o = osqp.OSQP()
        o.setup(one, np.zeros(1), one, -np.ones(1), np.ones(1), verbose=False)
        return {"max_iter": int(o.settings.max_iter), "polishing": bool(o.settings.polishing)}
    if solver == "piqp":
        import piqp

        return {"max_iter": piqp.DenseSolver().settings.max_iter}
    if solver == "proxqp":
        import proxsuite

        return {"max_iter": proxsuite.proxqp.dense.QP(1, 0, 0).settings.max_iter}
    if solver == "scs":
        # SCS's Python binding does not expose its defaults; 1e5 is SCS 3's documented max_iters.
        return {"max_iters": 100_000}
    if solver in ("highs", "quadprog"):
        return {}
    return None


def _test_set_class(qpb):
    class WallSlice(qpb.ParquetTestSet):
        title = "qpbench wall slice"
        description = "First problems of qpbench's wall problem set"
        sparse_only = False

    return WallSlice


def run_qpbenchmark(qpb, test_set, solvers, csv_path) -> pd.DataFrame:
    """qpbenchmark's runner on ``test_set`` restricted to ``solvers``; its results rows."""
    test_set.solvers = set(solvers)
    results = qpb.Results(csv_path, test_set)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        qpb.run(test_set, results)
    return results.df.reset_index(drop=True), results


def read_ours(path) -> pd.DataFrame:
    df = pd.read_csv(
        path
    )  # repr-exact floats in the CSV; a parser off by 1 ulp is far inside the allowance
    df["solver"] = df["backend"].str.split(":", n=1).str[1]
    return df


def metric_differences(merged: pd.DataFrame) -> pd.DataFrame:
    """Per row and metric: ``|a - b|`` and the rounding allowance; inf on both sides counts as equal."""
    out = {}
    for k in METRICS:
        a = merged[f"{k}_qpb"].to_numpy(float)
        b = merged[f"{k}_ours"].to_numpy(float)
        both_inf = np.isinf(a) & np.isinf(b) & (np.sign(a) == np.sign(b))
        with np.errstate(invalid="ignore"):
            d = np.where(both_inf, 0.0, np.abs(a - b))
        out[f"{k}_diff"] = d
        out[f"{k}_allow"] = RTOL_SAME * np.where(
            both_inf, 0.0, np.maximum(np.abs(a), np.abs(b))
        ) + 16 * EPS * merged["scale"].to_numpy(float)
    return pd.DataFrame(out, index=merged.index)


# ---------------------------------------------------------------- fixtures


@pytest.fixture(scope="module")
def wall_slice(tmp_path_factory, qpb) -> Path:
    if not SHIPPED_SET.exists():
        pytest.skip(f"{SHIPPED_SET} not found")
    df = pd.read_parquet(SHIPPED_SET).iloc[:COUNT]
    path = tmp_path_factory.mktemp("qpbenchmark") / "wall_slice.parquet"
    df[list(qpb.ProblemList.KEYS)].to_parquet(path, index=False)
    return path


@pytest.fixture(scope="module")
def problem_set(wall_slice):
    return load_problems(wall_slice)


@pytest.fixture(scope="module")
def scales(problem_set) -> dict:
    return {r.name: data_scale(r.problem) for r in problem_set.records}


@pytest.fixture(scope="module")
def references(problem_set):
    return reference_solutions(problem_set, cache=False)


@pytest.fixture(scope="module")
def solvers(qpb) -> list[str]:
    found = common_solvers(qpb)
    if not found:
        pytest.skip("no solver that both qpbenchmark and qpbench can drive")
    return found


# ---------------------------------------------------------------- tests


def test_slice_is_read_alike(qpb, wall_slice, problem_set):
    """Both programs read the same problems from the file (names and data, bit for bit)."""
    test_set = _test_set_class(qpb)(wall_slice)
    theirs = list(test_set)
    assert [p.name for p in theirs] == [r.name for r in problem_set.records]
    assert len(theirs) == COUNT
    for p, r in zip(theirs, problem_set.records):
        for k in ("P", "q", "G", "h", "A", "b", "lb", "ub"):
            a, b = getattr(p, k), getattr(r.problem, k)
            assert (a is None) == (b is None), (p.name, k)
            if a is not None:
                np.testing.assert_array_equal(a, b, err_msg=f"{p.name} {k}")


def test_same_solver_calls_same_metrics(
    qpb, tmp_path, wall_slice, problem_set, references, scales, solvers
):
    """qpbenchmark's named settings on both sides: same calls, metrics equal to rounding."""
    test_set = _test_set_class(qpb)(wall_slice)
    test_set.solver_settings = {k: test_set.solver_settings[k] for k in NAMED_SETTINGS}
    test_set.tolerances = {k: test_set.tolerances[k] for k in NAMED_SETTINGS}
    usable = [s for s in solvers if solver_default_limits(s) is not None]
    assert usable, f"no solver among {solvers} whose added options can be neutralised"
    theirs, results = run_qpbenchmark(qpb, test_set, usable, tmp_path / "qpbenchmark.csv")
    assert len(theirs) == COUNT * len(usable) * len(NAMED_SETTINGS)

    frames = []
    for settings_name, profile_name in NAMED_SETTINGS.items():
        tol = test_set.tolerances[settings_name]
        profile = replace(get_profile(profile_name), time_limit=tol.runtime)
        assert (profile.tolerance.primal, profile.tolerance.dual, profile.tolerance.gap) == (
            tol.primal,
            tol.dual,
            tol.gap,
        )
        for solver in usable:
            kwargs = dict(test_set.solver_settings[settings_name][solver])
            settings = {**solver_default_limits(solver), **kwargs}
            options = get_backend(f"qpsolvers:{solver}", profile, **settings).solver_options
            assert options == settings, (settings_name, solver, options, settings)
            out = tmp_path / f"ours-{settings_name}-{solver}.csv"
            config = BenchConfig(
                backends=[f"qpsolvers:{solver}"],
                profile=profile,
                mode="independent",
                isolate="never",
                settings=settings,
            )
            run_bench(problem_set, config, out, references=references)
            ours = read_ours(out)
            ours["settings"] = settings_name
            frames.append(ours)
    ours = pd.concat(frames, ignore_index=True)

    merged = theirs.merge(
        ours, on=["problem", "solver", "settings"], suffixes=("_qpb", "_ours"), validate="1:1"
    )
    assert len(merged) == len(theirs) == len(ours)
    merged["scale"] = merged["problem"].map(scales)

    mismatch = merged[merged["found_qpb"].astype(bool) != merged["found_ours"].astype(bool)]
    assert mismatch.empty, mismatch[
        ["problem", "solver", "settings", "found_qpb", "found_ours", "status"]
    ]
    # Infeasible ticks: nobody "finds" a solution; optimal ones: at least one solver does.
    infeasible = {r.name for r in references if r.status == "primal_infeasible"}
    assert infeasible, "the slice should hold the infeasible ticks at the start of the wall set"
    assert not merged[merged["problem"].isin(infeasible)]["found_qpb"].any()
    assert merged[~merged["problem"].isin(infeasible)]["found_qpb"].any()

    diffs = metric_differences(merged)
    for k in METRICS:
        bad = diffs[f"{k}_diff"] > diffs[f"{k}_allow"]
        assert not bad.any(), merged.loc[
            bad, ["problem", "solver", "settings", f"{k}_qpb", f"{k}_ours"]
        ]
        # not found <=> inf on both sides
        found = merged["found_qpb"].astype(bool)
        assert np.isinf(merged.loc[~found, f"{k}_ours"]).all()
        assert np.isfinite(merged.loc[found, f"{k}_ours"]).all()

    # qpbenchmark's success rule, row by row and as its own success-rate table.
    for settings_name in NAMED_SETTINGS:
        tol = test_set.tolerances[settings_name]
        rows = merged[merged["settings"] == settings_name]
        a = qpbenchmark_success(side(rows, "_qpb"), tol)
        b = qpbenchmark_success(side(rows, "_ours"), tol)
        assert (a == b).all(), rows.loc[a != b, ["problem", "solver"]]
    tols = test_set.tolerances
    rate_theirs = results.build_success_rate_df(
        {k: t.primal for k, t in tols.items()},
        {k: t.dual for k, t in tols.items()},
        {k: t.gap for k, t in tols.items()},
    )
    ours_as_qpb = ours.astype({"found": bool})[
        ["problem", "solver", "settings", "found", *METRICS]
    ].copy()
    ours_results = qpb.Results(None, test_set)
    ours_results.df = ours_as_qpb
    rate_ours = ours_results.build_success_rate_df(
        {k: t.primal for k, t in tols.items()},
        {k: t.dual for k, t in tols.items()},
        {k: t.gap for k, t in tols.items()},
    )
    pd.testing.assert_frame_equal(rate_theirs.sort_index(), rate_ours.sort_index())

    # Our success adds conditions: on problems with an optimal reference it implies qpbenchmark's.
    for settings_name in NAMED_SETTINGS:
        tol = test_set.tolerances[settings_name]
        rows = merged[
            (merged["settings"] == settings_name) & (merged["reference_status"] == "optimal")
        ]
        theirs_ok = qpbenchmark_success(side(rows, "_qpb"), tol)
        ours_ok = rows["success"].astype(bool)
        assert not (ours_ok & ~theirs_ok).any(), rows.loc[
            ours_ok & ~theirs_ok, ["problem", "solver"]
        ]


@pytest.mark.parametrize("profile_name", ["default", "high_accuracy"])
def test_cli_profile_against_qpbenchmark_settings(
    qpb, tmp_path, wall_slice, scales, solvers, profile_name
):
    """``qpbench bench --profile P`` against qpbenchmark with settings built by its API from P."""
    profile = get_profile(profile_name)
    SolverSettings = qpb.solver_settings.SolverSettings
    Tolerance = qpb.Tolerance

    class ProfileSlice(_test_set_class(qpb)):
        def define_tolerances(self, runtime: float = 10.0) -> None:
            t = profile.tolerance
            self.tolerances = {profile.name: Tolerance(t.primal, t.dual, t.gap, profile.time_limit)}

        def define_solver_settings(self) -> None:
            s = SolverSettings()
            s.set_eps_abs(profile.eps_abs)
            s.set_eps_rel(profile.eps_rel)
            s.set_param("piqp", "check_duality_gap", True)
            s.set_param("proxqp", "check_duality_gap", True)
            s.set_time_limit(profile.time_limit)
            self.solver_settings = {profile.name: s}

    test_set = ProfileSlice(wall_slice)
    same_run, other_run = [], []
    for solver in solvers:
        kwargs = test_set.solver_settings[profile.name][solver]
        options = get_backend(f"qpsolvers:{solver}", profile).solver_options
        differs = {k: (v, options.get(k)) for k, v in kwargs.items() if options.get(k) != v}
        assert not differs, f"{solver}: qpbenchmark's option (theirs, ours) {differs}"
        extra = set(options) - set(kwargs)
        (same_run if extra <= LIMIT_KEYS else other_run).append(solver)

    theirs, _ = run_qpbenchmark(qpb, test_set, solvers, tmp_path / "qpbenchmark.csv")
    out = tmp_path / "ours.csv"
    code = main(
        [
            "--quiet",
            "bench",
            str(wall_slice),
            "--backends",
            ",".join(f"qpsolvers:{s}" for s in solvers),
            "--profile",
            profile.name,
            "--mode",
            "independent",
            "--out",
            str(out),
        ]
    )
    assert code in (0, 1)
    ours = read_ours(out).rename(columns={"profile": "settings"})
    merged = theirs.merge(
        ours, on=["problem", "solver", "settings"], suffixes=("_qpb", "_ours"), validate="1:1"
    )
    assert len(merged) == len(theirs) == COUNT * len(solvers)
    merged["scale"] = merged["problem"].map(scales)
    diffs = metric_differences(merged)

    same = merged["solver"].isin(same_run)
    assert (
        merged.loc[same, "found_qpb"].astype(bool) == merged.loc[same, "found_ours"].astype(bool)
    ).all()
    tol = profile.tolerance
    for k, level in zip(METRICS, (tol.primal, tol.dual, tol.gap)):
        bad = same & (diffs[f"{k}_diff"] > diffs[f"{k}_allow"])
        assert not bad.any(), merged.loc[bad, ["problem", "solver", f"{k}_qpb", f"{k}_ours"]]
        both = ~same & merged["found_qpb"].astype(bool) & merged["found_ours"].astype(bool)
        bad = both & (diffs[f"{k}_diff"] > level)
        assert not bad.any(), merged.loc[bad, ["problem", "solver", f"{k}_qpb", f"{k}_ours"]]
    assert math.isfinite(float(diffs.to_numpy().max()))
