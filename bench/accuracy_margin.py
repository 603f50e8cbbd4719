"""What asking solvers for 10x the accuracy they are judged at buys, and what it costs.

qpbench's ``low_accuracy`` and ``default`` profiles ask every backend for
``eps_abs`` ten times below the threshold its success is judged at
(``default``: asked 1e-7, judged 1e-6); ``high_accuracy`` asks for its
threshold (1e-9), as qpbenchmark does (the numbers behind that choice are in
:mod:`qpbench.profiles`). This script runs ``run_bench`` (what ``qpbench bench``
runs) on the same problems twice per profile, once with ``eps_abs`` a tenth of
the threshold (``10x``) and once equal to it (``1x``), everything else equal, and
prints per backend: success %, rows ending at the time limit, the rows that
succeed under one and not the other, and the median and total solve time.

Usage::

    python bench/accuracy_margin.py [--sets problems/free,problems/wall,...] [--every 10]
        [--backends clarabel,osqp,...] [--profiles default,high_accuracy] [--out-dir DIR] [--reference none]
"""

from __future__ import annotations

import argparse
import sys
import tempfile
import time
import warnings
from dataclasses import replace
from pathlib import Path

import pandas as pd

from qpbench.formats import load_problems
from qpbench.harness.bench import BenchConfig, run_bench
from qpbench.profiles import get_profile
from qpbench.reference import reference_solutions
from qpbench.selection import select_set

ROOT = Path(__file__).resolve().parents[1]
DEFAULT_SETS = ",".join(str(ROOT / "problems" / s) for s in ("free", "wall", "adaptive", "narrow"))
DEFAULT_BACKENDS = (
    "clarabel,osqp,proxqp,piqp,daqp,qpsolvers:osqp,qpsolvers:proxqp,qpsolvers:scs,"
    "qpsolvers:clarabel,qpsolvers:piqp"
)


def run(problem_set, references, backends, profile, out: Path) -> pd.DataFrame:
    config = BenchConfig(backends=backends, profile=profile, mode="independent", warmup=True)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        run_bench(problem_set, config, out, force=True, references=references)
    return pd.read_csv(out)


def compare(tight: pd.DataFrame, loose: pd.DataFrame) -> pd.DataFrame:
    m = tight.merge(loose, on=["problem", "backend"], suffixes=("_10x", "_1x"), validate="1:1")
    rows = []
    for backend, g in m.groupby("backend", sort=True):
        s10, s1 = g["success_10x"].astype(bool), g["success_1x"].astype(bool)
        rows.append(
            {
                "backend": backend,
                "rows": len(g),
                "success 10x %": 100.0 * s10.mean(),
                "success 1x %": 100.0 * s1.mean(),
                "only 10x": int((s10 & ~s1).sum()),
                "only 1x": int((s1 & ~s10).sum()),
                "time_limit 10x": int((g["status_10x"] == "time_limit").sum()),
                "time_limit 1x": int((g["status_1x"] == "time_limit").sum()),
                "median us 10x": 1e6 * g["wall_time_min_s_10x"].median(),
                "median us 1x": 1e6 * g["wall_time_min_s_1x"].median(),
                "total s 10x": g["wall_time_min_s_10x"].sum(),
                "total s 1x": g["wall_time_min_s_1x"].sum(),
            }
        )
    return pd.DataFrame(rows)


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument(
        "--sets",
        default=DEFAULT_SETS,
        help="comma-separated problem sets (default: the 4 robot sets)",
    )
    parser.add_argument(
        "--every", type=int, default=10, help="every K-th problem of each set (default 10)"
    )
    parser.add_argument("--backends", default=DEFAULT_BACKENDS)
    parser.add_argument("--profiles", default="default,high_accuracy")
    parser.add_argument(
        "--out-dir", default=None, help="keep the CSVs here (default: a temporary folder)"
    )
    parser.add_argument(
        "--reference",
        choices=("auto", "none"),
        default="auto",
        help="none: no reference solutions (success from the residuals alone)",
    )
    args = parser.parse_args(argv)
    backends = args.backends.split(",")
    started = time.perf_counter()
    with tempfile.TemporaryDirectory() as tmp:
        out_dir = Path(args.out_dir or tmp)
        out_dir.mkdir(parents=True, exist_ok=True)
        for name in args.profiles.split(","):
            shipped = get_profile(name)
            tight = replace(shipped, eps_abs=shipped.tolerance.primal / 10)
            loose = replace(shipped, eps_abs=shipped.tolerance.primal)
            frames = []
            for set_path in args.sets.split(","):
                full = load_problems(set_path)
                problem_set = select_set(full, None, args.every, None)
                references = (
                    reference_solutions(problem_set)
                    if args.reference == "auto"
                    else [None] * len(problem_set.records)
                )
                stem = Path(set_path).name
                t = run(
                    problem_set, references, backends, tight, out_dir / f"{stem}-{name}-10x.csv"
                )
                lo = run(
                    problem_set, references, backends, loose, out_dir / f"{stem}-{name}-1x.csv"
                )
                frames.append((t, lo))
            rows_10x = pd.concat([f[0] for f in frames], ignore_index=True)
            rows_1x = pd.concat([f[1] for f in frames], ignore_index=True)
            table = compare(rows_10x, rows_1x)
            print(
                f"\nprofile {name}: asked eps_abs {tight.eps_abs:g} (10x) vs {loose.eps_abs:g} (1x), "
                f"judged at {shipped.tolerance.primal:g}; sets {args.sets} every {args.every}\n"
            )
            print(table.to_markdown(index=False, floatfmt=".4g"))
            sys.stdout.flush()
    print(f"\n{time.perf_counter() - started:.0f} s")
    return 0


if __name__ == "__main__":
    sys.exit(main())
