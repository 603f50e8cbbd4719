"""The kept ticks' QPs of a closed-loop run written as a problem set (``simulate --dump``)."""

from __future__ import annotations

from pathlib import Path

from .scenario import Scenario
from .summary import jsonable

__all__ = ["write_dump"]


def write_dump(
    folder: str | Path,
    records: list,
    scenario: Scenario,
    backend_name: str,
    formulation: str,
    every: int | None,
    duration: float | None,
    dt: float | None,
) -> Path:
    """Write the kept ticks' QPs as a problem set; the manifest holds the scenario file's full text."""
    from ..formats import write_problem_set

    generator = {
        "name": "qpbench simulate",
        "scenario": scenario.name,
        "backend": backend_name,
        "formulation": formulation,
        "every": every,
        "duration": duration,
        "dt": dt,
    }
    extra = {
        "scenario_file": scenario.path.name if scenario.path is not None else None,
        "scenario_toml": scenario.source,
        "ticks_per_record": every,
    }
    if scenario.overrides:  # values set over the file's (the TOML above is the file as it is)
        extra["scenario_overrides"] = jsonable(scenario.overrides)
    return write_problem_set(folder, records, generator=generator, extra=extra)
