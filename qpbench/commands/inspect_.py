"""``qpbench inspect PATH``: what a problem file or folder holds."""

from __future__ import annotations

import argparse
import sys
from collections import Counter

HELP = "show what a problem set, .parquet, .npz, .mat or folder holds (count, sizes, formulation, hash)"
EXAMPLE = "qpbench inspect problems/wall"


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("path", help="problem-set folder, .parquet, .npz, .mat, or a folder of .npz/.mat")


def _range(values: list[int]) -> str:
    lo, hi = min(values), max(values)
    return f"{lo}" if lo == hi else f"{lo}-{hi}"


def _counts(values) -> str:
    c = Counter("-" if v is None else str(v) for v in values)
    return ", ".join(f"{k} ({n})" for k, n in sorted(c.items()))


def run(args: argparse.Namespace) -> int:
    from ..formats import load_problems

    # The hash is checked and reported, not enforced, so a changed set can be inspected.
    ps = load_problems(args.path, verify_hash=False)
    sizes = [r.sizes for r in ps.records]
    print(f"path         {ps.path}")
    print(f"kind         {ps.kind}")
    print(f"problems     {len(ps)}")
    if sizes:
        print(f"n            {_range([s[0] for s in sizes])}")
        print(f"m_eq         {_range([s[1] for s in sizes])}")
        print(f"m_ineq       {_range([s[2] for s in sizes])}")
        bounds = sum(r.problem.lb is not None or r.problem.ub is not None for r in ps.records)
        print(f"with bounds  {bounds}")
        print(f"formulation  {_counts(r.formulation for r in ps.records)}")
        print(f"scenario     {_counts(r.scenario for r in ps.records)}")
        ts = [r.t for r in ps.records if r.t is not None]
        if ts:
            print(f"t [s]        {min(ts):g}-{max(ts):g}")
    if ps.manifest is not None:
        gen = ps.manifest.get("generator")
        print(f"generator    {gen}")
        state = "matches" if ps.hash_ok else "DOES NOT MATCH (file changed after it was written)"
        print(f"sha256       {ps.sha256} ({state} manifest)")
        if ps.manifest.get("count") != len(ps):
            print(f"count        manifest says {ps.manifest.get('count')}, file holds {len(ps)}")
    else:
        print("manifest     none (hash not checked)")
    if ps.hash_ok is False:
        print(
            f"qpbench inspect: error: {ps.files[0]}: key 'sha256': does not match manifest.json",
            file=sys.stderr,
        )
        return 2
    return 0
