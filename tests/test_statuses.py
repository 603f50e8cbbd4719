"""One vocabulary of solve outcomes (qpbench.statuses), used alike by the per-tick guard and the loop.

The same faulty answer gets the same status and the same text in a bench
row (:class:`~qpbench.harness.guard.LocalRunner`) and in a closed-loop tick
log (:func:`qpbench.sim.loop.simulate`); a dead worker is worded the same
way by the per-tick isolation and by an isolated closed-loop run.
"""

from __future__ import annotations

import signal
from pathlib import Path

import faulty_backends as fb
import pandas as pd
import pytest

from qpbench import metrics, statuses
from qpbench.backends import STATUSES, get_backend
from qpbench.cli import main
from qpbench.harness.guard import IsolatedRunner, LocalRunner
from qpbench.runner.process import death_message
from qpbench.sim.loop import simulate

PLUGIN = str(Path(fb.__file__).resolve())


def test_one_vocabulary():
    assert STATUSES is statuses.STATUSES and metrics.STATUSES is statuses.STATUSES
    assert (
        set(statuses.CERTIFIED_INFEASIBLE)
        < set(statuses.INFEASIBLE_OR_UNCLASSIFIED)
        <= set(statuses.STATUSES)
    )
    assert set(statuses.FAILURE_STATUSES) <= set(statuses.STATUSES) | set(statuses.GUARD_STATUSES)
    assert statuses.TICK_STATUSES == statuses.STATUSES + ("invalid",)


def test_describe_exception_is_one_line():
    assert statuses.describe_exception(RuntimeError("a\n  b")) == "RuntimeError: a b"
    assert statuses.describe_exception(KeyError()) == "KeyError"


@pytest.mark.parametrize("name, status", [("faulty:raise", "error"), ("faulty:nan", "invalid")])
def test_guard_and_loop_classify_the_same_answer_the_same_way(name, status):
    problem = fb.tick_records(1)[0].problem
    outcome = LocalRunner(get_backend(name), 1.0, True).solve(problem)
    result = simulate("wall", name, duration=0.003)
    assert outcome.status == status
    assert set(result.log["status"].astype(str)) == {status}
    assert result.summary[f"{status}_ticks"] == 3
    if status == "error":  # the same words for the same exception
        assert (
            result.summary["first_error"]
            == outcome.error
            == "RuntimeError: solver exploded on two lines"
        )
    # a tick without an answer: the soft fallback fails too (same backend), zero velocity
    assert result.log["zero_velocity"].all()


def test_late_answer_is_time_limit_in_both():
    problem = fb.tick_records(1)[0].problem
    solution = fb.exact_solution(problem)
    assert statuses.classify(solution, 2.0, 1.0)[0] == "time_limit"
    assert statuses.classify(solution, 0.5, 1.0) == ("optimal", None)
    assert (
        LocalRunner(get_backend("faulty:sleep"), 0.01, True).solve(problem).status == "time_limit"
    )


def test_a_dead_worker_is_worded_the_same_per_tick_and_in_the_loop(tmp_path):
    from qpbench.backends import load_plugins
    from qpbench.harness import closed_loop

    load_plugins([PLUGIN])  # what the CLI's --plugin does: the workers load it too
    runner = IsolatedRunner("faulty:segfault", "default", {}, 1.0, True)
    try:
        per_tick = runner.solve(fb.tick_records(1)[0].problem)
    finally:
        runner.close()
    outcome = closed_loop.run_closed_loop(
        ["wall"], ["faulty:segfault"], tmp_path, duration=0.01, run_time_limit=60.0
    )
    row = outcome.table.set_index("backend").loc["faulty:segfault"]  # after the noise floor's
    words = death_message(-signal.SIGSEGV)
    assert words == "worker process killed by SIGSEGV"
    assert per_tick.status == "crashed" and per_tick.error == f"{words} during solve"
    assert row["status"] == "crashed" and row["error"] == f"{words} during the closed-loop run"
    assert death_message(3) == "worker process exited with code 3"


def test_set_with_a_typo_exits_2_before_any_solve(tmp_path, capsys, monkeypatch):
    folder = fb.write_tick_set(tmp_path / "set", 2)
    out = tmp_path / "r.csv"

    def no_solve(*args, **kwargs):  # pragma: no cover - must not be reached
        raise AssertionError("a solve started")

    from qpbench.backends import osqp_

    monkeypatch.setattr(osqp_.OsqpBackend, "solve", no_solve)
    assert (
        main(
            [
                "bench",
                str(folder),
                "--backends",
                "osqp",
                "--set",
                "osqp.rhoo=0.1",
                "--out",
                str(out),
            ]
        )
        == 2
    )
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1 and "did you mean 'rho'" in err and "osqp.rhoo" in err
    assert not out.exists()
    # a real setting passes the check (and reaches the solver)
    monkeypatch.undo()
    assert main(
        [
            "-q",
            "bench",
            str(folder),
            "--backends",
            "osqp",
            "--set",
            "osqp.rho=0.1",
            "--out",
            str(out),
        ]
    ) in (0, 1)
    assert len(pd.read_csv(out)) == 2
