"""Closed-loop runs in worker processes, each with a deadline for the whole run.

A hang in native code cannot be interrupted in this process, nor a crash
survived: such a run is made in a worker process of its own
(:mod:`qpbench.harness.workers`) with a deadline (:func:`run_deadline`). A
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
import math
import time
from collections.abc import Callable
from pathlib import Path

from .loop_rows import LOG_DIR, error_row, failure_row, log_name
from .loop_run import RunSpec, run_guarded
from .workers import death_message, ignore_interrupts, start_worker, stop_worker

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
    (600 s up to 12 s of simulated time). It covers the worker's start, the
    warm-up, the run and the writing of its tick log."""
    if run_time_limit is not None:
        return float(run_time_limit)
    if duration is None:
        try:
            from ..sim.scenario import load_scenario

            duration = load_scenario(scenario).duration
        except Exception:  # noqa: BLE001 - the run itself reports a bad scenario
            duration = 0.0
    return max(RUN_TIME_LIMIT_MIN_S, RUN_TIME_LIMIT_PER_SIM_S * float(duration))


def _worker_main(conn, spec: RunSpec, plugins: list[str]) -> None:
    """Body of a run's worker process: load the parent's plugin files, make the run, send its row."""
    ignore_interrupts()
    try:
        from ..backends import load_plugins

        load_plugins(plugins)
        row = run_guarded(spec)
    except BaseException as exc:  # noqa: BLE001 - a plugin that fails to load
        row = error_row(spec.scenario, spec.backend, spec.formulation, spec.duration, exc)
    conn.send(row)
    conn.close()


class _RunWorker:
    """One run in its own worker process, with an optional deadline."""

    def __init__(
        self, key: tuple[str, str], spec: RunSpec, plugins: list[str], deadline_s: float | None
    ):
        self.key, self.spec = key, spec
        self.proc, self.conn = start_worker(
            _worker_main,
            (spec, plugins),
            duplex=False,
            name=f"qpbench-closed-loop-{key[0]}-{key[1]}",
        )
        self.deadline_s = deadline_s
        self.deadline = math.inf if deadline_s is None else time.monotonic() + deadline_s

    def result(self, now: float) -> dict | None:
        """The run's row once it is over (finished, died or past its deadline), else ``None``."""
        spec = self.spec
        try:
            if self.conn.poll():
                row = self.conn.recv()
                self.proc.join(5)
                stop_worker(None, self.conn)
                return row
        except (EOFError, OSError):
            pass
        if not self.proc.is_alive():
            self.proc.join()
            message = f"{death_message(self.proc.exitcode)} during the closed-loop run"
            status = "crashed"
        elif now >= self.deadline:
            message = f"no result after {self.deadline_s:.3g} s (run time limit); worker killed"
            status = "time_limit"
        else:
            return None
        self.kill()
        self._drop_partial_log()
        log.warning("closed loop %s with %s: %s", spec.scenario, spec.backend, message)
        return failure_row(
            spec.scenario, spec.backend, spec.formulation, spec.duration, status, message
        )

    def kill(self) -> None:
        stop_worker(self.proc, self.conn)

    def _drop_partial_log(self) -> None:
        """Remove the temporary tick or figure log a dead worker may have left (never a complete one)."""
        from ..sim.figure_log import FIGURE_LOG_DIR

        name = log_name(self.spec.scenario, self.spec.backend)
        for folder in (LOG_DIR, FIGURE_LOG_DIR):
            for tmp in (Path(self.spec.out) / folder).glob(f".{name}.*.tmp"):
                tmp.unlink(missing_ok=True)


def run_in_workers(items: list[tuple], jobs: int, plugins: list[str], emit: Callable) -> None:
    """Run ``items`` (key, :class:`RunSpec`, deadline or None) in worker processes, ``jobs`` at a time.

    Each run has a process of its own: a run that dies or overruns its
    deadline becomes a ``crashed`` or ``time_limit`` row and takes no other
    run's row with it. ``emit(key, row)`` is called as each run ends.
    """
    from multiprocessing.connection import wait

    pending = list(items)
    active: list[_RunWorker] = []
    try:
        while pending or active:
            while pending and len(active) < jobs:
                key, spec, deadline_s = pending.pop(0)
                active.append(_RunWorker(key, spec, plugins, deadline_s))
            now = time.monotonic()
            timeout = min(w.deadline for w in active) - now
            wait(
                [w.conn for w in active] + [w.proc.sentinel for w in active],
                timeout=None if timeout == math.inf else max(timeout, 0.0),
            )
            now = time.monotonic()
            for w in list(active):
                row = w.result(now)
                if row is not None:
                    active.remove(w)
                    emit(w.key, row)
    finally:
        for w in active:  # interrupted: no orphan workers
            w.kill()
