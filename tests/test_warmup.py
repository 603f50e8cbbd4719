"""Kernels compiled before the clock, once: a fresh machine's first run is the same run as the next.

The fresh-cache check runs two simulations in an empty numba cache folder of its own
(``NUMBA_CACHE_DIR``), with a backend whose run compiles little (``daqp``: the loop's kernels
and one compiled engine, whose solve calls DAQP's C library by name): the first compiles,
the second must only load. The ``warmup`` command is checked on the session's cache, which holds every
kernel once it has run.
"""

from __future__ import annotations

import json
import os
import subprocess
import sys
from pathlib import Path

import pytest
from conftest import SUMMARY_TIME_KEYS

QPBENCH = [sys.executable, "-m", "qpbench.cli"]


def _cache_files(folder: Path) -> dict[str, tuple[int, int]]:
    """numba's index and data files under ``folder``: name -> (size, mtime in ns)."""
    return {
        str(p.relative_to(folder)): (p.stat().st_size, p.stat().st_mtime_ns)
        for p in folder.rglob("*")
        if p.suffix in (".nbi", ".nbc")
    }


def _qpbench(args, cache: Path | str | None, cwd: Path) -> subprocess.CompletedProcess:
    """``qpbench ARGS`` in ``cwd`` with ``NUMBA_CACHE_DIR=cache`` (None: as this process has it)."""
    env = dict(os.environ, **({"NUMBA_CACHE_DIR": str(cache)} if cache else {}))
    proc = subprocess.run(
        QPBENCH + args, capture_output=True, text=True, env=env, cwd=cwd, timeout=1200
    )
    assert proc.returncode == 0, proc.stderr
    return proc


@pytest.fixture(scope="module")
def fresh(tmp_path_factory):
    """Two identical simulations, the first in an empty kernel cache; the cache after each."""
    cache = tmp_path_factory.mktemp("numba-cache")
    work = tmp_path_factory.mktemp("runs")
    args = [
        "simulate",
        "--scenario",
        "wall",
        "--backend",
        "daqp",
        "--set",
        "simulation.duration=0.1",
    ]
    runs, files = [], []
    for name in ("first.json", "second.json"):
        proc = _qpbench(args + ["--summary", name], cache, work)
        runs.append((proc, json.loads((work / name).read_text())))
        files.append(_cache_files(cache))
    return runs, files


@pytest.mark.slow
def test_first_run_on_a_fresh_cache_equals_the_next(fresh):
    runs, files = fresh
    (first, a), (second, b) = runs
    # the first run compiled before its clock started, the second only loaded
    assert "kernels: compiled" in first.stderr
    assert "kernels: loaded from the cache" in second.stderr and "(0 compiled)" in second.stderr
    assert files[0] and files[1] == files[0]  # nothing compiled or rewritten by the second run
    # the same trajectory: every figure but the time ones
    assert {k: v for k, v in a.items() if k not in SUMMARY_TIME_KEYS} == {
        k: v for k, v in b.items() if k not in SUMMARY_TIME_KEYS
    }
    assert (
        a["zero_velocity_ticks"] == 0
        and a["time_limit_ticks"] == 0
        and a["deadline_dropped"] is None
    )
    assert (
        a["solve_time_max_s"] < 5.0
    )  # no compile inside the loop (a compile takes tens of seconds)


def jit_kernels() -> tuple[str, ...]:
    from qpbench.jit import KERNELS

    return KERNELS


@pytest.mark.slow
def test_warmup_command_loads_what_the_cache_holds(tmp_path):
    """In the session's cache: the first call compiles what no test has compiled yet, the next
    ones compile nothing (numba's own count of compilations)."""
    cache = os.environ.get("NUMBA_CACHE_DIR")
    _qpbench(["-q", "warmup"], cache, tmp_path)
    for _ in range(2):
        report = json.loads(_qpbench(["warmup", "--json"], cache, tmp_path).stdout)
        assert report["compiled"] == 0 and report["kernels"] == list(jit_kernels())
        assert report["cache"] == cache if cache else report["cache"].endswith("__pycache__")
    proc = _qpbench(["warmup"], cache, tmp_path)
    assert (
        proc.stdout.startswith("kernels: loaded from the cache") and "(0 compiled)" in proc.stdout
    )
    assert _qpbench(["-q", "warmup"], cache, tmp_path).stdout == ""


def test_warmup_twice_in_one_process_does_nothing_more():
    """In process: a warmed process has every kernel; a second call does nothing."""
    from qpbench import jit

    jit.warmup()  # whatever earlier tests in this process prepared, now everything
    again = jit.warmup()
    assert again.in_memory and again.compiled == 0 and again.kernels == jit.KERNELS
    assert "already loaded" in again.line()


def test_warmup_selects_the_kernels_of_the_backends_run():
    """Only what the backends run: no kernel for daqp's bench, the network for rnn, the shim for qpoases."""
    from qpbench.jit import KERNELS, LOOP_KERNELS, SHIM, kernels_for

    assert kernels_for(["daqp", "osqp", "qpsolvers:daqp"], loop=False) == ()
    # a closed loop builds the controller's QPs, and runs daqp's compiled engine
    assert kernels_for(["daqp"]) == (*LOOP_KERNELS, "engine:daqp")
    assert kernels_for(["osqp"]) == LOOP_KERNELS  # no compiled solve: the Python engine
    assert kernels_for(["rnn-tuned"], loop=False) == ("network",)
    assert kernels_for(["pinv", "rnn"]) == (*KERNELS, "engine:pinv", "engine:rnn")
    assert kernels_for(["qpoases"], loop=False) == (SHIM,)
    assert kernels_for(["no-such-backend"], loop=False) == ()
    assert kernels_for(None) == (*KERNELS, SHIM)  # qpbench warmup: everything


def test_bench_of_daqp_compiles_nothing(tmp_path):
    """``qpbench bench --backends daqp`` in an empty kernel cache: no kernel compiled or loaded
    (nothing written to the cache), no shim; the log says so."""
    cache = tmp_path / "kernels"
    cache.mkdir()
    problems = Path(__file__).resolve().parents[1] / "problems" / "wall"
    args = ["bench", str(problems), "--backends", "daqp", "--limit", "3", "--repeat", "1",
            "--out", str(tmp_path / "bench.csv")]  # fmt: skip
    proc = _qpbench(args, cache, tmp_path)
    assert "kernels: none needed by these backends" in proc.stderr
    assert "compiled" not in proc.stderr and "native shim" not in proc.stderr
    assert not any(cache.rglob("*.nbi")) and not any(cache.rglob("*.nbc"))
