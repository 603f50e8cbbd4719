"""Verdict of a closed-loop run: thresholds from the scenario, the rules, ``simulate``'s output and exit code,
and the wall-time budget that stops a run between ticks."""

from __future__ import annotations

import json
import math
import re
from pathlib import Path
from types import SimpleNamespace

import numpy as np
import pandas as pd
import pytest
from conftest import simulate_args
from slow_backends import SlowExact

from qpbench.cli import main
from qpbench.exceptions import ParamError, ScenarioError
from qpbench.robot.kinematics import PlanarArm
from qpbench.robot.obstacles.line import LineObstacle
from qpbench.sim.log import TIME_COLUMNS
from qpbench.sim.loop import simulate
from qpbench.sim.scenario import load_scenario, scenario_names
from qpbench.sim.summary import summarize
from qpbench.sim.verdict import VerdictSettings, failed_run, floor_fields, judge_realtime_run

ROOT = Path(__file__).resolve().parents[1]
SHIPPED = ROOT / "qpbench" / "data" / "scenarios"


# ---------------------------------------------------------------- thresholds in the scenario files


def test_every_shipped_scenario_has_thresholds():
    for name in scenario_names():
        sc = load_scenario(name)
        v, d_safe = sc.verdict, sc.spec.controller.d_safe
        assert v.settle_time == 2.0 and v.max_tracking_error == 0.001
        assert v.safety_margin == pytest.approx(0.05 * d_safe)  # 5% of d_safe
        assert v.max_p99_fraction_of_dt == 0.5 and v.max_over_dt_share == 0.001
        # the defaults, written out (the margin: the default's 5% of d_safe)
        assert v == VerdictSettings(
            max_force_error=v.max_force_error, safety_margin=v.safety_margin
        )
        # the paper's adaptation gain leaves a 5 N force bias for tens of seconds: twice that is allowed
        assert v.max_force_error == (10.0 if name == "adaptive" else 2.0)


def _edited(tmp_path, old, new):
    text = (SHIPPED / "wall.toml").read_text()
    assert re.search(old, text, flags=re.M), old
    f = tmp_path / "edited.toml"
    f.write_text(re.sub(old, new, text, count=1, flags=re.M))
    return f


def test_safety_margin_defaults_to_half_a_millimetre(tmp_path):
    f = _edited(tmp_path, r"^safety_margin = .*$", "")
    assert (
        "safety_margin" not in f.read_text().split("[verdict]")[1].split("[rnn]")[0].split("#")[0]
    )
    assert load_scenario(f).verdict.safety_margin == 0.0005
    f = _edited(tmp_path, r"^safety_margin = .*$", "safety_margin = 0.002")
    assert load_scenario(f).verdict.safety_margin == 0.002
    assert (
        load_scenario("wall", overrides={"verdict.max_force_error": 3.5}).verdict.max_force_error
        == 3.5
    )


@pytest.mark.parametrize(
    "old,new,key",
    [
        (r"^settle_time = .*$", "settle_time = -1.0", "verdict.settle_time"),
        (r"^max_tracking_error = .*$", "max_tracking_error = 0.0", "verdict.max_tracking_error"),
        (r"^max_force_error = .*$", 'max_force_error = "two"', "verdict.max_force_error"),
        (r"^max_force_error = .*$", "max_force_error = -2.0", "verdict.max_force_error"),
        (r"^safety_margin = .*$", "safety_margin = -0.001", "verdict.safety_margin"),
        # safety_margin < d_safe: else a key point may touch the obstacle and pass
        (r"^safety_margin = .*$", "safety_margin = 0.01", "verdict.safety_margin"),
        (
            r"^max_p99_fraction_of_dt = .*$",
            "max_p99_fraction_of_dt = 0.0",
            "verdict.max_p99_fraction_of_dt",
        ),
        (
            r"^max_p99_fraction_of_dt = .*$",
            "max_p99_fraction_of_dt = 1.5",
            "verdict.max_p99_fraction_of_dt",
        ),
        (r"^max_over_dt_share = .*$", "max_over_dt_share = -0.1", "verdict.max_over_dt_share"),
        (r"^max_over_dt_share = .*$", "max_over_dt_share = 1.0", "verdict.max_over_dt_share"),
        (r"^settle_time = ", "settle_tim = ", "verdict.settle_tim"),  # typo
        (r"^\[verdict\]", "[verdit]", "verdit"),  # misspelt table
    ],
)
def test_bad_thresholds_are_refused_naming_file_and_key(tmp_path, capsys, old, new, key):
    f = _edited(tmp_path, old, new)
    with pytest.raises(ScenarioError) as err:
        load_scenario(f)
    assert err.value.key == key and str(f) in str(err.value)
    out = tmp_path / "s.json"
    assert main(["simulate", "--scenario", str(f), "--backend", "daqp", "--summary", str(out)]) == 2
    lines = capsys.readouterr().err.strip().splitlines()
    assert len(lines) == 1 and f"key '{key}'" in lines[0] and str(f) in lines[0]
    assert not out.exists()


