"""Closed-loop comparison: each scenario with each backend in the loop, one table.

For every (scenario, backend) pair :func:`qpbench.sim.loop.simulate` runs the
scenario with that backend solving every tick's QP
(:mod:`qpbench.harness.loop_run`). Each run writes its per-tick log to
``OUT/logs/<scenario>__<backend>.parquet`` and one row to
``OUT/closed_loop.csv`` (columns: :mod:`qpbench.harness.loop_rows`; the row is
the run's summary, nothing recomputed). The table is rewritten atomically
after each run (rows appear as they are produced); a run that raises becomes
a row with status ``error`` and the others continue.

Guards against a hang in native code and a process death (segfault, abort):
``isolate`` (``--isolate``) ``auto`` (the default: backends whose class has
``risky = True``, e.g. ``proxqp``), ``always`` or ``never``. An isolated run
is made in a worker process of its own with a deadline
(:mod:`qpbench.harness.loop_workers`; ``run_time_limit``,
``--run-time-limit``). With ``jobs > 1`` every run is made in a worker
process of its own (the deadline only for isolated ones), so one crash loses
no other run's row. No worker compiles: the kernels are compiled (or loaded)
in this process before the first worker starts (:mod:`qpbench.jit`).
``resume`` keeps the rows already done with the same formulation and
duration (status ``ok``) and runs the rest (rows of pairs not asked for this
time stay in the table); ``force`` starts again.
"""

from __future__ import annotations

import logging
import math
import shutil
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path

import pandas as pd

from ..atomic import check_folder, check_output, record
from ..exceptions import ParamError
from ..selection import parse_list
from ..statuses import FORMULATIONS
from .loop_rows import (
    BAD_VERDICTS,
    CSV_NAME,
    FAILED_RUN_STATUSES,
    LOG_DIR,
    read_rows,
    same_run,
    skipped_row,
    write_table,
)
from .loop_run import RunSpec, run_guarded
from .loop_workers import run_deadline, run_in_workers

__all__ = ["ISOLATE", "ClosedLoopOutcome", "is_risky", "log_row", "run_closed_loop"]

#: Choices of ``isolate``: ``auto`` isolates backends whose class says ``risky = True``.
ISOLATE = ("auto", "always", "never")


def is_risky(backend: str) -> bool:
    """The backend's class says ``risky = True`` (``False`` for an unknown name)."""
    from ..backends import backend_class
    from ..exceptions import BackendNotFound

    try:
        return bool(backend_class(backend).risky)
    except BackendNotFound:
        return False


@dataclass
class ClosedLoopOutcome:
    """What :func:`run_closed_loop` did: the full table, the runs that failed
    (``errors``: status ``error``, ``crashed`` or ``time_limit``), the runs made
    now (``ran``), those kept or skipped, and the rows of the table whose
    verdict is not ``ok`` (``not_ok``: every verdict of ``BAD_VERDICTS``;
    the failed runs among them)."""

    table: pd.DataFrame
    csv_path: Path
    errors: int
    ran: int
    skipped: int
    not_ok: int = 0


@dataclass
class _Table:
    """The table as it grows: its rows in the order asked (``order``: (scenario, backend) keys),
    then the rows kept from an earlier table for pairs not asked this time (``others``)."""

    order: list[tuple[str, str]]
    rows: dict[tuple[str, str], dict]
    others: list[dict]
    csv_path: Path
    isolated: Callable[[str], bool]
    budget: Callable[[str], float | None]
    on_row: Callable[[dict], None] | None

    def all_rows(self) -> list[dict]:
        return [self.rows[k] for k in self.order if k in self.rows] + self.others

    def emit(self, key: tuple[str, str], row: dict) -> None:
        """Add a run's row and rewrite the table (atomically); tell ``on_row``."""
        row["isolated"] = self.isolated(key[1])
        row["run_budget_s"] = self.budget(key[1])
        self.rows[key] = row
        if isinstance(row.get("log_file"), str):  # written here or by a worker process
            from ..sim.figure_log import figure_log_path

            log_path = self.csv_path.parent / row["log_file"]
            record(log_path)
            record(figure_log_path(log_path))
        write_table(self.all_rows(), self.csv_path)
        if self.on_row is not None:
            self.on_row(row)


