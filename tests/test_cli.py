"""End-to-end tests of the command line: bench -> report, closed-loop -> report, run.

Every sub-command's ``--help`` carries an example; exit codes follow the
convention (docs/exit-codes.md: 0 outputs written, 1 with ``--strict`` when a run or solve did not
pass, 2 usage or input error).
"""

from __future__ import annotations

import json
import re
from pathlib import Path

import numpy as np
import pandas as pd
import pytest
from conftest import simulate_args
from test_report import assert_close, parse_tables, qpbenchmark_ratios

from qpbench.cli import COMMANDS, build_parser, main
from qpbench.harness.pipeline import RUN_BUDGET_S
from qpbench.profiles import get_profile

MAROS = Path(__file__).resolve().parents[1] / "problems" / "maros_meszaros"
BACKENDS = "qpsolvers:daqp,osqp,pinv"


def _commands():
    parser = build_parser()
    sub = next(a for a in parser._actions if a.dest == "command")
    return sorted(sub.choices)


@pytest.mark.parametrize("command", sorted(COMMANDS))
def test_help_has_an_example(command, capsys):
    if command not in _commands():
        pytest.skip(f"qpbench {command} is not installed here")
    with pytest.raises(SystemExit) as exc:
        main([command, "--help"])
    assert exc.value.code == 0
    text = capsys.readouterr().out
    assert "example" in text.lower()
    assert f"qpbench {command}" in text


def test_no_command_is_a_usage_error(capsys):
    assert main([]) == 2
    with pytest.raises(SystemExit) as exc:
        main(["nosuchcommand"])
    assert exc.value.code == 2


@pytest.fixture(scope="module")
def bench_and_report(tmp_path_factory):
    """A few dozen ticks of wall dumped by the simulator and the Maros-Meszaros subset, benched and reported."""
    from qpbench.sim.loop import simulate

    root = tmp_path_factory.mktemp("e2e")
    simulate("wall", "qpsolvers:daqp", duration=0.4, every=10, dump=root / "wall")
    codes = [
        main(
            [
                "-q",
                "bench",
                str(root / "wall"),
                "--backends",
                BACKENDS,
                "--out",
                str(root / "wall.csv"),
            ]
        ),
        main(["-q", "bench", str(MAROS), "--backends", BACKENDS, "--out", str(root / "mm.csv")]),
    ]
    rep = main(
        ["-q", "report", str(root / "wall.csv"), str(root / "mm.csv"), "--out", str(root / "rep")]
    )
    return root, codes, rep


def test_bench_then_report_numbers_match_the_csvs(bench_and_report):
    root, codes, rep = bench_and_report
    assert rep == 0
    assert all(c in (0, 1) for c in codes)
    bench = pd.concat(
        [pd.read_csv(root / "wall.csv"), pd.read_csv(root / "mm.csv")], ignore_index=True
    )
    assert len(bench) == (40 + len(list(MAROS.glob("*.mat")))) * 3
    # the paper formulation is infeasible at the start of wall: the reference says so
    wall = bench[bench["scenario"] == "wall"]
    assert (wall.loc[wall["t"] < 0.1, "reference_status"] == "primal_infeasible").all()
    assert (wall.loc[wall["t"] > 0.2, "reference_status"] == "optimal").all()
    md = (root / "rep" / "report.md").read_text()
    tol = get_profile("default").tolerance
    tabs = parse_tables(md)
    ratios = next(t for t in tabs if t["caption"].startswith("Success rate and shifted"))
    shown = {r[0]: r for r in ratios["rows"]}
    assert set(shown) == set(BACKENDS.split(","))
    for name, col, nf, floor in (
        ("runtime", "wall_time_min_s", tol.runtime, None),
        ("primal residual", "primal_residual", tol.primal, tol.primal),
        ("duality gap", "duality_gap", tol.gap, tol.gap),
    ):
        j = ratios["header"].index(name)
        expected = qpbenchmark_ratios(bench, col, nf, floor)
        for b, r in shown.items():
            assert_close(r[j], expected[b], f"{name} of {b}")
    for b, r in shown.items():
        rows = bench[bench["backend"] == b]
        assert int(r[1]) == len(rows)
        assert_close(r[2], 100 * rows["success"].mean(), f"success of {b}")
    scen = {
        t["headings"][4]: t
        for t in tabs
        if t["headings"].get(4, "").startswith("Scenario")
        and t["caption"].startswith("Per backend, runtime")
    }
    assert set(scen) == {"Scenario wall (default, sequential)", "Scenario - (default, sequential)"}
    for r in scen["Scenario wall (default, sequential)"]["rows"]:
        t = wall.loc[wall["backend"] == r[0], "wall_time_min_s"].to_numpy(float)
        assert_close(r[4], np.percentile(t, 50) * 1e6, "p50")
        assert_close(r[6], t.max() * 1e6, "max")
    assert (root / "rep" / "plots" / "perf_profile_default_sequential.png").exists()
    assert (root / "rep" / "plots" / "per_tick_default_sequential_wall.png").exists()