@pytest.mark.parametrize(
    "key,value",
    [
        ("verdict.settle_time", "100"),  # past the 20 s duration
        ("verdict.safety_margin", "1.0"),  # past d_safe = 10 mm
        ("verdict.max_tracking_error", "0"),
        ("verdict.max_force_error", "-2"),
        ("verdict.max_p99_fraction_of_dt", "2"),
        ("verdict.max_over_dt_share", "1"),
    ],
)
def test_bad_thresholds_set_on_the_command_line_exit_2_naming_the_key(tmp_path, capsys, key, value):
    out = tmp_path / "s.json"
    argv = [
        *simulate_args("wall", "daqp", "0.05", "--set", f"{key}={value}"),
        "--summary",
        str(out),
    ]
    assert main(argv) == 2
    lines = capsys.readouterr().err.strip().splitlines()
    assert (
        len(lines) == 1
        and f"key '{key}'" in lines[0]
        and lines[0].startswith("qpbench simulate: error")
    )
    assert not out.exists()


def test_a_settle_time_set_past_the_duration_is_refused_a_shorter_run_is_not():
    """``--set verdict.settle_time`` at or past the duration is refused; a run set shorter
    than the settle time is judged on what it simulated and says tracking and force were not
    judged."""
    with pytest.raises(ScenarioError) as err:
        load_scenario("wall", overrides={"verdict.settle_time": 1.0, "simulation.duration": 1.0})
    assert err.value.key == "verdict.settle_time" and "simulation.duration = 1 s" in str(err.value)
    sc = load_scenario("wall", overrides={"simulation.duration": 1.0})
    assert sc.verdict.settle_time == 2.0 and sc.duration == 1.0


def test_a_settle_time_set_on_the_command_line_is_checked_against_the_duration_run():
    """The duration run is the one after every override (``--set``, then ``--duration``, or
    :meth:`Scenario.with_overrides`), not the file's nor the ``--set`` one before it."""
    settle = {"verdict.settle_time": 100.0, "simulation.duration": 200.0}
    with pytest.raises(ScenarioError) as err:
        load_scenario("wall", overrides=settle, duration=5.0)
    assert err.value.key == "verdict.settle_time" and "simulation.duration = 5 s" in str(err.value)
    # past the file's 20 s, inside the run's 30 s: allowed
    sc = load_scenario("wall", overrides={"verdict.settle_time": 25.0}, duration=30.0)
    assert (sc.verdict.settle_time, sc.duration) == (25.0, 30.0)
    with pytest.raises(ScenarioError) as err:
        sc.with_overrides(duration=25.0)
    assert err.value.key == "verdict.settle_time"
    # a settle time of the file's own, not set on the command line: a shorter run says so
    assert load_scenario("wall", duration=1.0).verdict.settle_time == 2.0


@pytest.mark.parametrize("command", ["simulate", "closed-loop"])
def test_a_diverging_run_cannot_pass_on_a_settle_time_beyond_its_duration(
    tmp_path, capsys, command
):
    """The paper's network diverges in free (docs/results.md): with a settle time set past the
    duration run it would not be judged, so the command refuses it before running."""
    out = tmp_path / "out"
    where = ["--scenario", "free", "--backend", "rnn", "--summary", str(out)]
    if command == "closed-loop":
        where = ["--scenarios", "free", "--backends", "rnn", "--out", str(out)]
    settle = ["--set", "simulation.duration=200", "--set", "verdict.settle_time=100"]
    assert main([command, *where, *settle, "--duration", "3"]) == 2
    lines = capsys.readouterr().err.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith(f"qpbench {command}: error"), lines
    assert "key 'verdict.settle_time'" in lines[0] and "simulation.duration = 3 s" in lines[0]
    assert not out.exists()
    if command == "simulate":  # judged on the file's settle time, the same run is not ok
        assert main([command, *where, "--duration", "3"]) == 1
        assert json.loads(out.read_text())["verdict"] == "diverged"


def test_closed_loop_judges_a_settle_time_set_on_the_command_line(tmp_path):
    """A settle time inside the duration run is allowed and the row is judged on it (the
    discarded warm-up, shorter than any settle time, is not judged): at 0.1 s wall's infeasible
    start (to about 0.13 s) still holds the arm off the path, so the run is diverged."""
    out = tmp_path / "loop"
    argv = ["closed-loop", "--scenarios", "wall", "--backends", "daqp", "--out", str(out)]
    assert main([*argv, "--duration", "0.2", "--set", "verdict.settle_time=0.1"]) == 0
    row = pd.read_csv(out / "closed_loop.csv").iloc[0]
    assert (row["status"], row["verdict"], row["duration_s"]) == ("ok", "diverged", 0.2)
    assert json.loads(row["verdict_overrides"]) == {"settle_time": 0.1}
    assert "after 0.1 s" in row["verdict_reasons"]


def _without(text: str, table: str) -> str:
    head, rest = text.split(f"[{table}]\n")
    nxt = rest.find("\n[")
    return head + (rest[nxt + 1 :] if nxt >= 0 else "")


