"""Backend names: matched without regard to case, with a suggestion for a typo; listed as JSON."""

from __future__ import annotations

import json
import subprocess
import sys

import pytest
from conftest import simulate_args

from qpbench.backends import backend_class, backend_names, get_backend, resolve_name
from qpbench.cli import main
from qpbench.exceptions import BackendNotFound


def test_case_insensitive():
    assert resolve_name("DAQP") == "daqp"
    assert resolve_name("QPSolvers:Clarabel") == "qpsolvers:clarabel"
    assert get_backend("Pinv").name == "pinv"
    assert backend_class("RNN-Tuned").name == "rnn-tuned"


def test_typo_gets_a_suggestion():
    with pytest.raises(BackendNotFound, match=r"did you mean 'osqp'"):
        resolve_name("osqq")
    with pytest.raises(BackendNotFound) as exc:
        resolve_name("zzzzzz")
    assert "did you mean" not in str(exc.value)
    assert "available: " in str(exc.value)


def test_backends_json(capsys):
    assert main(["backends", "--available", "--json"]) == 0
    rows = [json.loads(line) for line in capsys.readouterr().out.splitlines()]
    assert [r["name"] for r in rows] == backend_names()
    assert all(r["available"] and r["reason"] is None for r in rows)


def test_closed_pipe_is_quiet():
    proc = subprocess.run(
        f"{sys.executable} -m qpbench.cli backends | head -1",
        shell=True,
        capture_output=True,
        text=True,
        timeout=120,
    )
    assert proc.stdout.startswith("name")
    assert "Traceback" not in proc.stderr and "BrokenPipe" not in proc.stderr


def test_inspect_json(capsys):
    from pathlib import Path

    root = Path(__file__).resolve().parents[1]
    assert main(["inspect", str(root / "problems" / "narrow"), "--json"]) == 0
    info = json.loads(capsys.readouterr().out)
    assert info["problems"] == 2000 and info["n"] == [4, 4] and info["m_ineq"] == [14, 14]
    assert info["hash_ok"] is True and info["scenario"] == {"narrow": 2000}


def test_simulate_summary_to_stdout(tmp_path, monkeypatch, capsys):
    monkeypatch.chdir(tmp_path)
    assert main(
        [
            "-q",
            *simulate_args("wall", "pinv", "0.02"),
            "--summary",
            "-",
        ]
    ) in (0, 1)
    summary = json.loads(capsys.readouterr().out)
    assert summary["ticks"] == 20 and summary["backend"] == "pinv"
    assert not (tmp_path / "-").exists()


def test_closed_loop_checks_scenarios_before_running(tmp_path, capsys):
    out = tmp_path / "loop"
    assert main(["closed-loop", "--scenarios", "wal", "--backends", "daqp", "--out", str(out)]) == 2
    err = capsys.readouterr().err
    assert "wal" in err and "shipped: " in err
    assert not out.exists()


def test_closed_loop_prints_a_table_of_its_runs(tmp_path, capsys):
    out = tmp_path / "loop"
    code = main(
        [
            "closed-loop",
            "--scenarios",
            "wall",
            "--backends",
            "DAQP,pinv",
            "--duration",
            "2",
            "--out",
            str(out),
        ]
    )
    assert code == 0  # the table is written; pinv going through the wall is in it
    lines = capsys.readouterr().out.split("\n\n")[0].splitlines()  # the recommendation follows
    assert lines[0].split()[:3] == ["scenario", "backend", "verdict"]
    by_backend = {line.split()[1]: line.split() for line in lines[1:]}
    assert by_backend["daqp"][2] == "ok" and by_backend["pinv"][2] == "unsafe"
    assert float(by_backend["pinv"][6]) < 9.5  # d_min in mm
