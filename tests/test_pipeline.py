"""The main job's perturbed runs (qpbench.harness.pipeline): the budget rule that decides each
candidate's instances, and two quick runs in a row giving the same answer."""

from __future__ import annotations

import json
from dataclasses import replace
from pathlib import Path

import pandas as pd
import pytest

from qpbench.cli import main
from qpbench.harness.pipeline import PERTURBED, sweep_plan
from qpbench.report import recommend as rec

PROBLEMS = Path(__file__).resolve().parents[1] / "problems"


def test_the_cheapest_get_their_instances_first():
    costs = {"a": 1.0, "b": 2.0, "c": 3.0}
    # 100 of a (100 s) and 100 of b (200 s) fill 300 s; c gets none
    assert sweep_plan(costs, 300.0, 100) == {"a": 100, "b": 100, "c": 0}
    # what is left after the cheaper ones buys 16 of c, fewer than can recommend it: none
    assert sweep_plan(costs, 350.0, 100) == {"a": 100, "b": 100, "c": 0}
    assert sweep_plan(costs, 600.0, 100) == {"a": 100, "b": 100, "c": 100}
    assert sweep_plan(costs, 1e6, 100) == {"a": 100, "b": 100, "c": 100}
    assert sweep_plan(costs, 50.0, 100) == {"a": 0, "b": 0, "c": 0}
    assert sweep_plan(costs, -5.0, 100) == {"a": 0, "b": 0, "c": 0}
    # equal costs: by name, so the same costs give the same plan
    assert sweep_plan({"y": 1.0, "x": 1.0}, 150.0, 100) == {"x": 100, "y": 0}
    # every planned count reaches the target, and the plan's cost stays within the time
    plan = sweep_plan(costs, 450.0, 100)
    assert set(plan.values()) <= {0, 100} and sum(plan[b] * costs[b] for b in plan) <= 450.0


def strictly_before(answer: rec.Recommendation) -> set[tuple[str, str]]:
    """Pairs (a, b) of recommended backends with a ranked before b and not tied with it."""
    picks = answer.overall.recommended
    return {(a.backend, b.backend) for a in picks for b in picks if a.rank < b.rank}


@pytest.mark.slow
def test_two_quick_runs_give_the_same_answer(tmp_path, monkeypatch):
    """``run --quick`` on two scenarios and two backends (the same code path as the whole quick
    run, which takes a minute or more), twice: the same recommended backends, in the same order
    up to declared ties, and the same verdicts of the perturbed runs both made."""
    monkeypatch.chdir(tmp_path)
    answers, perturbed = [], []
    for out in ("q1", "q2"):
        args = ["-q", "run", "--quick", "--scenarios", "wall,narrow", "--backends", "daqp,pinv"]
        args += ["--problems", str(PROBLEMS), "--sweep-budget", "60", "--out", out]
        assert main(args) == 0
        sweeps = rec.read_sweeps(sorted((tmp_path / out / PERTURBED).glob("*/sweep.csv")))
        loop = pd.read_csv(tmp_path / out / "closed_loop.csv")
        answers.append(rec.recommend(loop, sweeps))
        manifest = json.loads((tmp_path / out / "run.json").read_text())
        assert manifest["perturbed"]["scenarios"] == ["wall", "narrow"]
        assert manifest["perturbed"]["min_ok_bound"] == rec.MIN_OK_BOUND
        assert "pinv" not in manifest["perturbed"]["candidates"]  # breaks the joint limits
        if len(sweeps):
            # an instance that could not run (its drawn scenario invalid) has no verdict: ""
            verdicts = sweeps.set_index(["base_scenario", "instance", "backend"])["verdict"]
            perturbed.append(verdicts.fillna(""))
        md = (tmp_path / out / "report.md").read_text()
        assert md.startswith("# qpbench report\n\n## Recommendation\n")
    first, second = answers
    assert first.overall.backends, "nothing recommended"
    assert set(first.overall.backends) == set(second.overall.backends)
    assert not strictly_before(first) & {(b, a) for a, b in strictly_before(second)}
    if len(perturbed) == 2:  # a run's verdicts do not depend on the machine
        both = perturbed[0].index.intersection(perturbed[1].index)
        differ = perturbed[0][both] != perturbed[1][both]
        assert not differ.any(), pd.concat(
            [perturbed[0][both][differ], perturbed[1][both][differ]], axis=1
        )


