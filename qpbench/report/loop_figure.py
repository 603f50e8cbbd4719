"""The closed-loop figure of one scenario's runs: |tracking error| [mm], |F - Fd| [N], the
closest key point [mm] against ``d_safe`` (with obstacles), solve time [µs] against the budget,
``|v|^2`` [rad²/s²], ``Kp_hat`` [N/m] (adaptive); a column per group of backends; ticks without
the backend's own answer (fallback, zero velocity) shaded along the top."""

from __future__ import annotations

from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np

from ..sim import log as tick_log
from ..sim.verdict import DEFAULT_SAFETY_MARGIN
from . import style

if TYPE_CHECKING:
    import pandas as pd


#: Width of one column of panels and height of one panel [in].
COLUMN_IN, PANEL_IN = 4.6, 1.75
#: The per-tick time budget drawn on the solve-time panel [s].
BUDGET_S = 1e-3
#: The panels, top to bottom, and their y labels.
PANELS = {
    "tracking": "|tracking error|\n[mm]",
    "force": "|force error|\n|F - Fd| [N]",
    "distance": "closest key point\nto an obstacle [mm]",
    "time": "solve time\nper tick [µs]",
    "speed": "joint speed\n|v|² [rad²/s²]",
    "kp": "estimated\nKp_hat [N/m]",
}


def has_distance(log: pd.DataFrame) -> bool:
    """The tick log has a finite closest key-point distance ``d_min``."""
    return tick_log.D_MIN in log.columns and np.isfinite(log[tick_log.D_MIN].to_numpy(float)).any()


def distance_axis(ax, d_safe: float | None, lowest_mm: float | None = None) -> None:
    """A distance axis in [mm]: linear up to ``d_safe`` [m] (else 10 mm), logarithmic beyond,
    with the ``d_safe`` line and the ``d_safe - 0.5 mm`` line a run must not cross (the region
    below shaded); ``lowest_mm``: the smallest distance drawn, which the axis reaches."""
    from matplotlib.ticker import FuncFormatter

    lin = d_safe * 1e3 if d_safe is not None and d_safe > 0 else 10.0
    ax.set_yscale("symlog", linthresh=lin, linscale=1.0)
    ax.yaxis.set_major_locator(_distance_ticks(lin))
    ax.yaxis.set_major_formatter(FuncFormatter(lambda v, _pos: f"{v:g}"))
    if d_safe is None:
        return
    bad = (d_safe - DEFAULT_SAFETY_MARGIN) * 1e3
    ax.axhline(d_safe * 1e3, color="black", ls="--", lw=0.9, label=f"d_safe {d_safe * 1e3:g} mm")
    ax.axhline(bad, color="red", ls=":", lw=1.0, label="d_safe - 0.5 mm")
    lo = min(0.0, lowest_mm if lowest_mm is not None and np.isfinite(lowest_mm) else 0.0)
    bottom = lo - 0.3 * max(abs(lo), lin) if lo < 0 else -0.3 * lin
    ax.axhspan(bottom, bad, color="red", alpha=0.06, lw=0)
    ax.set_ylim(bottom=bottom)


def _distance_ticks(lin: float):
    """Ticks in plain [mm] (symlog's are powers of ten): 0, +-``lin`` (d_safe) and 1-2-5 steps
    beyond; where none of those lies between ``lin`` and the top of the view (a run that stays
    close above d_safe), the largest 1-1.5-2-3-4-5-6-8 step there, so the data have a label."""
    from matplotlib.ticker import Locator

    def steps(mantissas):
        return [m * 10.0**e for e in range(-3, 6) for m in mantissas]

    beyond = [v for v in steps((1, 2, 5)) if v >= 1.8 * lin]
    ticks = sorted({0.0, lin, -lin, *beyond, *(-v for v in beyond)})
    finer = [v for v in steps((1, 1.5, 2, 3, 4, 5, 6, 8)) if 1.2 * lin <= v < beyond[0]]

    class Ticks(Locator):
        def __call__(self):
            top = max(self.axis.get_view_interval())
            if top >= beyond[0]:
                return ticks
            return sorted(ticks + [v for v in finer if v <= top][-1:])

    return Ticks()