def test_closed_loop_then_report(tmp_path):
    out = tmp_path / "cl"
    code = main(
        [
            "-q",
            "closed-loop",
            "--scenarios",
            "wall,narrow",
            "--backends",
            "qpsolvers:daqp,pinv",
            "--duration",
            "0.5",
            "--out",
            str(out),
        ]
    )
    assert code == 0  # written; pinv breaks the speed limits (and goes through narrow's lower line)
    table = pd.read_csv(out / "closed_loop.csv")
    assert list(table["backend"]).count("noop") == 2  # each scenario's noise floor
    table = table[table["backend"] != "noop"]
    assert len(table) == 4 and (table["status"] == "ok").all()
    assert list(table["verdict"]) == ["ok", "limits", "ok", "unsafe"]
    assert main(["-q", "report", str(out / "closed_loop.csv"), "--out", str(out)]) == 0
    md = (out / "report.md").read_text()
    failed = [
        t for t in parse_tables(md) if t["headings"].get(3) == "Runs that failed their verdict"
    ]
    assert len(failed) == 1 and failed[0]["header"] == [
        "scenario",
        "backend",
        "formulation",
        "verdict",
        "reasons",
    ]
    bad = table[table["verdict"] != "ok"]
    assert [r[:4] for r in failed[0]["rows"]] == [
        [s, b, "paper", v] for s, b, v in zip(bad["scenario"], bad["backend"], bad["verdict"])
    ]
    assert [r[4] for r in failed[0]["rows"]] == list(bad["verdict_reasons"])
    tabs = [t for t in parse_tables(md) if (t["caption"] or "").startswith("Closed-loop metrics")]
    assert [t["headings"][3] for t in tabs] == ["Scenario wall (paper)", "Scenario narrow (paper)"]
    for t in tabs:
        scenario = t["headings"][3].split()[1]
        for r in t["rows"]:
            row = table[(table["scenario"] == scenario) & (table["backend"] == r[0])].iloc[0]
            head = t["header"]
            assert_close(
                r[head.index("min key-point dist (mm)")], row["min_obstacle_distance"] * 1e3, "dist"
            )
            assert_close(
                r[head.index("min body dist (mm)")], row["min_body_distance"] * 1e3, "body"
            )
            assert r[head.index("key-point rule")] == row["key_point_rule"]
            assert_close(r[head.index("solve p99 (us)")], row["solve_time_p99_s"] * 1e6, "p99")
            assert_close(r[head.index("int v^2 dt")], row["v2_integral"], "v2")
            assert int(r[head.index("infeasible ticks")]) == row["infeasible_ticks"]
    for png in re.findall(r"\]\((plots/[^)]+\.png)\)", md):
        assert (out / png).exists()
    assert (out / "plots" / "closed_loop_wall_paper.png").exists()


