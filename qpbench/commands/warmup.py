"""``qpbench warmup``: compile (or load from the cache) every numba kernel, and nothing else.

The commands that solve prepare their backends' kernels themselves; this prepares all of them
ahead (after an install, in a CI image) and says whether the cache already held them.
"""

from __future__ import annotations

import argparse
import json

from .options import add

HELP = "compile every numba kernel into the on-disk cache (or load it from there) and report which"
EXAMPLE = "qpbench warmup    (NUMBA_CACHE_DIR=/tmp/kernels qpbench warmup --json)"


def add_arguments(parser: argparse.ArgumentParser) -> None:
    add(parser, "--json", help="print {compiled, seconds, cache, kernels} as JSON on stdout")


def run(args: argparse.Namespace) -> int:
    from ..jit import warmup

    report = warmup()
    if args.json:
        print(
            json.dumps(
                {
                    "compiled": report.compiled,
                    "seconds": round(report.seconds, 3),
                    "cache": report.cache,
                    "kernels": list(report.kernels),
                    "shims_compiled": report.shims_compiled,
                }
            )
        )
    elif not args.quiet:
        print(report.line())
    return 0
