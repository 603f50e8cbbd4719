"""qpbench sweep: sweep files, sampling, the same rows on every executor, re-runs, lost workers, resume."""

from __future__ import annotations

import json
import math
import tomllib
from pathlib import Path

import numpy as np
import pandas as pd
import pytest

from qpbench.cli import main
from qpbench.exceptions import InputError
from qpbench.harness.results import cell
from qpbench.sim.scenario import scenario_names, scenario_path
from qpbench.sim.summary import time_to_converge
from qpbench.sweep.runner import COLUMNS, TIMING_COLUMNS, read_sweep_rows
from qpbench.sweep.spec import load_sweep, sample_instances
from qpbench.sweep.toml_text import dumps

PLUGIN = str(Path(__file__).with_name("sweep_backends.py"))

#: A small sweep around wall: 8 instances of 0.25 s (every kind of distribution).
SWEEP = """
[sweep]
name = "tiny"
base = "wall"
seed = 7
samples = 8
duration = 0.25

[parameters]
"robot.theta0" = { dist = "normal", std = 0.03 }
"controller.desired_force" = { dist = "uniform", low = 10.0, high = 30.0 }
"obstacles[0].point" = { dist = "uniform", low = [-0.08, 0.0], high = [-0.03, 0.0] }
"contact.stiffness" = { dist = "loguniform", low = 2000.0, high = 20000.0 }
"simulation.dt" = { dist = "choice", values = [0.001, 0.002] }
"path.omega" = { dist = "normal", std = 0.1, low = 0.3, high = 0.7 }
"""


def write_sweep(folder: Path, text: str = SWEEP, name: str = "tiny.toml") -> Path:
    path = folder / name
    path.write_text(text)
    return path


def rows_of(folder: Path) -> list[dict]:
    """The sweep's rows but the noise floor's (the ``noop`` run of each instance)."""
    return [r for r in read_sweep_rows(folder / "sweep.csv") if r["backend"] != "noop"]


def assert_floors_where_needed(all_rows: list[dict]) -> None:
    """An instance has its noise floor's row exactly when one of its runs was not real time,
    and those runs carry the floor's figures."""
    by: dict[str, list[dict]] = {}
    for r in all_rows:
        by.setdefault(r["instance"], []).append(r)
    for instance, runs in by.items():
        floor = [r for r in runs if r["backend"] == "noop"]
        others = [r for r in runs if r["backend"] != "noop" and r["realtime"]]
        missed = [r for r in others if r["realtime"] != "yes"]
        assert len(floor) == (1 if missed or not others else 0), instance
        assert all(r["noise_floor_over_dt_share"] for r in missed), instance


def _tiny_sweep(folder: Path, out: Path, *options: str) -> int:
    """``qpbench sweep`` of the tiny sweep (written into ``folder``) with daqp and osqp: its exit code."""
    return main(
        ["sweep", str(write_sweep(folder)), "--backends", "daqp,osqp", "--out", str(out), *options]
    )


def _parse(value):
    """A cell as it reads back: text of a number -> the number (``""`` -> None)."""
    if value is None or (isinstance(value, float) and math.isnan(value)):
        return None
    if isinstance(value, str):
        if value == "":
            return None
        for kind in (int, float):
            try:
                return kind(value)
            except ValueError:
                pass
    return value


def same_outside_timing(a: dict, b: dict) -> list[str]:
    """Columns where rows ``a`` and ``b`` differ, timing columns aside (floats compared exactly, as text)."""
    return [
        c
        for c in COLUMNS
        if c not in TIMING_COLUMNS and cell(_parse(a.get(c))) != cell(_parse(b.get(c)))
    ]


def assert_same_rows(a: list[dict], b: list[dict]) -> None:
    assert [(r["instance"], r["backend"]) for r in a] == [(r["instance"], r["backend"]) for r in b]
    for x, y in zip(a, b):
        assert same_outside_timing(x, y) == [], (x["instance"], x["backend"])


# -- the sweep file ----------------------------------------------------------------------------
@pytest.mark.parametrize("name", scenario_names())
def test_toml_text_round_trips_every_shipped_scenario(name):
    raw = tomllib.loads(scenario_path(name).read_text())
    assert tomllib.loads(dumps(raw)) == raw


