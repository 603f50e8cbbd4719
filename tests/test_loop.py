"""Closed loop on the four paper scenarios (shortened), fallback logic, dumps, the CLI."""

from __future__ import annotations

import dataclasses
import hashlib
import json

import numpy as np
import pandas as pd
import pytest
import qpsolvers
from conftest import SUMMARY_TIME_KEYS, panda_adaptive, simulate_args
from test_environment import contact_force

from qpbench.backends import backend_names
from qpbench.backends.base import Backend, BackendSolution
from qpbench.exceptions import ParamError
from qpbench.sim import log as tick_log
from qpbench.sim.loop import simulate
from qpbench.sim.scenario import load_scenario


def qp_backend() -> str:
    names = backend_names()
    for b in ("qpsolvers:daqp", "qpsolvers:quadprog", "proxqp", "qpsolvers:clarabel", "clarabel"):
        if b in names:
            return b
    pytest.skip("no QP backend available")


@pytest.fixture(scope="module")
def short_runs():
    backend = qp_backend()
    return {
        name: simulate(name, backend, duration=3.5)
        for name in ("free", "wall", "adaptive", "adaptive_fast", "narrow")
    }


@pytest.mark.parametrize("name", ["free", "wall", "adaptive", "narrow"])
def test_paper_scenarios_in_closed_loop(short_runs, name):
    res = short_runs[name]
    s, log = res.summary, res.log
    sc = load_scenario(name)
    assert s["ticks"] == len(log) == 3500
    # the paper formulation is infeasible only during the initial transient; the soft fallback takes it
    assert 0 < s["infeasible_ticks"] == s["fallback_ticks"]
    assert s["zero_velocity_ticks"] == 0
    assert s["last_infeasible_t"] < 1.0
    after = log["t"] >= 2.0
    if name != "adaptive":
        assert np.abs(log.loc[after, "force"] - 20.0).max() < 0.5
        assert np.abs(log.loc[after, "tracking_error"]).max() < 1e-3
        assert s["force_error_max_after_2s"] < 0.5 and s["tracking_max_after_2s"] < 1e-3
    else:
        # the paper's K_in = diag(500, 20) is far too slow: the force is still off by several N
        assert 1.0 < s["force_error_max_after_2s"] < 10.0
        assert 4000.0 < s["kp_hat_final"] < 4500.0
        assert np.abs(log.loc[after, "tracking_error"]).max() < 1e-3
    # safety: no key point closer than d_safe - 1e-4, limits held at every tick
    d_cols = [c for c in log.columns if c.startswith("d_A")]
    if d_cols:
        assert log[d_cols].to_numpy().min() >= 0.01 - 1e-4
        assert s["min_obstacle_distance"] >= 0.01 - 1e-4
    theta = log[[f"theta_{i}" for i in range(4)]].to_numpy()
    v = log[[f"v_{i}" for i in range(4)]].to_numpy()
    assert np.all(np.abs(theta) <= 3.0) and np.all(np.abs(v) <= 1.0 + 1e-6)
    assert s["joint_limit_violations"] == 0 and s["joint_velocity_limit_violations"] == 0
    # the log's force is the environment's law at the logged end-effector path
    surf = sc.make_surface()
    ee = log[["ee_x", "ee_y"]].to_numpy()
    k = 2500
    f = contact_force(surf, ee[k], (ee[k] - ee[k - 1]) / sc.dt)
    assert log["force"].iloc[k] == pytest.approx(f, abs=1e-9)
    # ||J v - b0|| is zero (to solver accuracy) on feasible ticks of the paper formulation
    feasible = log["status"] == "optimal"
    assert log.loc[feasible, "task_residual"].max() < 1e-5
    # duals are logged: equality duals on feasible ticks
    assert log.loc[feasible, "y_0"].notna().all()


def test_obstacle_activates_in_wall_and_narrow(short_runs):
    wall = short_runs["wall"]
    assert wall.summary["min_obstacle_distance_key_point"] == "A2"
    assert wall.summary["min_obstacle_distance"] == pytest.approx(0.01, abs=1e-4)
    assert wall.log["z_max"].max() > 0  # an obstacle row's dual is positive while active
    narrow = short_runs["narrow"]
    assert narrow.summary["min_obstacle_distance"] == pytest.approx(0.01, abs=1e-4)


