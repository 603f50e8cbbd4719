"""Tests of qpbench.harness.closed_loop and ``qpbench closed-loop``.

Real simulator runs, shortened to 0.5 s: the table's figures are checked
against the per-tick logs they came from.
"""

from __future__ import annotations

import json
import math

import numpy as np
import pandas as pd
import pytest
from conftest import SUMMARY_TIME_KEYS

from qpbench import selection
from qpbench.cli import main
from qpbench.exceptions import OutputExistsError, ParamError
from qpbench.harness import closed_loop as cl
from qpbench.sim.log import TIME_COLUMNS

SCENARIOS = ["wall", "narrow"]
BACKENDS = ["qpsolvers:daqp", "pinv"]
#: The noise floor's backend, run first in each scenario of every run set.
FLOOR = "noop"


def _candidates(table: pd.DataFrame) -> pd.DataFrame:
    """The rows of a closed-loop table but the noise floor's."""
    return table[table["backend"] != FLOOR].reset_index(drop=True)


def _cli_args(scenarios: str, backends: str, duration: str, out, *options: str) -> list[str]:
    """``closed-loop --scenarios S --backends B --duration D --out OUT OPTIONS...`` as argv."""
    return [
        "closed-loop",
        "--scenarios",
        scenarios,
        "--backends",
        backends,
        "--duration",
        duration,
        "--out",
        str(out),
        *options,
    ]


@pytest.fixture(scope="module")
def table_dir(tmp_path_factory):
    out = tmp_path_factory.mktemp("cl")
    outcome = cl.run_closed_loop(SCENARIOS, BACKENDS, out, duration=0.5)
    return out, outcome


def test_table_has_one_row_per_pair(table_dir):
    out, outcome = table_dir
    table = pd.read_csv(out / cl.CSV_NAME)
    assert list(table.columns[: len(cl.COLUMNS)]) == list(cl.COLUMNS)
    assert [(r.scenario, r.backend) for r in table.itertuples()] == [
        (s, b) for s in SCENARIOS for b in [FLOOR, *BACKENDS]
    ]
    assert (table["status"] == "ok").all(), table["error"].tolist()
    assert outcome.errors == 0 and outcome.ran == 6 and outcome.skipped == 0
    # simulator summary keys come along
    for key in (
        "zero_velocity_ticks",
        "first_infeasible_t",
        "kp_hat_final",
        "joint_velocity_limit_violations",
    ):
        assert key in table.columns
    assert (table["duration_s"] == 0.5).all()
    assert (table["ticks"] == 500).all()
    assert (table["family"] == "planar").all() and (table["joints"] == 4).all()  # the arm


def test_figures_equal_the_tick_logs(table_dir):
    out, _ = table_dir
    table = pd.read_csv(out / cl.CSV_NAME)
    for r in table.itertuples():
        log = pd.read_parquet(out / r.log_file)
        assert len(log) == r.ticks
        dt = float(np.median(np.diff(log["t"])))
        assert dt == pytest.approx(0.001)
        v = log[[c for c in log.columns if c.startswith("v_") and c[2:].isdigit()]].to_numpy()
        assert r.v2_integral == pytest.approx(np.sum(v**2) * dt, rel=1e-9)
        st = log["solve_time_s"].to_numpy()
        assert r.solve_time_median_s == pytest.approx(np.percentile(st, 50))
        assert r.solve_time_p99_s == pytest.approx(np.percentile(st, 99))
        assert r.solve_time_max_s == pytest.approx(st.max())
        assert r.min_obstacle_distance == pytest.approx(log["d_min"].min())
        assert r.infeasible_ticks == int((log["status"] != "optimal").sum())
        assert r.fallback_ticks == int(log["fallback"].sum())
        assert r.real_time_factor > 0
    pinv = table[table["backend"] == "pinv"]
    assert (pinv["infeasible_ticks"] == 0).all()  # the pseudo-inverse always answers
    daqp = table[(table["backend"] == "qpsolvers:daqp") & (table["scenario"] == "wall")].iloc[0]
    # the paper formulation is infeasible at the start and the soft fallback takes over
    assert daqp["infeasible_ticks"] > 0 and daqp["fallback_ticks"] == daqp["infeasible_ticks"]
    # with the QP the key points keep d_safe (1e-4 m slack), the pseudo-inverse ignores obstacles
    assert daqp["min_obstacle_distance"] >= 0.01 - 1e-4