def run_args(scenarios: str, backends: str, out: str) -> list[str]:
    """``-q run`` of 0.3 simulated s per closed loop as argv; ``out`` is the last item."""
    return ["-q", "run", "--duration", "0.3", f"--scenarios={scenarios}", f"--backends={backends}",
            "--out", out]  # fmt: skip


def test_run_end_to_end(tmp_path, monkeypatch, capsys):
    from qpbench.report.recommend import recommend, render

    monkeypatch.chdir(tmp_path)
    args = run_args("wall", "qpsolvers:daqp,pinv", "tmp")
    # pinv breaks the joint speed limits: its closed-loop verdict is "limits"; exit 0 all the same
    assert main(args) == 0
    out = tmp_path / "tmp"
    assert (
        tmp_path / "problems" / "wall" / "problems.parquet"
    ).exists()  # regenerated: none shipped here
    assert len(pd.read_parquet(tmp_path / "problems" / "wall" / "problems.parquet")) == 2000
    bench = pd.read_csv(out / "bench" / "wall.csv.gz")
    assert set(bench["backend"]) == {"qpsolvers:daqp", "pinv"}
    assert (bench["t"] < 0.3).all() and len(bench) > 0
    assert (
        bench["repeat"] == 3
    ).all()  # run times every problem 3 times; the report uses the minimum
    assert set(bench["position"]) == {0, 1} and (bench["order_seed"] == 0).all()
    full = pd.read_csv(out / "closed_loop.csv")  # with the noise floor's run
    loop = full[full["backend"] != "noop"]
    assert (
        sorted(loop["backend"]) == ["pinv", "qpsolvers:daqp"] and (loop["duration_s"] == 0.3).all()
    )
    md = (out / "report.md").read_text()
    assert "## Per-tick benchmark" in md and "## Closed loop" in md
    assert md.startswith("# qpbench report\n\n" + render(recommend(full), markdown=True))
    manifest = json.loads((out / "run.json").read_text())
    assert manifest["backends"] == ["qpsolvers:daqp", "pinv"]
    assert (
        manifest["closed_loop_not_ok"] == {"wall/pinv": "limits"}
        and manifest["run_budget_s"] == RUN_BUDGET_S
    )
    # each backend's closed-loop budget, decided from its bench mean, is the one its row ran under
    assert set(manifest["closed_loop_budget_s"]) == {"qpsolvers:daqp", "pinv"}
    assert dict(zip(loop["backend"], loop["run_budget_s"])) == manifest["closed_loop_budget_s"]
    # the wall time of every phase, in the order run
    assert list(manifest["phase_wall_time_s"]) == [
        "compile", "problem set wall", "references", "bench wall", "closed loop", "report",
    ]  # fmt: skip
    assert all(t >= 0 for t in manifest["phase_wall_time_s"].values())
    assert not (out / ".partial").exists()
    # a second run replaces the previous run's outputs (run.json marks the folder as ours);
    # --strict: exit 1 with one line saying why; without -q the recommendation is printed last
    first = (out / "closed_loop.csv").stat().st_mtime_ns
    capsys.readouterr()
    assert main([*args[1:], "--strict"]) == 1
    assert (out / "closed_loop.csv").stat().st_mtime_ns != first
    printed = capsys.readouterr()
    assert printed.out.endswith(render(recommend(pd.read_csv(out / "closed_loop.csv"))))
    assert "limits in wall: " in printed.out
    (line,) = [x for x in printed.err.splitlines() if x.startswith("qpbench run: --strict: ")]
    assert "1 of 2 runs not ok (limits 1)" in line
    # --resume of a finished run starts from an empty staging folder and completes too
    assert main([*args, "--resume"]) == 0
    # other files in the folder are left alone; a report.md that no run wrote is not replaced
    other = tmp_path / "other"
    (other / "simulate").mkdir(parents=True)
    (other / "simulate" / "notes.txt").write_text("mine")
    (other / "report.md").write_text("hand-written")
    assert main([*args[:-1], "other"]) == 2
    assert (other / "report.md").read_text() == "hand-written"
    assert main([*args[:-1], "other", "--force"]) == 0
    assert (other / "simulate" / "notes.txt").read_text() == "mine"
    assert "## Closed loop" in (other / "report.md").read_text()
    assert main(["-q", "run", "--duration", "-1", "--out", "x"]) == 2
    assert main(["-q", "run", "--run-budget", "-1", "--out", "x"]) == 2


