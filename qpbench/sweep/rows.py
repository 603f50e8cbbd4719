"""The sweep table ``DIR/sweep.csv``: one row per (instance, backend), appended as runs end; a
resumed sweep appends the rows it re-runs, and the table is rewritten at the end with the last row
of each key.

A run's figures are its closed-loop summary's (:mod:`qpbench.sim.summary`; ``duration_s`` is
``duration``) with the time-to-converge figures ``t_converge_force_s`` and
``t_converge_tracking_s`` (empty: not converged) of the bands ``force_band_n`` [N] and
``tracking_band_m`` [m]. ``status``: ``ok`` (a result, whatever its verdict), ``error`` (it
raised), ``crashed`` (its worker was lost twice; ``attempts``: runs started) or
``invalid_scenario`` (the loader refused the instance; no verdict). ``executor``, ``host``,
``worker``, ``concurrent_solves``: where it ran.
"""

from __future__ import annotations

import json
from typing import TYPE_CHECKING

from ..harness.closed_loop import TABLE_NAMES

if TYPE_CHECKING:
    from .sample import Instance
    from .spec import SweepSpec

#: Names of the table and of the instances' folder inside the sweep's folder.
CSV_NAME = "sweep.csv"
INSTANCE_DIR = "instances"

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

#: Figures copied from the closed loop's row (column: ``TABLE_NAMES`` or the key).
SUMMARY_COLUMNS = _RUN + _SAFETY + _SOLVE_TIMES + _REALTIME + _WALL

#: Columns of ``sweep.csv``, in order.
COLUMNS = (
    _HEAD
    + tuple(TABLE_NAMES.get(key, key) for key in _RUN)
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


def head_row(spec: SweepSpec, inst: Instance, backend: str) -> dict:
    """The row of ``backend``'s run of instance ``inst`` of sweep ``spec``, without its figures."""
    row = dict.fromkeys(COLUMNS)
    row.update(
        instance=inst.name,
        backend=backend,
        instance_file=f"{INSTANCE_DIR}/{inst.name}.toml",
        sample=inst.index,
        sweep=spec.name,
        base_scenario=spec.base,
        parameters=json.dumps(inst.values, separators=(",", ":")),
        duration_s=spec.duration,
        force_band_n=spec.force_band,
        tracking_band_m=spec.tracking_band,
    )
    return row


def sweep_row(head: dict, row: dict) -> dict:
    """The sweep's row (``head``: :func:`head_row`) of a closed-loop row
    (:func:`qpbench.harness.closed_loop.run_row` or
    :func:`~qpbench.harness.closed_loop.failure_fields`)."""
    return head | {key: row[key] for key in COLUMNS if key in row and key not in _HEAD[:7]}
