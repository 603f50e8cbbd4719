"""``qpbench bench`` end to end: columns, references, success, state, resume, exit codes, bad input."""

from __future__ import annotations

import csv
import json
import shutil
from pathlib import Path

import faulty_backends as fb
import numpy as np
import pytest

from qpbench.cli import main
from qpbench.formats import write_problem_set
from qpbench.harness.bench import sequences
from qpbench.harness.results import TIMING_COLUMNS
from qpbench.harness.results import bench_columns as columns
from qpbench.profiles import PROFILES

PLUGIN = str(Path(fb.__file__).resolve())
STATEFUL = "stateful:count-state,stateful:count-copy,stateful:last-native"


def read(path):
    with open(path, newline="") as fh:
        return list(csv.DictReader(fh))


def untimed(rows):
    return sorted((tuple((k, v) for k, v in r.items() if k not in TIMING_COLUMNS) for r in rows))


def bench(*args) -> int:
    return main(["bench", *map(str, args), "--plugin", PLUGIN])


@pytest.fixture(scope="module")
def two_scenarios(tmp_path_factory):
    """Set of 2 scenarios x 5 ticks, stored with the ticks of 'free' shuffled."""
    wall = fb.tick_records(5, scenario="wall", seed=1)
    free = fb.tick_records(5, scenario="free", seed=2)
    order = [
        free[3],
        wall[0],
        free[0],
        wall[1],
        wall[2],
        free[4],
        free[1],
        wall[3],
        wall[4],
        free[2],
    ]
    return write_problem_set(
        tmp_path_factory.mktemp("sets") / "two", order, generator={"name": "test"}
    )


@pytest.fixture(scope="module")
def mm_small(tmp_path_factory, mm_dir):
    folder = tmp_path_factory.mktemp("mm")
    for name in ["HS21", "HS35", "HS51", "HS118", "GENHS28"]:
        shutil.copy(mm_dir / f"{name}.mat", folder)
    return folder


def test_maros_meszaros_rows_columns_references_and_success(mm_small, tmp_path, capsys):
    out = tmp_path / "mm.csv"
    code = bench(
        mm_small, "--backends", "clarabel,qpsolvers:daqp,faulty:nan", "--out", out, "--repeat", "2"
    )
    rows = read(out)
    assert code == 0  # written; faulty:nan fails everywhere (exit 1 only with --strict)
    assert list(rows[0].keys()) == list(columns())
    assert len(rows) == 5 * 3
    assert "harness overhead" in capsys.readouterr().out
    tol = PROFILES["default"].tolerance
    for r in rows:
        assert r["reference_status"] == "optimal"
        assert r["profile"] == "default" and r["mode"] == "sequential"
        assert float(r["wall_time_min_s"]) <= float(r["wall_time_median_s"])
        if r["backend"] == "faulty:nan":
            assert r["status"] == "invalid" and r["success"] == "False" and r["found"] == "False"
            assert r["repeat"] == "1"  # a failed solve is not repeated
            continue
        assert r["repeat"] == "2"
        expected = (
            r["found"] == "True"
            and float(r["primal_residual"]) <= tol.primal
            and float(r["dual_residual"]) <= tol.dual
            and float(r["duality_gap"]) <= tol.gap
            and float(r["optimality_gap"]) <= tol.gap
        )
        assert (r["success"] == "True") == expected
    clarabel = {r["problem"]: r for r in rows if r["backend"] == "clarabel"}
    assert all(r["success"] == "True" for r in clarabel.values())
    # HS21 optimum is -99.96 (Maros & Meszaros); HS118 is 664.82045
    assert float(clarabel["HS21"]["reference_objective"]) == pytest.approx(-99.96, rel=1e-6)
    assert float(clarabel["HS118"]["objective"]) == pytest.approx(664.82045, rel=1e-6)
    assert clarabel["HS118"]["n"] == "15" and int(clarabel["HS118"]["m_ineq"]) > 0