def test_adaptive_fast_converges(short_runs):
    s = short_runs["adaptive_fast"].summary
    assert s["kp_hat_final"] == pytest.approx(5000.0, rel=0.01)
    assert s["force_error_max_after_2s"] < 0.5
    assert s["tracking_max_after_2s"] < 1e-3


def test_adaptive_law_converges_on_the_spatial_arm():
    """The same scalar law along the table's normal on the Panda: ``Kp_hat`` reaches the table's
    stiffness as in ``adaptive_fast``, the force follows the spring's ``Kp_env Fd / Kp_hat``
    and its error settles; ``Kd_hat`` (the normal velocity is about zero in steady contact)
    only drifts towards the table's damping."""
    sc = panda_adaptive(duration=4.0)
    surface = sc.make_surface()
    res = simulate(sc, qp_backend())
    s, log = res.summary, res.log
    assert s["verdict"] == "ok" and s["fallback_ticks"] == s["zero_velocity_ticks"] == 0
    assert log["kp_hat"].iloc[0] == 4000.0 and log["kd_hat"].iloc[0] == 80.0
    assert s["kp_hat_final"] == pytest.approx(surface.stiffness, rel=0.01)
    t, kp, kd, force = (log[c].to_numpy() for c in ("t", "kp_hat", "kd_hat", "force"))
    assert surface.damping < kd[-1] < kd[0]
    settled = t >= 0.1  # after the first contact's transient: Kp_hat rises, the error falls
    error = np.abs(force[settled] - 20.0)
    assert np.all(np.diff(kp[settled]) >= 0.0) and np.all(np.diff(error) <= 1e-9)
    assert error[-1] < 0.2 and error[t[settled] >= 2.0][0] < 1.0
    after = t >= 2.0
    spring = surface.stiffness * 20.0 / kp[after]  # steady contact at the estimate's equilibrium
    np.testing.assert_allclose(force[after], spring, atol=0.02)
    assert s["tracking_max_after_2s"] < 1e-3


def test_summary_keys(short_runs):
    keys = {
        "scenario",
        "backend",
        "formulation",
        "ticks",
        "infeasible_ticks",
        "fallback_ticks",
        "zero_velocity_ticks",
        "first_infeasible_t",
        "last_infeasible_t",
        "tracking_rms_after_2s",
        "tracking_max_after_2s",
        "force_error_rms_after_2s",
        "force_error_max_after_2s",
        "min_obstacle_distance",
        "min_obstacle_distance_key_point",
        "joint_limit_violations",
        "joint_velocity_limit_violations",
        "kp_hat_final",
        "kd_hat_final",
        "wall_time_s",
        "real_time_factor",
    }
    s = short_runs["wall"].summary
    assert keys <= set(s)
    json.dumps(s, allow_nan=False)
    assert short_runs["free"].summary["min_obstacle_distance"] is None


def test_soft_formulation_is_never_infeasible():
    res = simulate("narrow", qp_backend(), formulation="soft", duration=1.0)
    assert res.summary["infeasible_ticks"] == 0 and res.summary["fallback_ticks"] == 0
    assert res.summary["min_obstacle_distance"] >= 0.01 - 1e-4


class _Failing(Backend):
    """A backend that never finds a solution."""

    name = "test-failing"

    def _solve(self, problem, warm_start):
        return BackendSolution(problem, status="primal_infeasible")


class _Online(Backend):
    """An online backend: returns the bound-clipped zero vector with a non-optimal status."""

    name = "test-online"
    online = True

    def _solve(self, problem, warm_start):
        sol = BackendSolution(problem, status="max_iter")
        sol.x = np.clip(np.full(problem.q.size, 0.5), problem.lb, problem.ub)
        return sol