def run_closed_loop(
    scenarios: list[str],
    backends: list[str],
    out: str | Path,
    *,
    duration: float | None = None,
    formulation: str = "paper",
    force: bool = False,
    resume: bool = False,
    jobs: int = 1,
    on_row: Callable[[dict], None] | None = None,
    skip: dict[str, str] | None = None,
    isolate: str = "auto",
    run_time_limit: float | None = None,
    deadline: float | None = None,
    run_budget: float | None = None,
    budgets: dict[str, float] | None = None,
    overrides: dict | None = None,
) -> ClosedLoopOutcome:
    """Run every (scenario, backend) pair in the loop, tabulated in ``out`` (module docstring).

    Args:
        scenarios, backends: Scenario names or TOML paths; backend names (each once).
        out: Output folder (``closed_loop.csv``, columns :mod:`~qpbench.harness.loop_rows`; ``logs/``).
        duration: Simulated time per run [s]; ``None`` keeps each scenario's ``T``.
        formulation: ``paper`` (hard task, eq. 11) or ``soft``.
        force, resume: Replace an existing table and its logs; keep its rows done under the same terms.
        jobs: Runs in parallel, each in a worker process of its own (with 1, only isolated ones).
        on_row: Called with each new row as soon as it is written.
        skip: Backend -> reason: a ``skipped`` row per scenario instead of a run.
        isolate: ``auto`` (backends whose class has ``risky = True``), ``always`` or ``never``: an
            isolated run is made in a worker process with a deadline (``run_time_limit`` [s],
            default :func:`~qpbench.harness.loop_workers.run_deadline`).
        deadline: Per-tick deadline [s] (default none; :func:`qpbench.sim.loop.simulate`).
        run_budget: Wall-time budget of each run [s] (default: none), of a backend's in ``budgets``
            (backend -> [s]): a run stops between ticks once it is spent (status ``budget``,
            verdict ``incomplete``).
        overrides: Values set over every scenario file's (``--set``; a resumed row is kept
            only when made under the same: its ``scenario_overrides``).

    Raises:
        OutputExistsError: the table exists and neither ``force`` nor ``resume``.
        ParamError: a bad formulation, duration or job count, or a name listed twice.
    """
    _check_arguments(
        scenarios,
        backends,
        duration,
        formulation,
        jobs,
        isolate,
        run_time_limit,
        deadline,
        run_budget,
    )
    from ..backends import plugin_files

    # loaded by the CLI or the caller (qpbench.backends.load_plugins); workers load them too
    plugins = plugin_files()
    out = Path(out)
    csv_path, previous_rows = _prepare_output(out, force, resume)

    order = [(s, b) for s in scenarios for b in backends]
    budget = {b: (budgets or {}).get(b, run_budget) for b in backends}.get  # backend -> budget
    overrides = dict(overrides or {})
    rows, others = _kept_rows(
        order, previous_rows, formulation, duration, budget, skip or {}, overrides
    )
    todo = [k for k in order if k not in rows]

    def _isolated(backend: str) -> bool:  # in a worker process with a deadline
        return isolate == "always" or (isolate == "auto" and is_risky(backend))

    table = _Table(order, rows, others, csv_path, _isolated, budget, on_row)
    spec = dict(formulation=formulation, duration=duration, out=str(out), deadline=deadline)
    spec.update(overrides=tuple(overrides.items()))
    items = _items(todo, spec, budget, _isolated, run_time_limit)
    _run_items(items, jobs, plugins, table.emit)
    write_table(table.all_rows(), csv_path)
    return _outcome(csv_path, len(todo), len(order) - len(todo))


def _items(todo, spec: dict, budget, isolated, run_time_limit: float | None) -> list[tuple]:
    """(key, what to run, deadline of an isolated run or None) of each pair to run."""
    return [
        (
            (s, b),
            RunSpec(s, b, **spec, run_budget=budget(b)),
            run_deadline(s, spec["duration"], run_time_limit) if isolated(b) else None,
        )
        for s, b in todo
    ]


def _prepare_output(out: Path, force: bool, resume: bool) -> tuple[Path, list[dict]]:
    """Check the output folder and its table (force, resume), read the rows to keep, make ``logs/``."""
    csv_path = out / CSV_NAME
    check_folder(out)
    if out.exists():
        check_output(csv_path, force=force, resume=resume)
    previous_rows = _previous_rows(out, force, resume)
    (out / LOG_DIR).mkdir(parents=True, exist_ok=True)
    return csv_path, previous_rows


def _outcome(csv_path: Path, ran: int, skipped: int) -> ClosedLoopOutcome:
    """The outcome, counted from the table as written."""
    table = pd.read_csv(csv_path)
    failed = table["status"].isin(FAILED_RUN_STATUSES)
    not_ok = int((table["verdict"].isin(BAD_VERDICTS) | failed).sum()) if len(table) else 0
    return ClosedLoopOutcome(table, csv_path, int(failed.sum()), ran, skipped, not_ok)


