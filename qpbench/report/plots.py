"""PNG figures of a report (matplotlib, Agg backend, imported inside the functions).

Keys of the returned mapping (used by :mod:`qpbench.report.markdown`):

- ``perf_profile_<group>``: Dolan-More performance profile of runtime;
- ``per_tick_<group>_<scenario>``: solve time and optimality gap against t;
- ``closed_loop_<scenario>_<formulation>``: every backend's run overlaid
  (:func:`qpbench.report.loop_figure.closed_loop_figure`): tracking and force
  error on log scales, the closest key point against ``d_safe``, solve time
  per tick against the 1 ms budget, ``|v|^2``, ``Kp_hat`` when adapting;
- ``closed_loop_v_<scenario>_<formulation>``: joint velocities, one panel per backend;
- ``closed_loop_d_<scenario>_<formulation>``: every key point's distance to every
  obstacle, one panel per backend;
- ``snapshot_<role>_<scenario>_<formulation>``: the arm, for the fastest exact
  backend and the network (:mod:`qpbench.report.snapshots`).

Closed-loop figures read each run's tick log, or its figure log when the tick
log is absent (:func:`qpbench.report.logs.read_log`). Figures of a previous report in the folder
that this one no longer links are removed (:func:`remove_unlinked`).
"""

from __future__ import annotations

import logging
import re
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np
import pandas as pd

from ..atomic import atomic_path
from ..sim import log as tick_log
from . import tables
from .logs import read_log as _read_log
from .snapshots import write_snapshots
from .tables import slug

if TYPE_CHECKING:
    from collections.abc import Iterable

log = logging.getLogger("qpbench.report")


def _velocity_columns(df: pd.DataFrame) -> list[str]:
    """Joint-velocity columns ``v_i`` of a tick log, in joint order."""
    return tick_log.velocity_columns(tick_log.joint_count(df))


def _pyplot():
    import matplotlib

    matplotlib.use("Agg", force=True)
    import matplotlib.pyplot as plt

    return plt


def _colours(ax, n: int) -> None:
    """Distinct colours for up to 20 lines (matplotlib's default cycle has 10)."""
    if n > 10:
        plt = _pyplot()
        ax.set_prop_cycle(color=plt.cm.tab20.colors)


def _save(fig, path: Path) -> None:
    plt = _pyplot()
    with atomic_path(path) as tmp:
        fig.savefig(tmp, format="png", dpi=110, bbox_inches="tight")
    plt.close(fig)


def performance_profile_plot(rows: pd.DataFrame, label: str, path: Path) -> None:
    """Dolan-More profile ``rho_s(tau)`` of runtime for each backend (log-scale tau)."""
    plt = _pyplot()
    taus, profiles = tables.performance_profile(rows)
    fig, ax = plt.subplots(figsize=(6.5, 4.0))
    _colours(ax, len(profiles))
    for backend, rho in profiles.items():
        ax.step(taus, rho, where="post", label=backend)
    ax.set_xscale("log")
    ax.set_ylim(-0.02, 1.02)
    ax.set_xlabel("tau (runtime / best runtime)")
    ax.set_ylabel("fraction of problems solved")
    ax.set_title(f"Performance profile of runtime ({label})")
    ax.grid(True, which="both", alpha=0.3)
    ax.legend(fontsize=7, loc="lower right")
    _save(fig, path)


def per_tick_plot(rows: pd.DataFrame, title: str, path: Path) -> bool:
    """Solve time [us] and |optimality gap| against t [s], one line per backend."""
    if "t" not in rows.columns:
        return False
    df = rows.copy()
    df["t"] = pd.to_numeric(df["t"], errors="coerce")
    df = df[np.isfinite(df["t"])]
    if df.empty:
        return False
    plt = _pyplot()
    fig, (ax_t, ax_g) = plt.subplots(2, 1, figsize=(7.5, 5.5), sharex=True)
    _colours(ax_t, df["backend"].nunique())
    _colours(ax_g, df["backend"].nunique())
    drawn = {ax_t: False, ax_g: False}
    for backend, g in df.sort_values("t").groupby("backend", sort=True):
        t = g["t"].to_numpy(float)
        times = pd.to_numeric(g[tables.runtime_column(g)], errors="coerce").to_numpy(float) * 1e6
        ax_t.plot(t, times, lw=0.8, label=backend)
        gap = np.abs(pd.to_numeric(g["optimality_gap"], errors="coerce").to_numpy(float))
        gap = np.maximum(np.where(g["found"].to_numpy(bool), gap, np.nan), 1e-16)
        ax_g.plot(t, gap, lw=0.8, label=backend)
        drawn[ax_t] |= bool(np.any(np.isfinite(times) & (times > 0)))
        drawn[ax_g] |= bool(np.any(np.isfinite(gap)))
    for ax, shown in drawn.items():
        if shown:  # a log axis needs one positive value (no solution found: nothing to draw)
            ax.set_yscale("log")
        else:
            ax.text(0.5, 0.5, "no solution found", transform=ax.transAxes, ha="center", va="center")
    ax_t.set_ylabel("solve time (us)")
    ax_t.set_title(title)
    ax_g.set_ylabel("|optimality gap|")
    ax_g.set_xlabel("t (s)")
    for ax in (ax_t, ax_g):
        ax.grid(True, which="both", alpha=0.3)
    ax_t.legend(fontsize=7, ncol=2)
    _save(fig, path)
    return True


