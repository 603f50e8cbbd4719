"""The report's pictures of the arm (:func:`qpbench.report.arm.draw_snapshot`): per scenario
and formulation, the *fastest exact backend* (a QP solver, neither the network nor the
pseudo-inverse, whose run ended ``ok`` and whole, with the smallest median solve time) and the
*network* (``rnn-tuned``, else ``rnn``, else another), from each run's tick or figure log.
Keys: ``snapshot_<role>_<scenario>_<formulation>``."""

from __future__ import annotations

import logging
from pathlib import Path

import numpy as np
import pandas as pd

from .inputs import numbers
from .markdown_table import slug

log = logging.getLogger("qpbench.report")

#: The two pictures of a scenario, left to right: role -> column header in the report.
ROLES = {"exact": "fastest exact backend", "network": "network"}
#: Network backends in order of preference.
NETWORKS = ("rnn-tuned", "rnn")


def read_log(path: str | None) -> pd.DataFrame | None:
    """The run's log (``log_path``) as a frame (``None``: no log, or a damaged one, warned)."""
    if path is None:
        return None
    try:
        return pd.read_parquet(path)
    except Exception as exc:  # noqa: BLE001 - a damaged log only loses its curve
        log.warning("%s: cannot read tick log (%s)", path, exc)
        return None


def _family(backend: str) -> str:
    from ..backends import backend_class

    try:
        return str(backend_class(backend).family)
    except Exception:  # noqa: BLE001 - an unknown (plugin) backend: judged by its name
        return "recurrent neural network" if backend.startswith("rnn") else ""


def snapshot_runs(runs: pd.DataFrame) -> dict[str, pd.Series]:
    """Of one scenario's runs (one formulation), the row of each role that has one."""
    runs = runs[runs["log_path"].notna().to_numpy()]
    chosen: dict[str, pd.Series] = {}
    whole = numbers(runs, "simulated_s") >= numbers(runs, "duration_s") - 1e-9
    families = [_family(str(b)) for b in runs["backend"]]
    network = np.array(["neural network" in f for f in families], dtype=bool)
    exact = ~network & ~np.array([f.startswith("pseudo-inverse") for f in families], dtype=bool)
    exact = runs[exact & (runs["verdict"].astype(str) == "ok").to_numpy(bool) & whole]
    if not exact.empty:
        p50 = numbers(exact, "solve_time_median_s")
        chosen["exact"] = exact.iloc[int(np.argmin(np.where(np.isnan(p50), np.inf, p50)))]
    networks = runs[network]
    if not networks.empty:
        rank = [
            NETWORKS.index(b) if b in NETWORKS else len(NETWORKS)
            for b in networks["backend"].astype(str)
        ]
        chosen["network"] = networks.iloc[int(np.argmin(rank))]
    return chosen


def write_snapshots(
    runs: pd.DataFrame, scenario: str, formulation: str, folder: Path
) -> dict[str, Path]:
    """Draw the snapshots of one scenario's runs into ``folder``; return key -> file."""
    from ..sim.log import theta_columns
    from ..sim.scenario import load_scenario
    from .arm import draw_snapshot

    files: dict[str, Path] = {}
    chosen = snapshot_runs(runs)
    if not chosen:
        return files
    try:
        scene = load_scenario(scenario)
    except Exception as exc:  # noqa: BLE001 - a scenario not found here only loses its pictures
        log.warning("%s: no arm snapshot (%s)", scenario, exc)
        return files
    for role, row in chosen.items():
        frame = read_log(row["log_path"])
        if frame is None or not set(theta_columns(scene.make_arm().n)) <= set(frame.columns):
            continue  # no log, or one without the joint angles: no picture of the arm
        key = f"snapshot_{role}_{slug(scenario)}_{slug(formulation)}"
        path = folder / f"{key}.png"
        draw_snapshot(
            scene,
            frame,
            path,
            title=f"{scenario}: {row['backend']} ({ROLES[role]})",
            backend=str(row["backend"]),
        )
        files[key] = path
    return files
