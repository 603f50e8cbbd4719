"""Guarded solves: exceptions, time limits, non-finite answers, hangs and crashes in a worker.

The fault-injection backends live in tests/faulty_backends.py (registered here
only). The end-to-end run goes through the CLI in a subprocess, so that the
worker processes also load them through ``QPBENCH_PLUGINS``.
"""

from __future__ import annotations

import csv
import os
import subprocess
import sys
from pathlib import Path

import faulty_backends as fb
import numpy as np
import pytest

from qpbench.backends import get_backend, load_plugins, plugin_files
from qpbench.harness.guard import IsolatedRunner, LocalRunner, classify
from qpbench.harness.results import TIMING_COLUMNS

PLUGIN = str(Path(fb.__file__).resolve())
QPBENCH = [sys.executable, "-m", "qpbench.cli"]


@pytest.fixture(scope="module")
def records():
    return fb.tick_records(4)


@pytest.fixture
def plugin_loaded():
    """The test plugin loaded as a plugin file: worker processes load it too."""
    load_plugins([PLUGIN])
    assert PLUGIN in plugin_files()


def local(name, time_limit=0.5, sequential=True):
    return LocalRunner(get_backend(name), time_limit, sequential)


def test_exception_becomes_error_with_type_and_message(records):
    out = local("faulty:raise").solve(records[0].problem)
    assert out.status == "error"
    assert out.error == "RuntimeError: solver exploded on two lines"
    assert out.solution is None and out.wall_times_s == []


def test_python_overrun_runs_to_its_end_and_is_time_limit(records):
    """The guard never raises inside a backend: a Python loop past the limit ends
    by itself (its last line and its ``finally`` run), then the row is ``time_limit``."""
    runner = local("faulty:busy", time_limit=0.05)
    out = runner.solve(records[0].problem)
    assert out.status == "time_limit" and "time limit 0.05" in out.error
    assert out.wall_times_s[0] >= fb.BUSY_S
    assert runner.backend.completed == runner.backend.cleanups == 1
    # the answer it returned is kept (right, only late)
    np.testing.assert_allclose(out.solution.x, fb.exact_solution(records[0].problem).x, atol=1e-9)
    assert runner.solve(records[1].problem).status == "time_limit" and runner.backend.completed == 2


def test_nan_answer_is_invalid(records):
    out = local("faulty:nan").solve(records[0].problem)
    assert out.status == "invalid"
    assert "non-finite x (4 of 4" in out.error


def test_classify_rules():
    sol = fb.exact_solution(fb.tick_records(1)[0].problem)
    assert classify(sol, 0.01, 1.0) == ("optimal", None)
    status, error = classify(sol, 2.0, 1.0)
    assert status == "time_limit" and "backend status optimal" in error
    sol.x = None
    assert classify(sol, 0.01, 1.0)[0] == "invalid"
    sol.status = "primal_infeasible"
    assert classify(sol, 0.01, 1.0)[0] == "primal_infeasible"


def test_reset_before_marks_state_reset_in_sequential_mode_only(records):
    runner = local("stateful:count-state")
    assert runner.solve(records[0].problem).solution.iterations == 1
    assert runner.solve(records[1].problem).solution.iterations == 2
    out = runner.solve(records[2].problem, reset_before=True)
    assert out.state_reset and out.solution.iterations == 1
    independent = local("stateful:count-state", sequential=False)
    for rec in records:
        out = independent.solve(rec.problem)
        assert out.solution.iterations == 1 and not out.state_reset


@pytest.mark.parametrize("name", ["stateful:count-state", "stateful:count-copy"])
def test_repeats_start_from_the_same_state(records, name):
    """Each timed repeat solves on its own replica, caught up with the kept one's history."""
    runner = local(name)
    runner.solve(records[0].problem)
    out = runner.solve(records[1].problem, repeat=4)
    assert len(out.wall_times_s) == 4
    assert out.solution.iterations == 2  # each repeat started from state "1 solve done"
    assert out.repeat_exact and out.repeat_note == ""
    assert [b.count for b in runner.replicas.members] == [2, 2, 2, 2]
    assert runner.solve(records[2].problem).solution.iterations == 3
    out = runner.solve(records[3].problem, repeat=3)  # replicas 1, 2 catch up on tick 2
    assert out.solution.iterations == 4 and out.repeat_exact


def test_repeats_of_uncopyable_state_follow_the_kept_replica(records):
    runner = LocalRunner(get_backend("stateful:last-native"), 0.5, True, repeat=3)
    assert len(runner.replicas.members) == 3  # made up front (warmed up with the first)
    outs = [runner.solve(r.problem) for r in records]
    assert [o.solution.iterations for o in outs] == [0, 1, 2, 3]
    assert all(len(o.wall_times_s) == 3 and o.repeat_exact for o in outs)
    runner.reset()
    assert runner.solve(records[2].problem).solution.iterations == 0