def test_a_row_is_the_summary_under_the_table_names(table_dir):
    """The figures are computed once (sim.summary): a row of closed_loop.csv is the run's summary."""
    from qpbench.sim.loop import simulate

    out, _ = table_dir
    table = pd.read_csv(out / cl.CSV_NAME)
    row = table[(table["scenario"] == "wall") & (table["backend"] == "pinv")].iloc[0]
    summary = simulate("wall", "pinv", duration=0.5).summary
    for key, value in summary.items():
        if key in SUMMARY_TIME_KEYS or key in ("scenario", "backend"):
            continue
        column = cl.TABLE_NAMES.get(key, key)
        cell = row[column]
        if value is None or value == "":
            assert pd.isna(cell), key  # an empty cell
        elif isinstance(value, (list, dict)):
            assert json.loads(cell) == value, key  # JSON text, read back as it was
        elif isinstance(value, float):
            assert cell == pytest.approx(value, rel=1e-12, abs=1e-15), key
        else:
            assert cell == value or str(cell) == str(value), key
    # one column per figure, one name: the summary's duration only as duration_s
    assert "duration" not in table.columns and "solve_time_p50_s" not in table.columns
    assert len(set(table.columns)) == len(table.columns)
    assert summary["v2_integral"] == pytest.approx(row["v2_integral"], rel=1e-12)


def test_structured_cells_are_json_and_the_report_reads_them_back(table_dir):
    from qpbench.report.inputs import read_results

    out, _ = table_dir
    text = (out / cl.CSV_NAME).read_text()
    assert "{'" not in text  # no Python repr
    table = pd.read_csv(out / cl.CSV_NAME)
    narrow = table[(table["scenario"] == "narrow") & (table["backend"] == "qpsolvers:daqp")].iloc[0]
    counts = json.loads(narrow["status_counts"])
    assert sum(counts.values()) == narrow["ticks"]
    loops = read_results([out / cl.CSV_NAME]).closed_loop
    read_back = loops[
        (loops["scenario"] == "narrow") & (loops["backend"] == "qpsolvers:daqp")
    ].iloc[0]
    assert read_back["status_counts"] == counts
    assert read_back["infeasible_intervals"] == json.loads(narrow["infeasible_intervals"])
    assert all(isinstance(v, list) for v in read_back["obstacle_active_intervals"].values())


def test_cell_writes_json():
    value = {"A2/wall": [[1.613, 6.467], [7.0, 7.5]]}
    assert json.loads(cl.cell(value)) == value
    assert cl.cell(np.float64(0.5)) == 0.5 and cl.cell(None) is None and cl.cell("x") == "x"


def test_duplicate_backends_are_refused_like_in_bench(tmp_path, capsys):
    with pytest.raises(ParamError, match="twice"):
        cl.run_closed_loop(["wall"], ["pinv", "pinv"], tmp_path / "o", duration=0.05)
    out = tmp_path / "cli"
    assert main(["-q", *_cli_args("wall", "pinv,daqp,pinv", "0.05", out)]) == 2
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1 and "'pinv' listed twice" in err
    assert not out.exists()
    # two spellings of one backend are one backend
    assert main(["-q", *_cli_args("wall", "pinv,PINV", "0.05", out)]) == 2
    assert "twice" in capsys.readouterr().err
    assert main(["-q", *_cli_args("wall,wall", "pinv", "0.05", out)]) == 2
    assert "'wall' listed twice" in capsys.readouterr().err