def test_zero_velocity_when_the_fallback_fails_too():
    res = simulate("wall", _Failing(), duration=0.05)
    s = res.summary
    assert s["infeasible_ticks"] == s["zero_velocity_ticks"] == 50 and s["fallback_ticks"] == 0
    theta = res.log[[f"theta_{i}" for i in range(4)]].to_numpy()
    np.testing.assert_array_equal(theta, np.broadcast_to(theta[0], theta.shape))
    assert (res.log["status"] == "primal_infeasible").all()


def test_online_backend_is_applied_without_fallback():
    res = simulate("free", _Online(), duration=0.05)
    s = res.summary
    assert s["fallback_ticks"] == 0 and s["zero_velocity_ticks"] == 0
    # not optimal on every tick, but never declared infeasible
    assert s["non_optimal_ticks"] == 50 and s["infeasible_ticks"] == 0
    assert (
        s["first_infeasible_t"] is None
        and s["last_infeasible_t"] is None
        and s["infeasible_intervals"] == []
    )
    assert np.allclose(res.log["v_0"], 0.5)


class _Scripted(Backend):
    """Solves with a real QP backend, but reports ``script[k]`` on the k-th paper-formulation call.

    ``script`` maps a call index to ``(status, x)``: ``x`` is ``"keep"`` (the
    real answer), ``None`` or ``"nan"``.
    """

    name = "test-scripted"

    def __init__(self, script):
        super().__init__()
        from qpbench.backends import get_backend

        self.inner = get_backend(qp_backend())
        self.script = script
        self.calls = 0

    def _solve(self, problem, warm_start):
        sol = self.inner.solve(problem, warm_start)
        if problem.A is not None:  # paper formulation (the soft one has no equality)
            k = self.calls
            self.calls += 1
            if k in self.script:
                status, x = self.script[k]
                sol.status = status
                sol.x = (
                    None if x is None else np.full(problem.q.size, np.nan) if x == "nan" else sol.x
                )
        return sol


def test_summary_counts_declared_infeasible_ticks_only():
    """infeasible_ticks: ticks declared infeasible (or not_solved); other failures are non-optimal only."""
    script = {
        300: ("primal_infeasible", None),
        301: ("primal_infeasible", None),
        305: ("not_solved", None),
        310: ("max_iter", None),  # a budget, not infeasibility
        320: ("optimal", "nan"),  # a non-finite answer is no answer
        330: ("error", None),
    }
    res = simulate("wall", _Scripted(script), duration=0.35)
    s, log = res.summary, res.log
    # the paper QP's own infeasible start, as the real backend reports it, then the scripted ticks
    start = int((log["t"] < 0.2).sum() - (log.loc[log["t"] < 0.2, "status"] == "optimal").sum())
    assert start > 50 and log["status"].iloc[:start].isin(["primal_infeasible", "not_solved"]).all()
    assert s["infeasible_ticks"] == start + 3
    assert (
        s["non_optimal_ticks"] == start + 6
    )  # tick 320 says optimal but its answer is not finite: invalid
    assert s["fallback_ticks"] == start + 6 and s["zero_velocity_ticks"] == 0
    assert s["first_infeasible_t"] == 0.0 and s["last_infeasible_t"] == pytest.approx(0.305)
    assert s["infeasible_intervals"][-2:] == [[0.3, 0.301], [0.305, 0.305]]
    assert s["status_counts"]["max_iter"] == 1 and s["status_counts"]["error"] == 1
    assert s["invalid_ticks"] == 1 and s["error_ticks"] == 1 and s["raised_ticks"] == 0
    assert (
        bool(log["fallback"].iloc[320])
        and np.isfinite(log[[f"v_{i}" for i in range(4)]].to_numpy()).all()
    )
    assert log["status"].iloc[320] == "invalid"


def test_rnn_online_ticks_are_non_optimal_not_infeasible():
    from qpbench.backends.rnn import WORKING_SETTINGS

    sc = load_scenario("wall")
    res = simulate(dataclasses.replace(sc, rnn=dict(WORKING_SETTINGS)), "rnn", duration=0.2)
    s = res.summary
    assert s["infeasible_ticks"] == 0 and s["first_infeasible_t"] is None
    assert s["fallback_ticks"] == 0 and s["zero_velocity_ticks"] == 0
    assert s["non_optimal_ticks"] == s["status_counts"].get("max_iter", 0) > 150