def closed_loop_plots(
    runs: pd.DataFrame, scenario: str, formulation: str, path: Path, path_v: Path
) -> tuple[bool, bool]:
    """The closed-loop figure of one scenario, every backend overlaid
    (:func:`qpbench.report.loop_figure.closed_loop_figure`), and the joint velocities per backend."""
    from .loop_figure import closed_loop_figure

    logs = {}
    d_safe = None
    for _, r in runs.iterrows():
        df = _read_log(r.get("log_path"))
        if df is not None and tick_log.T in df.columns and len(df):
            logs[str(r["backend"])] = df
            value = r.get("d_safe")
            if value is not None and np.isfinite(float(value)):
                d_safe = float(value)
    if not logs:
        return False, False
    closed_loop_figure(logs, path, title=f"Closed loop, {scenario} ({formulation})", d_safe=d_safe)
    done_v = _per_backend_figure(
        logs,
        _velocity_columns,
        "v (rad/s)",
        1.0,
        f"Joint velocities, {scenario} ({formulation})",
        path_v,
    )
    return True, done_v


def _per_backend_figure(
    logs: dict, columns, ylabel: str, scale: float, title: str, path: Path
) -> bool:
    """One panel per backend, one line per column that ``columns(log)`` names."""
    with_cols = {b: d for b, d in logs.items() if columns(d)}
    if not with_cols:
        return False
    plt = _pyplot()
    fig, axes = plt.subplots(
        len(with_cols), 1, figsize=(7.5, 1.8 * len(with_cols) + 0.6), sharex=True, squeeze=False
    )
    for ax, (backend, d) in zip(axes[:, 0], with_cols.items()):
        for c in columns(d):
            ax.plot(d[tick_log.T].to_numpy(float), d[c].to_numpy(float) * scale, lw=0.8, label=c)
        ax.set_ylabel(f"{backend}\n{ylabel}", fontsize=8)
        ax.grid(True, alpha=0.3)
    axes[0, 0].set_title(title)
    axes[0, 0].legend(fontsize=6, ncol=4)
    axes[-1, 0].set_xlabel("t (s)")
    _save(fig, path)
    return True


def keypoint_plot(runs: pd.DataFrame, scenario: str, formulation: str, path: Path) -> bool:
    """Distance of every key point to every obstacle [mm], one panel per backend."""
    logs = {}
    for _, r in runs.iterrows():
        df = _read_log(r.get("log_path"))
        if df is not None and tick_log.T in df.columns and len(df):
            logs[str(r["backend"])] = df
    return _per_backend_figure(
        logs,
        tick_log.distance_columns,
        "distance (mm)",
        1e3,
        f"Key-point distances, {scenario} ({formulation})",
        path,
    )


def write_plots(
    results: tables.Results, folder: str | Path, relative_to: str | Path
) -> dict[str, str]:
    """Write every figure of a report into ``folder``; return key -> path relative to ``relative_to``."""
    folder = Path(folder)
    folder.mkdir(parents=True, exist_ok=True)
    files: dict[str, str] = {}

    def _rel(p: Path) -> str:
        return Path(p).resolve().relative_to(Path(relative_to).resolve()).as_posix()

    for label, _tol, rows in tables.bench_groups(results.bench):
        key = f"perf_profile_{slug(label)}"
        performance_profile_plot(rows, label, folder / f"{key}.png")
        files[key] = _rel(folder / f"{key}.png")
        if "scenario" in rows.columns:
            for scenario, g in rows.groupby(rows["scenario"].map(tables.scenario_key), sort=True):
                key = f"per_tick_{slug(label)}_{slug(scenario)}"
                if per_tick_plot(g, f"{scenario} ({label})", folder / f"{key}.png"):
                    files[key] = _rel(folder / f"{key}.png")
    df = results.closed_loop
    if not df.empty:
        for (scenario, formulation), g in df.groupby(
            [df["scenario"].astype(str), df["formulation"].fillna("-").astype(str)], sort=False
        ):
            key = f"closed_loop_{slug(scenario)}_{slug(formulation)}"
            key_v = f"closed_loop_v_{slug(scenario)}_{slug(formulation)}"
            done, done_v = closed_loop_plots(
                g, scenario, formulation, folder / f"{key}.png", folder / f"{key_v}.png"
            )
            if done:
                files[key] = _rel(folder / f"{key}.png")
            if done_v:
                files[key_v] = _rel(folder / f"{key_v}.png")
            key_d = f"closed_loop_d_{slug(scenario)}_{slug(formulation)}"
            if done and keypoint_plot(g, scenario, formulation, folder / f"{key_d}.png"):
                files[key_d] = _rel(folder / f"{key_d}.png")
            files.update(
                {k: _rel(p) for k, p in write_snapshots(g, scenario, formulation, folder).items()}
            )
    remove_unlinked(folder, files.values(), relative_to)
    return files


#: Names of the figures :func:`write_plots` writes (and so may remove when it no longer links them).
FIGURE_PATTERN = re.compile(r"(perf_profile|per_tick|closed_loop|snapshot)_[A-Za-z0-9_.+-]*\.png")


def remove_unlinked(
    folder: str | Path, linked: Iterable[str], relative_to: str | Path
) -> list[Path]:
    """Remove the figures of a previous report in ``folder`` that the new one does not link.

    Only files named as :func:`write_plots` names its figures
    (:data:`FIGURE_PATTERN`) are removed; any other file stays. Returns them.
    """
    keep = {(Path(relative_to) / p).resolve() for p in linked}
    removed = []
    for path in sorted(Path(folder).iterdir()):
        if path.is_file() and FIGURE_PATTERN.fullmatch(path.name) and path.resolve() not in keep:
            path.unlink(missing_ok=True)
            removed.append(path)
    if removed:
        log.info("%s: removed %d figures no longer in the report", folder, len(removed))
    return removed