def test_failing_run_becomes_an_error_row(tmp_path):
    bad = tmp_path / "typo.toml"
    bad.write_text("[scenario]\nname = 'typo'\n")
    outcome = cl.run_closed_loop(["wall", str(bad)], ["pinv"], tmp_path / "o", duration=0.05)
    table = _candidates(outcome.table)
    assert list(table["status"]) == ["ok", "error"]
    assert "ScenarioError" in table["error"].iloc[1] and "typo.toml" in table["error"].iloc[1]
    assert outcome.errors == 2  # the noise floor's run of the bad scenario too


def test_resume_force_and_refusal(tmp_path):
    out = tmp_path / "o"
    first = cl.run_closed_loop(["wall"], ["pinv", "qpsolvers:daqp"], out, duration=0.05)
    assert first.ran == 3  # with the noise floor
    with pytest.raises(OutputExistsError):
        cl.run_closed_loop(["wall"], ["pinv"], out, duration=0.05)
    before = pd.read_csv(out / cl.CSV_NAME)
    again = cl.run_closed_loop(
        ["wall", "free"], ["pinv", "qpsolvers:daqp"], out, duration=0.05, resume=True
    )
    assert again.ran == 3 and again.skipped == 3  # only the new scenario runs
    kept = again.table[again.table["scenario"] == "wall"].reset_index(drop=True)
    pd.testing.assert_series_equal(kept["solve_time_median_s"], before["solve_time_median_s"])
    # another duration is another run: resume does not keep it
    longer = cl.run_closed_loop(["wall"], ["pinv"], out, duration=0.08, resume=True)
    assert longer.ran == 2
    # the pairs not asked for this time stay in the table
    assert sorted(zip(longer.table["scenario"], longer.table["backend"])) == sorted(
        (s, b) for s in ("wall", "free") for b in (FLOOR, "pinv", "qpsolvers:daqp")
    )
    assert longer.table.iloc[0]["duration_s"] == 0.08
    forced = cl.run_closed_loop(["wall"], ["pinv"], out, duration=0.05, force=True)
    assert forced.ran == 2 and len(forced.table) == 2
    assert sorted(p.name for p in (out / cl.LOG_DIR).iterdir()) == [
        "wall__noop.parquet",
        "wall__pinv.parquet",
    ]


def test_skipped_backends_get_a_row(tmp_path):
    outcome = cl.run_closed_loop(
        ["wall"], ["pinv", "cvxpy"], tmp_path, duration=0.05, skip={"cvxpy": "too slow here"}
    )
    table = _candidates(outcome.table)
    assert list(table["status"]) == ["ok", "skipped"]
    assert table["error"].iloc[1] == "too slow here"
    assert outcome.errors == 0 and outcome.ran == 2


def test_bad_parameters(tmp_path):
    with pytest.raises(ParamError):
        cl.run_closed_loop(["wall"], ["pinv"], tmp_path, formulation="hard")
    with pytest.raises(ParamError):
        cl.run_closed_loop(["wall"], ["pinv"], tmp_path, duration=-1.0)
    with pytest.raises(ParamError):
        selection.parse_list(",,", "--backends")
    assert selection.select_scenarios("all")[:4] == ["free", "wall", "adaptive", "narrow"]


def test_cli_exit_codes(tmp_path, capsys):
    out = tmp_path / "cli"
    args = _cli_args("wall", "daqp", "0.05", out)
    assert main(["-q", *args]) == 0
    assert main(["-q", *args]) == 2  # exists, no --force / --resume
    assert "--force" in capsys.readouterr().err
    assert main(["-q", *args, "--resume"]) == 0
    before = (out / "closed_loop.csv").read_bytes()
    # a scenario that does not exist is refused before any run (and before --force deletes anything)
    assert main(["-q", *args, "--force", "--scenarios", f"wall,{tmp_path / 'missing.toml'}"]) == 2
    assert "missing.toml" in capsys.readouterr().err
    assert (out / "closed_loop.csv").read_bytes() == before
    assert main(["-q", "closed-loop", "--backends", "nosuch", "--out", str(tmp_path / "x")]) == 2
    assert "nosuch" in capsys.readouterr().err
    with pytest.raises(SystemExit) as exc:
        main(["closed-loop", "--out", str(out), "--force", "--resume"])
    assert exc.value.code == 2