def test_sequences_group_by_scenario_in_tick_order():
    recs = [
        fb.tick_records(1, scenario="b")[0],
        *fb.tick_records(3, scenario="a"),
        fb.tick_records(1, scenario=None, prefix="x")[0],
    ]
    recs[1], recs[3] = recs[3], recs[1]  # a's ticks stored 2, 1, 0
    assert sequences(recs, "sequential") == [[0], [3, 2, 1], [4]]
    assert sequences(recs, "independent") == [[0], [1], [2], [3], [4]]


def test_sequential_mode_carries_state_per_scenario(two_scenarios, tmp_path):
    out = tmp_path / "seq.csv"
    assert bench(two_scenarios, "--backends", STATEFUL, "--out", out, "--repeat", "3") == 0
    rows = read(out)
    assert len(rows) == 30
    for r in rows:
        tick = int(r["tick"])
        expected = tick if r["backend"] == "stateful:last-native" else tick + 1
        assert int(r["iterations"]) == expected, r
        assert r["state_reset"] == "False" and r["success"] == "True"
    # rows come out per sequence, in tick order
    wall = [
        int(r["tick"])
        for r in rows
        if r["scenario"] == "wall" and r["backend"] == "stateful:count-copy"
    ]
    assert wall == [0, 1, 2, 3, 4]


def test_independent_mode_resets_before_every_problem(two_scenarios, tmp_path):
    out = tmp_path / "ind.csv"
    assert bench(two_scenarios, "--backends", STATEFUL, "--out", out, "--mode", "independent") == 0
    for r in read(out):
        assert int(r["iterations"]) == (0 if r["backend"] == "stateful:last-native" else 1)
        assert r["mode"] == "independent"


def test_failure_resets_state_and_says_so(two_scenarios, tmp_path):
    out = tmp_path / "fail.csv"
    assert bench(two_scenarios, "--backends", "stateful:count-fail2", "--out", out, "--strict") == 1
    rows = {(r["scenario"], int(r["tick"])): r for r in read(out)}
    for scenario in ("wall", "free"):
        assert [rows[(scenario, k)]["iterations"] for k in (0, 1, 3, 4)] == ["1", "2", "1", "2"]
        assert rows[(scenario, 2)]["status"] == "error"
        assert rows[(scenario, 2)]["error"] == "ValueError: tick two"
        assert [rows[(scenario, k)]["state_reset"] for k in range(5)] == [
            "False",
            "False",
            "False",
            "True",
            "False",
        ]


@pytest.mark.parametrize("keep", [0, 3, 7, 12, 25])
def test_resume_after_interruption_gives_the_rows_of_an_uninterrupted_run(
    two_scenarios, tmp_path, keep
):
    backends = STATEFUL + ",stateful:count-fail2"
    full = tmp_path / "full.csv"
    assert bench(two_scenarios, "--backends", backends, "--out", full) == 0
    lines = full.read_bytes().split(b"\n")
    cut = tmp_path / "cut.csv"
    # header + `keep` rows + half of the next line, as a kill -9 during a write leaves it
    cut.write_bytes(b"\n".join(lines[: 1 + keep]) + b"\n" + lines[1 + keep][:17])
    assert bench(two_scenarios, "--backends", backends, "--out", cut, "--resume") == 0
    assert untimed(read(cut)) == untimed(read(full))
    assert len(read(cut)) == 40


def test_existing_output_is_refused_and_untouched(two_scenarios, tmp_path, capsys):
    out = tmp_path / "exists.csv"
    out.write_text("precious\n")
    assert bench(two_scenarios, "--backends", "clarabel", "--out", out) == 2
    assert "exists" in capsys.readouterr().err
    assert out.read_text() == "precious\n"
    assert bench(two_scenarios, "--backends", "clarabel", "--out", out, "--force") == 0
    assert len(read(out)) == 10