def test_replicas_that_disagree_are_reported(records):
    """A backend whose instances share state: the repeats do other work, and the row says so."""
    runner = local("stateful:shared")
    out = runner.solve(records[0].problem, repeat=3)
    # the registered class (a plugin loaded by path in this process registers its own copy)
    from qpbench.backends import get_backend

    shared = type(get_backend("stateful:shared"))
    assert out.solution.iterations == shared.calls - 2  # the kept (first) solve's
    assert not out.repeat_exact
    assert "repeat 2:" in out.repeat_note and "iterations against" in out.repeat_note


def test_a_replica_that_cannot_be_made_leaves_one_timed_solve(records):
    runner = local("stateful:single")
    out = runner.solve(records[0].problem, repeat=3)
    assert out.status == "optimal" and len(out.wall_times_s) == 1
    assert out.repeat_exact  # the one timed solve is the kept one
    assert out.repeat_note.startswith("1 of 3 solves timed: replica 2: RuntimeError")


def test_failed_solve_is_not_repeated_and_replicas_catch_up(records):
    runner = local("stateful:count-fail2")
    for rec in records[:2]:
        assert runner.solve(rec.problem, repeat=2).repeat_exact
    out = runner.solve(records[2].problem, repeat=2)
    assert out.status == "error" and len(out.wall_times_s) == 0
    out = runner.solve(records[3].problem, repeat=2, reset_before=True)
    assert out.solution.iterations == 1 and out.repeat_exact and len(out.wall_times_s) == 2


def test_worker_survives_segfault_and_restarts(records, plugin_loaded):
    runner = IsolatedRunner("faulty:segfault", "default", {}, 1.0, True)
    try:
        out = runner.solve(records[0].problem)
        assert out.status == "crashed" and "SIGSEGV" in out.error and out.isolated
        out = runner.solve(records[1].problem, reset_before=True)
        assert out.status == "crashed" and out.state_reset
        assert runner.restarts == 2
    finally:
        runner.close()


def test_worker_hang_is_killed_at_the_deadline_and_state_is_lost(records, plugin_loaded):
    runner = IsolatedRunner("faulty:hang", "default", {}, 0.2, True)
    try:
        out = runner.solve(records[0].problem)
        assert out.status == "time_limit" and "worker killed" in out.error
        assert runner.restarts == 1
    finally:
        runner.close()


def test_worker_times_inside_and_carries_state(records, plugin_loaded):
    runner = IsolatedRunner("stateful:last-native", "default", {}, 5.0, True, repeat=2)
    try:
        outs = [runner.solve(r.problem) for r in records]
        assert [o.solution.iterations for o in outs] == [0, 1, 2, 3]
        assert all(o.status == "optimal" and o.isolated and len(o.wall_times_s) == 2 for o in outs)
        assert all(o.repeat_exact for o in outs)
        assert outs[0].solution.problem is records[0].problem  # re-attached in the parent
        np.testing.assert_allclose(
            outs[1].solution.x, fb.exact_solution(records[1].problem).x, atol=1e-9
        )
    finally:
        runner.close()


#: A command's order of work: prepare the kernels, then start a worker and solve in it; prints
#: the general integrator's specialisations in the parent and in the worker's first solve.
_KERNELS_IN_WORKER = """
import faulty_backends as fb
from qpbench import jit
from qpbench.harness.guard import IsolatedRunner
from qpbench.rnn import network as nw

jit.warmup()
runner = IsolatedRunner("stateful:kernels", "default", {}, 5.0, True)
try:
    out = runner.solve(fb.tick_records(1)[0].problem)
    print(out.status, len(nw.kernel(True).overloads), out.solution.iterations)
finally:
    runner.close()
"""


def test_worker_starts_with_the_kernels_in_memory():
    """Workers are forked from a server that loaded every kernel the command prepared: the
    worker's first solve finds them in memory, none compiled or loaded in a solve. In a process
    of its own: the test session's worker server may have started before anything was prepared."""
    env = dict(os.environ, QPBENCH_PLUGINS=PLUGIN, PYTHONPATH=str(Path(PLUGIN).parent))
    proc = subprocess.run(
        [sys.executable, "-c", _KERNELS_IN_WORKER],
        capture_output=True,
        text=True,
        env=env,
        timeout=300,
    )
    assert proc.returncode == 0, proc.stderr
    status, parent, worker = proc.stdout.split()
    assert status == "optimal"
    assert int(parent) >= 1 and int(worker) == int(parent)


def _read(path):
    with open(path, newline="") as fh:
        return list(csv.DictReader(fh))