def test_sampling_is_deterministic_and_per_instance(tmp_path):
    spec = load_sweep(write_sweep(tmp_path))
    a, b = sample_instances(spec), sample_instances(spec)
    assert [i.text for i in a] == [i.text for i in b]
    more = sample_instances(load_sweep(write_sweep(tmp_path), samples=12))
    assert [i.text for i in more[:8]] == [
        i.text for i in a
    ]  # instance i does not depend on the count
    assert len({i.text for i in a}) == 8
    for inst in a:
        v = inst.values
        assert 10.0 <= v["controller.desired_force"] <= 30.0
        assert -0.08 <= v["obstacles[0].point"][0] <= -0.03 and v["obstacles[0].point"][1] == 0.0
        assert 2000.0 <= v["contact.stiffness"] <= 20000.0
        assert v["simulation.dt"] in (0.001, 0.002)
        assert all(0.3 <= w <= 0.7 for w in v["path.omega"])
        assert inst.invalid is None
        raw = tomllib.loads(inst.text)
        assert raw["controller"]["desired_force"] == v["controller.desired_force"]
        assert raw["simulation"]["duration"] == 0.25


def test_distributions_have_their_moments(tmp_path):
    text = SWEEP.replace("samples = 8", "samples = 400")
    spec = load_sweep(write_sweep(tmp_path, text))
    dist = {d.key: d for d in spec.parameters}
    theta = np.array([dist["robot.theta0"].draw(spec.rng(i, "robot.theta0")) for i in range(400)])
    assert np.allclose(theta.mean(axis=0), [1.57, -0.628, -0.524, -0.524], atol=0.01)
    assert np.allclose(theta.std(axis=0), 0.03, rtol=0.15)
    k = np.array(
        [dist["contact.stiffness"].draw(spec.rng(i, "contact.stiffness")) for i in range(400)]
    )
    assert abs(np.mean(np.log(k)) - np.log(np.sqrt(2000.0 * 20000.0))) < 0.15  # uniform in log


@pytest.mark.parametrize(
    ("line", "key", "words"),
    [
        (
            '"controller.desire_force" = { dist = "uniform", low = 1.0, high = 2.0 }',
            "parameters.controller.desire_force",
            "did you mean controller.desired_force",
        ),
        (
            'Fd = { dist = "uniform", low = 1.0, high = 2.0 }',
            "parameters.Fd",
            "controller.desired_force",
        ),
        (
            '"robot.theta0" = { dist = "gauss", std = 0.1 }',
            "parameters.robot.theta0.dist",
            "unknown distribution",
        ),
        (
            '"robot.theta0" = { dist = ["normal"], std = 0.1 }',
            "parameters.robot.theta0.dist",
            "unknown distribution",
        ),
        (
            '"robot.theta0" = { dist = "uniform", low = [0.0, 0.0], high = 1.0 }',
            "parameters.robot.theta0.low",
            "shape",
        ),
        (
            '"contact.stiffness" = { dist = "loguniform", low = 0.0, high = 2.0 }',
            "parameters.contact.stiffness.low",
            "low > 0",
        ),
        (
            '"obstacles[3].point" = { dist = "uniform", low = 0.0, high = 1.0 }',
            "parameters.obstacles[3].point",
            "no such obstacle",
        ),
        (
            '"contact.noise_seed" = { dist = "uniform", low = 0.0, high = 9.0 }',
            "parameters.contact.noise_seed.dist",
            "integer",
        ),
        (
            '"simulation.dt" = { dist = "choice", values = [] }',
            "parameters.simulation.dt.values",
            "non-empty",
        ),
    ],
)
def test_bad_sweep_file_is_one_line_naming_file_and_key(tmp_path, capsys, line, key, words):
    head = SWEEP.split("[parameters]")[0]
    path = write_sweep(tmp_path, head + "[parameters]\n" + line + "\n")
    code = main(
        ["sweep", str(path), "--backends", "daqp", "--out", str(tmp_path / "out"), "--jobs", "1"]
    )
    err = capsys.readouterr().err.strip().splitlines()
    assert code == 2
    assert len(err) == 1 and str(path) in err[0] and f"key '{key}'" in err[0] and words in err[0], (
        err
    )
    assert not (tmp_path / "out").exists()


def test_bad_head_keys(tmp_path):
    for text, key in (
        (SWEEP.replace("seed = 7", "sed = 7"), "sweep.sed"),
        (SWEEP.replace('base = "wall"', 'base = "walll"'), "sweep.base"),
        (SWEEP + "\n[extra]\nx = 1\n", "extra"),
        (SWEEP.replace("duration = 0.25", "duration = -1.0"), "sweep.duration"),
    ):
        with pytest.raises(InputError) as err:
            load_sweep(tmp_path / "s.toml", text=text)
        assert err.value.key == key


