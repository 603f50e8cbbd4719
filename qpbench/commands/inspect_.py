"""``qpbench inspect PATH``: what a problem file or folder holds."""

from __future__ import annotations

import argparse
import json
from collections import Counter
from typing import TYPE_CHECKING

from .options import add

if TYPE_CHECKING:
    from ..formats import ProblemSet

HELP = "show what a problem set, .parquet, .npz, .mat or folder holds (count, sizes, formulation, hash)"
EXAMPLE = "qpbench inspect problems/wall    (qpbench inspect problems/wall --json)"


def add_arguments(parser: argparse.ArgumentParser) -> None:
    add(parser, "path")
    add(parser, "--json", help="print one JSON object instead of the table")
    add(parser, "--memory-budget")


def _counts(counts: dict) -> str:
    return ", ".join(f"{k} ({n})" for k, n in sorted(counts.items()))


def _notes(ps, budget: int) -> list[str]:
    """One line per problem a bench would warn about or skip for every backend (the memory a
    sparse solver needs, the least any backend needs, over ``budget`` [bytes])."""
    from ..memory import skip_reason

    out = []
    for r in ps.records:
        conv = r.convexity
        if conv is not None and (conv.skip_reason or conv.warning):
            kind = "skipped" if conv.skip_reason else "warning"
            out.append(f"{r.name}: {kind}: {conv.skip_reason or conv.warning}")
        why = skip_reason(r.problem, True, budget)
        if why is not None:
            out.append(f"{r.name}: skipped: {why} (every backend)")
    return out


def describe(ps: ProblemSet, budget: int) -> dict:
    """What the table shows, as a JSON-able dict (ranges as ``[min, max]``)."""
    from ..memory import nnz

    def span(values):
        return [min(values), max(values)] if values else None

    def count(values):
        return dict(Counter("-" if v is None else v for v in values))

    return {
        "path": str(ps.path),
        "kind": ps.kind,
        "problems": len(ps),
        **{
            k: span([r.sizes[i] for r in ps.records]) for i, k in enumerate(("n", "m_eq", "m_ineq"))
        },
        "nnz": span([sum(map(nnz, (r.problem.P, r.problem.G, r.problem.A))) for r in ps.records]),
        "sparse": sum(hasattr(r.problem.P, "nnz") for r in ps.records),
        "convexity": count(r.convexity and r.convexity.verdict for r in ps.records),
        "notes": _notes(ps, budget),
        "with_bounds": sum(
            r.problem.lb is not None or r.problem.ub is not None for r in ps.records
        ),
        "formulation": count(r.formulation for r in ps.records),
        "scenario": count(r.scenario for r in ps.records),
        "t": span([r.t for r in ps.records if r.t is not None]),
        "generator": (ps.manifest or {}).get("generator"),
        "sha256": ps.sha256,
        "hash_ok": ps.hash_ok,
        "manifest_count": (ps.manifest or {}).get("count"),
    }


def _print_table(ps, info: dict) -> None:
    lines = [("path", ps.path), ("kind", ps.kind), ("problems", len(ps))]
    if len(ps):
        spans = {k: info[k] for k in ("n", "m_eq", "m_ineq", "nnz")}
        lines += [(k, f"{lo}" + ("" if lo == hi else f"-{hi}")) for k, (lo, hi) in spans.items()]
        lines += [("sparse P", info["sparse"]), ("convexity", _counts(info["convexity"]))]
        lines += [("with bounds", info["with_bounds"])]
        lines += [(k, _counts(info[k])) for k in ("formulation", "scenario")]
        if info["t"]:
            lines.append(("t [s]", f"{info['t'][0]:g}-{info['t'][1]:g}"))
        lines += [("note", line) for line in info["notes"]]
    if ps.manifest is not None:
        gen = info["generator"] or {}
        lines.append(("generator", ", ".join(f"{k}={v}" for k, v in gen.items()) or "-"))
        state = "matches" if ps.hash_ok else "DOES NOT MATCH (file changed after it was written)"
        lines.append(("sha256", f"{ps.sha256} ({state} manifest)"))
        count = info["manifest_count"]
        if count != len(ps):
            lines.append(("count", f"manifest says {count}, file holds {len(ps)}"))
    else:
        lines.append(("manifest", "none (hash not checked)"))
    for label, value in lines:
        print(f"{label:<12} {value}")


def run(args: argparse.Namespace) -> int:
    from ..exceptions import InputError
    from ..formats import load_problems
    from ..memory import resolve_budget

    budget = resolve_budget(args.memory_budget)
    # The hash is checked and reported, not enforced, so a changed set can be inspected.
    ps = load_problems(args.path, verify_hash=False)
    info = describe(ps, budget)
    if args.json:
        print(json.dumps(info, indent=2))
    else:
        _print_table(ps, info)
    if ps.hash_ok is False:
        raise InputError("does not match manifest.json", path=ps.files[0], key="sha256")
    return 0
