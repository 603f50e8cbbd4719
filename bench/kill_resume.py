#!/usr/bin/env python3
"""Kill ``qpbench bench`` with SIGKILL at random moments, resume it, and count lost and duplicated rows.

1. An uninterrupted run writes ``full.csv``.
2. An interrupted run starts ``qpbench bench`` on ``cut.csv``, kills it with
   SIGKILL after a random delay, restarts it with ``--resume``, and so on
   ``--kills`` times; a last ``--resume`` runs to the end.
3. The rows are compared by key ``(problem, backend, profile)``: rows of
   ``full.csv`` missing from ``cut.csv`` are lost, keys present more than once
   are duplicated (both must be 0). Rows whose non-timing columns differ are
   counted too, beside the count between two uninterrupted runs (solver noise:
   a backend whose iteration count varies from run to run differs there too).

Usage::

    python bench/kill_resume.py [--problems problems/wall] [--backends LIST]
                                [--kills 8] [--limit N] [--seed 0]

Exit status 0 when no row is lost, duplicated or foreign, 1 otherwise.
"""

from __future__ import annotations

import argparse
import collections
import csv
import random
import subprocess
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
DEFAULT_BACKENDS = "clarabel,osqp,proxqp,pinv,qpsolvers:daqp,qpsolvers:quadprog,qpsolvers:piqp,rnn"
TIMING = {"wall_time_min_s", "wall_time_median_s", "solver_time_s", "isolated"}


def pick_problems(arg: str | None, limit: int, workdir: Path) -> Path:
    """The problem set to run: ``arg``, else problems/wall, else the Maros-Meszaros subset.

    With ``limit`` > 0, the first ``limit`` records are copied into a new set in ``workdir``.
    """
    candidates = (
        [Path(arg)] if arg else [ROOT / "problems" / "wall", ROOT / "problems" / "maros_meszaros"]
    )
    path = next((p for p in candidates if p.exists()), None)
    if path is None:
        sys.exit(f"no problem set found among {', '.join(map(str, candidates))}")
    if limit <= 0:
        return path
    from qpbench.formats import load_problems, write_problem_set

    pset = load_problems(path)
    if len(pset) <= limit:
        return path
    out = workdir / f"{path.name}-first{limit}"
    write_problem_set(
        out,
        pset.records[:limit],
        generator={"name": "kill_resume", "source": str(path), "limit": limit},
    )
    return out


def command(problems: Path, backends: str, out: Path, resume: bool) -> list[str]:
    cmd = [
        sys.executable,
        "-m",
        "qpbench.cli",
        "-q",
        "bench",
        str(problems),
        "--backends",
        backends,
        "--out",
        str(out),
    ]
    return cmd + (["--resume"] if resume else [])


def read_rows(path: Path) -> list[dict]:
    with open(path, newline="") as fh:
        return list(csv.DictReader(fh))


def key(row: dict) -> tuple:
    return (row["problem"], row["backend"], row["profile"])


