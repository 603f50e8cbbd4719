"""``qpbench inspect PATH``: what a problem file or folder holds."""

from __future__ import annotations

import argparse
import json
import sys
from collections import Counter

HELP = "show what a problem set, .parquet, .npz, .mat or folder holds (count, sizes, formulation, hash)"
EXAMPLE = "qpbench inspect problems/wall    (qpbench inspect problems/wall --json)"


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("path", help="problem-set folder, .parquet, .npz, .mat, or a folder of .npz/.mat")
    parser.add_argument("--json", action="store_true", help="print one JSON object instead of the table")


def _range(values: list[int]) -> str:
    lo, hi = min(values), max(values)
    return f"{lo}" if lo == hi else f"{lo}-{hi}"


def _counts(values) -> str:
    c = Counter("-" if v is None else str(v) for v in values)
    return ", ".join(f"{k} ({n})" for k, n in sorted(c.items()))


def describe(ps, sizes) -> dict:
    """What the table shows, as a JSON-able dict (ranges as ``[min, max]``)."""

    def span(values):
        return [min(values), max(values)] if values else None

    ts = [r.t for r in ps.records if r.t is not None]
    return {
        "path": str(ps.path),
        "kind": ps.kind,
        "problems": len(ps),
        "n": span([s[0] for s in sizes]),
        "m_eq": span([s[1] for s in sizes]),
        "m_ineq": span([s[2] for s in sizes]),
        "with_bounds": sum(r.problem.lb is not None or r.problem.ub is not None for r in ps.records),
        "formulation": dict(Counter("-" if r.formulation is None else r.formulation for r in ps.records)),
        "scenario": dict(Counter("-" if r.scenario is None else r.scenario for r in ps.records)),
        "t": span(ts),
        "generator": (ps.manifest or {}).get("generator"),
        "sha256": ps.sha256,
        "hash_ok": ps.hash_ok,
        "manifest_count": (ps.manifest or {}).get("count"),
    }


def run(args: argparse.Namespace) -> int:
    from ..formats import load_problems

    # The hash is checked and reported, not enforced, so a changed set can be inspected.
    ps = load_problems(args.path, verify_hash=False)
    sizes = [r.sizes for r in ps.records]
    if args.json:
        print(json.dumps(describe(ps, sizes), indent=2))
        return 2 if ps.hash_ok is False else 0
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
        gen = ps.manifest.get("generator") or {}
        print(f"generator    {', '.join(f'{k}={v}' for k, v in gen.items()) or '-'}")
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
