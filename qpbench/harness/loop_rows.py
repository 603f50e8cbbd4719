"""The closed-loop table (``closed_loop.csv``): one row per (scenario, backend) run.

A run's row is its summary (:func:`qpbench.sim.summary.summarize`) under the
table's column names (:func:`row_from_summary`): nothing is computed here. A
run that produced no result gets a row saying why (:func:`failure_row`,
:func:`skipped_row`). List- and dict-valued figures (e.g.
``obstacle_active_intervals``: ``{"A2/wall": [[1.613, 6.467], ...]}``) are
written as JSON text.

==========================  =====================================================
column                      meaning
==========================  =====================================================
scenario, backend           the pair
formulation, duration_s     the QP formulation (``paper`` | ``soft``), asked duration [s]
simulated_s                 simulated time reached [s] (less than ``duration_s``
                            when the run's wall-time budget ran out)
status, error               ``ok``; ``budget`` (stopped early by the run's
                            wall-time budget, ``run_budget``; the rest as ``ok``),
                            ``error`` (and the exception's message),
                            ``crashed`` (the worker died; the signal),
                            ``time_limit`` (the run overran its deadline) or
                            ``skipped`` (and why)
verdict                     ``ok``, ``diverged``, ``incomplete``, ``limits``,
                            ``unsafe`` or ``failed`` (:data:`qpbench.sim.verdict.VERDICTS`:
                            from the simulator's summary as it is; ``incomplete``
                            for a run stopped by its budget or without a result;
                            empty for a skipped one)
verdict_reasons             why, plain text, ``"; "`` between reasons (a
                            budget-stopped run says where it stopped)
realtime                    ``yes``/``no``: the measured call times kept ``dt``
                            (:func:`qpbench.sim.verdict.judge_realtime`; beside
                            the verdict, not part of it; ``no`` without a result)
realtime_reason             why: the p99 call time and ``over_dt_share`` against
                            the scenario's ``[verdict]`` real-time thresholds
realtime_solver             the same from the solver's own reported times
                            (``unknown`` when the backend reports none)
realtime_solver_reason      why
over_dt_share               share of ticks whose call time exceeded ``dt``
solver_time_p99_s           p99 of the solver's own reported time [s] (empty: none)
verdict_overrides           ``[verdict]`` thresholds set over the scenario file's
                            (JSON object, ``{}`` when none; the report marks the row)
ticks                       control ticks simulated
tracking_rms_after_2s       tangential tracking error RMS for t >= 2 s [m]
tracking_max_after_2s       its maximum [m]
force_error_rms_after_2s    contact-force error RMS for t >= 2 s [N]
force_error_max_after_2s    its maximum [N]
min_obstacle_distance       smallest key-point to obstacle distance [m]
min_body_distance           the body's smallest clearance to an obstacle [m]: the
                            link capsules' signed distance, < 0 inside
                            (:mod:`qpbench.robot.body`); ``min_body_distance_link``
                            (1-based, the last carries the end effector),
                            ``min_body_distance_obstacle`` and ``min_body_distance_t``
                            [s] among the other figures
key_point_rule              the paper's guarantee, key points kept ``d_safe -
                            safety_margin`` from obstacles: ``held``, ``broken``
                            or ``-`` without obstacles; ``key_point_rule_reason``
                            says where it broke
joint_limit_violations      ticks with a joint angle outside its limits
infeasible_ticks            ticks the backend declared infeasible or could not
                            classify (:data:`qpbench.statuses.INFEASIBLE_OR_UNCLASSIFIED`)
fallback_ticks              ticks that used the soft fallback
v2_integral                 integral of ||v||^2 dt over the run [rad^2/s]
solve_time_p50_s            median per-tick solve time [s]
solve_time_p99_s            99th percentile [s] (a 1 kHz loop lives by its tail)
solve_time_max_s            worst tick [s]
real_time_factor            simulated time / wall time, over what was simulated
log_file                    the tick log, relative to the CSV's folder
==========================  =====================================================

followed by ``isolated`` (the run was made in a worker process with a
deadline), ``run_budget_s`` (the run's wall-time budget [s], empty when
none) and every other figure of the summary, sorted by name (among them the
per-tick guards' counts ``error_ticks``, ``time_limit_ticks``,
``invalid_ticks``, ``first_error``, ``deadline_misses`` and, with a per-tick
deadline, ``deadline_dropped``).
"""