def test_resume_refuses_a_different_mode(two_scenarios, tmp_path, capsys):
    out = tmp_path / "m.csv"
    assert bench(two_scenarios, "--backends", "clarabel", "--out", out) == 0
    before = out.read_bytes()
    assert (
        bench(
            two_scenarios,
            "--backends",
            "clarabel",
            "--out",
            out,
            "--resume",
            "--mode",
            "independent",
        )
        == 2
    )
    assert "mode" in capsys.readouterr().err
    assert out.read_bytes() == before


def _corrupt_npz(folder):
    folder.mkdir()
    (folder / "a.npz").write_bytes(b"PK\x03\x04 truncated")


def _save_arrays(folder, **changes):
    """A qpsolvers-style .npz of a valid problem with some arrays replaced."""
    folder.mkdir()
    p = fb.tick_records(1)[0].problem
    arrays = dict(P=p.P, q=p.q, G=p.G, h=p.h, A=p.A, b=p.b, lb=p.lb, ub=p.ub)
    arrays.update(changes)
    np.savez(folder / "a.npz", **arrays)


def _nan_npz(folder):
    _save_arrays(folder, q=np.array([np.nan, 0.0, 0.0, 1.0]))


def _inf_npz(folder):
    _save_arrays(folder, h=np.array([1.0, np.inf, 1.0]))


def _hash_mismatch(folder):
    write_problem_set(folder, fb.tick_records(2), generator={"name": "test"})
    manifest = json.loads((folder / "manifest.json").read_text())
    manifest["sha256"] = "0" * 64
    (folder / "manifest.json").write_text(json.dumps(manifest))


