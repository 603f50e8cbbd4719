"""Closed-loop runs: :func:`run_row`, the one (scenario, backend) run of every command, made into
a row (the run's summary under :data:`TABLE_NAMES`), and :func:`run_closed_loop`, the table of
many (``OUT/closed_loop.csv``, ``OUT/logs/``); statuses: docs/architecture.md, "Closed-loop runs".
"""

from __future__ import annotations

import json
import logging
import math
import re
import shutil
from collections.abc import Callable
from dataclasses import dataclass, replace
from pathlib import Path

import numpy as np
import pandas as pd

from ..atomic import atomic_path, check_folder, check_output, record
from ..backends import NOISE_FLOOR, plugin_files
from ..control.controller import check_formulation
from ..exceptions import check_choice, positive_count, positive_seconds
from ..report.inputs import noise_floor_runs
from ..runner.process import run_tasks
from ..selection import parse_list
from ..sim.log import TICK_TIME
from ..sim.verdict import BAD_VERDICTS, failed_run, floor_fields, judge_realtime_run
from ..statuses import describe_exception
from .guard import ISOLATE, wants_worker

log = logging.getLogger("qpbench.harness")

CSV_NAME = "closed_loop.csv"
LOG_DIR = "logs"
#: Statuses of a run that produced no result.
FAILED_RUN_STATUSES = ("error", "crashed", "time_limit")
#: Least deadline of an isolated run [s].
RUN_TIME_LIMIT_MIN_S = 600.0
#: Deadline of an isolated run per simulated second [s] (a real-time factor of 1/50).
RUN_TIME_LIMIT_PER_SIM_S = 50.0

#: Leading columns of the table, in order.
COLUMNS = (
    "scenario",
    "backend",
    "family",
    "joints",
    "noise_floor",
    "formulation",
    "engine",
    "duration_s",
    "simulated_s",
    "status",
    "error",
    "verdict",
    "verdict_reasons",
    "realtime",
    "realtime_reason",
    "realtime_solver",
    "realtime_solver_reason",
    "ticks",
    "tracking_rms_after_2s",
    "tracking_max_after_2s",
    "force_error_rms_after_2s",
    "force_error_max_after_2s",
    "min_obstacle_distance",
    "min_body_distance",
    "key_point_rule",
    "joint_limit_violations",
    "infeasible_ticks",
    "fallback_ticks",
    "v2_integral",
    "solve_time_median_s",
    "solve_time_p99_s",
    "rank_time_source",
    "rank_time_p99_s",
    "rank_time_p99_lo_s",
    "rank_time_p99_hi_s",
    "solve_time_max_s",
    "fallback_solve_time_p99_s",
    "tick_time_median_s",
    "tick_time_p99_s",
    "over_dt_share",
    "noise_floor_over_dt_share",
    "noise_floor_tick_p99_s",
    "solver_time_p99_s",
    "real_time_factor",
    "verdict_overrides",
    "log_file",
)

#: The tables' names of summary figures named otherwise in the summary.
TABLE_NAMES = {"duration": "duration_s"}


@dataclass(frozen=True)
class LoopTask:
    """One closed-loop run, as plain picklable data: ``scenario``: a name or TOML path (with
    ``scenario_text``, the path naming that text); ``duration``, ``deadline`` (per tick),
    ``run_budget`` (wall time of the timed run): [s] or ``None``; ``overrides``: ``--set`` pairs;
    ``out``: the folder of the run's logs (``None``: none written); ``plugins``: files to load
    first; ``bands``: ``(force [N], tracking [m])`` of the time-to-converge figures."""

    scenario: str
    backend: str
    formulation: str = "paper"
    duration: float | None = None
    deadline: float | None = None
    run_budget: float | None = None
    overrides: tuple = ()
    out: str | None = None
    plugins: tuple = ()
    scenario_text: str | None = None
    bands: tuple | None = None
    engine: str = "compiled"
    p99_interval: bool = True