def test_a_python_engine_backend_the_perturbed_runs_cannot_afford_is_cut():
    """With a sweep of wall (6 s instances at 1 kHz), the least runs' solves at the bench mean are a lower
    bound of the perturbed runs' cost: above --sweep-budget times --jobs a backend on the Python
    engine is cut (it could not be recommended); a compiled-engine one is not (its bench time is
    the Python call, not the compiled solve); a larger sweep budget affords both."""
    from qpbench.harness.pipeline import CUT_BUDGET_S, RunConfig, closed_loop_budgets, sweep_specs

    config = RunConfig(out=Path("x"), problems=PROBLEMS, scenarios=["wall"],
                       backends=["daqp", "osqp"], sweep_budget=60.0)  # fmt: skip
    specs = sweep_specs(config)
    assert list(specs) == ["wall"]
    target = rec.least_runs(config.min_ok_bound, rec.TOLERATED_NOT_OK)
    per_tick = {"daqp": 5e-5, "osqp": 5e-5}  # 142 x 6,000 ticks x 50 us = 43 s: within 60 s
    assert target * 6_000 * 5e-5 < 60.0
    assert CUT_BUDGET_S not in closed_loop_budgets(config, per_tick, specs).values()
    per_tick = {"daqp": 1e-4, "osqp": 1e-4}  # 85 s > 60 s
    budgets = closed_loop_budgets(config, per_tick, specs)
    assert budgets["osqp"] == CUT_BUDGET_S and budgets["daqp"] > CUT_BUDGET_S
    # a compiled-engine backend whose Python call cannot keep up still gets its whole run
    slow = closed_loop_budgets(config, {"daqp": 1e-3, "osqp": 1e-3}, specs)
    assert slow == {"daqp": config.run_budget, "osqp": CUT_BUDGET_S}
    assert closed_loop_budgets(config, per_tick, {}) == closed_loop_budgets(
        replace(config, sweep_budget=120.0), per_tick, specs
    )


def test_the_bench_takes_the_paper_and_the_spatial_scenarios():
    """The bench's sets: the paper's and the spatial arm's among those run (adaptive_fast, a
    variant of adaptive, is left to the closed loop), else every one asked."""
    from qpbench.harness.closed_loop import arm_family
    from qpbench.harness.pipeline import bench_sets
    from qpbench.sim.scenario import load_scenario

    assert bench_sets(["free", "adaptive_fast", "panda_table"]) == ["free", "panda_table"]
    assert bench_sets(["adaptive_fast"]) == ["adaptive_fast"]
    assert [arm_family(load_scenario(s)) for s in ("wall", "panda_table")] == ["planar", "spatial"]


def test_the_closed_loops_engines_are_compiled_here_from_the_last_back_while_the_worker_lives(
    monkeypatch,
):
    """The run's compile worker takes its groups in order; this process, done benching, takes
    the engines from the last one back until the worker ends (never a non-engine group)."""
    from qpbench import jit
    from qpbench.harness.pipeline import _meet_halfway

    class Behind:
        todo = ("controller", "post", "engine:a", "engine:b", "engine:c")
        alive = [True, True, False]

        def is_alive(self):
            return self.alive.pop(0)

    calls = []
    monkeypatch.setattr(jit, "prepare", lambda groups: calls.append(list(groups)))
    _meet_halfway(Behind())
    assert calls == [["engine:c"], ["engine:b"]]
    Behind.alive = [True] * 5
    calls.clear()
    _meet_halfway(Behind())
    assert calls == [["engine:c"], ["engine:b"], ["engine:a"]]