def test_time_to_converge():
    t = np.arange(6) * 0.1
    assert time_to_converge(t, np.array([5, 3, 0.1, 2, 0.1, 0.0]), 0.5) == pytest.approx(0.4)
    assert time_to_converge(t, np.zeros(6), 0.5) == 0.0
    assert time_to_converge(t, np.array([0, 0, 0, 0, 0, 1.0]), 0.5) is None
    assert time_to_converge(t, np.array([0, 0, 0, 0, np.nan, 0]), 0.5) == pytest.approx(0.5)


# -- runs ----------------------------------------------------------------------------------------
@pytest.fixture(scope="module")
def serial(tmp_path_factory):
    """The tiny sweep run serially with daqp and osqp (the reference rows)."""
    tmp = tmp_path_factory.mktemp("serial")
    out = tmp / "out"
    code = _tiny_sweep(tmp, out, "--jobs", "1")
    assert code == 0
    return out


def test_serial_rows(serial):
    rows = rows_of(serial)
    assert len(rows) == 16 and all(r["status"] == "ok" for r in rows)
    assert {r["executor"] for r in rows} == {"processes"} and {
        r["concurrent_solves"] for r in rows
    } == {"1"}
    assert len({r["worker"] for r in rows}) == 1  # one worker, one run after the other
    assert len(list((serial / "instances").glob("*.toml"))) == 8
    manifest = json.loads((serial / "sweep.json").read_text())
    assert manifest["samples"] == 8 and manifest["backends"] == ["noop", "daqp", "osqp"]
    # an instance's noise floor, marked, where one of its runs was not real time; those runs
    # judged against it
    floors = [r for r in read_sweep_rows(serial / "sweep.csv") if r["backend"] == "noop"]
    assert all(r["noise_floor"] == "True" for r in floors)
    assert all(r["noise_floor"] == "False" for r in rows)
    assert_floors_where_needed(read_sweep_rows(serial / "sweep.csv"))
    # exact QPs agree on the trajectory: same closest approach per instance
    by = {(r["instance"], r["backend"]): float(r["min_obstacle_distance"]) for r in rows}
    for r in rows:
        assert by[(r["instance"], "daqp")] == pytest.approx(by[(r["instance"], "osqp")], abs=1e-5)


def test_two_jobs_give_the_serial_rows(serial, tmp_path, capsys):
    out = tmp_path / "out"
    assert _tiny_sweep(tmp_path, out, "--jobs", "2") == 0
    rows = rows_of(out)
    assert_same_rows(rows_of(serial), rows)
    assert {r["executor"] for r in rows} == {"processes"} and {
        r["concurrent_solves"] for r in rows
    } == {"2"}
    assert len({r["worker"] for r in rows}) == 2
    assert "Take timings with --jobs 1" in capsys.readouterr().err


def test_local_dask_cluster_gives_the_serial_rows(serial, tmp_path):
    pytest.importorskip("distributed")
    out = tmp_path / "out"
    assert _tiny_sweep(tmp_path, out, "--jobs", "2", "--executor", "dask") == 0
    rows = rows_of(out)
    assert_same_rows(rows_of(serial), rows)
    assert all(r["executor"] == "dask" and r["worker"].startswith("tcp://127.0.0.1:") for r in rows)


def test_simulate_reruns_a_saved_instance(serial, tmp_path):
    row = next(r for r in rows_of(serial) if r["instance"] == "i00003" and r["backend"] == "daqp")
    summary, log = tmp_path / "s.json", tmp_path / "log.parquet"
    code = main(
        [
            "simulate",
            "--scenario",
            str(serial / row["instance_file"]),
            "--backend",
            "daqp",
            "--summary",
            str(summary),
            "--log",
            str(log),
        ]
    )
    assert code == 0
    s = json.loads(summary.read_text())
    # the columns the summary gives (its "duration" is "duration_s"): all from duration_s to
    # verdict_overrides but the time-to-converge figures, their bands and ticks_over_1ms
    convergence = ("force_band_n", "tracking_band_m", "ticks_over_1ms")
    copied = COLUMNS[COLUMNS.index("duration_s") : COLUMNS.index("verdict_overrides")]
    copied = [c for c in copied if c not in convergence and not c.startswith("t_converge")]
    assert len(copied) == 45
    again = {c: s.get("duration" if c == "duration_s" else c) for c in copied}
    again.update(verdict=s["verdict"], verdict_reasons=s["verdict_reasons"])
    frame = pd.read_parquet(log)
    t = frame["t"].to_numpy()
    again["t_converge_force_s"] = time_to_converge(
        t, frame["force_error"].to_numpy(), float(row["force_band_n"])
    )
    again["t_converge_tracking_s"] = time_to_converge(
        t, frame["tracking_error"].to_numpy(), float(row["tracking_band_m"])
    )
    compared = [c for c in again if c not in TIMING_COLUMNS]
    assert len(compared) >= 25
    assert same_outside_timing({c: row[c] for c in compared}, again) == []


