"""One closed-loop run of the table: a warm-up, the timed run, its tick log and its row.

Called in this process or in a worker process (:mod:`qpbench.harness.loop_workers`);
either way a run that raises becomes an ``error`` row, never an exception.
"""

from __future__ import annotations

import logging
from dataclasses import dataclass
from pathlib import Path

import pandas as pd

from ..atomic import atomic_path
from .loop_rows import LOG_DIR, error_row, log_name, row_from_summary

__all__ = ["WARMUP_TICKS", "RunSpec", "run_guarded", "simulate_one"]

log = logging.getLogger("qpbench.harness")

#: Ticks of the discarded warm-up run before each timed run.
WARMUP_TICKS = 3


@dataclass(frozen=True)
class RunSpec:
    """What one run needs (picklable: it travels to a worker process).

    Attributes:
        scenario: Scenario name or TOML path. backend: Backend name.
        formulation: ``paper`` or ``soft``. duration: Simulated time [s] (``None``: the scenario's).
        out: Output folder (the tick log goes to ``out/logs/``, its figure log to ``out/figure_logs/``).
        deadline: Per-tick deadline [s] or ``None``. run_budget: Wall-time budget [s] or ``None``.
        overrides: ``(dotted key, value)`` pairs set over the scenario file's (``--set``).
    """

    scenario: str
    backend: str
    formulation: str
    duration: float | None
    out: str
    deadline: float | None = None
    run_budget: float | None = None
    overrides: tuple = ()

    @property
    def log_path(self) -> Path:
        return Path(self.out) / LOG_DIR / log_name(self.scenario, self.backend)


def simulate_one(spec: RunSpec, log_path: Path | None) -> tuple[dict, pd.DataFrame]:
    """Run one (scenario, backend) and return its table row and tick log.

    The tick log is written atomically to ``log_path`` (Parquet) when given, and
    its figure log (:mod:`qpbench.sim.figure_log`: what the report's figures
    draw, small enough to keep with the results) to ``<out>/figure_logs/``.
    The backend is passed by name, so a backend that reads a scenario table
    (the ``rnn`` backends: ``[rnn]``) gets it, and an online one the loop's
    ``dt`` (:func:`qpbench.sim.loop.resolve_backend`). ``run_budget`` is the
    wall-time budget of the timed run (``wall_budget_s`` of
    :func:`qpbench.sim.loop.simulate`; the warm-up is outside it).
    Exceptions propagate (the caller turns them into an error row).
    """
    from ..jit import warmup
    from ..sim.figure_log import figure_log_path, write_figure_log
    from ..sim.loop import simulate
    from ..sim.scenario import load_scenario

    scenario = load_scenario(spec.scenario, overrides=dict(spec.overrides) or None)
    warmup([spec.backend])  # the loop's and this backend's kernels, before the clock
    # warm-up: a discarded run of a few ticks, so one-off costs (solver imports, first-call
    # allocations; the numba kernels are ready before, see qpbench.jit) stay out of the timed run
    simulate(
        scenario,
        spec.backend,
        formulation=spec.formulation,
        duration=WARMUP_TICKS * scenario.dt,
        deadline=spec.deadline,
    )
    result = simulate(
        scenario,
        spec.backend,
        formulation=spec.formulation,
        duration=spec.duration,
        deadline=spec.deadline,
        wall_budget_s=spec.run_budget,
    )
    row = row_from_summary(spec.scenario, spec.backend, result.summary)
    if log_path is not None:
        with atomic_path(log_path) as tmp:
            result.log.to_parquet(tmp, index=False)
        write_figure_log(result.log, figure_log_path(log_path))
    return row, result.log


def run_guarded(spec: RunSpec) -> dict:
    """One run's row, its log written; a run that raises is an ``error`` row."""
    log_path = spec.log_path
    try:
        row, _ = simulate_one(spec, log_path)
        row["log_file"] = f"{LOG_DIR}/{log_path.name}"
    except Exception as exc:  # noqa: BLE001 - one failing run must not stop the others
        log.warning(
            "closed loop %s with %s failed: %s: %s",
            spec.scenario,
            spec.backend,
            type(exc).__name__,
            exc,
        )
        row = error_row(spec.scenario, spec.backend, spec.formulation, spec.duration, exc)
    return row
