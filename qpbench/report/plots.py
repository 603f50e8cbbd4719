"""PNG figures of a report by key: ``perf_profile_<group>``, ``per_tick_<group>_<scenario>``,
``closed_loop[_v|_d]_<scenario>_<formulation>`` (:mod:`.loop_figure`, joint velocities, closest
key point), ``snapshot_<role>_<scenario>_<formulation>`` (:func:`.arm.draw_snapshot`): the arm
under the *fastest exact backend* (a QP solver whose run ended ``ok`` and whole, with the
smallest median solve time) and the *network* (``rnn-tuned``, else ``rnn``, else another)."""

from __future__ import annotations

import logging
import re
from functools import partial
from pathlib import Path

import numpy as np
import pandas as pd

from ..sim import log as tick_log
from . import style, tables
from .arm import ROLES, closest_approach
from .inputs import Results, numbers
from .markdown_table import slug

log = logging.getLogger("qpbench.report")


def performance_profile_plot(rows: pd.DataFrame, label: str, path: Path) -> None:
    """Dolan-More profile ``rho_s(tau)`` of runtime (log tau), one panel per group of backends."""
    taus, profiles = tables.performance_profile(rows)
    fig, axes, groups = style.panels(profiles, 1, 4.6, 3.4, sharey=True)
    for ax, (title, group) in zip(axes[0], groups):
        for backend, lit in style.highlighted(profiles, group):
            kw = style.series(backend, lit, np.log(taus), lw=1.5, grey_lw=0.8)
            ax.step(taus, profiles[backend], where="post", **kw)
        ax.set(xscale="log", ylim=(-0.02, 1.02), xlabel="tau (runtime / best runtime)")
        ax.grid(True, which="both", alpha=0.3)
        style.legend_above(ax, title=title)
    axes[0, 0].set_ylabel("fraction of problems solved")
    fig.suptitle(f"Performance profile of runtime ({label}); grey: the other backends")
    style.save(fig, path)


def per_tick_plot(rows: pd.DataFrame, title: str, path: Path) -> bool:
    """Solve time [us] and |optimality gap| against t [s], one column per group of backends."""
    df = rows.assign(t=numbers(rows, "t"))
    df = df[np.isfinite(df["t"])]
    if df.empty:
        return False
    series = {}
    for backend, g in df.sort_values("t").groupby("backend", sort=True):
        times = numbers(g, tables.RUNTIME) * 1e6
        gap = np.abs(numbers(g, "optimality_gap"))
        gap = np.maximum(np.where(g["found"].to_numpy(bool), gap, np.nan), 1e-16)
        series[str(backend)] = (g["t"].to_numpy(float), times, gap)
    fig, axes, groups = style.panels(series, 2, 4.6, 2.4, sharex=True, sharey="row")
    shown = [any(np.any(np.isfinite(s[k]) & (s[k] > 0)) for s in series.values()) for k in (1, 2)]
    for col, (group_title, group) in enumerate(groups):
        for backend, lit in style.highlighted(series, group):
            t, times, gap = series[backend]
            kw = style.series(backend, lit, t, lw=0.9, grey_lw=0.6)
            axes[0, col].plot(t, times, **kw)
            axes[1, col].plot(t, gap, **kw)
        for ax, ok in zip(axes[:, col], shown):
            if ok:  # a log axis needs one positive value (no solution found: nothing to draw)
                ax.set_yscale("log")
            else:
                ax.text(0.5, 0.5, "no solution found", transform=ax.transAxes, ha="center")
            ax.grid(True, which="both", alpha=0.3)
        axes[1, col].set_xlabel("t (s)")
        style.legend_above(axes[0, col], title=group_title)
    axes[0, 0].set_ylabel("solve time (us)")
    axes[1, 0].set_ylabel("|optimality gap|")
    fig.suptitle(f"{title}; grey: the other backends")
    style.save(fig, path)
    return True


def _logs(runs: pd.DataFrame) -> tuple[dict, float | None]:
    """The tick (or figure) logs of ``runs`` by backend, and their ``d_safe`` [m]."""
    logs, d_safe = {}, None
    for _, r in runs.iterrows():
        df = read_log(r["log_path"])
        if df is not None and len(df):
            logs[str(r["backend"])] = df
            value = r.get("d_safe")
            if value is not None and np.isfinite(float(value)):
                d_safe = float(value)
    return logs, d_safe


