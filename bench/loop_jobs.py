"""Closed-loop runs one at a time against two side by side: do their per-tick solve times differ?

``qpbench run`` runs its closed loops two at a time on a machine with two cores or
more (``--jobs``, :data:`qpbench.harness.pipeline.LOOP_JOBS`). This script runs the
same closed loops with ``qpbench closed-loop --jobs 1`` and ``--jobs 2`` (every run
in a worker process of its own, as in ``qpbench run``), ``--passes`` times each,
alternating, and prints per run the median over passes of each backend's per-tick
solve time (p50 and p99, the figures the real-time verdict reads) and the ratio of
side by side to one at a time. The load average is printed with the figures.

    python bench/loop_jobs.py [--scenarios wall,narrow] [--backends daqp,qpoases,...]
        [--passes 2]
"""

from __future__ import annotations

import argparse
import os
import subprocess
import sys
import tempfile
from pathlib import Path

import pandas as pd

BACKENDS = "daqp,qpoases,osqp,proxqp,piqp,clarabel"
FIGURES = ("solve_time_median_s", "solve_time_p99_s")


def closed_loop(scenarios: str, backends: str, jobs: int, out: Path) -> pd.DataFrame:
    """One ``qpbench closed-loop`` call; its table indexed by (scenario, backend)."""
    cmd = [sys.executable, "-m", "qpbench.cli", "-q", "closed-loop", "--scenarios", scenarios]
    cmd += ["--backends", backends, "--jobs", str(jobs), "--out", str(out), "--force"]
    subprocess.run(cmd, check=True)
    return pd.read_csv(out / "closed_loop.csv").set_index(["scenario", "backend"])[list(FIGURES)]


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--scenarios", default="wall,narrow")
    parser.add_argument("--backends", default=BACKENDS)
    parser.add_argument("--passes", type=int, default=2)
    args = parser.parse_args()
    runs: dict[int, list[pd.DataFrame]] = {1: [], 2: []}
    with tempfile.TemporaryDirectory() as tmp:
        for k in range(args.passes):
            for jobs in (1, 2) if k % 2 == 0 else (2, 1):
                out = Path(tmp) / f"j{jobs}-{k}"
                runs[jobs].append(closed_loop(args.scenarios, args.backends, jobs, out))
    med = {j: pd.concat(frames).groupby(level=[0, 1]).median() for j, frames in runs.items()}
    table = pd.DataFrame(index=med[1].index)
    for fig in FIGURES:
        short = fig.removeprefix("solve_time_").removesuffix("_s")
        table[f"{short} one [us]"] = (med[1][fig] * 1e6).round(1)
        table[f"{short} two [us]"] = (med[2][fig] * 1e6).round(1)
        table[f"{short} ratio"] = (med[2][fig] / med[1][fig]).round(3)
    print(f"load average {' '.join(f'{x:.2f}' for x in os.getloadavg())}; {args.passes} passes")
    print(table.to_string())
    for fig in FIGURES:
        short = fig.removeprefix("solve_time_").removesuffix("_s")
        ratio = table[f"{short} ratio"]
        print(
            f"{short}: median ratio {ratio.median():.3f} (min {ratio.min():.3f}, max {ratio.max():.3f})"
        )


if __name__ == "__main__":
    main()