# ---------------------------------------------------------------- guards: crash, hang, per-tick faults

import sys  # noqa: E402
from pathlib import Path  # noqa: E402

sys.path.insert(0, str(Path(__file__).parent))
import faulty_backends as fb  # noqa: E402

from qpbench.backends import load_plugins  # noqa: E402

PLUGIN = str(Path(fb.__file__).resolve())

#: Columns that hold timings (differ between two runs of the same thing).
#: The row's columns that depend on the machine's timing.
TIMED = tuple(SUMMARY_TIME_KEYS)


def _untimed(row: pd.Series) -> pd.Series:
    return row.drop([c for c in TIMED if c in row.index])


def _same_daqp_run(out_a, row_a, out_b, row_b):
    pd.testing.assert_series_equal(
        _untimed(row_a).sort_index(), _untimed(row_b).sort_index(), check_names=False
    )
    log_a = pd.read_parquet(out_a / row_a["log_file"]).drop(columns=list(TIME_COLUMNS))
    log_b = pd.read_parquet(out_b / row_b["log_file"]).drop(columns=list(TIME_COLUMNS))
    pd.testing.assert_frame_equal(log_a, log_b)


@pytest.fixture(scope="module")
def daqp_alone(tmp_path_factory):
    out = tmp_path_factory.mktemp("alone")
    assert main(["-q", *_cli_args("wall", "daqp", "0.1", out)]) == 0
    return out, _candidates(pd.read_csv(out / cl.CSV_NAME)).iloc[0]


def test_segfault_and_hang_are_rows_and_the_others_are_intact(tmp_path, daqp_alone):
    out = tmp_path / "o"
    args = [
        "-q",
        *_cli_args(
            "wall",
            "faulty:segfault,faulty:hang,daqp",
            "0.1",
            out,
            "--run-time-limit",
            "8",  # covers the worker's start too (forkserver's imports on a loaded machine)
            "--plugin",
            PLUGIN,
            "--strict",
        ),
    ]
    assert main(args) == 1  # failed runs, and --strict
    table = _candidates(pd.read_csv(out / cl.CSV_NAME))
    assert list(table["backend"]) == ["faulty:segfault", "faulty:hang", "daqp"]
    crashed, hung, daqp = (table.iloc[i] for i in range(3))
    assert crashed["status"] == "crashed" and "SIGSEGV" in crashed["error"]
    assert hung["status"] == "time_limit" and "killed" in hung["error"]
    assert crashed["verdict"] == hung["verdict"] == "incomplete" and daqp["verdict"] == "ok"
    assert crashed["verdict_reasons"].startswith("run crashed: worker process killed by SIGSEGV")
    assert hung["verdict_reasons"].startswith("run overran its deadline: no result after 8 s")
    assert (
        bool(crashed["isolated"]) and bool(hung["isolated"]) and not bool(daqp["isolated"])
    )  # auto: risky ones
    assert daqp["status"] == "ok"
    _same_daqp_run(out, daqp, *daqp_alone)
    assert sorted(p.name for p in (out / cl.LOG_DIR).iterdir()) == [
        "wall__daqp.parquet",
        "wall__noop.parquet",
    ]  # no partial logs
    # resume keeps the ok row and retries only the failed ones
    seen = []
    load_plugins([PLUGIN])  # what the CLI's --plugin did: the workers load it too
    outcome = cl.run_closed_loop(
        ["wall"], ["faulty:segfault", "daqp"], out, duration=0.1, resume=True, on_row=seen.append
    )
    assert [r["backend"] for r in seen] == ["faulty:segfault"] and outcome.errors == 2