def test_a_file_without_verdict_rnn_adaptive_runs_on_the_defaults(tmp_path):
    text = (SHIPPED / "wall.toml").read_text()
    for table in ("verdict", "rnn", "adaptive"):
        text = _without(text, table)
    assert "[verdict]" not in text and "[rnn]" not in text and "[adaptive]" not in text
    f = tmp_path / "task_only.toml"
    f.write_text(text)
    bare, shipped = load_scenario(f), load_scenario("wall")
    assert bare.verdict == shipped.verdict == VerdictSettings()
    assert bare.rnn == shipped.rnn == {"eps": 0.02}
    assert not bare.spec.adaptive.enabled
    np.testing.assert_array_equal(bare.spec.adaptive.gain, shipped.spec.adaptive.gain)
    assert bare.spec.adaptive.kp_min == shipped.spec.adaptive.kp_min
    # a threshold set over a table the file leaves out: the table's defaults, then the key
    assert (
        load_scenario(f, overrides={"verdict.max_force_error": 3.0}).verdict.max_force_error == 3.0
    )
    s = simulate(bare, "daqp", duration=0.1).summary
    assert s["verdict"] == "ok" and s["verdict_reasons"] == (
        "tracking and force not judged (settle time 2 s not reached)"
    )
    # defaults that fit the task: a short scenario's settle time is half its duration, a small
    # d_safe's margin half of it
    f.write_text(
        text.replace("duration = 20.0", "duration = 1.0").replace(
            "d_safe = 0.01", "d_safe = 0.0004"
        )
    )
    short = load_scenario(f).verdict
    assert short.settle_time == 0.5 and short.safety_margin == 0.0002


# ---------------------------------------------------------------- the rules, on logs made by hand

LIMITS = SimpleNamespace(
    theta_min=np.full(2, -1.0),
    theta_max=np.full(2, 1.0),
    v_min=np.full(2, -0.5),
    v_max=np.full(2, 0.5),
)
SETTINGS = VerdictSettings(
    settle_time=1.0, max_tracking_error=1e-3, max_force_error=2.0, safety_margin=5e-4
)


def _log(n=3000, dt=1e-3, **over):
    t = np.arange(n) * dt
    cols = {
        "t": t,
        "theta_0": np.zeros(n),
        "theta_1": np.zeros(n),
        "v_0": np.zeros(n),
        "v_1": np.zeros(n),
        "tracking_error": np.zeros(n),
        "force": np.zeros(n),
        "force_error": np.zeros(n),
        "d_A1_wall": np.full(n, 0.02),
        "d_body_min": np.full(n, 0.02),
        "d_body_link": np.full(n, 2),
        "d_body_obstacle": np.full(n, "wall"),
        "v_sq": np.zeros(n),
        "task_residual": np.zeros(n),
        "status": np.full(n, "optimal"),
        "fallback": np.zeros(n, dtype=bool),
        "zero_velocity": np.zeros(n, dtype=bool),
        "solve_time_s": np.full(n, 1e-5),
        "solver_time_s": np.full(n, np.nan),
        "kp_hat": np.ones(n),
        "kd_hat": np.ones(n),
    }
    for k, f in over.items():
        cols[k] = f(t)
    return pd.DataFrame(cols)


#: What :func:`summarize` reads of a scenario and a controller: 2 joints, one wall, key point A1
#: (the logs' arm lies still along x, 0.05 m from the wall; the body columns are made by hand).
SCENARIO = SimpleNamespace(
    name="hand", overrides={}, verdict_overrides={}, dt=1e-3, duration=3.0, verdict=SETTINGS
)
CONTROLLER = SimpleNamespace(
    n=2,
    limits=LIMITS,
    d_safe=0.01,
    arm=PlanarArm([0.3, 0.4]),
    obstacles=[LineObstacle("wall", [-0.05, 0.0], [1.0, 0.0])],
    exempt=[False],
    obstacle_columns=lambda: [("A1", "wall", slice(0, 1))],
    key_points=SimpleNamespace(kind="paper", radius=0.0),
)


def _judge(frame, **run_info):
    """The verdict of a hand-made log: its summary's (``run_info`` over the summary's figures),
    the reasons split where the summary joins them."""
    s = summarize(frame, SCENARIO, CONTROLLER, "b", "paper", 1.0, run_info)
    reasons = tuple(s["verdict_reasons"].split("; ")) if s["verdict_reasons"] else ()
    return SimpleNamespace(
        verdict=s["verdict"],
        reasons=reasons,
        text=s["verdict_reasons"],
        ok=s["verdict"] == "ok",
        key_point_rule=s["key_point_rule"],
        key_point_rule_reason=s["key_point_rule_reason"],
    )


def test_clean_run_is_ok():
    v = _judge(
        _log(
            tracking_error=lambda t: np.where(t < 1.0, 0.5, 9e-4),
            force_error=lambda t: np.where(t < 1.0, 50.0, -1.9),
            d_A1_wall=lambda t: np.full_like(t, 0.0096),
        )
    )
    assert (
        v.verdict == "ok" and v.reasons == () and v.ok
    )  # big errors inside the transient are not judged