def test_backend_dt_must_match():
    class WithDt(_Online):
        dt = 0.002

    with pytest.raises(ParamError, match="dt"):
        simulate("free", WithDt(), duration=0.01)


def test_dump_round_trip_and_determinism(tmp_path):
    from qpbench.formats import load_npz, read_problem_set, save_npz

    backend = qp_backend()
    a = simulate("wall", backend, duration=0.3, every=10, dump=tmp_path / "a")
    simulate("wall", backend, duration=0.3, every=10, dump=tmp_path / "b")
    pa, pb = (tmp_path / d / "problems.parquet" for d in "ab")
    assert (
        hashlib.sha256(pa.read_bytes()).hexdigest() == hashlib.sha256(pb.read_bytes()).hexdigest()
    )
    assert (tmp_path / "a" / "manifest.json").read_bytes() == (
        tmp_path / "b" / "manifest.json"
    ).read_bytes()
    ps = read_problem_set(tmp_path / "a")
    assert len(ps) == len(a.records) == 30
    manifest = ps.manifest
    assert manifest["extra"]["scenario_toml"] == load_scenario("wall").source
    for rec, mine in zip(ps, a.records):
        assert rec.tick % 10 == 0 and rec.scenario == "wall" and rec.formulation == "paper"
        assert rec.t == pytest.approx(rec.tick * 1e-3)
        for f in ("P", "q", "G", "h", "A", "b", "lb", "ub"):
            np.testing.assert_array_equal(getattr(rec.problem, f), getattr(mine.problem, f))
    # one tick through qpsolvers' own .npz format
    rec = ps.records[-1]
    save_npz(rec, tmp_path / "tick.npz")
    back = qpsolvers.Problem.load(str(tmp_path / "tick.npz"))
    np.testing.assert_array_equal(back.G, rec.problem.G)
    assert load_npz(tmp_path / "tick.npz").tick == rec.tick
    # the dumped tick is the one the loop solved: re-solving it gives the logged command
    sol = qpsolvers.solve_problem(
        back, solver="daqp" if "daqp" in qpsolvers.available_solvers else "clarabel"
    )
    if sol.found:
        logged = a.log.iloc[rec.tick][[f"v_{i}" for i in range(4)]].to_numpy(float)
        np.testing.assert_allclose(sol.x, logged, atol=1e-6)


def _outputs(folder) -> list[str]:
    """``--summary folder/s.json --log folder/log.csv --dump folder/set`` as argv."""
    return [
        f"--{k}={folder / name}"
        for k, name in (("summary", "s.json"), ("log", "log.csv"), ("dump", "set"))
    ]


def test_cli(tmp_path, capsys):
    from qpbench.cli import main

    args = [
        *simulate_args("wall", qp_backend(), "0.2", *_outputs(tmp_path)),
        "--every",
        "5",
        "--plot",
        str(tmp_path / "p.png"),
    ]
    assert main(args) == 0
    s = json.loads((tmp_path / "s.json").read_text())
    assert s["ticks"] == 200 and s["scenario"] == "wall"
    assert (tmp_path / "set" / "manifest.json").is_file() and (
        tmp_path / "p.png"
    ).stat().st_size > 1000
    import pandas as pd

    assert len(pd.read_csv(tmp_path / "log.csv")) == 200
    # outputs are not overwritten without --force
    assert main(args) == 2
    assert "exists" in capsys.readouterr().err
    assert main(args + ["--force"]) == 0
    # a scenario typo is an input error naming the key
    bad = tmp_path / "bad.toml"
    bad.write_text(load_scenario("wall").source.replace("d_safe =", "d_sefe ="))
    assert main(["simulate", "--scenario", str(bad), "--backend", qp_backend()]) == 2
    assert "controller.d_sefe" in capsys.readouterr().err


