"""Native solver output never reaches qpbench's stdout (unless -v asks for everything)."""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
QPBENCH = [sys.executable, "-m", "qpbench.cli"]


def bench(tmp_path, *flags):
    pytest.importorskip("highspy")
    out = tmp_path / "x.csv"
    proc = subprocess.run(
        [
            *QPBENCH,
            *flags,
            "bench",
            str(ROOT / "problems" / "maros_meszaros"),
            "--backends",
            "qpsolvers:highs",
            "--out",
            str(out),
        ],
        capture_output=True,
        text=True,
        timeout=600,
    )
    assert proc.returncode in (0, 1), proc.stderr
    return proc.stdout


def test_solver_banner_silenced(tmp_path):
    stdout = bench(tmp_path)
    assert "HiGHS" not in stdout
    assert "Running" not in stdout


def test_verbose_lets_native_output_through(tmp_path):
    assert "HiGHS" in bench(tmp_path, "-v")


def test_python_output_still_reaches_stdout(tmp_path):
    proc = subprocess.run(
        [*QPBENCH, "list", str(ROOT / "problems" / "wall"), "--limit", "2"],
        capture_output=True,
        text=True,
        timeout=300,
    )
    assert proc.returncode == 0
    assert proc.stdout.splitlines()[1].startswith("wall_paper_000000")


def test_descriptor_one_silenced_inside_and_restored_after():
    code = (
        "import os, sys\n"
        "from qpbench.native_output import silence_native_stdout\n"
        "with silence_native_stdout():\n"
        "    os.write(1, b'native inside\\n')\n"
        "    print('python inside')\n"
        "os.write(1, b'native after\\n')\n"
        "print('python after')\n"
    )
    proc = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=120)
    assert proc.returncode == 0, proc.stderr
    assert proc.stdout.splitlines() == ["python inside", "native after", "python after"]