def test_each_rule_and_its_reason():
    # the key-point rule broken, the body clear: reported beside an ok verdict
    near = _judge(_log(d_A1_wall=lambda t: np.where((t >= 1.5) & (t < 1.6), 0.0064, 0.02)))
    assert near.verdict == "ok" and near.key_point_rule == "broken"
    assert near.key_point_rule_reason == (
        "d_min 6.4 mm < d_safe - 0.5 mm = 9.5 mm (A1/wall at 1.500 s; 100 ticks)"
    )
    assert _judge(_log()).key_point_rule == "held"
    # the body inside an obstacle: unsafe, naming link, obstacle, depth and time
    unsafe = _judge(
        _log(
            d_body_min=lambda t: np.where((t >= 1.5) & (t < 1.6), -0.03 + (t - 1.5) / 10, 0.02),
            d_body_link=lambda t: np.where(t >= 1.5, 2, 1),
        )
    )
    assert unsafe.verdict == "unsafe"
    assert unsafe.text == (
        "link 2 (end effector) 30.0 mm inside line 'wall' at 1.50 s "
        "(the body inside an obstacle on 100 ticks from 1.500 s)"
    )
    limits = _judge(
        _log(
            v_1=lambda t: np.where(t == 0.25, -0.7, 0.0),
            theta_0=lambda t: np.where(t > 2.5, 1.0 + 2e-6, 0.0),
        )
    )
    assert limits.verdict == "limits"
    assert limits.reasons[0].startswith(
        "joint angle limit broken on 499 ticks (worst theta_0 = 1 rad > 1 rad at 2.501 s"
    )
    assert (
        limits.reasons[1]
        == "joint speed limit broken on 1 tick (worst v_1 = -0.7 rad/s < -0.5 rad/s at 0.250 s)"
    )
    # within VIOLATION_TOL of a limit is no violation
    assert _judge(_log(v_0=lambda t: np.full_like(t, 0.5 + 5e-7))).verdict == "ok"
    diverged = _judge(_log(force_error=lambda t: np.where(t > 2.0, 2.5, 0.0)))
    assert (
        diverged.verdict == "diverged"
        and diverged.text == "force error 2.5 N > 2 N after 1 s (at 2.001 s)"
    )
    nan = _judge(_log(tracking_error=lambda t: np.where(t > 2.0, np.nan, 0.0)))
    assert nan.verdict == "diverged" and nan.text.startswith("tracking error not finite > 1 mm")
    failed = _judge(_log(), error_ticks=3, first_error="RuntimeError: boom", first_error_t=0.005)
    assert (
        failed.verdict == "failed"
        and failed.text == "3 ticks with an error (first at 0.005 s: RuntimeError: boom)"
    )
    for key in ("invalid_ticks", "time_limit_ticks", "zero_velocity_ticks", "fallback_errors"):
        assert _judge(_log(), **{key: 1}).verdict == "failed", key


def test_precedence_failed_unsafe_limits_diverged_with_every_reason():
    frame = _log(
        d_A1_wall=lambda t: np.full_like(t, -0.09),
        d_body_min=lambda t: np.full_like(t, -0.09),
        v_0=lambda t: np.full_like(t, 2.0),
        tracking_error=lambda t: np.full_like(t, 0.3),
    )
    v = _judge(frame)
    assert v.verdict == "unsafe"
    assert [r.split()[0] for r in v.reasons] == ["link", "joint", "tracking"]
    assert v.reasons[0].startswith("link 2 (end effector) 90.0 mm inside line 'wall' at 0.00 s")
    assert v.key_point_rule == "broken" and "d_min -90.0 mm" in v.key_point_rule_reason
    v = _judge(frame, invalid_ticks=2)
    assert v.verdict == "failed" and len(v.reasons) == 4 and v.reasons[0] == "2 non-finite answers"
    assert (
        _judge(
            _log(v_0=lambda t: np.full_like(t, 2.0), tracking_error=lambda t: np.full_like(t, 0.3))
        ).verdict
        == "limits"
    )


def test_a_run_stopped_early_is_incomplete_and_judged_on_what_it_simulated():
    short = _log(n=800)  # 0.8 s: before the settle time
    v = _judge(short, stopped_early=True, simulated_s=0.8, duration=20.0, wall_budget_s=5.0)
    assert v.verdict == "incomplete"
    assert v.text == (
        "stopped at 0.80 s of 20 s (wall-time budget 5 s): tracking and force not judged "
        "(settle time 1 s not reached)"
    )
    # a run asked shorter than the settle time reached its end: ok, with the note
    v = _judge(short, simulated_s=0.8, duration=0.8)
    assert (
        v.verdict == "ok"
        and v.text == "tracking and force not judged (settle time 1 s not reached)"
    )
    # worse verdicts rank above incomplete, diverged below it
    diverging = _log(force_error=lambda t: np.where(t > 2.0, 2.5, 0.0))
    v = _judge(diverging, stopped_early=True, simulated_s=3.0, duration=20.0, wall_budget_s=5.0)
    assert v.verdict == "incomplete" and v.reasons[1].startswith("force error 2.5 N")
    v = _judge(
        _log(d_body_min=lambda t: np.full_like(t, -0.001)),
        stopped_early=True,
        simulated_s=3.0,
        duration=20.0,
        wall_budget_s=5.0,
    )
    assert v.verdict == "unsafe" and v.reasons[-1].endswith("judged on what was simulated")


def test_failed_run_verdict():
    v = failed_run("crashed", "worker process killed by SIGSEGV\n during the run")
    assert (
        v.verdict == "incomplete"
        and v.text == "run crashed: worker process killed by SIGSEGV during the run"
    )


# ---------------------------------------------------------------- real runs