def _truncated_parquet(folder):
    write_problem_set(folder, fb.tick_records(2), generator={"name": "test"})
    data = (folder / "problems.parquet").read_bytes()
    (folder / "problems.parquet").write_bytes(data[: len(data) // 2])


def _wrong_shape_npz(folder):
    _save_arrays(folder, q=np.ones(3))


def _missing_column_parquet(folder):
    import pyarrow.parquet as pq

    folder.mkdir()
    write_problem_set(folder / "set", fb.tick_records(2), generator={"name": "test"})
    table = pq.read_table(folder / "set" / "problems.parquet").drop(["q"])
    pq.write_table(table, folder / "bad.parquet")
    shutil.rmtree(folder / "set")


@pytest.mark.parametrize(
    "make",
    [
        _corrupt_npz,
        _nan_npz,
        _inf_npz,
        _hash_mismatch,
        _truncated_parquet,
        _wrong_shape_npz,
        _missing_column_parquet,
        None,
    ],
)
def test_bad_input_is_one_line_exit_2_and_no_output(tmp_path, capsys, make):
    folder = tmp_path / "bad"
    if make is not None:
        make(folder)
    if make is _missing_column_parquet:
        folder = folder / "bad.parquet"
    out = tmp_path / "out" / "r.csv"
    assert bench(folder, "--backends", "clarabel", "--out", out) == 2
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1 and err.startswith("qpbench bench: error:") and "bad" in err
    assert not out.exists() and not out.parent.exists()


@pytest.mark.parametrize(
    "args, key",
    [
        (["--backends", "nope"], "nope"),
        (["--backends", "clarabel", "--repeat", "0"], "repeat"),
        (["--backends", "clarabel", "--time-limit", "-1"], "time"),
        (["--backends", "clarabel,clarabel"], "twice"),
        (["--backends", "clarabel", "--plugin", "/no/such/plugin.py"], "plugin"),
    ],
)
def test_bad_parameters_exit_2_without_output(two_scenarios, tmp_path, capsys, args, key):
    out = tmp_path / "r.csv"
    assert main(["bench", str(two_scenarios), "--out", str(out), *args]) == 2
    assert key in capsys.readouterr().err
    assert not out.exists()


def test_all_means_every_available_backend(tmp_path):
    import subprocess
    import sys

    folder = fb.write_tick_set(tmp_path / "set", 2)
    out = tmp_path / "all.csv"
    env = {k: v for k, v in __import__("os").environ.items() if k != "QPBENCH_PLUGINS"}
    cmd = [sys.executable, "-m", "qpbench.cli"]
    proc = subprocess.run(
        cmd + ["bench", str(folder), "--backends", "all", "--out", str(out)],
        capture_output=True,
        text=True,
        env=env,
    )
    assert proc.returncode in (0, 1), proc.stderr
    listed = subprocess.run(
        cmd + ["backends", "--available"], capture_output=True, text=True, env=env
    ).stdout
    available = {line.split()[0] for line in listed.splitlines()[1:] if line.strip()}
    available.discard("noop")  # the noise floor: listed, never benched
    rows = read(out)
    assert {r["backend"] for r in rows} == available and len(rows) == 2 * len(available)


def test_online_backend_integrates_the_time_between_records(tmp_path):
    """A set keeping every 10th tick of a 1 ms loop: the network integrates 10 ms per record."""
    from qpbench.formats import read_problem_set
    from qpbench.harness.bench import BenchConfig, backend_settings

    folder = write_problem_set(
        tmp_path / "s",
        fb.tick_records(3),
        generator={"name": "qpbench simulate", "dt": 0.001, "every": 10},
    )
    pset = read_problem_set(folder)
    config = BenchConfig(backends=["rnn", "rnn-tuned", "clarabel"], settings={})
    got = {name: backend_settings(name, config, pset) for name in config.backends}
    assert got == {
        "rnn": {"dt": pytest.approx(0.01)},
        "rnn-tuned": {"dt": pytest.approx(0.01)},
        "clarabel": {},
    }
    # an explicit dt wins; a set without a generator period leaves the default
    explicit = BenchConfig(backends=["rnn"], settings={"dt": 0.002})
    assert backend_settings("rnn", explicit, pset) == {"dt": 0.002}
    bare = read_problem_set(
        write_problem_set(tmp_path / "b", fb.tick_records(3), generator={"name": "t"})
    )
    assert backend_settings("rnn", config, bare) == {}


def test_set_gives_one_backend_its_own_settings(two_scenarios, tmp_path, capsys, monkeypatch):
    """--set rnn.eps=0.001 reaches the rnn backend only; a --set naming no backend of the run is exit 2."""
    from qpbench.backends import get_backend as real_get_backend

    seen = {}  # every call's settings, by backend (the kernels' warm-up builds its own)

    def spy(name, profile="default", **settings):
        seen.setdefault(name, []).append(settings)
        return real_get_backend(name, profile, **settings)

    monkeypatch.setattr("qpbench.backends.get_backend", spy)
    out = tmp_path / "s.csv"
    assert bench(
        two_scenarios,
        "--backends",
        "rnn,clarabel",
        "--out",
        out,
        "--set",
        "rnn.eps=0.001",
        "--set",
        "rnn.substeps=5",
    ) in (0, 1)
    assert any(s.get("eps") == 0.001 and s.get("substeps") == 5 for s in seen["rnn"])
    assert seen["clarabel"] and all("eps" not in s for s in seen["clarabel"])
    capsys.readouterr()
    bad = tmp_path / "bad.csv"
    assert (
        bench(two_scenarios, "--backends", "clarabel", "--out", bad, "--set", "osqp.rho=0.1") == 2
    )
    assert "osqp.rho" in capsys.readouterr().err and not bad.exists()


# ------------------------------------------------------------ backend order, violation, summary, timing

ORDER = ["faulty:order-a", "faulty:order-b", "faulty:order-c"]


def _calls() -> list:
    """The call log of the ``faulty:order-*`` backends registered now (a ``--plugin`` run loads its own copy)."""
    import sys

    from qpbench.backends import backend_class

    return sys.modules[backend_class("faulty:order-a").__module__].CALLS


def _order_run(pset, out, **kw):
    from qpbench.harness.bench import BenchConfig, run_bench
    from qpbench.reference import reference_solutions

    refs = reference_solutions(pset)
    _calls().clear()
    config = BenchConfig(backends=list(ORDER), isolate="never", warmup=False, **kw)
    return run_bench(pset, config, out, references=refs), refs


def test_backend_order_is_drawn_per_problem_recorded_and_followed(two_scenarios, tmp_path):
    from qpbench.formats import load_problems
    from qpbench.harness.bench import backend_order

    pset = load_problems(two_scenarios)
    _order_run(pset, tmp_path / "o.csv")
    rows = read(tmp_path / "o.csv")
    by_problem = {}
    for r in rows:
        by_problem.setdefault(r["problem"], {})[r["backend"]] = int(r["position"])
        assert r["order_seed"] == "0"
    orders = set()
    for problem, positions in by_problem.items():
        assert sorted(positions.values()) == [0, 1, 2]
        order = sorted(positions, key=positions.get)
        assert order == backend_order(problem, ORDER, 0)
        orders.add(tuple(order))
    # the first place moves between backends across problems
    assert len({o[0] for o in orders}) > 1
    # the solves happened in the recorded order: sequences in tick order, each problem's backends in a row
    seqs = sequences(pset.records, "sequential")
    expected = []
    for seq in seqs:
        for i in seq:
            rec = pset.records[i]
            expected += [(b, float(rec.tick)) for b in backend_order(rec.name, ORDER, 0)]
    assert _calls() == expected
    # another seed, another order; the order does not depend on how the list is given
    assert backend_order("wall/tick-0001", ORDER, 0) == backend_order(
        "wall/tick-0001", ORDER[::-1], 0
    )
    assert any(backend_order(p, ORDER, 1) != backend_order(p, ORDER, 0) for p in by_problem)


def test_resume_reproduces_the_order_and_refuses_another_seed(two_scenarios, tmp_path, capsys):
    full, cut = tmp_path / "full.csv", tmp_path / "cut.csv"
    # x = 0 is not optimal where the reference is: failed solves (exit 0: the outputs are written)
    assert bench(two_scenarios, "--backends", ",".join(ORDER), "--out", full, "--seed", "5") == 0
    lines = full.read_bytes().split(b"\n")
    cut.write_bytes(b"\n".join(lines[:12]) + b"\n" + lines[12][:9])
    assert bench(two_scenarios, "--backends", ",".join(ORDER), "--out", cut, "--resume") == 2
    assert "seed 5" in capsys.readouterr().err
    assert (
        bench(two_scenarios, "--backends", ",".join(ORDER), "--out", cut, "--resume", "--seed", "5")
        == 0
    )
    pos = lambda rows: sorted(
        (r["problem"], r["backend"], r["position"], r["order_seed"]) for r in rows
    )  # noqa: E731
    assert pos(read(cut)) == pos(read(full))
    assert {r["order_seed"] for r in read(cut)} == {"5"}


def test_violation_columns_for_answers_found_or_not(two_scenarios, tmp_path):
    from qpbench.formats import load_problems

    out = tmp_path / "v.csv"
    assert (
        bench(two_scenarios, "--backends", "faulty:order-a,faulty:outside-box", "--out", out) == 0
    )
    problems = {r.name: r.problem for r in load_problems(two_scenarios).records}
    for r in read(out):
        p = problems[r["problem"]]
        if (
            r["backend"] == "faulty:order-a"
        ):  # x = 0, not found: only the equality is violated, by |b|
            assert r["found"] == "False" and r["primal_residual"] == "inf"
            assert float(r["violation_eq"]) == pytest.approx(float(np.max(np.abs(p.b))), rel=1e-15)
            assert float(r["violation_ineq"]) == 0.0 and float(r["violation_box"]) == 0.0
            assert float(r["constraint_violation"]) == float(r["violation_eq"])
        else:  # x = 3, "optimal": 1 outside the box [-2, 2]
            x = 3.0 * np.ones(p.q.shape[0])
            assert float(r["violation_box"]) == pytest.approx(1.0, rel=1e-15)
            assert float(r["violation_ineq"]) == pytest.approx(
                max(0.0, float(np.max(p.G @ x - p.h))), rel=1e-12
            )
            assert float(r["violation_eq"]) == pytest.approx(
                float(np.max(np.abs(p.A @ x - p.b))), rel=1e-12
            )
            assert float(r["constraint_violation"]) == pytest.approx(
                float(r["primal_residual"]), rel=1e-12
            )
        assert float(r["reference_agreement"]) <= 1e-7


def test_closing_summary_counts_failures_and_unsuccessful_solves_by_backend(
    two_scenarios, tmp_path, capsys
):
    out = tmp_path / "s.csv"
    code = bench(two_scenarios, "--backends", "clarabel,pinv,stateful:count-fail2", "--out", out)
    assert code == 0
    text = capsys.readouterr().out
    rows = read(out)
    pinv_bad = sum(1 for r in rows if r["backend"] == "pinv" and r["success"] == "False")
    assert pinv_bad > 0  # pinv ignores the objective: its answers are off the optimum
    assert "2 failed solves (stateful:count-fail2 2)" in text
    assert f"pinv {pinv_bad}" in text.splitlines()[0]
    table = {line.split()[0]: line for line in text.splitlines()[1:] if line.strip()}
    assert table["backend"].split()[:3] == ["backend", "rows", "success"]
    assert table["stateful:count-fail2"].rstrip().endswith("2 (error 2)")
    pinv = table["pinv"].split()
    assert float(pinv[2]) == pytest.approx(100.0 * (10 - pinv_bad) / 10, abs=0.05)
    viol = max(float(r["constraint_violation"]) for r in rows if r["backend"] == "pinv")
    assert pinv[5] == f"{viol:.3g}"
    clarabel = table["clarabel"].split()
    assert clarabel[1] == "10" and clarabel[2] == "100.0" and clarabel[-1] == "0"
    # -q hides both
    assert bench(two_scenarios, "--backends", "clarabel", "--out", tmp_path / "q.csv", "-q") == 0
    assert capsys.readouterr().out == ""


def test_deferred_parts_of_the_answer_are_inside_the_timed_region(two_scenarios, tmp_path):
    from qpbench.backends.base import timed_call
    from qpbench.formats import load_problems

    problem = load_problems(two_scenarios).records[0].problem
    sol, ns = timed_call(get_backend_instance("faulty:lazy-duals"), problem)
    assert "_y" in sol.__dict__  # built by the timed call
    assert ns >= fb.LAZY_SECONDS * 1e9
    out = tmp_path / "lazy.csv"
    assert (
        bench(
            two_scenarios, "--backends", "faulty:lazy-duals", "--out", out, "--mode", "independent"
        )
        == 0
    )
    assert all(float(r["wall_time_min_s"]) >= fb.LAZY_SECONDS for r in read(out))


def get_backend_instance(name):
    from qpbench.backends import get_backend

    return get_backend(name)


def test_warmup_solves_cover_every_problem_structure():
    """The discarded warm-up solves reach each structure of the set (a kernel specialises on
    which parts are present), so no timed solve pays a first-structure cost."""
    from qpbench.harness.bench import _structure, _warmup_problems

    records = fb.tick_records(6)
    records[3].problem.A = records[3].problem.b = None
    records[4].problem.A = records[4].problem.b = None
    records[5].problem.lb = records[5].problem.ub = None
    seqs = sequences(records, "sequential")
    firsts = _warmup_problems(records, seqs)
    assert firsts == [records[0].problem, records[3].problem, records[5].problem]
    assert len({_structure(p) for p in firsts}) == 3
    assert _warmup_problems(records[:3], sequences(records[:3], "sequential")) == [
        records[0].problem
    ]