from __future__ import annotations

import json
import math
import re
from pathlib import Path

import numpy as np
import pandas as pd

from ..atomic import atomic_path
from ..sim.verdict import BAD_VERDICTS
from ..statuses import describe_exception

__all__ = [
    "BAD_VERDICTS",
    "COLUMNS",
    "CSV_NAME",
    "FAILED_RUN_STATUSES",
    "LOG_DIR",
    "TABLE_NAMES",
    "cell",
    "error_row",
    "failure_row",
    "log_name",
    "row_from_summary",
    "same_run",
    "skipped_row",
    "write_table",
]

#: Name of the table inside the output folder.
CSV_NAME = "closed_loop.csv"
#: Folder of the per-tick logs inside the output folder.
LOG_DIR = "logs"

#: Leading columns of the closed-loop table, in order.
COLUMNS = (
    "scenario",
    "backend",
    "formulation",
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
    "solve_time_p50_s",
    "solve_time_p99_s",
    "solve_time_max_s",
    "over_dt_share",
    "solver_time_p99_s",
    "real_time_factor",
    "verdict_overrides",
    "log_file",
)

#: The table's names of two summary figures (the table's names are older than the summary's).
TABLE_NAMES = {"duration": "duration_s", "solve_time_median_s": "solve_time_p50_s"}

#: Statuses of a run that produced no result.
FAILED_RUN_STATUSES = ("error", "crashed", "time_limit")
#: Fields of a row without a result (no tick was timed: not real time, nothing overridden).
_NO_RESULT = dict(
    realtime="no",
    realtime_reason="no result to time",
    realtime_solver="unknown",
    realtime_solver_reason="no result to time",
    verdict_overrides="{}",
)


def cell(value: object) -> object:
    """A summary value as one CSV cell: scalars as they are, lists and dicts as JSON text."""
    if value is None or isinstance(value, (bool, int, float, str)):
        return value
    if isinstance(value, np.generic):
        return value.item()
    return json.dumps(value, default=lambda v: v.tolist() if isinstance(v, np.ndarray) else str(v))


def row_from_summary(scenario: str, backend: str, summary: dict) -> dict:
    """The table row of a run: ``summary`` under the table's names (:data:`TABLE_NAMES`).

    ``scenario`` and ``backend`` are as the run was asked for (a scenario may
    be a file path); the status is ``budget`` when the summary says
    ``stopped_early``, else ``ok``. ``log_file`` is filled in by the caller.
    """
    row = {
        "scenario": scenario,
        "backend": backend,
        "status": "budget" if summary.get("stopped_early") else "ok",
        "error": "",
        "log_file": "",
    }
    for key, value in summary.items():
        if key not in ("scenario", "backend"):
            row[TABLE_NAMES.get(key, key)] = cell(value)
    return row


def log_name(scenario: str, backend: str) -> str:
    """File name of a run's tick log (``:`` and ``/`` of backend names made safe)."""
    safe = re.sub(r"[^A-Za-z0-9_.-]+", "-", f"{scenario}__{backend}")
    return f"{safe}.parquet"


def _no_result_row(
    scenario: str, backend: str, formulation: str, duration: float | None, **fields: str
) -> dict:
    """A row of a run without a result: its key, the duration asked, ``fields``; no figures."""
    row = {c: math.nan for c in COLUMNS}
    row.update(
        scenario=scenario,
        backend=backend,
        formulation=formulation,
        duration_s=float(duration) if duration is not None else math.nan,
        log_file="",
        **fields,
    )
    return row


