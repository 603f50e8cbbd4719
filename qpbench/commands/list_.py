"""``qpbench list PROBLEMS``: one line per problem (name, sizes, scenario, tick, time)."""

from __future__ import annotations

import argparse
import json
from typing import TYPE_CHECKING

from .options import add

if TYPE_CHECKING:
    from ..formats import ProblemRecord

HELP = (
    "list the problems of a set: name, n, equality and inequality rows, bounds, scenario, tick, t"
)
EXAMPLE = "qpbench list problems/wall --limit 5      (qpbench list problems/maros_meszaros --json)"


def add_arguments(parser: argparse.ArgumentParser) -> None:
    add(parser, "path")
    add(parser, "--problems", "--every", "--limit")
    add(parser, "--json", help="one JSON object per problem, one per line")


def rows(records: list[ProblemRecord]) -> list[dict]:
    out = []
    for r in records:
        n, m_eq, m_ineq = r.sizes
        p = r.problem
        n_box = sum(int((x is not None) and (abs(x) < float("inf")).sum()) for x in (p.lb, p.ub))
        out.append(
            {
                "name": r.name,
                "n": n,
                "m_eq": m_eq,
                "m_ineq": m_ineq,
                "n_box": n_box,
                "scenario": r.scenario,
                "tick": r.tick,
                "t": r.t,
                "formulation": r.formulation,
            }
        )
    return out


def run(args: argparse.Namespace) -> int:
    from ..formats import load_problems
    from ..selection import select_records

    ps = load_problems(args.path)
    table = rows(select_records(ps.records, args.pattern, args.every, args.limit))
    if args.json:
        for row in table:
            print(json.dumps(row))
        return 0
    width = max([len("name")] + [len(r["name"]) for r in table])
    print(
        f"{'name':<{width}}  {'n':>6} {'m_eq':>6} {'m_ineq':>6} {'bounds':>6}  scenario  {'tick':>6} {'t [s]':>8}"
    )
    for r in table:
        t = "" if r["t"] is None else f"{r['t']:.3f}"
        tick = "" if r["tick"] is None else str(r["tick"])
        print(
            f"{r['name']:<{width}}  {r['n']:>6} {r['m_eq']:>6} {r['m_ineq']:>6} {r['n_box']:>6}  "
            f"{r['scenario'] or '-':<8}  {tick:>6} {t:>8}"
        )
    return 0