@pytest.mark.filterwarnings("ignore::UserWarning")
def test_qpbenchmark_runs_a_dumped_set_unchanged(tmp_path):
    qpbenchmark = pytest.importorskip("qpbenchmark")
    from qpbenchmark.results import Results

    if "daqp" not in qpsolvers.available_solvers:
        pytest.skip("daqp not installed")
    res = simulate("wall", qp_backend(), duration=0.3, every=10, dump=tmp_path / "set")

    class RobotTicks(qpbenchmark.ParquetTestSet):
        description = "per-tick QPs of the wall scenario"
        title = "wall ticks"
        sparse_only = False

    test_set = RobotTicks(tmp_path / "set" / "problems.parquet")
    results = Results(tmp_path / "results.csv", test_set)
    qpbenchmark.run(test_set, results, only_solver="daqp", only_settings="default")
    df = results.df.set_index("problem")
    assert len(df) == 30
    # qpbenchmark finds exactly the ticks the loop found feasible
    feasible = res.log["status"].iloc[::10].to_numpy() == "optimal"
    names = [r.name for r in res.records]
    assert df.loc[names, "found"].to_numpy().tolist() == feasible.tolist()


# ----------------------------------------------------------------- scenario values set over the file's


def test_overrides_round_trip_through_loader_cli_summary_and_dump(tmp_path):
    from qpbench.cli import main
    from qpbench.formats import read_problem_set
    from qpbench.selection import parse_overrides

    items = [
        "rnn.eps=0.001",
        "rnn.substeps=5",
        "rnn.l1_clip=10.0",
        "controller.k=20",
        "obstacles[0].velocity=[0.0, 0.01]",
    ]
    overrides = parse_overrides(items)
    assert overrides == {
        "rnn.eps": 0.001,
        "rnn.substeps": 5,
        "rnn.l1_clip": 10.0,
        "controller.k": 20,
        "obstacles[0].velocity": [0.0, 0.01],
    }
    plain = load_scenario("wall")
    sc = load_scenario("wall", overrides=overrides)
    assert sc.rnn == {"eps": 0.001, "substeps": 5, "l1_clip": 10.0}
    assert sc.spec.controller.k == 20.0 and isinstance(sc.spec.controller.k, float)
    np.testing.assert_array_equal(sc.spec.obstacles[0].velocity, [0.0, 0.01])
    assert sc.overrides == overrides and plain.overrides == {} and sc.source == plain.source
    # everything not overridden is the file's
    for table in ("robot", "contact", "path", "simulation"):
        for key, value in getattr(plain.spec, table):
            np.testing.assert_array_equal(getattr(sc.spec, table).__dict__[key], value)
    # the CLI runs exactly that scenario, and says so in the summary and the dump's manifest
    args = [
        *simulate_args("wall", "rnn", "0.1", *_outputs(tmp_path)),
    ]
    for item in items:
        args += ["--set", item]
    assert main(args) == 0
    summary = json.loads((tmp_path / "s.json").read_text())
    assert summary["scenario_overrides"] == overrides
    manifest = read_problem_set(tmp_path / "set").manifest
    assert manifest["extra"]["scenario_overrides"] == overrides
    import pandas as pd

    logged = pd.read_csv(tmp_path / "log.csv")[[f"v_{i}" for i in range(4)]].to_numpy()
    direct = simulate(sc, "rnn", duration=0.1).log[[f"v_{i}" for i in range(4)]].to_numpy()
    np.testing.assert_allclose(logged, direct, rtol=1e-9, atol=0)  # the CSV keeps 10 digits
    assert not np.allclose(
        direct, simulate("wall", "rnn", duration=0.1).log[[f"v_{i}" for i in range(4)]].to_numpy()
    )
    assert simulate("wall", "rnn", duration=0.01).summary["scenario_overrides"] == {}