def test_run_never_leaves_a_backend_out_of_the_closed_loop(tmp_path, monkeypatch):
    """A backend slower than the 1 kHz loop (real-time factor about 0.3) runs every scenario, under the budget."""
    from slow_backends import registered

    slow = registered(monkeypatch)
    monkeypatch.chdir(tmp_path)
    # a small problem set (30 ticks of wall) so the bench is quick
    (tmp_path / "problems").mkdir()
    assert (
        main(
            [
                "-q",
                *simulate_args("wall", "daqp", "0.3"),
                "--dump",
                "problems/wall",
                "--every",
                "10",
            ]
        )
        == 0
    )
    # one run at a time, in this process: the slow backend is registered here only, and a
    # worker process (``--jobs 2``) would not know it
    args = [*run_args("wall,free", f"daqp,{slow}", "r"), "--jobs", "1"]
    assert main(args) == 0
    loop = pd.read_csv(tmp_path / "r" / "closed_loop.csv")
    loop = loop[loop["backend"] != "noop"]  # the noise floor's runs
    assert sorted(zip(loop["scenario"], loop["backend"])) == sorted(
        (s, b) for s in ("wall", "free") for b in ("daqp", slow)
    )
    # the slow runs' budget is three times the bench's prediction: a machine loaded enough to
    # stretch its sleeps further cuts them, and their rows say how far they got
    cut = (loop["status"] == "budget") & (loop["verdict"] == "incomplete")
    assert ((loop["verdict"] == "ok") & loop["status"].isin(("ok", "budget")) | cut).all()
    assert (loop["ticks"] > 0).all()
    fast = loop[loop["backend"] == "daqp"]
    assert (
        (fast["status"] == "ok").all()
        and (fast["ticks"] == 300).all()
        and (fast["simulated_s"] == 0.3).all()
    )
    assert (
        loop.loc[loop["backend"] == slow, "real_time_factor"] < 1
    ).all()  # slower than real time, still in
    manifest = json.loads((tmp_path / "r" / "run.json").read_text())
    assert "closed_loop_skipped" not in manifest and "min_rtf" not in manifest
    # a budget that runs out: the run stops and says how far it got, it is not left out
    # a run cut short is incomplete: exit 0 (the outputs are written), 1 with --strict
    assert main([*args, "--run-budget", "0.2", "--strict"]) == 1
    loop = pd.read_csv(tmp_path / "r" / "closed_loop.csv").set_index(["scenario", "backend"])
    cut = loop.loc[("wall", slow)]
    assert cut["status"] == "budget" and 0 < cut["simulated_s"] < 0.3
    assert cut["verdict"] == "incomplete" and cut["verdict_reasons"].startswith(
        f"stopped at {cut['simulated_s']:.2f} s of 0.3 s (wall-time budget 0.2 s)"
    )
    assert json.loads((tmp_path / "r" / "run.json").read_text())["closed_loop_stopped_by_budget"][
        f"wall/{slow}"
    ] == pytest.approx(cut["simulated_s"])
    with pytest.raises(SystemExit) as exc:  # no probe, no admission threshold
        main(["run", "--min-rtf", "1"])
    assert exc.value.code == 2


def test_run_bench_subset_keeps_the_time_between_records():
    """`run --bench-every K` keeps every K-th record: an online backend then integrates K record periods per call."""
    from qpbench.formats import read_problem_set
    from qpbench.harness.bench import record_period
    from qpbench.harness.pipeline import bench_subset

    full = read_problem_set(Path(__file__).resolve().parents[1] / "problems" / "wall")
    subset, refs = bench_subset(full, None, 5)
    assert len(subset) == len(refs) == 400
    assert [r.tick for r in subset.records[:3]] == [0, 50, 100]
    assert record_period(full) == pytest.approx(0.01)
    assert record_period(subset) == pytest.approx(0.05)
    assert full.manifest["generator"]["every"] == 10  # the set itself is untouched


