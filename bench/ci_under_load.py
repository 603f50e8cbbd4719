#!/usr/bin/env python3
"""Run ``.ci/run`` on a fresh clone, with an empty compile cache, idle and then under load.

What a new machine and a shared CI runner see:

1. ``git clone`` of this repository (its committed ``HEAD``) into a temporary
   folder, with ``../shared`` linked beside it when it exists here (CI's layout);
2. ``.ci/run`` there without ``NUMBA_CACHE_DIR``, as CI runs it: a fresh clone has
   no kernel compiled, so the suite compiles them into a folder of its session
   (tests/conftest.py); it creates a fresh virtual environment, installs the
   project as README says and runs the test suite;
3. ``.ci/run`` again, in a second fresh clone, while ``--burners`` (default 2)
   other processes each keep a core busy (``python3 -c "while 1: pass"``).

It prints one line per run (exit status, duration, the load average of the
minute before it ended, pytest's last line) and exits non-zero when a run
fails. ``--durations N`` has pytest list the N slowest tests in each run's log
(kept with ``--keep``). It takes two full CI runs.

Usage::

    python bench/ci_under_load.py [--burners 2] [--only idle|load] [--durations N] [--keep]
"""

from __future__ import annotations

import argparse
import os
import shutil
import signal
import subprocess
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]


def fresh_clone(workdir: Path, name: str, shared: Path) -> Path:
    """Clone this repository's HEAD into ``workdir/<name>/main`` with ``shared`` beside it."""
    base = workdir / name
    base.mkdir()
    dest = base / "main"
    subprocess.run(["git", "clone", "--quiet", str(ROOT), str(dest)], check=True)
    if shared.exists():
        (base / "shared").symlink_to(shared)
    return dest


def last_line(text: str) -> str:
    lines = [ln for ln in text.strip().splitlines() if ln.strip()]
    return lines[-1] if lines else ""


def ci_run(clone: Path, log: Path, durations: int) -> tuple[int, float, str]:
    """``.ci/run`` in ``clone`` as CI runs it; (status, seconds, last output line)."""
    env = dict(os.environ, CI="true")
    for name in ("VIRTUAL_ENV", "NUMBA_CACHE_DIR", "PYTHONPATH", "PYTEST_ADDOPTS"):
        env.pop(name, None)
    if durations:
        env["PYTEST_ADDOPTS"] = f"--durations={durations}"
    start = time.perf_counter()
    with open(log, "wb") as fh:
        proc = subprocess.run(
            ["bash", ".ci/run"], cwd=clone, env=env, stdout=fh, stderr=subprocess.STDOUT
        )
    elapsed = time.perf_counter() - start
    return proc.returncode, elapsed, last_line(log.read_text(errors="replace"))


def start_burners(count: int) -> list[subprocess.Popen]:
    return [subprocess.Popen([sys.executable, "-c", "while 1: pass"]) for _ in range(count)]


def stop_burners(procs: list[subprocess.Popen]) -> None:
    for p in procs:
        p.send_signal(signal.SIGKILL)
    for p in procs:
        p.wait()


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument(
        "--burners", type=int, default=2, help="CPU-bound processes beside the loaded run"
    )
    parser.add_argument("--only", choices=("idle", "load"), help="run only one of the two")
    parser.add_argument(
        "--durations", type=int, default=0, help="pytest's N slowest tests in the log"
    )
    parser.add_argument(
        "--shared",
        type=Path,
        default=ROOT.parent / "shared",
        help="the folder linked as ../shared beside each clone (default: the one beside this one)",
    )
    parser.add_argument("--keep", action="store_true", help="keep the temporary clones and logs")
    args = parser.parse_args(argv)

    workdir = Path(tempfile.mkdtemp(prefix="qpbench-ci-"))
    failures = 0
    try:
        runs = [("idle", 0), ("load", args.burners)]
        if args.only:
            runs = [r for r in runs if r[0] == args.only]
        for name, burners in runs:
            clone = fresh_clone(workdir, name, args.shared)
            procs = start_burners(burners)
            try:
                status, elapsed, tail = ci_run(clone, workdir / f"{name}.log", args.durations)
                load = os.getloadavg()[0]
            finally:
                stop_burners(procs)
            failures += status != 0
            print(
                f"{name:>4} ({burners} busy processes beside it): exit {status} in {elapsed:.0f} s"
                f" (load average {load:.1f}); {tail}",
                flush=True,
            )
            if status != 0:
                print(f"     log: {workdir / f'{name}.log'}")
    finally:
        if not args.keep and not failures:
            shutil.rmtree(workdir, ignore_errors=True)
        else:
            print(f"kept: {workdir}")
    return 1 if failures else 0


if __name__ == "__main__":
    sys.exit(main())