@pytest.mark.parametrize("scenario", ["free", "wall", "adaptive", "narrow", "adaptive_fast"])
def test_exact_qp_passes_and_paper_rnn_fails_every_shipped_scenario(scenario):
    """Full 20 s runs: the thresholds separate a controller that solves its QP from the paper's RNN (eps = 0.02 s)."""
    exact = simulate(scenario, "daqp").summary
    assert exact["verdict"] == "ok" and exact["verdict_reasons"] == "", exact["verdict_reasons"]
    rnn = simulate(scenario, "rnn").summary
    assert rnn["verdict"] in ("unsafe", "diverged")
    assert "tracking error" in rnn["verdict_reasons"]  # it misses the tracking threshold everywhere
    if scenario != "free":  # its key points come closer than d_safe allows
        assert rnn["key_point_rule"] == "broken"
        # the verdict judges the body: unsafe exactly where a link went into an obstacle
        assert (rnn["min_body_distance"] < 0) == (rnn["verdict"] == "unsafe")
    if scenario == "wall":  # there the links go through the wall
        assert rnn["min_body_distance"] < 0 and rnn["verdict_reasons"].startswith("link ")


def test_simulate_pinv_through_the_wall_is_unsafe_and_exits_1(tmp_path, capsys):
    """pinv ignores the obstacle: A2 is 9.5 mm from the wall by 1.5 s, link 1 through it by 1.92 s
    (and it breaks the speed limit at t = 0)."""
    out = tmp_path / "s.json"
    code = main(
        [
            *simulate_args("wall", "pinv", "2.2"),
            "--summary",
            str(out),
        ]
    )
    assert code == 1
    s = json.loads(out.read_text())
    assert s["verdict"] == "unsafe"
    assert (
        s["verdict_reasons"].startswith("link 1 ")
        and " inside line 'wall' at 2.20 s" in (s["verdict_reasons"])
    )
    assert "joint speed limit broken" in s["verdict_reasons"]
    assert s["min_body_distance"] < 0 and s["min_body_distance_link"] == 1
    assert s["key_point_rule"] == "broken"
    assert "< d_safe - 0.5 mm = 9.5 mm (A2/wall at " in s["key_point_rule_reason"]
    assert s["min_obstacle_distance"] < 0.0095
    err = capsys.readouterr().err.splitlines()
    warnings = [line for line in err if line.startswith("WARNING: ")]
    # the distances are part of the verdict's output, not plain INFO lines
    assert warnings == [
        f"WARNING: verdict unsafe: {s['verdict_reasons']}; key-point rule broken: "
        f"{s['key_point_rule_reason']}"
    ]
    assert f"{-s['min_body_distance'] * 1e3:.1f} mm inside" in warnings[0]
    assert f"d_min {s['min_obstacle_distance'] * 1e3:.1f} mm" in warnings[0]
    assert not [line for line in err if line.startswith("INFO: ") and "obstacle distance" in line]


def test_simulate_exact_backend_is_ok_and_exits_0(tmp_path, capsys):
    out = tmp_path / "s.json"
    assert (
        main(
            [
                *simulate_args("wall", "daqp", "0.3"),
                "--summary",
                str(out),
            ]
        )
        == 0
    )
    s = json.loads(out.read_text())
    assert (s["verdict"], s["verdict_reasons"]) == (
        "ok",
        "tracking and force not judged (settle time 2 s not reached)",
    )
    assert s["verdict_overrides"] == {}
    err = capsys.readouterr().err.splitlines()
    assert not [line for line in err if line.startswith("WARNING")]
    assert [
        line
        for line in err
        if line.startswith("INFO: verdict ok: tracking and force not judged")
        and "; min body distance " in line
        and "; key-point rule held: min obstacle distance " in line
    ]


def test_faulty_backend_fails_its_verdict():
    import faulty_backends  # noqa: F401 - registers the faulty-ticks:* backends

    s = simulate("wall", "faulty-ticks:raise", duration=0.1).summary
    assert s["verdict"] == "failed"
    assert (
        s["verdict_reasons"].startswith("10 ticks with an error (first at ")
        and "RuntimeError: tick fault" in s["verdict_reasons"]
    )
    s = simulate("wall", "faulty-ticks:nan", duration=0.1).summary
    assert s["verdict"] == "failed" and s["verdict_reasons"] == (
        "10 non-finite answers; tracking and force not judged (settle time 2 s not reached)"
    )


# ---------------------------------------------------------------- the wall-time budget


def test_budget_stops_between_ticks_with_the_uncut_prefix():
    cut = simulate("wall", SlowExact(), duration=0.5, wall_budget_s=0.25)
    s = cut.summary
    assert s["stopped_early"] and s["wall_budget_s"] == 0.25
    assert 0 < s["ticks"] == len(cut.log) < 500
    assert s["simulated_s"] == pytest.approx(s["ticks"] * 0.001) and s["duration"] == 0.5
    assert s["real_time_factor"] == pytest.approx(s["simulated_s"] / s["wall_time_s"])
    assert s["wall_time_s"] >= 0.25  # it stopped because the budget was spent
    assert s["verdict"] == "incomplete" and s["verdict_reasons"] == (
        f"stopped at {s['simulated_s']:.2f} s of 0.5 s (wall-time budget 0.25 s): "
        "tracking and force not judged (settle time 2 s not reached)"
    )
    whole = simulate("wall", SlowExact(), duration=0.5)
    assert not whole.summary["stopped_early"] and whole.summary["ticks"] == 500
    n = s["ticks"]
    pd.testing.assert_frame_equal(
        cut.log.drop(columns=list(TIME_COLUMNS)),
        whole.log.drop(columns=list(TIME_COLUMNS)).iloc[:n],
    )
    json.dumps(s, allow_nan=False)