def _run_items(items: list[tuple], jobs: int, plugins: list[str], emit: Callable) -> None:
    """Make the runs: with one job, those not isolated in this process and the isolated ones
    each in a worker; with more, every run in a worker of its own (a crash is that run's row,
    not the pool's end)."""
    if jobs > 1:
        run_in_workers(items, jobs, plugins, emit)
        return
    for key, spec, deadline_s in items:
        if deadline_s is None:
            emit(key, run_guarded(spec))
        else:
            run_in_workers([(key, spec, deadline_s)], 1, plugins, emit)


def _kept_rows(
    order: list[tuple[str, str]],
    previous_rows: list[dict],
    formulation: str,
    duration: float | None,
    budget: Callable[[str], float | None],
    skip: dict[str, str],
    overrides: dict,
) -> tuple[dict, list[dict]]:
    """Rows of this run's pairs that need no run (done before under the same terms, or skipped),
    and the resumed table's rows of other pairs (kept, after this run's)."""
    done = {
        (str(r["scenario"]), str(r["backend"])): r
        for r in previous_rows
        if same_run(r, formulation, duration, budget(str(r["backend"])), overrides)
    }
    others = [r for r in previous_rows if (str(r["scenario"]), str(r["backend"])) not in set(order)]
    rows: dict[tuple[str, str], dict] = {k: done[k] for k in order if k in done}
    for key in order:
        if key not in rows and key[1] in skip:
            rows[key] = skipped_row(key[0], key[1], formulation, duration, skip[key[1]])
    return rows, others


def _check_arguments(
    scenarios, backends, duration, formulation, jobs, isolate, run_time_limit, deadline, run_budget
) -> None:
    """Every argument checked before anything is written or run (one-line errors naming the option)."""
    if formulation not in FORMULATIONS:
        raise ParamError(
            f"unknown formulation '{formulation}' (choose from {', '.join(FORMULATIONS)})",
            key="--formulation",
        )
    parse_list(list(scenarios), "--scenarios")  # a name given twice is refused, as everywhere
    parse_list(list(backends), "--backends")
    if duration is not None and not (duration > 0 and math.isfinite(duration)):
        raise ParamError(
            f"duration must be a positive number of seconds, got {duration}", key="--duration"
        )
    if jobs < 1:
        raise ParamError(f"jobs must be >= 1, got {jobs}", key="--jobs")
    if isolate not in ISOLATE:
        raise ParamError(
            f"unknown isolation '{isolate}' (choose from {', '.join(ISOLATE)})", key="--isolate"
        )
    for value, key in (
        (run_time_limit, "--run-time-limit"),
        (deadline, "--deadline"),
        (run_budget, "--run-budget"),
    ):
        if value is not None and not (value > 0 and math.isfinite(value)):
            raise ParamError(f"must be a positive number of seconds, got {value}", key=key)


def _previous_rows(out: Path, force: bool, resume: bool) -> list[dict]:
    """The rows of the table to resume (none without ``resume``); ``force`` removes table and logs."""
    from ..sim.figure_log import FIGURE_LOG_DIR

    csv_path = out / CSV_NAME
    if csv_path.exists() and resume and not force:
        return read_rows(csv_path)
    if force:
        if csv_path.exists():
            csv_path.unlink()
        for folder in (LOG_DIR, FIGURE_LOG_DIR):
            if (out / folder).exists():
                shutil.rmtree(out / folder)
    return []


def log_row(logger: logging.Logger, row: dict) -> None:
    """One line per run: INFO when its verdict is ``ok`` (or it was skipped), else WARNING with the reasons."""
    verdict = row.get("verdict")
    verdict = verdict if isinstance(verdict, str) else ""
    reasons = row.get("verdict_reasons")
    reasons = reasons if isinstance(reasons, str) else ""
    where = f"{row['scenario']} / {row['backend']}"
    if verdict and verdict != "ok":
        logger.warning("%s: %s (%s)", where, verdict, reasons or row.get("status"))
        return
    status = str(row.get("status"))
    error = row.get("error") if isinstance(row.get("error"), str) else ""
    detail = "; ".join(
        x for x in (status if status != "ok" and verdict else "", error, reasons) if x
    )
    logger.info("%s: %s%s", where, verdict or status, f" ({detail})" if detail else "")