def test_parallel_runs_survive_a_crash(tmp_path, daqp_alone):
    out = tmp_path / "p"
    load_plugins([PLUGIN])
    outcome = cl.run_closed_loop(
        ["wall"],
        ["faulty:segfault", "daqp", "faulty-ticks:raise"],
        out,
        duration=0.1,
        jobs=2,
        isolate="always",
    )
    table = outcome.table.set_index("backend")
    assert table.loc["faulty:segfault", "status"] == "crashed"
    assert table.loc["daqp", "status"] == "ok" and table.loc["faulty-ticks:raise", "status"] == "ok"
    assert table["isolated"].all() and outcome.errors == 1
    alone_out, alone_row = daqp_alone
    _same_daqp_run(
        out,
        _candidates(outcome.table).iloc[1].drop("isolated"),
        alone_out,
        alone_row.drop("isolated"),
    )
    # the per-tick guards' counts reach the table (the test plugin loaded in the worker)
    raised = table.loc["faulty-ticks:raise"]
    assert raised["error_ticks"] == len(fb.fault_ticks(100)) and raised["first_error"].startswith(
        "RuntimeError"
    )
    assert raised["fallback_ticks"] >= raised["error_ticks"]
    # the verdict is the simulator's, copied: a backend that raises on ticks fails it
    assert raised["verdict"] == "failed" and raised["verdict_reasons"].startswith(
        "10 ticks with an error (first at "
    )
    assert outcome.not_ok == 2  # the crashed run and the raising backend


def test_guard_parameters(tmp_path):
    with pytest.raises(ParamError):
        cl.run_closed_loop(["wall"], ["pinv"], tmp_path, isolate="sometimes")
    with pytest.raises(ParamError):
        cl.run_closed_loop(["wall"], ["pinv"], tmp_path, run_time_limit=0.0)
    assert cl.run_deadline("wall", 0.1) == cl.RUN_TIME_LIMIT_MIN_S
    assert cl.run_deadline("wall", 100.0) == 100.0 * cl.RUN_TIME_LIMIT_PER_SIM_S
    assert cl.run_deadline("wall", None, 7.0) == 7.0
    from qpbench.harness.guard import wants_worker

    risky = [wants_worker("auto", b) for b in ("faulty:hang", "daqp", "nosuch")]
    assert risky == [True, False, False]


# ---------------------------------------------------------------- verdicts and the wall-time budget

from slow_backends import registered  # noqa: E402


def test_pinv_through_the_wall_is_unsafe_and_exits_1_with_strict(tmp_path, capsys):
    """pinv ignores obstacles: its A2 dips below d_safe - 0.5 mm at 1.48 s of wall and link 1 goes
    through the wall by 1.92 s; daqp keeps d_safe."""
    out = tmp_path / "o"
    code = main(_cli_args("wall", "daqp,pinv", "2.2", out, "--strict"))
    assert code == 1
    table = pd.read_csv(out / cl.CSV_NAME).set_index("backend")
    pinv, daqp = table.loc["pinv"], table.loc["daqp"]
    assert daqp["verdict"] == "ok" and math.isnan(daqp["verdict_reasons"])  # empty in the CSV
    assert pinv["status"] == "ok" and pinv["verdict"] == "unsafe"
    assert pinv["verdict_reasons"].startswith(
        f"link 1 {-pinv['min_body_distance'] * 1e3:.1f} mm inside line 'wall' at "
    )
    assert pinv["min_body_distance"] < 0 and pinv["min_body_distance_link"] == 1
    assert pinv["key_point_rule"] == "broken" and daqp["key_point_rule"] == "held"
    assert pinv["key_point_rule_reason"].startswith(
        f"d_min {pinv['min_obstacle_distance'] * 1e3:.1f} mm < d_safe - 0.5 mm = 9.5 mm"
    )
    assert pinv["min_obstacle_distance"] < 0.0095 and daqp["min_body_distance"] > 0.0095
    # the verdict is the simulator's, never recomputed: the tick log gives the same one
    from qpbench.sim.loop import simulate

    again = simulate("wall", "pinv", duration=2.2).summary
    assert (again["verdict"], again["verdict_reasons"]) == (
        pinv["verdict"],
        pinv["verdict_reasons"],
    )
    err = capsys.readouterr().err
    assert f"WARNING: wall / pinv: unsafe ({pinv['verdict_reasons']})" in err
    assert "INFO: wall / daqp: ok" in err


