"""What the terminal shows: log lines never run into a progress bar."""

from __future__ import annotations

import subprocess
import sys

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
