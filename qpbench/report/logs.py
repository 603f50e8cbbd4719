"""A closed-loop run's log as the report's figures read it: the tick log, else its figure log."""

from __future__ import annotations

import logging
from pathlib import Path

import pandas as pd

__all__ = ["log_file", "read_log"]

log = logging.getLogger("qpbench.report")


def log_file(path: str | Path) -> str | None:
    """A run's tick log; its figure log (:mod:`qpbench.sim.figure_log`) when the full one is absent; else ``None``."""
    from ..sim.figure_log import figure_log_path

    if not isinstance(path, str) or not path:
        return None
    if Path(path).exists():
        return path
    compact = figure_log_path(path)
    return str(compact) if compact.exists() else None


def read_log(path: str | Path) -> pd.DataFrame | None:
    path = log_file(path)
    if path is None:
        return None
    try:
        return pd.read_parquet(path)
    except Exception as exc:  # noqa: BLE001 - a damaged log only loses its curve
        log.warning("%s: cannot read tick log (%s)", path, exc)
        return None