def _strip_timing(row):
    # the position in a problem's backend order depends on which backends ran
    return {k: v for k, v in row.items() if k not in TIMING_COLUMNS and k != "position"}


@pytest.fixture(scope="module")
def tick_set(tmp_path_factory):
    return fb.write_tick_set(tmp_path_factory.mktemp("set") / "wall", 4)


def _bench(args, env_extra=None):
    env = dict(os.environ, QPBENCH_PLUGINS=PLUGIN, **(env_extra or {}))
    return subprocess.run(
        QPBENCH + ["bench", *args], capture_output=True, text=True, env=env, timeout=300
    )


def test_fault_injection_run_completes_and_keeps_real_rows(tick_set, tmp_path):
    faulty = ["faulty:raise", "faulty:sleep", "faulty:hang", "faulty:segfault", "faulty:nan"]
    out = tmp_path / "faults.csv"
    proc = _bench(
        [
            str(tick_set),
            "--backends",
            ",".join(["clarabel", *faulty]),
            "--out",
            str(out),
            "--time-limit",
            "0.3",
            "--no-warmup",
            "--strict",
        ]
    )
    assert proc.returncode == 1, proc.stderr  # completed, some solves failed: --strict says so
    assert "qpbench bench: --strict: " in proc.stderr
    assert "failed solves" in proc.stdout
    rows = _read(out)
    assert len(rows) == 4 * 6
    status = {(r["problem"], r["backend"]): r["status"] for r in rows}
    for problem in {r["problem"] for r in rows}:
        assert status[(problem, "faulty:raise")] == "error"
        assert status[(problem, "faulty:sleep")] == "time_limit"
        assert status[(problem, "faulty:hang")] == "time_limit"
        assert status[(problem, "faulty:segfault")] == "crashed"
        assert status[(problem, "faulty:nan")] == "invalid"
        assert status[(problem, "clarabel")] == "optimal"
    by_backend = {
        b: [r for r in rows if r["backend"] == b]
        for b in ["faulty:raise", "faulty:segfault", "faulty:hang"]
    }
    assert all(
        r["error"] == "RuntimeError: solver exploded on two lines"
        for r in by_backend["faulty:raise"]
    )
    assert all(
        "SIGSEGV" in r["error"] and r["isolated"] == "True" for r in by_backend["faulty:segfault"]
    )
    # a Python-level overrun runs to its end in this process (never interrupted: time_limit by its
    # wall time), then the backend moves to a worker, whose deadline can stop it
    assert [r["isolated"] for r in rows if r["backend"] == "faulty:sleep"] == [
        "False",
        "True",
        "True",
        "True",
    ]
    assert "overran its time limit" in proc.stderr
    # after the first failure of a sequence, each later solve starts from a reset state
    assert [r["state_reset"] for r in by_backend["faulty:hang"]] == [
        "False",
        "True",
        "True",
        "True",
    ]
    # the real backend's rows equal those of a run of it alone
    alone = tmp_path / "alone.csv"
    proc = _bench([str(tick_set), "--backends", "clarabel", "--out", str(alone)])
    assert proc.returncode == 0, proc.stderr
    mine = [_strip_timing(r) for r in rows if r["backend"] == "clarabel"]
    assert mine == [_strip_timing(r) for r in _read(alone)]
    assert all(r["success"] == "True" for r in mine)


def test_in_process_crash_is_learned_on_resume(tick_set, tmp_path):
    out = tmp_path / "learn.csv"
    args = [
        str(tick_set),
        "--backends",
        "clarabel,faulty:segfault-once",
        "--out",
        str(out),
        "--no-warmup",
    ]
    proc = _bench(args, {"QPBENCH_TEST_SEGV": "2"})
    assert proc.returncode == -11  # the in-process segfault took the run down ...
    rows = _read(out)
    assert len(rows) == 4  # ... after the rows of ticks 0 and 1 were written
    marker = out.with_name(f".{out.name}.inflight")
    assert "Segmentation fault" in marker.read_text()
    proc = _bench(args + ["--resume"], {"QPBENCH_TEST_SEGV": "2"})
    assert proc.returncode == 0, proc.stderr  # completed (the crashed solve is a failed row)
    assert "runs in a worker process from now on" in proc.stderr
    rows = _read(out)
    assert len(rows) == 8 and len({(r["problem"], r["backend"]) for r in rows}) == 8
    st = {(r["problem"], r["backend"]): (r["status"], r["isolated"]) for r in rows}
    assert st[("wall/tick-0002", "faulty:segfault-once")] == ("crashed", "True")
    assert st[("wall/tick-0003", "faulty:segfault-once")] == ("optimal", "True")
    assert not marker.exists()