def velocity_plot(logs: dict, title: str, path: Path) -> bool:
    """Joint velocities [rad/s] against t, one small panel per backend (titled in its colour),
    five panels a row; one colour per joint (viridis, not a backend's)."""
    joints = {b: tick_log.velocity_columns(tick_log.joint_count(d)) for b, d in logs.items()}
    names = [b for _, group in style.groups(logs, max_series=len(logs)) for b in group if joints[b]]
    if not names:
        return False
    ncol = min(5, len(names))
    nrow = -(-len(names) // ncol)
    fig, axes = style.subplots(nrow, ncol, 3.0 * ncol + 0.6, 1.55 * nrow + 1.0, sharex=True)
    for ax in axes.flat[len(names) :]:
        ax.set_visible(False)
    for ax, backend in zip(axes.flat, names):
        d, cols = logs[backend], joints[backend]
        t = d[tick_log.T].to_numpy(float)
        for c, colour in zip(cols, style.pyplot().cm.viridis(np.linspace(0.0, 0.85, len(cols)))):
            ax.plot(t, d[c].to_numpy(float), lw=0.8, color=colour, label=c)
        ax.set_title(backend, fontsize=9, color=style.look(backend).colour, loc="left")
        ax.tick_params(labelsize=7)
        ax.grid(True, alpha=0.3)
    for ax in axes[:, 0]:
        ax.set_ylabel("v (rad/s)", fontsize=8)
    for ax in axes[-1, :]:
        ax.set_xlabel("t (s)", fontsize=8)
    handles, labels = axes.flat[0].get_legend_handles_labels()
    where = dict(loc="outside upper right", ncol=len(labels), fontsize=8, frameon=False)
    fig.legend(handles, labels, **where)
    fig.suptitle(title, ha="left", x=0.02)
    style.save(fig, path)
    return True


def distance_plot(logs: dict, title: str, path: Path, d_safe: float | None) -> bool:
    """Each backend's ``d_min`` [mm] against t (``d_body_min`` dashed) on the distance axis of
    :mod:`.loop_figure`, a panel per group of backends; each closest approach marked and named."""
    from .loop_figure import distance_axis, has_distance

    logs = {b: d for b, d in logs.items() if has_distance(d)}
    if not logs:
        return False
    fig, axes, groups = style.panels(logs, 1, 4.6, 3.6, sharey=True)
    lowest = min(float(np.nanmin(d[tick_log.D_MIN].to_numpy(float))) for d in logs.values())
    for ax, (group_title, group) in zip(axes[0], groups):
        for backend, lit in style.highlighted(logs, group):
            _distance_series(ax, backend, logs[backend], lit)
        distance_axis(ax, d_safe, lowest * 1e3)
        ax.set_xlabel("t [s]")
        ax.grid(True, which="major", alpha=0.3)
        style.legend_above(ax, ncol=1, title=group_title)
    axes[0, 0].set_ylabel("closest key point to an obstacle [mm]\n(linear below d_safe, log above)")
    fig.suptitle(f"{title}; grey: the other backends")
    style.save(fig, path)
    return True


def _distance_series(ax, backend: str, d: pd.DataFrame, lit: bool) -> None:
    """One backend's ``d_min`` (and ``d_body_min``); its closest approach marked."""
    t = d[tick_log.T].to_numpy(float)
    dist = d[tick_log.D_MIN].to_numpy(float) * 1e3
    if not lit:
        ax.plot(t, dist, color=style.GREY, lw=0.7, zorder=1)
        return
    look = style.look(backend)
    ax.plot(t, dist, color=look.colour, ls=look.linestyle, lw=1.0, zorder=3)
    label = backend
    close = closest_approach(d)
    if close is not None:
        where = f"{close['key_point']} / {close['obstacle']}, {close['t']:.2f} s"
        label = f"{backend}: {close['distance'] * 1e3:.1f} mm, {where}"
        marker = look.line(lw=0, ms=7, zorder=4, markevery=None)
        ax.plot([close["t"]], [close["distance"] * 1e3], **marker)
    ax.plot([], [], **look.line(lw=1.0, label=label, markevery=None))  # legend: line and marker
    if "d_body_min" in d.columns:
        ax.plot(t, d["d_body_min"].to_numpy(float) * 1e3, color=look.colour, ls=(0, (2, 2)), lw=0.8)


def write_plots(
    results: Results, folder: str | Path, relative_to: str | Path, jobs: int = 1
) -> dict[str, str]:
    """Write every figure of a report into ``folder`` (and remove a previous report's there that
    it does not link, :data:`FIGURE_PATTERN`), ``jobs`` figures at a time (more than one: each
    in a worker process); return key -> path relative to ``relative_to``."""
    from .loop_figure import closed_loop_figure

    folder = Path(folder)
    folder.mkdir(parents=True, exist_ok=True)
    planned: dict[str, object] = {}  # key -> figure(path), False when there is nothing to draw
    for label, _tol, rows in tables.bench_groups(results.bench):
        planned[f"perf_profile_{slug(label)}"] = partial(performance_profile_plot, rows, label)
        for scenario, g in rows.groupby("scenario", sort=True):
            key = f"per_tick_{slug(label)}_{slug(scenario)}"
            planned[key] = partial(per_tick_plot, g, f"{scenario} ({label})")
    df = results.closed_loop  # without columns when there is no closed-loop run
    by = [] if df.empty else [df["scenario"].astype(str), df["formulation"].fillna("-").astype(str)]
    for (scenario, formulation), g in df.groupby(by, sort=False) if by else []:
        logs, d_safe = _logs(g)
        name, where = f"{slug(scenario)}_{slug(formulation)}", f"{scenario} ({formulation})"
        if logs:
            loop = partial(closed_loop_figure, logs, title=f"Closed loop, {where}", d_safe=d_safe)
            planned[f"closed_loop_{name}"] = loop
            title = f"Joint velocities, {where}"
            planned[f"closed_loop_v_{name}"] = partial(velocity_plot, logs, title)
            title = f"Closest key point to an obstacle, {where}"
            planned[f"closed_loop_d_{name}"] = partial(distance_plot, logs, title, d_safe=d_safe)
        planned.update(_snapshots(g, scenario, formulation))
    drawn = _draw_all(planned, folder, jobs)
    written = {key: folder / f"{key}.png" for key in planned if drawn.get(key)}
    keep = {p.resolve() for p in written.values()}
    removed = [
        p
        for p in sorted(folder.iterdir())
        if p.is_file() and FIGURE_PATTERN.fullmatch(p.name) and p.resolve() not in keep
    ]
    for p in removed:
        p.unlink(missing_ok=True)
    if removed:
        log.info("%s: removed %d figures no longer in the report", folder, len(removed))
    relative = Path(relative_to).resolve()
    return {k: p.resolve().relative_to(relative).as_posix() for k, p in written.items()}


def draw_figure(job: tuple) -> bool:
    """``figure(path)`` of a job ``(figure, path)``: whether it drew one (``False``: nothing to
    draw)."""
    figure, path = job
    return figure(path) is not False


def _draw_all(planned: dict, folder: Path, jobs: int) -> dict[str, bool]:
    """Draw each planned figure into ``folder/<key>.png``: here, or ``jobs`` at a time in worker
    processes (:func:`qpbench.runner.process.run_tasks`; a figure whose worker failed is left
    out, warned)."""
    tasks = [(key, (figure, folder / f"{key}.png"), None) for key, figure in planned.items()]
    if jobs <= 1 or len(tasks) <= 1:
        return {key: draw_figure(job) for key, job, _ in tasks}
    from ..runner.process import run_tasks

    drawn = {}
    for done in run_tasks(draw_figure, tasks, jobs, name="qpbench-figure"):
        if done.lost is not None:
            log.warning("figure %s not drawn: %s", done.key, done.lost)
        drawn[done.key] = done.lost is None and bool(done.value)
    return drawn


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
        rank = networks["backend"].astype(str).map({b: i for i, b in enumerate(NETWORKS)})
        chosen["network"] = networks.iloc[int(np.argmin(rank.fillna(len(NETWORKS))))]
    return chosen


def _snapshots(runs: pd.DataFrame, scenario: str, formulation: str) -> dict:
    """The snapshots of one scenario's runs: key -> figure(path)."""
    from ..sim.scenario import load_scenario
    from .arm import draw_snapshot

    chosen = snapshot_runs(runs)
    if not chosen:
        return {}
    try:
        scene = load_scenario(scenario)
    except Exception as exc:  # noqa: BLE001 - a scenario not found here only loses its pictures
        log.warning("%s: no arm snapshot (%s)", scenario, exc)
        return {}
    figures, angles = {}, set(tick_log.theta_columns(scene.make_arm().n))
    for role, row in chosen.items():
        frame = read_log(row["log_path"])
        if frame is None or not angles <= set(frame.columns):
            continue  # no log, or one without the joint angles: no picture of the arm
        key = f"snapshot_{role}_{slug(scenario)}_{slug(formulation)}"
        backend = str(row["backend"])
        title = f"{scenario}: {backend} ({ROLES[role]})"
        figures[key] = partial(draw_snapshot, scene, frame, title=title, backend=backend)
    return figures


#: Names of the figures :func:`write_plots` writes (and so may remove when it no longer links them).
FIGURE_PATTERN = re.compile(r"(perf_profile|per_tick|closed_loop|snapshot)_[A-Za-z0-9_.+-]*\.png")
