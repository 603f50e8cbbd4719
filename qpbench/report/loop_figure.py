"""The closed-loop figure: one or several backends' runs of one scenario, overlaid.

Panels, top to bottom (each backend one colour, the legend outside the axes):

1. magnitude of the tangential tracking error [mm], log scale so that a
   1e-4 mm steady state and a 100 mm transient are both readable;
2. magnitude of the contact-force error ``|F - Fd|`` [N], log scale;
3. smallest key-point distance to an obstacle [mm], with the safety
   distance ``d_safe`` and the ``d_safe - 0.5 mm`` line a run must not cross
   (scenarios with obstacles only);
4. solve time per tick [µs], log scale, with the 1 ms budget of a 1 kHz loop;
5. ``|v|^2`` [rad²/s²], log scale;
6. the adaptive estimate ``Kp_hat`` [N/m] (adaptive scenarios only).

Ticks where a backend's own answer was not applied (the soft fallback's or
zero velocity was) are shaded in its colour along the top of the first panel.

Columns read are the tick log's, by the names :mod:`qpbench.sim.log` gives
them (``t``, ``tracking_error``, ``force_error``, ``d_min``, ``solve_time_s``,
``v_sq``, ``kp_hat``, ``fallback``, ``zero_velocity``). One run's figure
(``qpbench simulate --plot``) and a scenario's runs overlaid (the report) are
both drawn by :func:`closed_loop_figure`.
"""

from __future__ import annotations

from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np

from ..sim import log as tick_log

if TYPE_CHECKING:
    import pandas as pd

__all__ = ["closed_loop_figure", "run_figure"]

#: Margin below ``d_safe`` at which a run counts as unsafe [m] (drawn as a line).
UNSAFE_MARGIN = 5e-4


def _palette(count: int) -> list:
    import matplotlib

    cmap = matplotlib.colormaps["tab10" if count <= 10 else "tab20"]
    return [cmap(i % cmap.N) for i in range(count)]


def _floor(values: np.ndarray, floor: float) -> np.ndarray:
    """``values`` with entries below ``floor`` raised to it (zeros on a log axis)."""
    return np.maximum(values, floor)


def _intervals(mask: np.ndarray) -> list[tuple[int, int]]:
    if not mask.any():
        return []
    idx = np.flatnonzero(mask)
    breaks = np.flatnonzero(np.diff(idx) > 1)
    return list(zip(np.r_[idx[0], idx[breaks + 1]], np.r_[idx[breaks], idx[-1]]))


def closed_loop_figure(
    logs: dict,
    path: str | Path,
    *,
    title: str,
    d_safe: float | None = None,
    adaptive: bool | None = None,
    budget_s: float = 1e-3,
) -> Path:
    """Draw the closed-loop figure of ``logs`` (backend name -> tick log) to ``path`` (PNG).

    Args:
        logs: Tick logs by backend name, in legend order.
        path: Output file.
        title: Figure title.
        d_safe: Safety distance [m]; ``None`` draws no safety lines.
        adaptive: Draw the ``Kp_hat`` panel; ``None``: when any log's ``kp_hat`` varies.
        budget_s: Per-tick time budget [s] drawn on the solve-time panel (1 ms: 1 kHz).

    Returns:
        ``path``.
    """
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    from ..atomic import atomic_path

    path = Path(path)
    logs = {name: df for name, df in logs.items() if df is not None and len(df)}
    if not logs:
        raise ValueError("no tick log to draw")
    has_d = any(
        tick_log.D_MIN in d.columns and np.isfinite(d[tick_log.D_MIN].to_numpy(float)).any()
        for d in logs.values()
    )
    if adaptive is None:
        adaptive = any(
            tick_log.KP_HAT in d.columns and np.nanstd(d[tick_log.KP_HAT].to_numpy(float)) > 0
            for d in logs.values()
        )
    panels = (
        ["tracking", "force"]
        + (["distance"] if has_d else [])
        + ["time", "speed"]
        + (["kp"] if adaptive else [])
    )
    colours = dict(zip(logs, _palette(len(logs))))

    fig, axes = plt.subplots(
        len(panels), 1, figsize=(9.5, 1.9 * len(panels) + 0.8), sharex=True, squeeze=False
    )
    axes = {name: ax for name, ax in zip(panels, axes[:, 0])}
    for backend, d in logs.items():
        _plot_log(axes, d, backend, colours[backend], has_d, adaptive)
    _label_axes(axes, logs, has_d, adaptive, d_safe, budget_s)
    axes[panels[-1]].set_xlabel("t [s]")
    _legend(fig, axes, logs)
    fig.suptitle(title)
    fig.tight_layout()
    try:
        with atomic_path(path) as tmp:
            fig.savefig(tmp, format="png", dpi=100, bbox_inches="tight")
    finally:
        plt.close(fig)
    return path