def test_bad_budget():
    with pytest.raises(ParamError, match="positive"):
        simulate("wall", "daqp", duration=0.01, wall_budget_s=0.0)


# ---------------------------------------------------------------- real time, beside the verdict

#: A plugin file: ``daqp``'s answers after a sleep of 20 ms per solve (20 times a 1 kHz period).
SLEEPY_PLUGIN = """
import time

from qpbench.backends import Backend, get_backend, register


@register
class Sleepy(Backend):
    name = "test-sleepy-20ms"
    family = "test"

    def __init__(self, profile="default", **settings):
        super().__init__(profile, **settings)
        self.inner = get_backend("daqp", profile)

    def reset(self):
        self.inner.reset()

    def _solve(self, problem, warm_start):
        time.sleep(0.02)
        return self.inner.solve(problem, warm_start)
"""


def _timed(n, times, status=None, fallback=None, own=None, **over):
    """A hand-made log of ``n`` ticks (``dt`` 1 ms) with the given call times [s], statuses,
    fallback flags and solver's own times; real time judged on the defaults."""
    frame = _log(n, **over)
    frame["solve_time_s"] = times
    if status is not None:
        frame["status"] = status
    if fallback is not None:
        frame["fallback"] = fallback
    if own is not None:
        frame["solver_time_s"] = own
    scenario = SimpleNamespace(**{**vars(SCENARIO), "verdict": VerdictSettings()})
    return summarize(frame, scenario, CONTROLLER, "b", "paper", 1.0)


def _start(n, infeasible_times, steady=100e-6):
    """Times [s], statuses and fallback flags of a run whose first ticks are infeasible (their
    times ``infeasible_times``), the soft fallback applied there, the rest optimal at ``steady``."""
    k = len(infeasible_times)
    times = np.full(n, steady)
    times[:k] = infeasible_times
    status = np.array(["primal_infeasible"] * k + ["optimal"] * (n - k))
    return times, status, np.arange(n) < k


def test_the_p99_and_the_share_rule_on_hand_made_logs():
    s = _timed(1000, np.full(1000, 100e-6))
    assert (s["realtime"], s["realtime_reason"]) == (
        "yes",
        "p99 call 100 µs <= 50% of dt 1 ms; 0 of 1000 ticks over dt (0.00%; <= 1 allowed: "
        "0.10% rounded up)",
    )
    # the p99 rule: 2% of the ticks at 0.6 ms put the p99 above half of dt, none over dt
    tail = np.full(1000, 100e-6)
    tail[:20] = 0.6e-3
    s = _timed(1000, tail)
    assert s["realtime"] == "no"
    assert s["realtime_reason"].startswith("p99 call 600 µs > 50% of dt 1 ms; 0 of 1000")
    # the share rule: 2 ticks of 1000 over dt, the p99 fine; the failed criterion first, the cause last
    two = np.full(1000, 100e-6)
    two[[10, 500]] = 1.5e-3
    s = _timed(1000, two)
    assert s["realtime"] == "no" and s["deadline_misses"] == 2 and s["over_dt_optimal"] == 2
    assert s["realtime_reason"].startswith(
        "2 of 1000 ticks over dt (0.20%; > 1 allowed: 0.10% rounded up); p99 call"
    )
    # one miss in fewer than 1,000 ticks is within one in a thousand, rounded up
    one = np.full(885, 100e-6)
    one[10] = 1.5e-3
    assert _timed(885, one)["realtime"] == "yes"
    assert s["realtime_reason"].endswith("over dt on 2 of 1000 ticks: 2 optimal (p99 call 100 µs)")
    # the thresholds come from the scenario
    wider = SimpleNamespace(
        **{**vars(SCENARIO), "verdict": VerdictSettings(max_over_dt_share=0.002)}
    )
    frame = _log(1000)
    frame["solve_time_s"] = two
    assert summarize(frame, wider, CONTROLLER, "b", "paper", 1.0)["realtime"] == "yes"


def test_each_miss_with_its_kind_and_the_time_to_certify_infeasibility():
    # OSQP in free: 115 infeasible start ticks, 2.6 ms median to certify, at most 5.3 ms
    certify = np.r_[np.full(57, 2.0e-3), np.full(57, 3.2e-3), 5.3e-3]
    times, status, fallback = _start(20000, certify, steady=120e-6)
    times[[5000, 9000]] = 1.2e-3  # two optimal ticks over dt
    status[[7000, 7001]] = "time_limit"  # a fallback: its own answer dropped
    times[[7000, 7001]] = [0.8e-3, 1.1e-3]
    fallback[[7000, 7001]] = True
    status[8000] = "max_iter"  # an answer applied whatever its status (an online backend's)
    s = _timed(20000, times, status, fallback)
    counts = {
        k: (s[f"ticks_{k}"], s[f"over_dt_{k}"])
        for k in ("optimal", "infeasible", "fallback", "other")
    }
    assert counts == {
        "optimal": (19882, 2),
        "infeasible": (115, 115),
        "fallback": (2, 1),
        "other": (1, 0),
    }
    assert s["deadline_misses"] == 118 == sum(n for _, n in counts.values())
    assert s["certify_time_median_s"] == pytest.approx(3.2e-3)  # the 58th of 115
    assert s["certify_time_max_s"] == pytest.approx(5.3e-3)
    assert s["time_p99_infeasible_s"] == pytest.approx(np.quantile(certify, 0.99))
    assert s["time_p99_fallback_s"] == pytest.approx(np.quantile([0.8e-3, 1.1e-3], 0.99))
    assert s["time_p99_without_infeasible_s"] == pytest.approx(np.quantile(times[115:], 0.99))
    why = s["realtime_reason"]
    assert s["realtime"] == "no" and why.startswith(
        "the 115 infeasible ticks: median call 3.2 ms > 50% of dt 1 ms; "
    )
    assert why.endswith(
        "over dt on 118 of 20000 ticks: 115 infeasible (of 115 infeasible ticks, 0.000-0.114 s; "
        "3.2 ms median solve to certify infeasibility, at most 5.3 ms), "
        "2 optimal (p99 call 120 µs), 1 fallback (p99 call 1.1 ms, own answer not applied: the "
        "soft fallback ran)"
    )
    # the other ticks keep the rules: 3 of 19885 over dt, p99 120 µs
    assert "3 of 19885 ticks not declared infeasible over dt (0.02%; <= 20 allowed" in why