def run_row(task: LoopTask) -> dict:
    """The row of one run (:func:`qpbench.sim.loop.simulate`, its warm-up included), its logs
    written when ``task.out`` is set; a run that raises is an ``error`` row. The noise floor's
    run is judged on its whole ticks (``tick_time_s``)."""
    from ..backends import backend_class, load_plugins
    from ..jit import warmup
    from ..sim.figure_log import figure_log_path, write_figure_log
    from ..sim.loop import simulate
    from ..sim.scenario import load_scenario, parse_scenario
    from ..sim.summary import convergence_figures, realtime_figures

    try:
        load_plugins(list(task.plugins))
        if task.scenario_text is None:
            overrides = dict(task.overrides) or None
            scenario = load_scenario(task.scenario, overrides, duration=task.duration)
        else:
            scenario = parse_scenario(task.scenario_text, task.scenario, duration=task.duration)
        warmup([task.backend])
        result = simulate(
            scenario,
            task.backend,
            formulation=task.formulation,
            deadline=task.deadline,
            wall_budget_s=task.run_budget,
            engine=task.engine,
            p99_interval=task.p99_interval,
        )
        floor = backend_class(task.backend).noise_floor
        summary = dict(result.summary, noise_floor=floor)
        if floor:
            ticks = result.log[TICK_TIME].to_numpy()
            summary.update(
                realtime_figures(result.log, scenario.dt, scenario.verdict, ticks, "tick")
            )
        if task.bands is not None:
            summary.update(convergence_figures(result.log, *task.bands))
        status = "budget" if summary.get("stopped_early") else "ok"
        row = dict(scenario=task.scenario, backend=task.backend, status=status, error="")
        row.update(family=arm_family(scenario), joints=len(scenario.theta0), log_file="")
        for key, value in summary.items():
            if key not in ("scenario", "backend"):
                row[TABLE_NAMES.get(key, key)] = cell(value)
        if task.out is not None:
            name = log_name(task.scenario, task.backend)
            with atomic_path(Path(task.out) / LOG_DIR / name) as tmp:
                result.log.to_parquet(tmp, index=False)
            write_figure_log(result.log, figure_log_path(Path(task.out) / LOG_DIR / name))
            row["log_file"] = f"{LOG_DIR}/{name}"
        return row
    except Exception as exc:  # noqa: BLE001 - one failing run must not stop the others
        return failure_row(task, "error", describe_exception(exc), warn=True)


def arm_family(scenario) -> str:
    """``"planar"`` or ``"spatial"``: the family of a scenario's arm (its task space's dim, 2 or
    3), by which the report ranks the backends apart."""
    return "planar" if len(scenario.normal) == 2 else "spatial"


def cell(value: object) -> object:
    """A summary value as one CSV cell: scalars as they are, lists and dicts as JSON text."""
    if value is None or isinstance(value, (bool, int, float, str)):
        return value
    if isinstance(value, np.generic):
        return value.item()
    return json.dumps(value, default=lambda v: v.tolist() if isinstance(v, np.ndarray) else str(v))


def log_name(scenario: str, backend: str) -> str:
    """File name of a run's tick log (``:`` and ``/`` of backend names made safe)."""
    return re.sub(r"[^A-Za-z0-9_.-]+", "-", f"{scenario}__{backend}") + ".parquet"


def failure_fields(status: str, message: str) -> dict:
    """Fields of a row without a result: ``status``, why (``error``) and its verdict (none for
    ``skipped`` or ``invalid_scenario``)."""
    message = " ".join(str(message).split())
    if status in ("skipped", "invalid_scenario"):
        return dict(status=status, error=message, verdict="", verdict_reasons="")
    verdict = failed_run(status, message)
    return dict(
        status=status,
        error=message,
        verdict=verdict.verdict,
        verdict_reasons=verdict.text,
        realtime="no",
        realtime_reason="no result to time",
        realtime_solver="unknown",
        realtime_solver_reason="no result to time",
        verdict_overrides="{}",
    )


