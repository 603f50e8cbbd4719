"""``qpbench scenarios``: the shipped scenario files; ``show NAME [--filled]`` prints one."""

from __future__ import annotations

import argparse
import json

from .options import add, print_listing

HELP = "list the shipped scenarios; 'show NAME' prints one's TOML file to start your own from"
EXAMPLE = (
    "qpbench scenarios    (qpbench scenarios show wall > my.toml; "
    "qpbench scenarios show my.toml --filled; qpbench scenarios --json)"
)


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument(
        "action", nargs="?", default="list", metavar="list|show", help="list (default) or show one"
    )
    parser.add_argument(
        "name",
        nargs="?",
        metavar="NAME",
        help="the scenario to show (a shipped name or a .toml path)",
    )
    add(parser, "--json", help="JSON: one object per scenario, or the file's tables")
    parser.add_argument(
        "--filled",
        action="store_true",
        help="show: every table and key, the defaults of those the file leaves out filled in",
    )


def _show(name: str, as_json: bool, fill: bool) -> None:
    """Print scenario ``name`` (shipped name or file) as its TOML file (a file that loads), or
    ``fill``: with every default filled in; ``as_json``: its tables as JSON."""
    import tomllib

    from ..sim.scenario import load_scenario
    from ..sim.scenario_schema import filled
    from ..sweep.toml_text import dumps

    sc = load_scenario(name)
    text = sc.source
    if fill:
        header = (
            f"Scenario {sc.name!r} ({name}) with every default filled in: the file as it is run.\n"
            "Keys, units and defaults: qpbench.sim.scenario_schema; why these thresholds: "
            "docs/verdicts.md."
        )
        text = dumps(filled(sc.spec), header=header)
    if as_json:
        print(json.dumps(tomllib.loads(text), indent=2))
    else:
        print(text, end="" if text.endswith("\n") else "\n")


def run(args: argparse.Namespace) -> int:
    from ..exceptions import ParamError
    from ..sim.scenario import load_scenario, scenario_names

    stray = (
        args.action if args.action not in ("list", "show") else args.action == "list" and args.name
    )
    if stray:
        raise ParamError(
            f"unexpected '{stray}' (list, or show NAME; did you mean: qpbench scenarios show "
            f"{stray}?)",
            key="NAME",
        )
    if args.action == "show":
        if not args.name:
            raise ParamError("which scenario? (qpbench scenarios show NAME)", key="NAME")
        _show(args.name, args.json, args.filled)
        return 0
    listing = []
    rows = [("name", "paper", "duration", "obstacles", "description")]
    for sc in map(load_scenario, scenario_names()):
        section = sc.spec.scenario.paper_section
        obstacles = [o.name for o in sc.spec.obstacles]
        listing.append(
            dict(name=sc.name, paper_section=section, in_paper=sc.in_paper, duration_s=sc.duration)
            | dict(obstacles=obstacles, description=sc.description)
        )
        duration = f"{sc.duration:g} s"
        rows.append((sc.name, section, duration, ", ".join(obstacles) or "none", sc.description))
    return print_listing(args, listing, rows, align="llll", free_last=True)