def skipped_row(
    scenario: str, backend: str, formulation: str, duration: float | None, reason: str
) -> dict:
    """The row of a run that was not made (status ``skipped``, the reason in ``error``, no verdict)."""
    return _no_result_row(
        scenario,
        backend,
        formulation,
        duration,
        status="skipped",
        error=reason,
        verdict="",
        verdict_reasons="",
    )


def error_row(
    scenario: str, backend: str, formulation: str, duration: float | None, exc: BaseException
) -> dict:
    """The row of a run that raised: status ``error`` and ``"Type: message"``, in one line."""
    return failure_row(scenario, backend, formulation, duration, "error", describe_exception(exc))


def failure_row(
    scenario: str, backend: str, formulation: str, duration: float | None, status: str, message: str
) -> dict:
    """The row of a run that produced no result: ``status`` (``error``, ``crashed``,
    ``time_limit``) and why in ``error``; verdict ``incomplete``, real time ``no``."""
    from ..sim.verdict import failed_run

    verdict = failed_run(status, message)
    return _no_result_row(
        scenario,
        backend,
        formulation,
        duration,
        status=status,
        error=message,
        verdict=verdict.verdict,
        verdict_reasons=verdict.text,
        **_NO_RESULT,
    )


def same_run(
    row: dict,
    formulation: str,
    duration: float | None,
    run_budget: float | None = None,
    overrides: dict | None = None,
) -> bool:
    """``row`` (read back from the table) is a finished run of this formulation, duration, budget
    and scenario overrides (``--set``; its ``scenario_overrides``)."""
    status = str(row.get("status"))
    if str(row.get("formulation")) != formulation:
        return False
    if _row_overrides(row) != json.loads(json.dumps(overrides or {})):
        return False
    if status == "budget":  # a budget-stopped run is the same run only under the same budget
        try:
            if run_budget is None or not math.isclose(
                float(row.get("run_budget_s")), float(run_budget)
            ):
                return False
        except (TypeError, ValueError):
            return False
    elif status != "ok":
        return False
    if duration is None:
        return True
    try:
        return math.isclose(
            float(row.get("duration_s")), float(duration), rel_tol=1e-9, abs_tol=1e-12
        )
    except (TypeError, ValueError):
        return False


def _row_overrides(row: dict) -> dict | None:
    """A row's ``scenario_overrides`` as a dict (``{}`` when empty; ``None`` when unreadable)."""
    value = row.get("scenario_overrides")
    if value is None or (isinstance(value, float) and math.isnan(value)) or value == "":
        return {}
    try:
        out = json.loads(value) if isinstance(value, str) else value
    except ValueError:
        return None
    return out if isinstance(out, dict) else None


def write_table(rows: list[dict], path: Path) -> pd.DataFrame:
    """Write the closed-loop table atomically (leading :data:`COLUMNS`, then the rest sorted)."""
    df = pd.DataFrame(rows)
    extra = sorted(c for c in df.columns if c not in COLUMNS)
    for c in COLUMNS:
        if c not in df.columns:
            df[c] = math.nan
    df = df[list(COLUMNS) + extra]
    with atomic_path(path) as tmp:
        df.to_csv(tmp, index=False)
    return df


#: Text columns whose empty cells read back as ``""``.
_TEXT_COLUMNS = (
    "error",
    "log_file",
    "verdict",
    "verdict_reasons",
    "realtime",
    "realtime_reason",
    "realtime_solver",
    "realtime_solver_reason",
)


def read_rows(path: Path) -> list[dict]:
    """The rows of an existing table, text cells that were empty as ``""`` (for resuming)."""
    rows = []
    for rec in pd.read_csv(path, keep_default_na=True).to_dict("records"):
        rows.append(
            {
                k: ("" if k in _TEXT_COLUMNS and isinstance(v, float) and math.isnan(v) else v)
                for k, v in rec.items()
            }
        )
    return rows
