"""The sweep table: one row per (instance, backend), appended crash-safely as runs end.

``DIR/sweep.csv`` is written by :class:`qpbench.harness.results.ResultsWriter`
(one line per row, one ``write`` + ``fsync`` per row on an ``O_APPEND``
descriptor) and read back by :func:`qpbench.harness.results.read_results`
(a half-written last line dropped), so a kill at any moment loses at most the
runs in flight. A resumed sweep appends the rows it re-runs; when it ends the
table is rewritten atomically with the last row of each key.

==============================  =====================================================
column                          meaning
==============================  =====================================================
instance, backend               the key; ``instance_file`` re-runs it alone
sample, sweep, base_scenario    sample index, sweep name, base scenario
parameters                      the drawn values (JSON: scenario key -> value)
status                          ``ok`` (the run gave a result, whatever its verdict),
                                ``error`` (it raised: ``error`` says what),
                                ``crashed`` (its worker was lost twice),
                                ``invalid_scenario`` (the loader refused the instance)
attempts                        runs started for this row (2: its first worker was lost)
verdict, verdict_reasons        the closed loop's verdict (:mod:`qpbench.sim.verdict`);
                                ``incomplete`` for ``error``/``crashed``; empty when invalid
duration_s, simulated_s, dt     asked and simulated time [s], control period [s]
tracking_*_after_2s             tangential tracking error, RMS and max, t >= 2 s [m]
force_error_*_after_2s          contact-force error, RMS and max, t >= 2 s [N]
t_converge_force_s              first time from which ``|force - Fd| <= force_band_n``
                                to the end [s]; empty: not converged at the end
t_converge_tracking_s           the same for ``|tracking error| <= tracking_band_m`` [s]
min_obstacle_distance           closest key point to an obstacle, d_min [m] (where,
                                when: ``..._key_point``, ``..._obstacle``, ``..._t``)
joint_*_violations, max_abs_v   ticks beyond a joint limit; largest joint speed [rad/s]
infeasible_ticks ...            ticks: declared infeasible, not optimal, soft fallback
                                applied, zero velocity, raised/error, non-finite answer
solve_time_{median,p99,max}_s   per-tick solve time [s] (timing)
deadline_misses                 ticks whose solve took longer than dt (timing)
realtime, realtime_reason       the run kept real time at dt, from the measured call
                                times (``yes``/``no``; :mod:`qpbench.sim.summary`; timing)
realtime_solver, ..._reason     the same from the solver's own times (``unknown``: none)
over_dt_share                   share of ticks whose call took longer than dt (timing)
solver_time_p99_s               p99 of the solver's own time [s]; ``solver_over_dt_share``
verdict_overrides               ``[verdict]`` thresholds set over the file's (JSON, ``{}``)
ticks_over_1ms                  ticks whose solve took longer than 1 ms: missed at 1 kHz
wall_time_s, real_time_factor   the run's wall time [s], simulated / wall (timing)
executor, host, worker          where it ran
concurrent_solves               closed loops that could solve at once on that host
==============================  =====================================================
"""

from __future__ import annotations

import json
import math
from typing import TYPE_CHECKING

import numpy as np

if TYPE_CHECKING:
    import pandas as pd

__all__ = [
    "COLUMNS",
    "CSV_NAME",
    "KEY_COLUMNS",
    "STATUSES",
    "TIMING_COLUMNS",
    "failed_row",
    "result_row",
    "time_to_converge",
]

#: Name of the table inside the sweep's folder.
CSV_NAME = "sweep.csv"

#: Statuses of a row (see the module docstring).
STATUSES = ("ok", "error", "crashed", "invalid_scenario")

#: A row's key.
KEY_COLUMNS = ("instance", "backend")

# Column groups, each name once; the tables below are made of them.
_HEAD = (
    "instance",
    "backend",
    "instance_file",
    "sample",
    "sweep",
    "base_scenario",
    "parameters",
    "status",
    "error",
    "attempts",
    "verdict",
    "verdict_reasons",
)
_RUN = (  # from the summary
    "duration",
    "simulated_s",
    "dt",
    "ticks",
    "tracking_rms_after_2s",
    "tracking_max_after_2s",
    "force_error_rms_after_2s",
    "force_error_max_after_2s",
)
_CONVERGENCE = ("t_converge_force_s", "t_converge_tracking_s", "force_band_n", "tracking_band_m")
_SAFETY = (  # from the summary
    "min_obstacle_distance",
    "min_obstacle_distance_key_point",
    "min_obstacle_distance_obstacle",
    "min_obstacle_distance_t",
    "d_safe",
    "joint_limit_violations",
    "joint_velocity_limit_violations",
    "max_abs_v",
    "infeasible_ticks",
    "non_optimal_ticks",
    "fallback_ticks",
    "zero_velocity_ticks",
    "error_ticks",
    "invalid_ticks",
    "first_error",
)
_SOLVE_TIMES = (  # from the summary
    "solve_time_median_s",
    "solve_time_p99_s",
    "solve_time_max_s",
    "deadline_misses",
)
_REALTIME = (  # from the summary (timing)
    "realtime",
    "realtime_reason",
    "realtime_solver",
    "realtime_solver_reason",
    "over_dt_share",
    "solver_time_p99_s",
    "solver_over_dt_share",
)
_WALL = ("wall_time_s", "real_time_factor")  # from the summary
_PLACE = ("executor", "host", "worker", "concurrent_solves")