def test_lost_worker_loses_only_its_run_and_resume_fills_it(serial, tmp_path, monkeypatch):
    flag = tmp_path / "die"
    flag.touch()
    monkeypatch.setenv("QPBENCH_TEST_DIE", str(flag))
    path, out = write_sweep(tmp_path), tmp_path / "out"
    args = [
        "sweep",
        str(path),
        "--backends",
        "daqp,sweep:die-on-flag",
        "--out",
        str(out),
        "--jobs",
        "2",
        "--plugin",
        PLUGIN,
    ]
    assert main(args) == 0  # the table is written, the crashed rows in it
    rows = rows_of(out)
    dead = [r for r in rows if r["backend"] == "sweep:die-on-flag"]
    assert len(rows) == 16 and len(dead) == 8
    assert all(
        r["status"] == "crashed"
        and r["attempts"] == "2"
        and r["verdict"] == "incomplete"
        and r["realtime"] == "no"
        and "SIGKILL" in r["error"]
        for r in dead
    )
    daqp = [r for r in rows if r["backend"] == "daqp"]
    assert_same_rows([r for r in rows_of(serial) if r["backend"] == "daqp"], daqp)
    flag.unlink()
    assert main(args + ["--resume"]) == 0
    rows = rows_of(out)
    assert len(rows) == 16 and all(r["status"] == "ok" for r in rows)
    again = [r for r in rows if r["backend"] == "sweep:die-on-flag"]
    for a, b in zip(again, daqp):  # the same DAQP solves: the same trajectories
        assert (
            a["min_obstacle_distance"] == b["min_obstacle_distance"]
            and a["verdict"] == b["verdict"]
        )


def test_killed_sweep_resumes_to_the_same_rows(serial, tmp_path):
    """A sweep killed while writing: its half-written last line is dropped and --resume runs what is missing."""
    out = tmp_path / "out"
    path = write_sweep(tmp_path)
    args = ["sweep", str(path), "--backends", "daqp,osqp", "--out", str(out), "--jobs", "1"]
    assert main(args) == 0
    data = (out / "sweep.csv").read_bytes()
    lines = data.split(b"\n")
    (out / "sweep.csv").write_bytes(
        b"\n".join(lines[:10]) + b"\n" + lines[10][:40]
    )  # 9 rows and a half
    assert main(args) == 2  # exists: neither --force nor --resume
    assert main(args + ["--resume"]) == 0
    assert_same_rows(rows_of(serial), rows_of(out))


def test_resume_refuses_another_sweep_file(serial, tmp_path, capsys):
    other = write_sweep(tmp_path, SWEEP.replace("seed = 7", "seed = 8"))
    out = tmp_path / "out"
    import shutil

    shutil.copytree(serial, out)
    assert main(["sweep", str(other), "--backends", "daqp", "--out", str(out), "--resume"]) == 2
    assert "another sweep file" in capsys.readouterr().err


def test_invalid_instance_is_a_row(tmp_path):
    head = SWEEP.split("[parameters]")[0].replace("samples = 8", "samples = 3")
    path = write_sweep(
        tmp_path,
        head + '[parameters]\n"robot.theta0" = { dist = "uniform", low = 3.1, high = 3.2 }\n',
    )
    out = tmp_path / "out"
    assert main(["sweep", str(path), "--backends", "daqp", "--out", str(out), "--jobs", "1"]) == 0
    rows = rows_of(out)
    assert [r["status"] for r in rows] == ["invalid_scenario"] * 3
    assert all("robot.theta0" in r["error"] and r["verdict"] == "" for r in rows)