@pytest.mark.parametrize(
    "overrides, key",
    [
        ({"rnn.epz": 0.001}, "rnn.epz"),
        ({"controller.kk": 3.0}, "controller.kk"),
        ({"controller.k": "abc"}, "controller.k"),
        ({"controller.k": -1.0}, "controller.k"),
        ({"k": 3.0}, "k"),
        ({"nosuch.k": 3.0}, "nosuch.k"),
        ({"obstacles[3].velocity": [0.0, 0.0]}, "obstacles[3]"),
        ({"obstacles[0].speed": [0.0, 0.0]}, "obstacles[0].speed"),
        ({"robot[0].theta0": 1.0}, "robot[0].theta0"),
        ({"rnn.eps": 0.0}, "rnn.eps"),
    ],
)
def test_bad_overrides_are_errors_naming_the_key(overrides, key):
    from qpbench.exceptions import ScenarioError

    with pytest.raises(ScenarioError) as err:
        load_scenario("wall", overrides=overrides)
    assert err.value.key == key
    assert key in str(err.value) and "wall.toml" in str(err.value)


def test_set_option_errors(capsys):
    from qpbench.cli import main
    from qpbench.selection import parse_overrides

    assert parse_overrides(
        ["rnn.method=euler", "a.b = [1, 2]", "x.y=true", 's.t="q=1"', "x.y=false"]
    ) == {"rnn.method": "euler", "a.b": [1, 2], "x.y": False, "s.t": "q=1"}
    with pytest.raises(ParamError) as err:
        parse_overrides(["controller.k"])
    assert err.value.key == "--set"
    assert (
        main(["simulate", "--scenario", "wall", "--backend", "daqp", "--set", "controller.kk=3"])
        == 2
    )
    assert "controller.kk" in capsys.readouterr().err


def test_force_sensor_noise_is_logged():
    """With force_noise_std > 0 the logged force is the law plus the scenario's seeded noise."""
    sc = load_scenario("wall", overrides={"contact.force_noise_std": 0.5, "contact.noise_seed": 3})
    log = simulate(sc, qp_backend(), duration=0.3).log
    quiet, noisy = (
        load_scenario("wall").make_surface(),
        sc.make_surface(),
    )  # law without noise; the noise alone
    ee = log[["ee_x", "ee_y"]].to_numpy()
    law = np.array(
        [
            contact_force(quiet, ee[k], (ee[k] - ee[k - 1]) / sc.dt if k else np.zeros(2))
            for k in range(len(log))
        ]
    )
    noise = np.array([noisy.noise() for _ in range(len(log))])
    assert np.abs(noise).max() > 0.5
    np.testing.assert_allclose(log["force"].to_numpy(), law + noise, rtol=0, atol=1e-9)
    np.testing.assert_allclose(log["force_error"].to_numpy(), law + noise - 20.0, rtol=0, atol=1e-9)


# ---------------------------------------------------------------- per-tick guards (test-only faulty backends)


def _fault_run(kind, ticks=100, **kw):
    """A run of ``ticks`` ms of wall with ``faulty-ticks:KIND``; the run and its faulty ticks."""
    import faulty_backends as fb

    res = simulate("wall", f"faulty-ticks:{kind}", duration=ticks / 1000, **kw)
    return res, fb.fault_ticks(ticks)


def _check_fault_ticks(res, ticks, status):
    s, log = res.summary, res.log
    assert s["ticks"] == len(log) == round(s["duration"] * 1000)
    assert "invalid" in log["status"].cat.categories
    assert list(np.flatnonzero((log["status"] == status).to_numpy())) == ticks
    # the soft fallback covered every faulty tick; the arm never stopped
    assert log["fallback"].iloc[ticks].all() and s["zero_velocity_ticks"] == 0
    assert np.isfinite(log[[f"v_{i}" for i in range(4)]].to_numpy()).all()
    assert s["status_counts"][status] == len(ticks)
    json.dumps(s, allow_nan=False)


def test_exception_on_a_tick_is_an_error_tick_covered_by_the_fallback():
    res, ticks = _fault_run("raise")
    s = res.summary
    _check_fault_ticks(res, ticks, "error")
    assert s["error_ticks"] == s["raised_ticks"] == len(ticks) == 10
    assert s["first_error"] == f"RuntimeError: tick fault {ticks[0]}"
    assert s["first_error_t"] == pytest.approx(ticks[0] * 0.001)
    assert s["fallback_errors"] == 0 and s["invalid_ticks"] == s["time_limit_ticks"] == 0
    assert np.isfinite(res.log["tracking_error"]).all()  # every tick logged


