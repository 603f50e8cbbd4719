"""Exit codes of every command that benchmarks many backends, with and without ``--strict``, and
``simulate``'s (docs/exit-codes.md): 0 once the outputs are written whatever the verdicts, 1 only
with ``--strict`` (one line on stderr says why), 2 on bad input; ``simulate`` exits 1 on a verdict
that is not ok. ``run``'s are checked in tests/test_cli.py::test_run_end_to_end (one run's set)."""

from __future__ import annotations

from pathlib import Path

import faulty_backends as fb
import pandas as pd
import pytest
from conftest import simulate_args

from qpbench.cli import main
from qpbench.formats import write_problem_set
from qpbench.report.recommend import recommend, render

PLUGIN = str(Path(fb.__file__).resolve())


def strict_line(err: str, command: str) -> str:
    """The one line of a --strict exit 1 (the last line on stderr)."""
    lines = [x for x in err.splitlines() if x.startswith(f"qpbench {command}: --strict: ")]
    assert len(lines) == 1, err
    return lines[0]


@pytest.fixture(scope="module")
def tiny_set(tmp_path_factory):
    """Three ticks of wall."""
    return write_problem_set(
        tmp_path_factory.mktemp("set") / "wall",
        fb.tick_records(3, scenario="wall", seed=1),
        generator={"name": "test"},
    )


def test_bench(tiny_set, tmp_path, capsys):
    """faulty:nan answers NaN on every problem: 3 failed solves."""

    def bench(out, *options):
        return main(
            ["-q", "bench", str(tiny_set), "--backends", "clarabel,faulty:nan", "--out",
             str(tmp_path / out), "--plugin", PLUGIN, *options]
        )  # fmt: skip

    assert bench("a.csv") == 0
    assert capsys.readouterr().err == ""
    assert len(pd.read_csv(tmp_path / "a.csv")) == 6
    assert bench("b.csv", "--strict") == 1
    assert strict_line(capsys.readouterr().err, "bench") == (
        "qpbench bench: --strict: 3 failed solves"
    )
    good = ["-q", "bench", str(tiny_set), "--backends", "clarabel", "--strict"]
    assert main([*good, "--out", str(tmp_path / "c.csv")]) == 0
    assert main([*good, "--out", str(tmp_path / "c.csv")]) == 2  # exists: bad input
    assert main([*good, "--out", str(tmp_path / "d.csv"), "--repeat", "0"]) == 2


def closed_loop(out: Path, backends: str, *options: str) -> int:
    return main(
        ["closed-loop", "--scenarios", "wall", "--backends", backends, "--duration", "0.05",
         "--out", str(out), *options]
    )  # fmt: skip


def test_closed_loop(tmp_path, capsys):
    """pinv breaks the joint speed limits from the first tick: its verdict is ``limits``."""
    out = tmp_path / "a"
    assert closed_loop(out, "daqp,pinv") == 0
    captured = capsys.readouterr()
    table = pd.read_csv(out / "closed_loop.csv")
    assert list(table["backend"]) == ["noop", "daqp", "pinv"]  # the noise floor first
    assert list(table["verdict"])[1:] == ["ok", "limits"]
    assert "--strict" not in captured.err
    # the recommendation is the last thing printed, after the table of runs
    answer = render(recommend(table))
    assert captured.out.endswith("\n" + answer)
    assert "limits in wall: " in answer.split("Not recommended:")[1]
    assert closed_loop(out, "daqp,pinv", "--resume", "--strict") == 1
    line = strict_line(capsys.readouterr().err, "closed-loop")
    assert line.startswith("qpbench closed-loop: --strict: 1 of 2 runs not ok (limits 1)")
    assert closed_loop(tmp_path / "b", "daqp,pinv", "-q", "--strict") == 1
    assert capsys.readouterr().out == ""  # -q: no table and no recommendation
    assert closed_loop(tmp_path / "c", "nosuch", "--strict") == 2


def test_sweep(tmp_path, capsys):
    sweep = tmp_path / "s.toml"
    sweep.write_text(
        '[sweep]\nname = "s"\nbase = "wall"\nseed = 1\nsamples = 1\nduration = 0.05\n\n'
        '[parameters]\n"controller.desired_force" = { dist = "uniform", low = 10.0, high = 30.0 }\n'
    )

    def run(out, *options):
        return main(
            ["-q", "sweep", str(sweep), "--backends", "daqp,pinv", "--out", str(tmp_path / out),
             "--jobs", "1", *options]
        )  # fmt: skip

    assert run("a") == 0
    rows = pd.read_csv(tmp_path / "a" / "sweep.csv")
    rows = rows[~rows["noise_floor"]]  # the noop run: the machine's noise floor
    assert sorted(rows["verdict"]) == ["limits", "ok"]
    assert "--strict" not in capsys.readouterr().err
    assert run("b", "--strict") == 1
    line = strict_line(capsys.readouterr().err, "sweep")
    assert line.startswith("qpbench sweep: --strict: 1 of 2 runs not ok (limits 1)")
    assert run("c", "--strict", "--samples", "0") == 2


def test_scaling(tmp_path, capsys):
    """faulty:nan on the smallest size: every solve fails; daqp drives the loop."""

    def scaling(out, backends, *options):
        return main(
            ["-q", "scaling", "--backends", backends, "--sizes", "n4-p1-m1", "--out",
             str(tmp_path / out), "--duration", "0.02", "--every", "10", "--repeat", "1",
             "--no-report", "--plugin", PLUGIN, *options]
        )  # fmt: skip

    assert scaling("a", "daqp,faulty:nan") == 0
    assert "--strict" not in capsys.readouterr().err
    assert scaling("a", "daqp,faulty:nan", "--resume", "--strict") == 1  # the kept size counts
    assert strict_line(capsys.readouterr().err, "scaling") == (
        "qpbench scaling: --strict: 2 failed solves"
    )
    assert scaling("b", "daqp", "--strict") == 0
    assert scaling("c", "daqp", "--strict", "--every", "0") == 2


def test_simulate_keeps_its_verdict_as_exit_code(tmp_path):
    assert main(["-q", *simulate_args("wall", "daqp", "0.05")]) == 0
    assert main(["-q", *simulate_args("wall", "pinv", "0.05")]) == 1  # limits
    assert main(["-q", *simulate_args("wall", "pinv", "-1")]) == 2