def failure_row(task: LoopTask, status: str, message: str, warn: bool = False) -> dict:
    """The table row of a run without a result (:func:`failure_fields`); ``warn``: log it."""
    if warn:
        log.warning("closed loop %s with %s: %s", task.scenario, task.backend, message)
    row = {c: math.nan for c in COLUMNS}
    row.update(
        scenario=task.scenario,
        backend=task.backend,
        noise_floor=task.backend == NOISE_FLOOR,
        formulation=task.formulation,
        duration_s=float(task.duration) if task.duration is not None else math.nan,
        log_file="",
        **failure_fields(status, message),
    )
    return row


def run_deadline(
    scenario: str, duration: float | None, run_time_limit: float | None = None
) -> float:
    """Deadline [s] of an isolated run (warm-up, run and log writing): ``run_time_limit``, else
    ``max(RUN_TIME_LIMIT_MIN_S, RUN_TIME_LIMIT_PER_SIM_S * simulated seconds)``."""
    if run_time_limit is not None:
        return float(run_time_limit)
    if duration is None:
        try:
            from ..sim.scenario import load_scenario

            duration = load_scenario(scenario).duration
        except Exception:  # noqa: BLE001 - the run itself reports a bad scenario
            duration = 0.0
    return max(RUN_TIME_LIMIT_MIN_S, RUN_TIME_LIMIT_PER_SIM_S * float(duration))


@dataclass
class ClosedLoopOutcome:
    """What :func:`run_closed_loop` did: the table, its failed runs, the runs made now and kept,
    and the rows whose verdict is bad or whose run failed (``not_ok``)."""

    table: pd.DataFrame
    csv_path: Path
    errors: int
    ran: int
    skipped: int
    not_ok: int = 0


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
    engine: str = "compiled",
) -> ClosedLoopOutcome:
    """Run every (scenario, backend) pair in the loop into ``out``, an isolated one in a worker
    (the options of ``qpbench closed-loop``): ``resume`` keeps the ``ok`` rows made under the
    same terms and the rows of pairs not asked; ``skip``: backend -> reason of a ``skipped``
    row; ``run_budget`` [s]: a backend's in ``budgets``; ``on_row`` is called with each row
    once written."""
    # the arguments checked before anything is written or run (errors naming the option)
    check_formulation(formulation, key="--formulation")
    parse_list(list(scenarios), "--scenarios")  # a name given twice is refused, as everywhere
    parse_list(list(backends), "--backends")
    times = {"--duration": duration, "--run-time-limit": run_time_limit, "--deadline": deadline}
    for key, value in {**times, "--run-budget": run_budget}.items():
        if value is not None:
            positive_seconds(value, key)
    positive_count(jobs, "--jobs")
    check_choice(isolate, ISOLATE, "isolation", "--isolate")
    out = Path(out)
    csv_path = out / CSV_NAME
    previous = _prepare_output(out, force, resume)
    # each scenario's noise floor first, run like the others (docs/verdicts.md, "The noise floor")
    floored = [NOISE_FLOOR, *(b for b in backends if b != NOISE_FLOOR)]
    order = [(s, b) for s in scenarios for b in floored]
    budget = {b: (budgets or {}).get(b, run_budget) for b in floored}.get
    overrides = dict(overrides or {})
    rows, others = _kept_rows(order, previous, formulation, duration, budget, skip or {}, overrides)
    todo = [k for k in order if k not in rows]

    def emit(key: tuple[str, str], row: dict) -> None:
        row["isolated"] = wants_worker(isolate, key[1])
        row["run_budget_s"] = budget(key[1])
        rows[key] = row
        if row["log_file"]:  # written here or by a worker process
            from ..sim.figure_log import figure_log_path

            record(out / row["log_file"])
            record(figure_log_path(out / row["log_file"]))
        _write_table([rows[k] for k in order if k in rows] + others, csv_path)
        if on_row is not None:
            on_row(row)

    pairs, plugins = tuple(overrides.items()), tuple(plugin_files())  # workers load them too
    common = LoopTask("", "", formulation, duration, deadline, None, pairs, str(out), plugins)
    items = [
        (
            (s, b),
            replace(common, scenario=s, backend=b, run_budget=budget(b), engine=engine),
            run_deadline(s, duration, run_time_limit) if wants_worker(isolate, b) else None,
        )
        for s, b in todo
    ]
    _run_items(items, jobs, emit)
    for (s, _), row in rows.items():
        judge_against_floor(row, rows.get((s, NOISE_FLOOR)))
    _write_table([rows[k] for k in order if k in rows] + others, csv_path)
    table = pd.read_csv(csv_path)  # the outcome, counted from the table as written
    failed = table["status"].isin(FAILED_RUN_STATUSES)
    candidate = ~noise_floor_runs(table)  # the floor's verdict judges nothing (x = 0)
    not_ok = int(((table["verdict"].isin(BAD_VERDICTS) | failed) & candidate).sum())
    ran = len(todo)
    return ClosedLoopOutcome(table, csv_path, int(failed.sum()), ran, len(order) - ran, not_ok)