@pytest.mark.parametrize("certify,expected", [(50e-6, "yes"), (2.6e-3, "no")])
def test_a_1_s_and_a_20_s_run_of_the_same_backend_agree(certify, expected):
    """The infeasible start is the same 115 ticks in a 1 s and a 20 s run; judged by its median,
    not as a share of the run, so a quick run and a full run give the same answer."""
    start = np.full(115, certify)
    start[:10] = 3e-3  # ten of the start ticks over dt, whatever the backend
    answers = []
    for n in (1000, 20000):
        s = _timed(n, *_start(n, start))
        answers.append(s["realtime"])
        assert s["over_dt_infeasible"] == (10 if certify < 1e-3 else 115)
    assert answers == [expected, expected]
    # judged as a share of all the ticks, the 1 s run would not be real time (1 % > 0.1 %)
    assert _timed(1000, *_start(1000, start))["over_dt_share"] > 1e-3


def test_the_solvers_own_time_is_judged_only_where_every_tick_has_one():
    times = np.full(20000, 100e-6)
    own = np.full(20000, np.nan)
    own[::36][:547] = 20e-6  # reported on a few ticks (Clarabel: only where it rebuilds)
    s = _timed(20000, times, own=own)
    assert s["realtime_solver"] == "unknown" and s["solver_time_ticks"] == 547
    assert s["realtime_solver_reason"].startswith("reports its own time on 547 of 20000 ticks")
    assert s["solver_time_p99_s"] is None and s["solver_over_dt_share"] is None
    s = _timed(20000, times, own=np.full(20000, 20e-6))
    assert s["realtime_solver"] == "yes" and s["solver_time_p99_s"] == pytest.approx(20e-6)
    s = _timed(20000, times)
    assert (s["realtime_solver"], s["realtime_solver_reason"]) == (
        "unknown",
        "no solver time reported",
    )


def _floor(share, p99=60e-6):
    return {"over_dt_share": share, "time_p99_without_infeasible_s": p99}


def test_the_noise_floor_enters_each_criterion():
    times = np.full(10000, 100e-6)
    times[:12] = 2e-3  # 12 of 10000 over dt: 0.12 % > 0.1 %
    s = _timed(10000, times)
    assert s["realtime"] == "no"
    # the machine's own loop missed 0.04 %: 8 of the 12 are beyond it, 0.08 % <= 0.1 %
    verdict, why = judge_realtime_run(s, "call", _floor(4e-4))
    assert verdict == "yes"
    assert "12 of 10000 ticks over dt, 8 beyond the 0.04% this machine's own loop missed" in why
    # the floor itself misses 0.4 % of ticks: the share cannot be judged on this machine
    verdict, why = judge_realtime_run(s, "call", _floor(4e-3))
    assert verdict == "unknown"
    assert why.startswith("this machine's own loop (no solver) missed 0.40% of ticks at 1 kHz")
    # ... but a p99 the floor holds is the backend's own: not real time
    slow = times.copy()
    slow[:300] = 0.7e-3
    verdict, why = judge_realtime_run(_timed(10000, slow), "call", _floor(4e-3))
    assert verdict == "no" and why.startswith("p99 call 700 µs > 50%")
    # ... and a backend that passes anyway is real time
    assert judge_realtime_run(_timed(10000, np.full(10000, 1e-4)), "call", _floor(4e-3))[0] == "yes"
    # a floor whose p99 fails makes a failed p99 unknown too
    assert judge_realtime_run(_timed(10000, slow), "call", _floor(4e-3, p99=0.8e-3))[0] == "unknown"
    # the floor's figures as a table row holds them (read back: NaN for None, counts as floats)
    row = {
        k: (float(v) if isinstance(v, int) and not isinstance(v, bool) else v) for k, v in s.items()
    }
    row = {k: (math.nan if v is None else v) for k, v in row.items()}
    floor = floor_fields({**_floor(4e-4), "realtime": "yes"})
    assert judge_realtime_run(row, "call", floor) == judge_realtime_run(s, "call", floor)