def test_run_bench_subset_solves_references_of_the_kept_records_only(tmp_path, monkeypatch):
    """Without a reference cache, `run --bench-every K` solves the K-th records' references
    only, and caches them in the set's cache for the next run."""
    import shutil

    import qpbench.reference as reference_module
    from qpbench.formats import read_problem_set
    from qpbench.harness.pipeline import bench_subset

    folder = tmp_path / "wall"
    folder.mkdir()
    for name in ("manifest.json", "problems.parquet"):
        shutil.copy(Path(__file__).resolve().parents[1] / "problems" / "wall" / name, folder)
    solved = []
    real = reference_module._compute

    def spy(todo, *args, **kwargs):
        solved.extend(r.name for r in todo)
        return real(todo, *args, **kwargs)

    monkeypatch.setattr(reference_module, "_compute", spy)
    subset, refs = bench_subset(read_problem_set(folder), None, 200)
    assert solved == [r.name for r in subset.records] == [r.name for r in refs]
    assert len(solved) == 10
    solved.clear()
    assert bench_subset(read_problem_set(folder), None, 400)[1][1].name == refs[2].name
    assert solved == []  # every 400th is among every 200th: read from the cache


def test_closed_loop_budgets_follow_the_bench():
    """Each backend's budget from its bench mean: room to finish for one that keeps up, the floor
    for one that cannot finish within --run-budget, --run-budget for one without a bench time."""
    from qpbench.harness.pipeline import (
        BUDGET_FLOOR_S,
        BUDGET_MARGIN,
        CUT_BUDGET_S,
        RunConfig,
        closed_loop_budgets,
    )

    config = RunConfig(out=Path("x"), problems=Path("p"), scenarios=["wall"],
                       backends=["fast", "medium", "tight", "slow", "unbenched"], duration=2.0,
                       run_budget=10.0)  # fmt: skip
    ticks = 2000  # 2 s of wall at dt = 1 ms
    per_tick = {"fast": 1e-5, "medium": 1e-3, "tight": 3e-3, "slow": 1e-2}
    budgets = closed_loop_budgets(config, per_tick)
    assert budgets["fast"] == BUDGET_FLOOR_S  # 3 x 0.02 s predicted: the floor
    assert budgets["medium"] == pytest.approx(BUDGET_MARGIN * ticks * 1e-3)  # 6 s
    assert budgets["medium"] > ticks * 1e-3  # it can finish
    assert budgets["tight"] == 10.0  # 6 s of solves: all of --run-budget, not 3 x 6 s
    assert budgets["slow"] == CUT_BUDGET_S < BUDGET_FLOOR_S  # 20 s of solves alone > 10 s: cut
    assert budgets["unbenched"] == 10.0
    config.run_budget = None
    assert closed_loop_budgets(config, per_tick) == {}


def test_run_runs_closed_loops_side_by_side_one_per_core(monkeypatch):
    """`run`'s closed-loop runs: LOOP_JOBS at once, never more than the machine's cores; 0 refused."""
    from qpbench.exceptions import ParamError
    from qpbench.harness import pipeline

    monkeypatch.setattr(pipeline.os, "cpu_count", lambda: 1)
    assert pipeline.default_jobs() == 1
    monkeypatch.setattr(pipeline.os, "cpu_count", lambda: 64)
    assert pipeline.default_jobs() == pipeline.LOOP_JOBS
    with pytest.raises(ParamError, match="--jobs"):
        pipeline.RunConfig(out=Path("x"), problems=Path("p"), scenarios=["wall"],
                           backends=["daqp"], jobs=0)  # fmt: skip