#: The fields :func:`judge_against_floor` sets.
FLOOR_JUDGED = (
    "realtime",
    "realtime_reason",
    "noise_floor_over_dt_share",
    "noise_floor_tick_p99_s",
)


def judge_against_floor(row: dict, floor: dict | None) -> None:
    """Judge ``row``'s real time again, in place, against its scenario's noise floor row
    (``None``: none; docs/verdicts.md, "The noise floor"): :data:`FLOOR_JUDGED`. A row without
    real-time figures and the floor's own row are left as they are."""
    if row.get("backend") == NOISE_FLOOR or floor is None or not (_judged(row) and _judged(floor)):
        return
    row["realtime"], row["realtime_reason"] = judge_realtime_run(row, "call", floor_fields(floor))
    row["noise_floor_over_dt_share"] = floor["over_dt_share"]
    row["noise_floor_tick_p99_s"] = floor["time_p99_without_infeasible_s"]


def _judged(row: dict) -> bool:
    """``row`` holds the real-time figures of a run with a result."""
    return pd.notna(row.get("ticks_infeasible")) and row.get("status") in ("ok", "budget")


def _run_items(items: list[tuple], jobs: int, emit: Callable) -> None:
    """Each ``(key, task, deadline)``'s row to ``emit``: here, or in a worker where it has a
    deadline (isolated) or ``jobs > 1`` (then every run in a worker: a crash is that run's
    row, not the pool's end)."""
    if jobs > 1:
        _run_in_workers(items, jobs, emit)
        return
    for key, task, limit in items:
        if limit is None:
            emit(key, run_row(task))
        else:
            _run_in_workers([(key, task, limit)], 1, emit)


def _run_in_workers(items: list[tuple], jobs: int, emit: Callable) -> None:
    """Each run in a worker process of its own, ``jobs`` at a time: a run that dies or overruns its
    deadline is a ``crashed`` or ``time_limit`` row and takes no other run's row with it."""
    from ..sim.figure_log import FIGURE_LOG_DIR

    tasks = {key: (task, deadline_s) for key, task, deadline_s in items}
    for done in run_tasks(run_row, items, jobs, fresh=True, name="qpbench-closed-loop"):
        if done.status is None:
            emit(done.key, done.value)
            continue
        task, deadline_s = tasks[done.key]
        if done.status == "time_limit":
            message = f"no result after {deadline_s:.3g} s (run time limit); worker killed"
        else:
            message = f"{done.lost} during the closed-loop run"
        name = log_name(task.scenario, task.backend)
        for folder in (LOG_DIR, FIGURE_LOG_DIR):  # the temporary logs the worker may have left
            for tmp in (Path(task.out) / folder).glob(f".{name}.*.tmp"):
                tmp.unlink(missing_ok=True)
        emit(done.key, failure_row(task, done.status, message, warn=True))