def test_exact_backend_short_run_is_ok_and_exits_0(tmp_path):
    out = tmp_path / "o"
    assert main(["-q", *_cli_args("wall,narrow", "qpsolvers:daqp", "0.3", out)]) == 0
    table = pd.read_csv(out / cl.CSV_NAME)
    assert (table["verdict"] == "ok").all() and (table["simulated_s"] == 0.3).all()


def test_budget_stops_a_run_and_the_row_says_so(tmp_path, monkeypatch, capsys):
    slow = registered(monkeypatch)  # about 4 ms per tick: 1 s of simulated time takes about 4 s
    out = tmp_path / "cut"
    args = [
        "closed-loop",
        "--scenarios",
        "wall",
        "--backends",
        slow,
        "--duration",
        "1.0",
        "--isolate",
        "never",
    ]
    # stopped early: its verdict is incomplete, a verdict that is not ok (exit 1 with --strict)
    assert main([*args, "--out", str(out), "--run-budget", "0.4", "--strict"]) == 1
    row = _candidates(pd.read_csv(out / cl.CSV_NAME)).iloc[0]
    assert row["status"] == "budget" and row["verdict"] == "incomplete"
    assert row["run_budget_s"] == 0.4 and row["realtime"] == "no"  # about 4 ms a tick
    assert 0 < row["simulated_s"] < row["duration_s"] == 1.0
    assert row["ticks"] == round(row["simulated_s"] / 0.001)
    assert row["verdict_reasons"] == (
        f"stopped at {row['simulated_s']:.2f} s of 1 s (wall-time budget 0.4 s): "
        "tracking and force not judged (settle time 2 s not reached)"
    )
    assert row["real_time_factor"] == pytest.approx(row["simulated_s"] / row["wall_time_s"])
    assert "WARNING: wall / test-slow-exact: incomplete (stopped at" in capsys.readouterr().err
    cut_log = pd.read_parquet(out / row["log_file"])
    assert len(cut_log) == row["ticks"]
    # the uncut run: its first ticks are the budgeted run's log
    whole_out = tmp_path / "whole"
    assert main([*args, "--out", str(whole_out)]) == 0  # not real time: no change of the exit code
    whole = _candidates(pd.read_csv(whole_out / cl.CSV_NAME)).iloc[0]
    assert whole["status"] == "ok" and whole["simulated_s"] == 1.0 and whole["ticks"] == 1000
    whole_log = pd.read_parquet(whole_out / whole["log_file"])
    pd.testing.assert_frame_equal(
        cut_log.drop(columns=list(TIME_COLUMNS)),
        whole_log.drop(columns=list(TIME_COLUMNS)).iloc[: len(cut_log)],
    )
    # resume keeps a budget row made under the same budget, and reruns it under another
    seen = []
    cl.run_closed_loop(
        ["wall"], [slow], out, duration=1.0, resume=True, run_budget=0.4, on_row=seen.append
    )
    assert seen == []
    cl.run_closed_loop(
        ["wall"], [slow], out, duration=1.0, resume=True, run_budget=0.3, on_row=seen.append
    )
    assert len(seen) == 1 and seen[0]["status"] == "budget"


def test_bad_budget(tmp_path):
    with pytest.raises(ParamError, match="run-budget"):
        cl.run_closed_loop(["wall"], ["daqp"], tmp_path, run_budget=-1.0)


# ---------------------------------------------------------------- the machine's noise floor


def test_the_noop_backend_answers_zero_and_times_the_loop_tick_by_tick():
    from qpbench.backends import NOISE_FLOOR
    from qpbench.sim.loop import simulate

    for engine in ("python", "compiled"):
        run = simulate("wall", NOISE_FLOOR, duration=0.03, engine=engine)
        assert run.summary["engine"] == engine
        assert (run.log["status"] == "optimal").all() and not run.log["fallback"].any()
        assert np.all(run.log[[f"v_{i}" for i in range(4)]].to_numpy() == 0.0)
        # a whole tick is longer than the call inside it
        assert np.all(run.log["tick_time_s"] > run.log["solve_time_s"])
        assert run.summary["realtime_solver"] == "unknown"  # no time of its own


