"""``qpbench list PROBLEMS``: one line per problem (name, sizes, scenario, tick, time)."""

from __future__ import annotations

import argparse

from .options import add, print_listing

HELP = (
    "list the problems of a set: name, n, equality and inequality rows, bounds, scenario, tick, t"
)
EXAMPLE = "qpbench list problems/wall --limit 5      (qpbench list problems/maros_meszaros --json)"


def add_arguments(parser: argparse.ArgumentParser) -> None:
    add(parser, "path", "--problems", "--every", "--limit")
    add(parser, "--json", help="one JSON object per problem, one per line")


def run(args: argparse.Namespace) -> int:
    from ..formats import load_problems
    from ..formats.records import box_bounds
    from ..selection import select_set

    table = []
    lines = [("name", "n", "m_eq", "m_ineq", "bounds", "scenario", "tick", "t [s]")]
    for r in select_set(load_problems(args.path), args.pattern, args.every, args.limit):
        n, m_eq, m_ineq = r.sizes
        n_box = box_bounds(r.problem)
        table.append(
            dict(name=r.name, n=n, m_eq=m_eq, m_ineq=m_ineq, n_box=n_box, scenario=r.scenario)
            | dict(tick=r.tick, t=r.t, formulation=r.formulation)
        )
        tick = "" if r.tick is None else str(r.tick)
        t = "" if r.t is None else f"{r.t:.3f}"
        lines.append((r.name, *map(str, (n, m_eq, m_ineq, n_box)), r.scenario or "-", tick, t))
    return print_listing(args, table, lines, align="lrrrrl")
