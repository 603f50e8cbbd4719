"""qpbench export, bench and closed-loop on a spatial arm (panda_table): the dumped ticks' QPs
have the Panda's 7 variables and the 3 task rows, read back equal to what the controller builds,
in a schema qpbenchmark reads; the problem set benches and the scenario runs in closed loop."""

from __future__ import annotations

import csv

import numpy as np
import pytest

from qpbench.cli import main
from qpbench.formats import load_problems
from qpbench.sim.loop import simulate
from qpbench.sim.scenario import load_scenario


@pytest.fixture(scope="module")
def dumped(tmp_path_factory):
    """panda_table's every 10th tick of 0.05 s with daqp, dumped: (folder, scenario, result)."""
    folder = tmp_path_factory.mktemp("panda") / "set"
    scenario = load_scenario("panda_table", duration=0.05)
    return folder, scenario, simulate(scenario, "daqp", every=10, dump=folder)


def _arrays(problem) -> dict:
    keys = ("P", "q", "G", "h", "A", "b", "lb", "ub")
    return {k: np.asarray(getattr(problem, k), dtype=float) for k in keys}


@pytest.mark.parametrize("fmt", ["parquet", "npz"])
def test_export_round_trips_the_controllers_qps(dumped, tmp_path, fmt):
    folder, scenario, result = dumped
    out = tmp_path / "out"
    assert main(["export", str(folder), "--format", fmt, "--out", str(out)]) == 0
    back = list(load_problems(out))
    assert [r.name for r in back] == [r.name for r in result.records] and len(back) == 5
    controller, log = scenario.make_controller(), result.log
    thetas = log[[f"theta_{i}" for i in range(7)]].to_numpy()
    for rec, dumped_rec in zip(back, result.records):
        assert rec.problem.P.shape == (7, 7) and rec.problem.A.shape == (3, 7)
        assert rec.problem.G.shape == (7, 7)  # one row per link and the ball
        k = dumped_rec.tick
        built = controller.build(np.ascontiguousarray(thetas[k]), float(log["t"].iloc[k]))
        mine, theirs = _arrays(rec.problem), _arrays(built.problem)
        for key in mine:  # read back as the controller built it
            np.testing.assert_allclose(mine[key], theirs[key], rtol=1e-12, atol=1e-12)
            assert np.array_equal(mine[key], _arrays(dumped_rec.problem)[key])  # bit-exact


def test_exported_panda_set_is_read_by_qpbenchmark(dumped, tmp_path):
    qpbenchmark = pytest.importorskip("qpbenchmark")
    folder, _, result = dumped
    out = tmp_path / "out"
    assert main(["export", str(folder), "--format", "parquet", "--out", str(out)]) == 0

    class PandaTicks(qpbenchmark.ParquetTestSet):
        description = "Panda per-tick QPs"
        title = "panda ticks"
        sparse_only = False

    theirs = list(PandaTicks(out / "problems.parquet"))
    assert [p.name for p in theirs] == [r.name for r in result.records]
    for prob, rec in zip(theirs, result.records):
        assert prob.A.shape == (3, 7)
        np.testing.assert_array_equal(prob.b, rec.problem.b)
        np.testing.assert_array_equal(prob.G, rec.problem.G)


def test_bench_on_the_panda_set(dumped, tmp_path):
    folder = dumped[0]
    out = tmp_path / "bench.csv"
    assert main(["bench", str(folder), "--backends", "daqp,clarabel", "--out", str(out)]) == 0
    with open(out, newline="") as fh:
        rows = list(csv.DictReader(fh))
    assert len(rows) == 10 and {(r["n"], r["m_eq"]) for r in rows} == {("7", "3")}
    assert all(r["status"] == "optimal" for r in rows)
    assert all(float(r["optimality_gap"] or 0) < 1e-6 for r in rows)


def test_closed_loop_on_panda_table(tmp_path):
    out = tmp_path / "loop"
    args = ["closed-loop", "--scenarios", "panda_table", "--backends", "daqp", "--duration", "0.1"]
    assert main([*args, "--out", str(out)]) == 0
    [table] = list(out.glob("*.csv"))
    with open(table, newline="") as fh:
        rows = {r["backend"]: r for r in csv.DictReader(fh)}
    assert set(rows) == {"noop", "daqp"}  # daqp beside the machine's noise floor
    row = rows["daqp"]
    assert row["scenario"] == "panda_table" and row["status"] == "ok"
    assert row["verdict"] == "ok" and float(row["min_body_distance"]) > 0.0
    assert row["realtime"] in ("yes", "no") and row["realtime_reason"]  # judged, as planar
