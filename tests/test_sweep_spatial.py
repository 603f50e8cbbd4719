"""qpbench sweep on a spatial arm: the shipped panda_table sweep, its draws and a short run."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from qpbench.cli import main
from qpbench.robot.body import body_clearance
from qpbench.sim.scenario import load_scenario, parse_scenario
from qpbench.sweep.runner import read_sweep_rows
from qpbench.sweep.spec import load_sweep, sample_instances, start_clearance

SWEEP = Path(__file__).resolve().parents[1] / "problems" / "sweeps" / "panda_table.toml"


def test_panda_table_draws_stay_on_the_table_and_in_the_limits():
    spec = load_sweep(SWEEP, samples=20)
    instances = sample_instances(spec)
    assert sum(i.invalid is None for i in instances) >= 15
    for inst in instances:
        sc = parse_scenario(inst.text, path=f"{inst.name}.toml")
        chain = sc.make_arm().model
        assert np.all((sc.theta0 >= chain.q_min) & (sc.theta0 <= chain.q_max))
        p = sc.spec.path  # the path's centre and circle in the table's plane z = 0.2 m
        assert p.centre[2] == 0.2 and p.amplitude[2] == 0.0
        assert len(sc.spec.obstacles[0].velocity) == 3  # the ball's default velocity, drawn
        d, link, obstacle = start_clearance(sc)
        kp = sc.spec.key_points
        body = body_clearance(sc.make_arm(), sc.theta0, 0.0, sc.make_obstacles(), kp.link_radius)
        assert d == pytest.approx(np.nanmin(body.d)) and link.startswith("link ")
        assert (inst.invalid is None) == (d >= sc.spec.controller.d_safe)


def test_a_ball_on_the_arm_is_an_invalid_start(tmp_path):
    base = load_scenario("panda_table")
    elbow = base.make_arm().joint_positions(base.theta0[None])[0, 4]  # a point of the arm [m]
    text = f"""
[sweep]
name = "onarm"
base = "panda_table"
seed = 1
samples = 2

[parameters]
"obstacles[0].center" = {{ dist = "uniform", low = {elbow.tolist()}, high = {elbow.tolist()} }}
"""
    (tmp_path / "s.toml").write_text(text)
    inst = sample_instances(load_sweep(tmp_path / "s.toml"))
    assert all("from obstacle ball, inside d_safe" in i.invalid for i in inst)
    assert all(" -" in i.invalid.split("mm")[0] for i in inst)  # inside the ball: negative


def test_sweep_runs_on_panda_table_with_daqp(tmp_path):
    out = tmp_path / "out"
    args = ["sweep", str(SWEEP), "--backends", "daqp", "--samples", "2", "--duration", "0.2"]
    assert main([*args, "--out", str(out), "--jobs", "1"]) == 0
    rows = [r for r in read_sweep_rows(out / "sweep.csv") if r["backend"] == "daqp"]
    assert len(rows) == 2 and all(r["status"] == "ok" for r in rows)
    assert all(r["verdict"] == "ok" and r["realtime"] in ("yes", "no") for r in rows)
    assert all(float(r["min_obstacle_distance"]) > 0.03 - 0.0015 for r in rows)
    rerun = load_scenario(out / "instances" / "i00000.toml")
    assert rerun.make_arm().n == 7 and rerun.duration == 0.2
    report = tmp_path / "report"
    assert main(["report", str(out), "--out", str(report)]) == 0
    assert "### Sweep panda_table" in (report / "report.md").read_text()