def test_the_noise_floor_is_no_candidate(tmp_path, capsys):
    from qpbench.backends import NOISE_FLOOR

    assert NOISE_FLOOR not in selection.select_backends("all")
    assert selection.select_backends(NOISE_FLOOR) == [NOISE_FLOOR]  # by name, in the loop
    with pytest.raises(ParamError, match="noise floor"):
        selection.select_backends(f"daqp,{NOISE_FLOOR}", floor=False)
    argv = ["bench", "problems/wall", "--backends", NOISE_FLOOR, "--out", str(tmp_path / "b.csv")]
    assert main(argv) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "noise floor" in err[0] and "--backends" in err[0]


def test_a_run_set_measures_the_noise_floor_and_judges_real_time_against_it(tmp_path):
    from qpbench.backends import NOISE_FLOOR
    from qpbench.report import recommend as rec
    from qpbench.sim.verdict import floor_fields, judge_realtime_run

    # 2.5 s: past the settle time, so the noop run's own verdict (x = 0: diverged) exists
    out = cl.run_closed_loop(["wall"], ["qpsolvers:daqp"], tmp_path / "cl", duration=2.5)
    table = out.table
    assert list(table["backend"]) == [NOISE_FLOOR, "qpsolvers:daqp"]  # the floor first
    floor, daqp = (r for r in table.to_dict("records"))
    assert floor["noise_floor"] is True and daqp["noise_floor"] is False
    assert floor["verdict"] == "diverged" and daqp["verdict"] == "ok"
    # the floor is judged tick to tick: every tick but the first, all of them optimal
    assert floor["timed_ticks"] == floor["ticks"] == floor["ticks_optimal"] == 2500
    log = pd.read_parquet(tmp_path / "cl" / floor["log_file"])
    assert floor["time_p99_without_infeasible_s"] > np.quantile(log["solve_time_s"], 0.99)
    # the candidate judged by the rule on its figures and the floor's, the floor beside
    assert daqp["noise_floor_over_dt_share"] == floor["over_dt_share"]
    assert daqp["noise_floor_tick_p99_s"] == floor["time_p99_without_infeasible_s"]
    expected = judge_realtime_run(daqp, "call", floor_fields(floor))
    assert (daqp["realtime"], daqp["realtime_reason"]) == expected
    # the floor's verdict counts for nothing: not a run that is not ok, never recommended
    assert out.not_ok == 0
    answer = rec.recommend(table)
    assert answer.runs == 1 and NOISE_FLOOR not in answer.overall.not_recommended
    assert NOISE_FLOOR not in answer.overall.backends
    assert len(answer.noise_floor) == 1 and answer.noise_floor[0].startswith("wall: p99 tick ")
    assert "noise floor" in rec.render(answer)
    assert not any("not ok" in s for s in rec.shortfalls(table))


def test_a_run_of_scenario_text_lasts_the_task_duration():
    """A task's ``duration`` holds for a scenario given as text (a sweep's instance) as for one
    given by name: the same ticks, the same trajectory."""
    from qpbench.backends import NOISE_FLOOR
    from qpbench.sim.scenario import load_scenario

    text = load_scenario("wall").source
    by_name = cl.run_row(cl.LoopTask("wall", NOISE_FLOOR, duration=0.003))
    by_text = cl.run_row(cl.LoopTask("w.toml", NOISE_FLOOR, duration=0.003, scenario_text=text))
    assert by_name["status"] == by_text["status"] == "ok"
    assert by_name["ticks"] == by_text["ticks"] == 3
    assert by_name["min_obstacle_distance"] == by_text["min_obstacle_distance"]
    whole = cl.run_row(cl.LoopTask("w.toml", NOISE_FLOOR, scenario_text=text, duration=None))
    assert whole["ticks"] == round(load_scenario("wall").duration / load_scenario("wall").dt)