def _plot_log(axes: dict, d, backend: str, c, has_d: bool, adaptive: bool) -> None:
    """One backend's tick log on every panel, and a band on top of the first where it did not answer."""
    t = d[tick_log.T].to_numpy(float)
    style = dict(color=c, lw=0.9, label=backend)
    axes["tracking"].plot(
        t, _floor(np.abs(d[tick_log.TRACKING_ERROR].to_numpy(float)) * 1e3, 1e-7), **style
    )
    axes["force"].plot(t, _floor(np.abs(d[tick_log.FORCE_ERROR].to_numpy(float)), 1e-7), **style)
    if has_d and tick_log.D_MIN in d.columns:
        axes["distance"].plot(t, d[tick_log.D_MIN].to_numpy(float) * 1e3, **style)
    axes["time"].plot(
        t,
        d[tick_log.SOLVE_TIME].to_numpy(float) * 1e6,
        color=c,
        lw=0.0,
        marker=".",
        ms=1.2,
        alpha=0.6,
        rasterized=True,
    )
    axes["speed"].plot(t, _floor(d[tick_log.V_SQ].to_numpy(float), 1e-9), **style)
    if adaptive and tick_log.KP_HAT in d.columns:
        axes["kp"].plot(t, d[tick_log.KP_HAT].to_numpy(float), **style)
    # ticks without the backend's own answer: a band along the top of the first panel
    not_own = np.zeros(len(d), dtype=bool)
    for col in (tick_log.FALLBACK, tick_log.ZERO_VELOCITY):
        if col in d.columns:
            not_own |= d[col].to_numpy(bool)
    for a, b in _intervals(not_own):
        axes["tracking"].axvspan(
            t[a],
            t[b] + (t[1] - t[0] if len(t) > 1 else 0.0),
            ymin=0.94,
            ymax=1.0,
            color=c,
            alpha=0.5,
            lw=0,
        )


def _label_axes(
    axes: dict, logs: dict, has_d: bool, adaptive: bool, d_safe: float | None, budget_s: float
) -> None:
    """Scales, labels, the safety lines and the time budget of the panels."""
    ax = axes["tracking"]
    ax.set_yscale("log")
    ax.set_ylabel("|tracking error|\n[mm]")
    ax = axes["force"]
    ax.set_yscale("log")
    ax.set_ylabel("|force error|\n|F - Fd| [N]")
    if has_d:
        ax = axes["distance"]
        if d_safe is not None:
            ax.axhline(d_safe * 1e3, color="black", ls="--", lw=0.8, label="d_safe")
            ax.axhline(
                (d_safe - UNSAFE_MARGIN) * 1e3, color="red", ls=":", lw=0.9, label="d_safe - 0.5 mm"
            )
            lo = min(
                float(np.nanmin(d[tick_log.D_MIN].to_numpy(float)))
                for d in logs.values()
                if tick_log.D_MIN in d.columns
            )
            ax.set_ylim(bottom=min(lo * 1e3 - 1.0, d_safe * 1e3 - 2.0))
        ax.set_ylabel("closest key point\nto an obstacle [mm]")
    ax = axes["time"]
    ax.set_yscale("log")
    ax.axhline(budget_s * 1e6, color="red", ls="--", lw=0.9, label=f"{budget_s * 1e3:g} ms budget")
    ax.set_ylabel("solve time\nper tick [µs]")
    ax = axes["speed"]
    ax.set_yscale("log")
    ax.set_ylabel("joint speed\n|v|² [rad²/s²]")
    if adaptive:
        axes["kp"].set_ylabel("estimated\nKp_hat [N/m]")
    for ax in axes.values():
        ax.grid(True, alpha=0.3, which="major")


def _legend(fig, axes: dict, logs: dict) -> None:
    """One legend for the figure: the backends, then the reference lines (d_safe, budget)."""
    handles, labels = axes["tracking"].get_legend_handles_labels()
    extra = []
    for name in ("distance", "time"):
        if name in axes:
            h, lab = axes[name].get_legend_handles_labels()
            extra += [(hh, ll) for hh, ll in zip(h, lab) if ll not in logs]
    fig.legend(
        handles + [h for h, _ in extra],
        labels + [lab for _, lab in extra],
        loc="upper left",
        bbox_to_anchor=(1.0, 0.97),
        fontsize=8,
        frameon=False,
        title="band on top: fallback\nor zero velocity",
        title_fontsize=7,
    )


def run_figure(frame: pd.DataFrame, summary: dict, path: str | Path) -> Path:
    """The figure of one run (``qpbench simulate --plot``): its tick log and its summary's names."""
    return closed_loop_figure(
        {summary["backend"]: frame},
        path,
        title=f"{summary['scenario']} / {summary['backend']} / {summary['formulation']}",
        d_safe=summary.get("d_safe"),
    )