def differing(rows_a: list[dict], rows_b: list[dict]) -> list[tuple[tuple, dict]]:
    """``(key, {column: (a, b)})`` for rows of the same key whose non-timing columns differ."""
    b = {key(r): r for r in rows_b}
    out = []
    for ra in rows_a:
        rb = b.get(key(ra))
        if rb is None:
            continue
        diff = {c: (ra[c], rb[c]) for c in ra if c not in TIMING and ra[c] != rb[c]}
        if diff:
            out.append((key(ra), diff))
    return out


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument(
        "--problems", help="problem set (default: problems/wall, else problems/maros_meszaros)"
    )
    parser.add_argument("--backends", default=DEFAULT_BACKENDS)
    parser.add_argument("--kills", type=int, default=8, help="number of SIGKILLs (default 8)")
    parser.add_argument(
        "--limit", type=int, default=0, help="use the first N problems (default 0: all)"
    )
    parser.add_argument("--seed", type=int, default=0)
    args = parser.parse_args()
    rng = random.Random(args.seed)

    with tempfile.TemporaryDirectory(prefix="kill_resume-") as tmp:
        tmp = Path(tmp)
        problems = pick_problems(args.problems, args.limit, tmp)
        full, again, cut = tmp / "full.csv", tmp / "again.csv", tmp / "cut.csv"

        # Two uninterrupted runs: the first also fills the reference cache, the second
        # gives the duration and, compared with the first, the run-to-run noise.
        first = subprocess.run(
            command(problems, args.backends, again, False), capture_output=True, text=True
        )
        if first.returncode not in (0, 1):
            print(first.stderr, file=sys.stderr)
            return 2
        start = time.perf_counter()
        done = subprocess.run(
            command(problems, args.backends, full, False), capture_output=True, text=True
        )
        duration = time.perf_counter() - start
        print(f"problems: {problems} ; backends: {args.backends}")
        print(
            f"uninterrupted run: {len(read_rows(full))} rows in {duration:.1f} s (exit {done.returncode})"
        )
        noise = differing(read_rows(full), read_rows(again))
        print(f"rows differing outside timing columns between two uninterrupted runs: {len(noise)}")

        # Even kills when the CSV has grown by a random fraction of what is left (certainly
        # mid-run), odd kills at a random time (start-up, replay or solving).
        kills = []
        total_bytes = full.stat().st_size
        for k in range(args.kills):
            proc = subprocess.Popen(
                command(problems, args.backends, cut, resume=cut.exists()),
                stdout=subprocess.DEVNULL,
                stderr=subprocess.DEVNULL,
            )
            size0 = cut.stat().st_size if cut.exists() else 0
            if k % 2 == 1:
                how = f"{rng.uniform(0.05, 0.7) * duration:.2f} s"
                deadline = time.perf_counter() + float(how.split()[0])
                target = None
            else:
                target = size0 + rng.uniform(0.05, 0.6) * (total_bytes - size0)
                how = f"{(target - size0) / 1e3:.0f} kB more output"
                deadline = time.perf_counter() + 10 * duration
            while proc.poll() is None and time.perf_counter() < deadline:
                if target is not None and cut.exists() and cut.stat().st_size >= target:
                    break
                time.sleep(0.005)
            if proc.poll() is not None:
                kills.append(f"{how}: finished before the kill")
                break
            proc.kill()  # SIGKILL
            proc.wait()
            rows = len(read_rows(cut)) if cut.exists() else 0
            size = cut.stat().st_size if cut.exists() else 0
            tail = (
                ""
                if not size
                else (
                    "ends mid-line" if not cut.read_bytes().endswith(b"\n") else "ends on a newline"
                )
            )
            kills.append(f"{how}: {rows} complete rows on disk, {tail}".rstrip(", "))
        final = subprocess.run(
            command(problems, args.backends, cut, resume=cut.exists()),
            capture_output=True,
            text=True,
        )
        for line in kills:
            print(f"  SIGKILL after {line}")
        if final.returncode not in (0, 1):
            print(final.stderr, file=sys.stderr)
            return 2
        warnings = [
            ln for ln in final.stderr.splitlines() if "half-written" in ln or "malformed" in ln
        ]
        for ln in warnings:
            print(f"  last resume: {ln}")

        ref_rows, got_rows = read_rows(full), read_rows(cut)
        ref = {key(r): r for r in ref_rows}
        counts = collections.Counter(key(r) for r in got_rows)
        lost = sum(1 for k in ref if k not in counts)
        duplicated = sum(c - 1 for c in counts.values() if c > 1)
        extra = sum(1 for k in counts if k not in ref)
        differ = differing(ref_rows, got_rows)
        print(f"final rows: {len(got_rows)} (uninterrupted: {len(ref_rows)})")
        print(f"rows lost: {lost}")
        print(f"rows duplicated: {duplicated}")
        print(f"rows not in the uninterrupted run: {extra}")
        print(
            f"rows differing outside timing columns: {len(differ)} (between two uninterrupted runs: {len(noise)})"
        )
        by_backend = collections.Counter(k[1] for k, _ in differ)
        for backend, count in sorted(by_backend.items()):
            columns = sorted({c for k, d in differ if k[1] == backend for c in d})
            print(f"  {backend}: {count} rows differ in {', '.join(columns)}")
        return 0 if lost == duplicated == extra == 0 else 1


if __name__ == "__main__":
    sys.exit(main())