#: Summary keys whose column has another name.
RENAMED = {"duration": "duration_s"}

#: Figures copied from the closed loop's summary as they are (column: ``RENAMED`` or the key).
SUMMARY_COLUMNS = _RUN + _SAFETY + _SOLVE_TIMES + _REALTIME + _WALL

#: Columns of ``sweep.csv``, in order.
COLUMNS = (
    _HEAD
    + tuple(RENAMED.get(key, key) for key in _RUN)
    + _CONVERGENCE
    + _SAFETY
    + _SOLVE_TIMES
    + ("ticks_over_1ms",)
    + _REALTIME
    + _WALL
    + ("verdict_overrides",)
    + _PLACE
)

#: Columns that depend on timing or on where the run was made (ignored when comparing two sweeps).
TIMING_COLUMNS = ("attempts",) + _SOLVE_TIMES + ("ticks_over_1ms",) + _REALTIME + _WALL + _PLACE

#: One tick's solve longer than this misses a 1 kHz loop's deadline [s].
KHZ_DEADLINE_S = 1e-3


def time_to_converge(t: np.ndarray, error: np.ndarray, band: float) -> float | None:
    """First time [s] from which ``|error| <= band`` holds at every tick to the end.

    ``None`` when the last tick is outside the band (or not finite): the run
    did not converge in the simulated time. ``t[0]`` when it never left it.
    """
    if len(t) == 0:
        return None
    outside = ~(np.abs(np.asarray(error, dtype=float)) <= band)
    if outside[-1]:
        return None
    idx = np.flatnonzero(outside)
    return float(t[0]) if idx.size == 0 else float(t[idx[-1] + 1])


def _head(meta: dict) -> dict:
    row = {c: None for c in COLUMNS}
    for key in ("instance", "backend", "instance_file", "sample", "sweep", "base_scenario"):
        row[key] = meta[key]
    row["parameters"] = json.dumps(meta["parameters"], separators=(",", ":"))
    row["force_band_n"], row["tracking_band_m"] = meta["force_band"], meta["tracking_band"]
    row["duration_s"] = meta.get("duration")
    return row


def result_row(meta: dict, summary: dict, log: pd.DataFrame) -> dict:
    """The row of a run that gave a result: the summary's figures plus those taken from the tick log.

    ``log`` is the run's tick log (columns ``t``, ``force_error``,
    ``tracking_error``, ``solve_time_s``).
    """
    row = _head(meta)
    for key in SUMMARY_COLUMNS:
        value = summary.get(key)
        if isinstance(value, (np.generic,)):
            value = value.item()
        row[RENAMED.get(key, key)] = value
    row["status"], row["error"] = "ok", ""
    row["verdict"], row["verdict_reasons"] = (
        summary.get("verdict"),
        summary.get("verdict_reasons", ""),
    )
    row["verdict_overrides"] = json.dumps(summary.get("verdict_overrides") or {})
    t = log["t"].to_numpy(dtype=float)
    row["t_converge_force_s"] = time_to_converge(
        t, log["force_error"].to_numpy(), meta["force_band"]
    )
    row["t_converge_tracking_s"] = time_to_converge(
        t, log["tracking_error"].to_numpy(), meta["tracking_band"]
    )
    solve = log["solve_time_s"].to_numpy(dtype=float)
    row["ticks_over_1ms"] = int(np.count_nonzero(solve > KHZ_DEADLINE_S))
    return row


def failed_row(meta: dict, status: str, message: str) -> dict:
    """The row of a run without a result: ``error``/``crashed`` (verdict ``incomplete``) or ``invalid_scenario``."""
    row = _head(meta)
    row["status"], row["error"] = status, " ".join(str(message).split())
    if status == "invalid_scenario":
        row["verdict"], row["verdict_reasons"] = "", ""
    else:
        from ..sim.verdict import failed_run

        verdict = failed_run(status, row["error"])
        row["verdict"], row["verdict_reasons"] = verdict.verdict, verdict.text
        row["realtime"], row["realtime_reason"] = "no", "no result to time"
        row["realtime_solver"], row["realtime_solver_reason"] = "unknown", "no result to time"
    return row


def same_outside_timing(a: dict, b: dict) -> list[str]:
    """Columns where rows ``a`` and ``b`` differ, timing columns aside (floats compared exactly, as text)."""
    from ..harness.results import cell

    return [
        c
        for c in COLUMNS
        if c not in TIMING_COLUMNS and cell(_parse(a.get(c))) != cell(_parse(b.get(c)))
    ]


def _parse(value):
    """A cell as it reads back: text of a number -> the number (``""`` -> None)."""
    if value is None or (isinstance(value, float) and math.isnan(value)):
        return None
    if isinstance(value, str):
        if value == "":
            return None
        for kind in (int, float):
            try:
                return kind(value)
            except ValueError:
                pass
    return value
