"""``qpbench warmup``: compile (or load from the cache) every numba kernel, and nothing else."""

from __future__ import annotations

import argparse
import json

from .options import add

HELP = "compile every numba kernel into the on-disk cache (or load it from there) and report which"
EXAMPLE = "qpbench warmup    (NUMBA_CACHE_DIR=/tmp/kernels qpbench warmup --json)"


def add_arguments(parser: argparse.ArgumentParser) -> None:
    add(parser, "--json", help="print {compiled, seconds, cache, kernels} as JSON on stdout")


def run(args: argparse.Namespace) -> int:
    from dataclasses import asdict

    from ..jit import warmup

    report = warmup()
    if args.json:
        info = {**asdict(report), "seconds": round(report.seconds, 3)}
        del info["in_memory"]
        print(json.dumps(info))
    elif not args.quiet:
        print(report.line())
    return 0
