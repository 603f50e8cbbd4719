"""The ``qpbench`` command line: argument parsing, logging set-up, plugins and exit codes.

Each sub-command is a module of :mod:`qpbench.commands` with ``HELP`` (one line), ``EXAMPLE``
(shown under ``--help``), ``add_arguments(parser)`` and ``run(args) -> int``. Exit codes:
``docs/exit-codes.md``.
"""

from __future__ import annotations

import argparse
import importlib
import logging
import os
import sys

from . import __version__
from .exceptions import QpbenchError

#: Sub-command name -> module under qpbench.commands (``inspect_``, ``list_``: not builtins).
COMMANDS = {
    name: name.replace("-", "_") + ("_" if name in ("inspect", "list") else "")
    for name in (
        "run bench closed-loop simulate sweep report backends scenarios inspect list export "
        "warmup scaling"
    ).split()
}

#: Shown at the end of ``qpbench --help``.
EXAMPLES = """examples:
  qpbench run                                    the main job: every backend, per tick and in the loop, into results/
  qpbench bench problems/wall --backends daqp,osqp,rnn --out wall.csv
  qpbench simulate --scenario narrow --backend daqp --summary narrow.json --snapshot narrow.png

every command has --help with an example; exit codes: 0 done (whatever the verdicts), 1 simulate's
verdict not ok or, with --strict, a run or solve that did not pass, 2 bad input"""

log = logging.getLogger("qpbench")


def _available_commands():
    """``(name, module)`` of each sub-command."""
    for name, module in COMMANDS.items():
        yield name, importlib.import_module(f"qpbench.commands.{module}")


def build_parser() -> argparse.ArgumentParser:
    """The full argument parser (used by :func:`main` and by the tests)."""
    # The flags are accepted before and after the sub-command; SUPPRESS keeps the
    # sub-parser from resetting a value given before it (``qpbench -q simulate``).
    common = argparse.ArgumentParser(add_help=False)
    verbosity = common.add_mutually_exclusive_group()
    verbosity.add_argument(
        "-q", "--quiet", action="store_true", default=argparse.SUPPRESS, help="only errors"
    )
    verbosity.add_argument(
        "-v",
        "--verbose",
        action="count",
        default=argparse.SUPPRESS,
        help="-v: the run's settings, each backend's version and settings, and the solvers' own output; "
        "-vv: also one line per solve",
    )
    parser = argparse.ArgumentParser(
        prog="qpbench",
        description="Benchmark QP solvers on the per-tick QPs of a compliant redundant manipulator.",
        epilog=EXAMPLES,
        formatter_class=argparse.RawDescriptionHelpFormatter,
        parents=[common],
    )
    parser.add_argument("--version", action="version", version=f"qpbench {__version__}")
    _add_plugin_option(parser, "plugins_before")
    sub = parser.add_subparsers(dest="command", metavar="COMMAND")
    for name, module in _available_commands():
        p = sub.add_parser(
            name,
            help=module.HELP,
            description=module.HELP,
            epilog=f"example:\n  {module.EXAMPLE}",
            formatter_class=argparse.RawDescriptionHelpFormatter,
            parents=[common],
        )
        module.add_arguments(p)
        _add_plugin_option(p, "plugins_after")
        p.set_defaults(_run=module.run)
    return parser


def _add_plugin_option(parser: argparse.ArgumentParser, dest: str) -> None:
    # Two destinations: a sub-command's parser starts from a namespace of its own and would
    # replace a list given before the sub-command (``qpbench --plugin a.py bench --plugin b.py``).
    parser.add_argument(
        "--plugin",
        dest=dest,
        action="append",
        default=[],
        metavar="FILE",
        help=f"a Python file that registers extra backends; repeatable (also QPBENCH_PLUGINS, "
        f"files separated by '{os.pathsep}', and entry points of group qpbench.backends)",
    )


def _configure_logging(args: argparse.Namespace) -> None:
    """``-q``: errors only; default: progress and results; ``-v``: DEBUG; ``-vv``: also every
    solve (logger ``qpbench.solves``)."""
    level = logging.ERROR if args.quiet else logging.DEBUG if args.verbose else logging.INFO
    handler = logging.StreamHandler(sys.stderr)
    handler.setFormatter(logging.Formatter("%(levelname)s: %(message)s"))
    log.handlers[:] = [handler]
    log.setLevel(level)
    log.propagate = False
    solves = logging.DEBUG if args.verbose >= 2 else max(level, logging.INFO)
    logging.getLogger("qpbench.solves").setLevel(solves)


def main(argv: list[str] | None = None) -> int:
    """Entry point of the ``qpbench`` console script; returns the exit code."""
    from .cache import configure_numba_cache

    configure_numba_cache()  # before numba is imported: workers inherit the variable it may set
    # the system allocator, not pyarrow's, which reserves address space that ulimit -v counts
    os.environ.setdefault("ARROW_DEFAULT_MEMORY_POOL", "system")
    parser = build_parser()
    args = parser.parse_args(argv)
    args.quiet = getattr(args, "quiet", False)
    args.verbose = getattr(args, "verbose", 0) or 0
    if args.command is None:
        parser.print_help()
        return 2
    _configure_logging(args)
    shown = (f"{k}={v!r}" for k, v in sorted(vars(args).items()) if k[0] != "_" and k != "command")
    log.debug("qpbench %s %s: %s", __version__, args.command, ", ".join(shown))
    from tqdm.contrib.logging import logging_redirect_tqdm

    from .atomic import listing, recording
    from .backends import load_plugins
    from .native_output import silence_native_stdout

    try:
        load_plugins([*args.plugins_before, *getattr(args, "plugins_after", [])])
        # log lines go through tqdm.write: a progress bar is redrawn below them, never mixed into one line
        with (
            silence_native_stdout(enabled=not args.verbose),
            logging_redirect_tqdm(loggers=[log]),
            recording() as written,
        ):
            try:
                return int(args._run(args) or 0)
            finally:
                if written():  # every file the command wrote, once, whatever its exit code
                    log.info("%s", listing(written()))
    except QpbenchError as exc:
        print(f"qpbench {args.command}: error: {exc}", file=sys.stderr)
        return exc.exit_code
    except BrokenPipeError:
        # stdout's reader closed early (``qpbench list ... | head``): stop quietly, as Unix tools do
        os.dup2(os.open(os.devnull, os.O_WRONLY), sys.stdout.fileno())
        return 141
    except KeyboardInterrupt:
        print(f"qpbench {args.command}: interrupted", file=sys.stderr)
        return 130


if __name__ == "__main__":  # pragma: no cover
    sys.exit(main())