def test_non_finite_answer_is_an_invalid_tick():
    res, ticks = _fault_run("nan")
    s = res.summary
    _check_fault_ticks(res, ticks, "invalid")
    assert s["invalid_ticks"] == len(ticks) and s["error_ticks"] == 0 and s["first_error"] is None


#: Columns that measure time (all others must not depend on it).
TIME_COLUMNS = list(tick_log.TIME_COLUMNS)


def test_late_answer_past_a_deadline_is_dropped_and_counted():
    import faulty_backends as fb

    # the deadline is half the faulty ticks' sleep and far above any ordinary solve's time, also
    # on a loaded machine: only the faulty ticks arrive late, whatever the load
    deadline = fb.SLOW_S / 2
    res, ticks = _fault_run("slow", 30, deadline=deadline)
    s = res.summary
    assert len(ticks) == 3
    _check_fault_ticks(res, ticks, "time_limit")
    assert s["time_limit_ticks"] == s["deadline_dropped"] == len(ticks)
    assert s["deadline_s"] == deadline
    assert (res.log["solve_time_s"].iloc[ticks] > deadline).all()
    assert s["deadline_misses"] >= len(ticks)  # each of them took longer than dt = 1 ms


def test_late_first_answer_is_applied_without_a_deadline():
    """A solve that sleeps past any sensible limit on tick 0 (a compile on a fresh machine):
    its answer is applied, the run is the one without the sleep, and the tick is a deadline miss."""
    import faulty_backends as fb

    slow = simulate("wall", "faulty-ticks:slow-first", duration=0.05)
    fast = simulate("wall", "daqp", duration=0.05, engine="python")  # the faulty backend's engine
    s = slow.summary
    assert slow.log["solve_time_s"].iloc[0] >= fb.SLOW_S
    assert s["deadline_misses"] >= 1 and s["deadline_s"] is None and s["deadline_dropped"] is None
    assert s["time_limit_ticks"] == 0 and slow.log["status"].iloc[0] == fast.log["status"].iloc[0]
    pd.testing.assert_frame_equal(
        slow.log.drop(columns=TIME_COLUMNS), fast.log.drop(columns=TIME_COLUMNS)
    )
    skip = SUMMARY_TIME_KEYS | {"backend", "engine_note"}
    assert {k: v for k, v in s.items() if k not in skip} == {
        k: v for k, v in fast.summary.items() if k not in skip
    }
    # with a deadline the late first answer is dropped: the soft fallback covers tick 0
    dropped = simulate("wall", "faulty-ticks:slow-first", duration=0.05, deadline=fb.SLOW_S / 2)
    d = dropped.summary
    assert d["deadline_dropped"] == d["time_limit_ticks"] == 1 and d["deadline_s"] == fb.SLOW_S / 2
    assert dropped.log["status"].iloc[0] == "time_limit" and dropped.log["fallback"].iloc[0]


def test_fallback_exception_means_zero_velocity():
    class _AlwaysRaises(Backend):
        name = "test-raises"

        def _solve(self, problem, warm_start):
            raise ValueError("boom")

    res = simulate("wall", _AlwaysRaises(), duration=0.02)
    s = res.summary
    assert (
        s["error_ticks"]
        == s["raised_ticks"]
        == s["zero_velocity_ticks"]
        == s["fallback_errors"]
        == 20
    )
    assert s["first_error"] == "ValueError: boom"
    assert (res.log["status"] == "error").all()


@pytest.mark.parametrize("bad", [0.0, -1.0, float("nan"), float("inf"), "1"])
def test_bad_deadline(bad):
    with pytest.raises(ParamError, match="positive"):
        simulate("wall", "pinv", duration=0.01, deadline=bad)


def test_bad_deadline_on_the_command_line(tmp_path, capsys):
    from qpbench.cli import main

    out = tmp_path / "s.json"
    assert (
        main(["simulate", "--scenario=wall", "--backend=pinv", "--deadline=0", f"--summary={out}"])
        == 2
    )
    assert "--deadline" in capsys.readouterr().err and not out.exists()
