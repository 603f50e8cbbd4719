"""Closed-loop runs in worker processes, each with a deadline for the whole run.

A hang in native code cannot be interrupted in this process, nor a crash
survived: such a run is made in a worker process of its own
(:func:`qpbench.runner.process.run_tasks`, a new worker per run) with a
deadline (:func:`run_deadline`). A
worker that dies gives a row with status ``crashed`` and the signal
(``worker process killed by SIGSEGV during the closed-loop run``); one that
overruns its deadline is killed (SIGKILL) and gives a row with status
``time_limit``; the other runs go on. Isolation costs no timing accuracy:
the worker times the run itself exactly as this process would (warm-up run
first); its start (a fork of the forkserver, which already holds qpbench and
the compiled kernels) adds only to the total duration.
"""

from __future__ import annotations

import logging
from collections.abc import Callable
from pathlib import Path

from ..runner.process import run_tasks
from .loop_rows import LOG_DIR, error_row, failure_row, log_name
from .loop_run import RunSpec, run_guarded

__all__ = ["RUN_TIME_LIMIT_MIN_S", "RUN_TIME_LIMIT_PER_SIM_S", "run_deadline", "run_in_workers"]

log = logging.getLogger("qpbench.harness")

#: Least deadline of an isolated run [s] (see :func:`run_deadline`).
RUN_TIME_LIMIT_MIN_S = 600.0
#: Deadline of an isolated run per simulated second [s] (a real-time factor of 1/50).
RUN_TIME_LIMIT_PER_SIM_S = 50.0


def run_deadline(
    scenario: str, duration: float | None, run_time_limit: float | None = None
) -> float:
    """Deadline [s] of one isolated run: ``run_time_limit`` when given, else
    ``max(RUN_TIME_LIMIT_MIN_S, RUN_TIME_LIMIT_PER_SIM_S * simulated seconds)``
    (600 s up to 12 s of simulated time). It covers the warm-up, the run and
    the writing of its tick log (the worker's start has a limit of its own)."""
    if run_time_limit is not None:
        return float(run_time_limit)
    if duration is None:
        try:
            from ..sim.scenario import load_scenario

            duration = load_scenario(scenario).duration
        except Exception:  # noqa: BLE001 - the run itself reports a bad scenario
            duration = 0.0
    return max(RUN_TIME_LIMIT_MIN_S, RUN_TIME_LIMIT_PER_SIM_S * float(duration))


def _run(task: tuple[RunSpec, list[str]]) -> dict:
    """In a run's worker process: load the parent's plugin files, make the run, give its row."""
    spec, plugins = task
    try:
        from ..backends import load_plugins

        load_plugins(plugins)
        return run_guarded(spec)
    except BaseException as exc:  # noqa: BLE001 - a plugin that fails to load
        return error_row(spec.scenario, spec.backend, spec.formulation, spec.duration, exc)


def _drop_partial_logs(spec: RunSpec) -> None:
    """Remove the temporary tick or figure log a dead worker may have left (never a complete one)."""
    from ..sim.figure_log import FIGURE_LOG_DIR

    name = log_name(spec.scenario, spec.backend)
    for folder in (LOG_DIR, FIGURE_LOG_DIR):
        for tmp in (Path(spec.out) / folder).glob(f".{name}.*.tmp"):
            tmp.unlink(missing_ok=True)


def run_in_workers(items: list[tuple], jobs: int, plugins: list[str], emit: Callable) -> None:
    """Run ``items`` (key, :class:`RunSpec`, deadline or None) in worker processes, ``jobs`` at a time.

    Each run has a process of its own: a run that dies or overruns its
    deadline becomes a ``crashed`` or ``time_limit`` row and takes no other
    run's row with it. ``emit(key, row)`` is called as each run ends.
    """
    specs = {key: (spec, deadline_s) for key, spec, deadline_s in items}
    tasks = [(key, (spec, plugins), deadline_s) for key, spec, deadline_s in items]
    for done in run_tasks(_run, tasks, jobs, fresh=True, name="qpbench-closed-loop"):
        spec, deadline_s = specs[done.key]
        if done.status is None:
            emit(done.key, done.value)
            continue
        if done.status == "time_limit":
            message = f"no result after {deadline_s:.3g} s (run time limit); worker killed"
        else:
            message = f"{done.lost} during the closed-loop run"
        _drop_partial_logs(spec)
        log.warning("closed loop %s with %s: %s", spec.scenario, spec.backend, message)
        row = failure_row(
            spec.scenario, spec.backend, spec.formulation, spec.duration, done.status, message
        )
        emit(done.key, row)
