"""Options several commands take, one definition each, and what commands share: the exit code
(:func:`strict_exit`), progress bars and plain-text tables (:func:`aligned`)."""

from __future__ import annotations

import argparse
import logging
import sys
from contextlib import contextmanager
from pathlib import Path

from ..memory import DEFAULT_FRACTION
from ..statuses import FORMULATIONS

log = logging.getLogger("qpbench")

#: Flag -> ``add_argument`` keywords of the options several commands take.
SHARED: dict[str, dict] = {
    "path": {
        "metavar": "PROBLEMS",
        "help": "problem-set folder, qpbenchmark .parquet, .npz or .mat file, or a folder of them",
    },
    "--out": {"required": True, "metavar": "DIR"},
    "--backends": {"help": "comma-separated backend names, or 'all' (every available backend)"},
    "--duration": {
        "type": float,
        "metavar": "S",
        "help": "simulated time in [s] (default: the scenario's)",
    },
    "--formulation": {
        "default": "paper",
        "choices": FORMULATIONS,
        "help": "the per-tick QP: paper (hard task equality, eq. 11) or soft (task as a weighted "
        "cost) (default: paper)",
    },
    "--deadline": {
        "type": float,
        "metavar": "SECONDS",
        "help": "per-tick deadline in [s]: a later answer is dropped (status time_limit; soft "
        "fallback, else zero velocity), as a real-time controller would, and the run depends on "
        "the machine's speed (default: none, every answer is applied; deadline_misses counts "
        "ticks slower than dt)",
    },
    "--engine": {
        "default": "compiled",
        "choices": ("compiled", "python"),
        "help": "compiled: each run in one compiled function, the solver called as a C controller "
        "calls it, for the backends that have a compiled solve (the others, and python: the "
        "Python loop; the row's engine column says which ran) (default: compiled)",
    },
    "--isolate": {"default": "auto", "choices": ("auto", "always", "never")},
    "--jobs": {"type": int, "metavar": "N"},
    "--run-budget": {"type": float, "metavar": "S"},
    "--profile": {"default": "default", "help": "settings profile (default: default)"},
    "--set": {
        "action": "append",
        "default": [],
        "metavar": "KEY=VALUE",
        "dest": "overrides",
        "help": "set a scenario value over the file's (repeatable): TABLE.KEY=VALUE or "
        "obstacles[i].KEY=VALUE, VALUE in TOML syntax (a bare word is a string), e.g. "
        "--set rnn.eps=0.001 --set key_points.kind=closest",
    },
    "--json": {"action": "store_true"},
    "--force": {"action": "store_true"},
    "--strict": {
        "action": "store_true",
        "help": "exit 1 when a run's verdict is not ok, a run was not real time or a solve "
        "failed, with one line saying why (for CI); without it the exit code is 0 once the "
        "outputs are written, whatever the verdicts",
    },
    # which problems of a set (qpbench.selection)
    "--problems": {
        "dest": "pattern",
        "metavar": "PATTERN",
        "help": "keep problems whose name matches a shell-style pattern (comma-separated patterns)",
    },
    "--every": {"type": int, "metavar": "K", "help": "keep every K-th problem"},
    "--limit": {"type": int, "metavar": "N", "help": "keep the first N problems"},
    "--min-ok-bound": {
        "type": float,
        "default": 0.95,
        "metavar": "P",
        "help": "recommend a backend only when, in every scenario with perturbed runs, the "
        "Wilson lower bound (95 %% interval) of its share of ok runs is at least P (default: "
        "0.95: at least 73 perturbed runs a scenario, all ok; 0.99: 381)",
    },
    "--memory-budget": {
        "metavar": "SIZE",
        "help": "bytes a step may allocate, e.g. 2GB, 512MB, 1.5GiB (default: "
        f"{DEFAULT_FRACTION * 100:.0f}%% of the machine's memory, within ulimit -v); a problem "
        "that needs more is a 'skipped' row saying so",
    },
}


def add(parser: argparse.ArgumentParser, *flags: str, **kw) -> None:
    """Add the shared options ``flags``, ``kw`` (a command's own help...) over their keywords."""
    for flag in flags:
        parser.add_argument(flag, **{**SHARED[flag], **kw})


def pick(args: argparse.Namespace, names: str) -> dict:
    """The options ``names`` (space-separated destinations) as keyword arguments."""
    return {name: getattr(args, name) for name in names.split()}


def add_force_resume(parser: argparse.ArgumentParser, force: str, resume: str) -> None:
    """``--force`` or ``--resume`` (not both), with the command's help texts, and ``--strict``."""
    group = parser.add_mutually_exclusive_group()
    group.add_argument("--force", action="store_true", help=force)
    group.add_argument("--resume", action="store_true", help=resume)
    add(parser, "--strict")


def check_tables(folder, names, args: argparse.Namespace, key: str = "out") -> None:
    """Output folder ``folder`` may exist, its files ``names`` only with ``--force``/``--resume``."""
    from ..atomic import check_folder, check_output

    check_folder(folder, key=key)
    for name in names if Path(folder).exists() else ():
        check_output(Path(folder) / name, force=args.force, resume=getattr(args, "resume", None))


def strict_exit(
    args: argparse.Namespace,
    *,
    runs=None,
    failed_solves: int = 0,
    recommend: bool = False,
    sweeps=None,
) -> int:
    """0 once the outputs are written; with ``--strict``, 1 when ``runs`` or ``failed_solves``
    fall short (one line on stderr). ``recommend``: then print the recommendation."""
    from ..report import recommend as rec

    found = rec.shortfalls(runs, failed_solves) if getattr(args, "strict", False) else None
    if found:
        print(f"qpbench {args.command}: --strict: {'; '.join(found)}", file=sys.stderr)
    if recommend and not args.quiet:
        bound = getattr(args, "min_ok_bound", rec.MIN_OK_BOUND)
        print(rec.render(rec.recommend(runs, sweeps, bound)), end="")
    return 1 if found else 0


@contextmanager
def run_bar(args: argparse.Namespace, total: int, desc: str, on_row, leave: bool = True):
    """A progress bar of ``total`` runs (none with ``-q``) around the runner's ``on_row``."""
    from tqdm import tqdm

    with tqdm(total=total, unit="run", desc=desc, leave=leave, disable=args.quiet or None) as bar:
        yield lambda row: (bar.update(1), on_row(row))


def print_listing(args: argparse.Namespace, items: list[dict], rows: list, **kw) -> int:
    """``items`` as JSON lines with ``--json``, else ``rows`` aligned; 0."""
    import json

    from ..report.markdown_table import aligned

    for line in [json.dumps(item) for item in items] if args.json else [aligned(rows, **kw)]:
        print(line)
    return 0
