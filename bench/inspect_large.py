"""``qpbench inspect`` on every published problem of a folder: wall time and peak memory of each.

Each file is inspected in its own process (``qpbench inspect FILE``, the installed
command's code path), and the process's wall time and peak resident memory
(``ru_maxrss`` of the child) are printed, with the problem's sizes and the
convexity verdict. Targets: under 10 s and under 1 GB per file.

Usage::

    python bench/inspect_large.py [FOLDER] [--limit-s 10] [--limit-gb 1]

FOLDER defaults to ``../shared/data/maros_meszaros_large`` beside the checkout.
Exit status 1 when a file misses a target or ``inspect`` fails.
"""

from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
import time
from pathlib import Path

DEFAULT = Path(__file__).resolve().parents[1].parent / "shared" / "data" / "maros_meszaros_large"


def inspect_one(path: Path) -> tuple[float, float, dict | None, str]:
    """``(wall s, peak RSS GB, inspect's JSON or None, stderr)`` of ``qpbench inspect path --json``."""
    code = "import sys; from qpbench.cli import main; sys.exit(main(sys.argv[1:]))"
    start = time.perf_counter()
    proc = subprocess.Popen(
        [sys.executable, "-c", code, "inspect", str(path), "--json"],
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
    )
    _, status, usage = os.wait4(proc.pid, 0)
    wall = time.perf_counter() - start
    out, err = proc.stdout.read(), proc.stderr.read()
    info = json.loads(out) if os.waitstatus_to_exitcode(status) == 0 else None
    return wall, usage.ru_maxrss / 1e6, info, err.strip()  # ru_maxrss in kB on Linux


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("folder", nargs="?", default=str(DEFAULT))
    parser.add_argument("--limit-s", type=float, default=10.0)
    parser.add_argument("--limit-gb", type=float, default=1.0)
    args = parser.parse_args()
    files = sorted(Path(args.folder).glob("*.mat"))
    if not files:
        print(f"no .mat file in {args.folder}", file=sys.stderr)
        return 2
    print(
        f"{'problem':<10} {'n':>7} {'m_eq':>6} {'m_ineq':>7} {'nnz':>8} {'convexity':<10} "
        f"{'wall [s]':>8} {'peak RSS [GB]':>13}"
    )
    worst_s = worst_gb = 0.0
    bad = []
    for f in files:
        wall, rss, info, err = inspect_one(f)
        worst_s, worst_gb = max(worst_s, wall), max(worst_gb, rss)
        if info is None:
            bad.append(f"{f.name}: {err.splitlines()[-1] if err else 'failed'}")
            print(
                f"{f.stem:<10} {'-':>7} {'-':>6} {'-':>7} {'-':>8} {'FAILED':<10} {wall:8.2f} {rss:13.3f}"
            )
            continue
        verdict = ",".join(info["convexity"])
        print(
            f"{f.stem:<10} {info['n'][0]:>7} {info['m_eq'][0]:>6} {info['m_ineq'][0]:>7} {info['nnz'][0]:>8} "
            f"{verdict:<10} {wall:8.2f} {rss:13.3f}",
            flush=True,
        )
        if wall > args.limit_s or rss > args.limit_gb:
            bad.append(f"{f.name}: {wall:.2f} s, {rss:.3f} GB")
    print(
        f"{len(files)} files; slowest {worst_s:.2f} s (target {args.limit_s:g} s), "
        f"largest peak RSS {worst_gb:.3f} GB (target {args.limit_gb:g} GB); "
        f"load average {os.getloadavg()[0]:.2f}"
    )
    for line in bad:
        print(f"MISSED: {line}")
    return 1 if bad else 0


if __name__ == "__main__":
    sys.exit(main())