def test_a_sleeping_plugin_backend_is_not_real_time_without_any_flag(tmp_path, capsys):
    plugin = tmp_path / "sleepy.py"
    plugin.write_text(SLEEPY_PLUGIN)
    out = tmp_path / "s.json"
    argv = ["--plugin", str(plugin), *simulate_args("wall", "test-sleepy-20ms", "0.02")]
    assert main([*argv, "--summary", str(out)]) == 0  # real time is not part of the verdict
    s = json.loads(out.read_text())
    assert s["verdict"] == "ok" and s["deadline_s"] is None
    assert s["realtime"] == "no" and s["over_dt_share"] == 1.0
    # wall's first 123 ticks are infeasible: the 20 ticks run are all of them
    assert s["realtime_reason"].startswith("the 20 infeasible ticks: median call ")
    assert "over dt on 20 of 20 ticks: 20 infeasible" in s["realtime_reason"]
    assert s["solve_time_p99_s"] >= 0.02
    # daqp reports its own time: a C controller calling it would keep up
    assert s["realtime_solver"] == "yes" and 0 < s["solver_time_p99_s"] < 1e-3
    err = capsys.readouterr().err
    assert "INFO: real time at dt = 1 ms: no (the 20 infeasible ticks: median call" in err


def test_solver_time_is_logged_per_tick_and_unknown_without_one():
    import faulty_backends  # noqa: F401 - registers the faulty-ticks:* backends

    run = simulate("wall", "daqp", duration=0.02)
    own = run.log["solver_time_s"].to_numpy()
    assert np.isfinite(own).all() and (own > 0).all()
    # inside the calls it is part of: wall starts infeasible, so the soft fallback's own time
    # adds to the tick's (as its call time does)
    calls = run.log["solve_time_s"] + run.log["fallback_solve_time_s"].fillna(0.0)
    assert (own <= calls.to_numpy()).all()
    assert run.summary["solver_time_p99_s"] == pytest.approx(np.quantile(own, 0.99))
    # pinv reports no time of its own
    s = simulate("wall", "pinv", duration=0.02).summary
    assert s["realtime_solver"] == "unknown" and s["solver_time_p99_s"] is None
    assert s["realtime"] in ("yes", "no") and s["realtime_reason"].startswith("p99 call ")


# ---------------------------------------------------------------- thresholds set on the command line


def test_a_verdict_override_is_warned_and_recorded(tmp_path, capsys):
    out = tmp_path / "s.json"
    argv = simulate_args(
        "wall", "daqp", "0.05", "--set", "verdict.max_force_error=3.5", "--set", "rnn.eps=0.01"
    )
    assert main([*argv, "--summary", str(out)]) == 0
    s = json.loads(out.read_text())
    assert s["verdict_overrides"] == {"max_force_error": 3.5}  # only the [verdict] keys
    assert s["scenario_overrides"] == {"verdict.max_force_error": 3.5, "rnn.eps": 0.01}
    warnings = [line for line in capsys.readouterr().err.splitlines() if "WARNING" in line]
    assert len(warnings) == 1 and "verdict.max_force_error=3.5" in warnings[0]


def test_the_report_marks_a_verdict_judged_on_overridden_thresholds():
    from qpbench.report.markdown import FOOTNOTE, OVERRIDDEN, failed_verdicts

    df = pd.DataFrame(
        [
            dict(
                scenario="wall",
                backend="a",
                formulation="paper",
                verdict="diverged",
                verdict_reasons="x",
                verdict_overrides='{"settle_time": 5.0}',
            ),
            dict(
                scenario="wall",
                backend="b",
                formulation="paper",
                verdict="incomplete",
                verdict_reasons="y",
                verdict_overrides="{}",
            ),
        ]
    )
    text = "".join(failed_verdicts(df))
    assert f"diverged{OVERRIDDEN}" in text and "| incomplete |" in text
    assert f"incomplete{OVERRIDDEN}" not in text and OVERRIDDEN in FOOTNOTE
    # rows held in memory carry the summary's dict, not its JSON text
    df["verdict_overrides"] = [{"settle_time": 5.0}, {}]
    assert "".join(failed_verdicts(df)) == text


# ---------------------------------------------------------------- a scenario with every default


@pytest.mark.parametrize("name", ["wall", "adaptive", "free"])
def test_show_filled_prints_a_file_that_loads_back_to_the_same_scenario(tmp_path, capsys, name):
    text = (SHIPPED / f"{name}.toml").read_text()
    for table in ("verdict", "rnn", "adaptive"):
        text = _without(text, table)
    source = tmp_path / f"{name}_task_only.toml"
    source.write_text(text)
    assert main(["scenarios", "show", str(source), "--filled"]) == 0
    printed = capsys.readouterr().out
    for table in ("[verdict]", "[rnn]", "[adaptive]", "max_over_dt_share = 0.001"):
        assert table in printed
    back = tmp_path / "filled.toml"
    back.write_text(printed)
    a, b = load_scenario(source), load_scenario(back)
    assert (a.name, a.rnn, a.verdict) == (b.name, b.rnn, b.verdict)
    assert list(a.spec.model_fields) == list(b.spec.model_fields)
    for table in a.spec.model_fields:  # arrays and types alike
        assert repr(getattr(a.spec, table)) == repr(getattr(b.spec, table)), table
    # and again: the filled file filled is the same text
    assert main(["scenarios", "show", str(back), "--filled"]) == 0
    assert capsys.readouterr().out.split("\n", 2)[2] == printed.split("\n", 2)[2]