def _prepare_output(out: Path, force: bool, resume: bool) -> list[dict]:
    """Check the output; the rows to resume (``force`` removes table and logs); make ``logs/``."""
    from ..sim.figure_log import FIGURE_LOG_DIR

    csv_path = out / CSV_NAME
    check_folder(out)
    if out.exists():
        check_output(csv_path, force=force, resume=resume)
    previous = []
    if csv_path.exists() and resume and not force:
        previous = pd.read_csv(csv_path).to_dict("records")
    if force:
        csv_path.unlink(missing_ok=True)
        for folder in (LOG_DIR, FIGURE_LOG_DIR):
            shutil.rmtree(out / folder, ignore_errors=True)
    (out / LOG_DIR).mkdir(parents=True, exist_ok=True)
    return previous


def _kept_rows(order, previous, formulation, duration, budget, skip, overrides):
    """Rows of the pairs asked that need no run (done under the same terms, or skipped), and the
    resumed table's rows of other pairs (kept after this run's)."""
    done = {
        (str(r["scenario"]), str(r["backend"])): r
        for r in previous
        if _same_run(r, formulation, duration, budget(str(r["backend"])), overrides)
    }
    others = [r for r in previous if (str(r["scenario"]), str(r["backend"])) not in set(order)]
    rows = {k: done[k] for k in order if k in done}
    for s, b in order:
        if (s, b) not in rows and b in skip:
            rows[(s, b)] = failure_row(LoopTask(s, b, formulation, duration), "skipped", skip[b])
    return rows, others


def _same_run(row: dict, formulation, duration, run_budget, overrides: dict) -> bool:
    """``row`` (read back) is a finished run of this formulation, duration, budget and overrides."""
    text, status = row.get("scenario_overrides"), row.get("status")
    try:
        stored = (
            json.loads(text) if isinstance(text, str) and text else {} if pd.isna(text) else None
        )
        finished = status == "ok" or (  # a stopped run is the same only under the same budget
            status == "budget"
            and run_budget is not None
            and math.isclose(float(row["run_budget_s"]), run_budget)
        )
        return (
            finished
            and str(row.get("formulation")) == formulation
            and stored == json.loads(json.dumps(overrides))
            and (duration is None or math.isclose(float(row.get("duration_s")), float(duration)))
        )
    except (TypeError, ValueError):
        return False


def _write_table(rows: list[dict], path: Path) -> None:
    """Write the table atomically (:data:`COLUMNS`, then the rest sorted)."""
    df = pd.DataFrame(rows)
    extra = sorted(c for c in df.columns if c not in COLUMNS)
    df = df.reindex(columns=list(COLUMNS) + extra)
    with atomic_path(path) as tmp:
        df.to_csv(tmp, index=False)


def log_row(logger: logging.Logger, row: dict) -> None:
    """One line per run: INFO when its verdict is ``ok`` (or skipped), else WARNING with why."""
    keys = ("verdict", "verdict_reasons", "error")
    verdict, reasons, error = (row[k] if isinstance(row.get(k), str) else "" for k in keys)
    where = f"{row['scenario']} / {row['backend']}"
    if row.get("noise_floor") is True:  # x = 0: no verdict to tell, the machine's own loop
        why = row.get("realtime_reason") or row.get("error") or row.get("status")
        logger.info("%s: noise floor, real time %s (%s)", where, row.get("realtime"), why)
        return
    if verdict and verdict != "ok":
        logger.warning("%s: %s (%s)", where, verdict, reasons or row.get("status"))
        return
    status = str(row.get("status"))
    detail = "; ".join(
        x for x in (status if status != "ok" and verdict else "", error, reasons) if x
    )
    logger.info("%s: %s%s", where, verdict or status, f" ({detail})" if detail else "")
