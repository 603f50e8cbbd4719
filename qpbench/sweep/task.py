"""One task of a sweep: one instance's closed loop with one backend, turned into its row.

A task carries everything it needs as plain data (the instance's scenario
text, the backend's name, the plugins to load), so it runs the same in this
process, in a local worker process or on a Dask worker on another machine:
nothing is read from the sweep's folder there, and only the row comes back.

:func:`closed_loop_run` is the one place a sweep calls the closed loop.
"""

from __future__ import annotations

import logging
from dataclasses import dataclass, field
from typing import TYPE_CHECKING

if TYPE_CHECKING:
    import pandas as pd

    from ..sim.scenario import Scenario

log = logging.getLogger("qpbench.sweep")

__all__ = ["SweepTask", "closed_loop_run", "run_task"]

#: Ticks of the discarded warm-up run before each run (one-off costs out of the timed run).
WARMUP_TICKS = 3


@dataclass(frozen=True)
class SweepTask:
    """One (instance, backend) run, as plain picklable data.

    Attributes:
        meta: The row's identifying columns (``instance``, ``backend``,
            ``instance_file``, ``sample``, ``sweep``, ``base_scenario``,
            ``parameters``, ``duration``, ``force_band``, ``tracking_band``).
        scenario_text: The instance's scenario file (TOML).
        plugins: Plugin ``.py`` files registering extra backends (:func:`qpbench.backends.plugin_files`).
    """

    meta: dict
    scenario_text: str
    plugins: tuple = field(default_factory=tuple)

    @property
    def key(self) -> tuple[str, str]:
        return self.meta["instance"], self.meta["backend"]


def closed_loop_run(scenario: Scenario, backend: str) -> tuple[dict, pd.DataFrame]:
    """Run ``scenario`` (a :class:`~qpbench.sim.scenario.Scenario`) in closed loop with ``backend``.

    A discarded warm-up run of :data:`WARMUP_TICKS` ticks first, then the
    run itself; returns ``(summary, tick log)`` of
    :func:`qpbench.sim.loop.simulate` (the summary with its verdict). The
    backend goes by name, so the ``rnn`` backends get the scenario's
    ``[rnn]`` settings and its ``dt``.
    """
    from ..jit import warmup
    from ..sim.loop import simulate

    warmup([backend])  # loads what the parent compiled (nothing more), before the clock
    simulate(scenario, backend, duration=WARMUP_TICKS * scenario.dt)
    result = simulate(scenario, backend)
    return result.summary, result.log


def run_task(task: SweepTask) -> dict:
    """The row of ``task`` (module level: worker processes and Dask workers call it by name).

    An exception of the run becomes a row with status ``error``; only a
    lost process loses the row (the executor then says ``crashed``).
    """
    from ..backends import load_plugins
    from ..sim.scenario import parse_scenario
    from ..statuses import describe_exception
    from .rows import failed_row, result_row

    try:
        load_plugins(list(task.plugins))
        scenario = parse_scenario(task.scenario_text, path=task.meta["instance_file"])
        summary, tick_log = closed_loop_run(scenario, task.meta["backend"])
        return result_row(task.meta, summary, tick_log)
    except Exception as exc:  # noqa: BLE001 - one failing run must not stop the sweep
        log.warning(
            "%s / %s failed: %s",
            task.meta["instance"],
            task.meta["backend"],
            describe_exception(exc),
        )
        return failed_row(task.meta, "error", describe_exception(exc))