def test_report_has_the_sweep_section(serial, tmp_path):
    report = tmp_path / "report"
    assert main(["report", str(serial), "--out", str(report)]) == 0
    text = (report / "report.md").read_text()
    assert "### Sweep tiny" in text and "McNemar" in text and "| daqp | osqp | 8 |" in text
    assert "| sweep.csv | sweep | 16 |" in text  # listed with the result files
    assert (report / "plots" / "sweep_ecdf_out_tiny.png").stat().st_size > 10_000


def test_columns_are_unique():
    assert len(set(COLUMNS)) == len(COLUMNS) and set(TIMING_COLUMNS) <= set(COLUMNS)


def test_same_draws_one_value_for_every_component(tmp_path):
    head = SWEEP.split("[parameters]")[0]
    text = (
        head
        + """[parameters]
"path.centre" = { dist = "uniform", spread = 0.03, same = true }
"path.amplitude" = { dist = "uniform", low = 0.05, high = 0.12, same = true }
"""
    )
    for inst in sample_instances(load_sweep(write_sweep(tmp_path, text))):
        cx, cy = inst.values["path.centre"]
        assert (
            cx - 0.4 == pytest.approx(cy - 0.5) and abs(cx - 0.4) <= 0.03
        )  # along wall's surface tangent
        ax, ay = inst.values["path.amplitude"]
        assert ax == ay and 0.05 <= ax <= 0.12
    with pytest.raises(InputError, match="same = true takes numbers"):
        load_sweep(
            tmp_path / "s.toml",
            text=head
            + '[parameters]\n"path.centre" = { dist = "uniform", low = [0.3, 0.4], high = [0.5, 0.6], '
            "same = true }\n",
        )


def test_a_start_inside_d_safe_is_invalid_unless_allowed(tmp_path):
    from qpbench.sim.scenario import load_scenario
    from qpbench.sweep.spec import start_clearance

    assert start_clearance(load_scenario("wall"))[1:] == ("link 1", "wall")
    assert start_clearance(load_scenario("wall"))[0] == pytest.approx(
        0.05, abs=1e-3
    )  # link 1 from the base at x = 0
    head = SWEEP.split("[parameters]")[0].replace("samples = 8", "samples = 2")
    line = '[parameters]\n"obstacles[0].point" = { dist = "uniform", low = [-0.005, 0.0], high = [-0.001, 0.0] }\n'
    inst = sample_instances(load_sweep(write_sweep(tmp_path, head + line)))
    assert all("inside d_safe" in i.invalid and "from obstacle wall" in i.invalid for i in inst)
    allowed = head.replace("duration = 0.25", "duration = 0.25\nsafe_start = false")
    assert all(
        i.invalid is None
        for i in sample_instances(load_sweep(write_sweep(tmp_path, allowed + line)))
    )


@pytest.mark.parametrize("name", ["wall", "narrow"])
def test_shipped_sweeps_hold_500_instances_with_a_safe_start(name):
    path = Path(__file__).resolve().parents[1] / "problems" / "sweeps" / f"{name}.toml"
    spec = load_sweep(path)
    instances = sample_instances(spec)
    assert spec.base == name and spec.duration is not None and spec.duration < 20.0
    assert sum(i.invalid is None for i in instances) >= 500
    assert all("inside d_safe" in i.invalid for i in instances if i.invalid)


def test_an_instance_gets_its_noise_floor_when_a_run_misses_real_time(tmp_path, monkeypatch):
    """A backend slower than the loop misses real time on every instance: each instance's floor
    runs and its runs are judged against it; a criterion met needs no floor (it only excuses
    misses), so a sweep whose runs all hold the rate runs none (docs/verdicts.md)."""
    import slow_backends

    from qpbench.runner import SerialExecutor
    from qpbench.sweep.runner import run_sweep

    slow = slow_backends.registered(monkeypatch)
    text = SWEEP.replace("samples = 8", "samples = 3").replace("duration = 0.25", "duration = 0.05")
    spec = load_sweep(write_sweep(tmp_path, text))
    run_sweep(spec, ["daqp", slow], tmp_path / "out", SerialExecutor())
    rows = read_sweep_rows(tmp_path / "out" / "sweep.csv")
    valid = {r["instance"] for r in rows if r["status"] != "invalid_scenario"}
    assert {r["instance"] for r in rows if r["backend"] == slow and r["realtime"] == "no"} == valid
    assert {r["instance"] for r in rows if r["backend"] == "noop"} == valid
    assert_floors_where_needed(rows)
