"""What the terminal shows: log lines never run into a progress bar."""

from __future__ import annotations

import subprocess
import sys

from conftest import simulate_args

from qpbench.cli import main

CODE = """
import logging, sys
from tqdm import tqdm
from qpbench import cli

def run(args):
    bar = tqdm(total=3, file=sys.stderr, desc="bench")
    for i in range(3):
        bar.update(1)
        logging.getLogger("qpbench.harness").info("wall / daqp: ok %d", i)
    bar.close()
    return 0

import qpbench.commands.backends as command
command.run = run  # the sub-command's body replaced by one that logs while a bar runs

sys.exit(cli.main(["backends"]))
"""


def test_log_lines_start_on_their_own_line():
    proc = subprocess.run([sys.executable, "-c", CODE], capture_output=True, text=True, timeout=120)
    assert proc.returncode == 0, proc.stderr
    shown = [line.split("\r")[-1] for line in proc.stderr.split("\n")]
    logged = [line for line in shown if "wall / daqp" in line]
    assert len(logged) == 3
    assert all(line.startswith("INFO: wall / daqp: ok") for line in logged), shown


def _simulate_stderr(capsys, *flags: str) -> list[str]:
    """What ``qpbench FLAGS simulate ...`` writes on stderr (run in this process: the logging set-up
    of each call is the command line's own, replacing the previous one)."""
    capsys.readouterr()
    assert main([*flags, *simulate_args("wall", "daqp", "0.005")]) == 0
    return capsys.readouterr().err.splitlines()


def test_verbosity_levels(capsys):
    """-q: nothing but errors; default: the run's story; -v: also the settings; -vv: also one line per solve."""
    quiet, default, v, vv = (_simulate_stderr(capsys, *f) for f in (["-q"], [], ["-v"], ["-vv"]))
    assert quiet == []
    assert any("verdict ok" in line for line in default)
    assert not any(line.startswith("DEBUG") for line in default)
    settings = [line for line in v if line.startswith("DEBUG: qpbench ") and "simulate:" in line]
    assert (
        len(settings) == 1 and "backend='daqp'" in settings[0] and "duration=0.005" in settings[0]
    )
    per_solve = [line for line in vv if line.startswith("DEBUG: wall daqp tick ")]
    assert [line.split(" tick ")[1].split(" ")[0] for line in per_solve] == [
        "0",
        "1",
        "2",
        "3",
        "4",
    ]
    assert not any(" tick " in line and line.startswith("DEBUG: wall daqp") for line in v)


def test_phases_off_a_terminal_one_line_at_start_and_end(caplog):
    """Off a terminal a phase is two log lines (start, end with its time) and no bar; its time is kept.
    A phase that raises says no "done"."""
    import logging
    import re

    import pytest

    from qpbench.harness.pipeline import Phases

    logger = logging.getLogger("qpbench.test_phases")
    phases = Phases(logger, bars=None)  # stderr is no terminal under pytest: no bars
    assert phases.bars is False
    with caplog.at_level(logging.INFO, logger=logger.name):
        for name in ("compile", "bench wall"):
            with phases.phase(name, total=3) as phase:
                assert phase.bar is None
                for _ in range(3):
                    phase.update()
                logger.info("inside %s", name)
        with pytest.raises(RuntimeError), phases.phase("report"):
            raise RuntimeError("boom")
    lines = [re.sub(r"done in \d+\.\d s$", "done in T s", r.getMessage()) for r in caplog.records]
    assert lines == [
        "compile: started",
        "inside compile",
        "compile: done in T s",
        "bench wall: started",
        "inside bench wall",
        "bench wall: done in T s",
        "report: started",
    ]
    assert list(phases.times_s) == ["compile", "bench wall"]
    assert all(t >= 0 for t in phases.times_s.values())


def test_run_tells_each_phase_off_a_terminal(tmp_path, capsys):
    """``qpbench run`` off a terminal: one line when each phase starts and one when it ends, in order,
    and no progress bar (no carriage return)."""
    out = tmp_path / "out"
    args = ["run", "--duration", "0.05", "--bench-every", "400", "--repeat", "1",
            "--scenarios", "wall", "--backends", "qpsolvers:daqp,pinv",
            "--problems", str(tmp_path / "problems"), "--out", str(out)]  # fmt: skip
    capsys.readouterr()
    assert main(args) in (0, 1)  # 1: pinv fails its verdict
    err = capsys.readouterr().err
    assert "\r" not in err
    phases = ["compile", "problem set wall", "references", "bench wall", "closed loop", "report"]
    told = [
        line.split(": ", 1)[1]
        for line in err.splitlines()
        if line.startswith("INFO: ") and (line.endswith(": started") or ": done in " in line)
    ]
    expected = []
    for name in phases:
        expected += [f"{name}: started", f"{name}: done in"]
    assert [t if t.endswith("started") else t.rsplit(" ", 2)[0] for t in told] == expected