def closed_loop_figure(
    logs: dict, path: str | Path, *, title: str, d_safe: float | None = None
) -> Path:
    """Draw the closed-loop figure of ``logs`` (backend -> tick log) to ``path``; return it.
    ``d_safe`` [m] (``None``: no safety lines); the ``Kp_hat`` panel when a log's one varies."""
    if not logs:
        raise ValueError("no tick log to draw")
    has_d = any(has_distance(d) for d in logs.values())
    adaptive = any(np.nanstd(d[tick_log.KP_HAT].to_numpy(float)) > 0 for d in logs.values())
    shown = {"distance": has_d, "kp": adaptive}
    panels = [name for name in PANELS if shown.get(name, True)]
    fig, grid, groups = style.panels(
        logs, len(panels), COLUMN_IN, PANEL_IN, pad=(1.0, 1.4), sharex=True, sharey="row"
    )
    if has_d:
        lowest = min(float(np.nanmin(d[tick_log.D_MIN])) for d in logs.values() if has_distance(d))
    budget = f"{BUDGET_S * 1e3:g} ms budget"
    for col, (group_title, group) in enumerate(groups):
        axes = dict(zip(panels, grid[:, col]))
        for backend, lit in style.highlighted(logs, group):
            _plot_log(axes, logs[backend], backend, lit, has_d, adaptive)
        # scales, labels (first column only), the safety lines and the time budget
        for name in ("tracking", "force", "time", "speed"):
            axes[name].set_yscale("log")
        if has_d:
            distance_axis(axes["distance"], d_safe, lowest * 1e3)
        axes["time"].axhline(BUDGET_S * 1e6, color="red", ls="--", lw=0.9, label=budget)
        for name, ax in axes.items():
            ax.grid(True, alpha=0.3, which="major")
            if col == 0:
                ax.set_ylabel(PANELS[name], fontsize=9)
        axes[panels[-1]].set_xlabel("t [s]")
        # the column's legend above it: its backends, then (first column) the reference lines
        handles, labels = axes["tracking"].get_legend_handles_labels()
        if col == 0:
            lines = style.entries([axes[n] for n in ("distance", "time") if n in axes], skip=group)
            handles, labels = handles + lines[0], labels + lines[1]
            band = "band on top: fallback or zero velocity"
            group_title = (group_title + "\n" if group_title else "") + band
        style.legend_above(axes["tracking"], handles, labels, title=group_title)
    fig.suptitle(title + "; grey: the other backends" if len(groups) > 1 else title)
    return style.save(fig, path, dpi=100)


def _plot_log(axes: dict, d, backend: str, lit: bool, has_d: bool, adaptive: bool) -> None:
    """One backend's tick log on every panel of a column: in its look when ``lit``, else grey."""
    from scipy import ndimage

    t = d[tick_log.T].to_numpy(float)
    style_kw = style.series(backend, lit, t, lw=1.0, grey_lw=0.7)
    c = style_kw["color"]
    errors = np.abs(d[[tick_log.TRACKING_ERROR, tick_log.FORCE_ERROR]].to_numpy(float))
    axes["tracking"].plot(t, np.maximum(errors[:, 0] * 1e3, 1e-7), **style_kw)
    axes["force"].plot(t, np.maximum(errors[:, 1], 1e-7), **style_kw)
    if has_d:
        axes["distance"].plot(t, d[tick_log.D_MIN].to_numpy(float) * 1e3, **style_kw)
    dots = dict(ms=1.6, alpha=0.7, zorder=3) if lit else dict(ms=1.0, alpha=0.5, zorder=1)
    solve_time = d[tick_log.SOLVE_TIME].to_numpy(float) * 1e6
    axes["time"].plot(t, solve_time, color=c, lw=0.0, marker=".", rasterized=True, **dots)
    axes["speed"].plot(t, np.maximum(d[tick_log.V_SQ].to_numpy(float), 1e-9), **style_kw)
    if adaptive:
        axes["kp"].plot(t, d[tick_log.KP_HAT].to_numpy(float), **style_kw)
    if not lit:
        return
    # ticks without the backend's own answer: a band along the top of the first panel per run
    not_own = d[[tick_log.FALLBACK, tick_log.ZERO_VELOCITY]].to_numpy(bool).any(axis=1)
    step = t[1] - t[0] if len(t) > 1 else 0.0
    for (run,) in ndimage.find_objects(ndimage.label(not_own)[0]):
        a, b = run.start, run.stop - 1
        axes["tracking"].axvspan(t[a], t[b] + step, ymin=0.94, ymax=1.0, color=c, alpha=0.5, lw=0)


def run_figure(frame: pd.DataFrame, summary: dict, path: str | Path) -> Path:
    """The figure of one run (``qpbench simulate --plot``): its tick log and its summary's names."""
    return closed_loop_figure(
        {summary["backend"]: frame},
        path,
        title=f"{summary['scenario']} / {summary['backend']} / {summary['formulation']}",
        d_safe=summary.get("d_safe"),
    )
