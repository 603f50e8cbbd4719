"""The scaling study's report: ``scaling.md`` and ``scaling.png`` from ``scaling.csv``.

Every number is recomputed from the CSV (:mod:`qpbench.scaling.runner`):

- the plot: median solve time per tick against variables (the ``arm`` axis:
  4 to 64 links, a 16-point cloud) and against constraint rows (the ``cloud``
  axis: the 4-link arm, 1 to 1,000 cloud points), log-log, one colour per
  backend, its fitted power law dashed, the 1 ms tick as a line;
- the slopes (:func:`qpbench.scaling.fit.fit_power_law`) with their standard
  errors;
- where sparse solvers overtake dense ones: per axis, the first size from
  which the fastest sparse backend's median stays below the fastest dense
  one's (and where their fitted lines meet, when that is beyond the grid);
- where each backend stops fitting a 1 ms tick: the first size from which
  the tick's p99 build time plus the backend's p99 solve time stay above 1 ms
  (and the same with medians).
"""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pandas as pd

from ..atomic import write_text
from .fit import crossing, extrapolated_crossing, first_above, fit_power_law

__all__ = ["TICK_S", "is_scaling_dir", "write_scaling_report"]

#: The control period a tick must fit in [s].
TICK_S = 1e-3
#: ``axis -> (column on x, label)`` of the two panels and fits.
AXES = {
    "arm": ("n", "variables n (arm axis: 4-64 links, 16 cloud points)"),
    "cloud": ("rows", "constraint rows (cloud axis: 4 links, 1-1,000 cloud points)"),
}


def is_scaling_dir(path: str | Path) -> bool:
    """Whether ``path`` is a folder written by ``qpbench scaling`` (it holds ``scaling.csv``)."""
    from .runner import SUMMARY_NAME

    return Path(path).is_dir() and (Path(path) / SUMMARY_NAME).is_file()


def load(folder: str | Path) -> pd.DataFrame:
    """``scaling.csv`` of ``folder`` as a frame (numbers typed)."""
    from .runner import COLUMNS, SUMMARY_NAME, TEXT_COLUMNS, read_summary

    rows = read_summary(Path(folder) / SUMMARY_NAME)
    frame = pd.DataFrame(rows)
    for col in COLUMNS:
        if col in frame and col not in TEXT_COLUMNS:
            frame[col] = pd.to_numeric(frame[col], errors="coerce")
    return frame


def fits(frame: pd.DataFrame) -> dict:
    """``{(backend, axis): PowerFit}`` of median solve time on each axis."""
    out = {}
    measured = frame[frame["status"] == "measured"]
    for (backend, axis), g in measured.groupby(["backend", "axis"]):
        if axis in AXES:
            out[(backend, axis)] = fit_power_law(g[AXES[axis][0]], g["time_median_s"])
    return out


def _size_label(frame: pd.DataFrame, name) -> str:
    if name is None:
        return "none in the measured range"
    r = frame[frame["size"] == name].iloc[0]
    return f"{name} ({int(r['n'])} variables, {int(r['rows']):,} rows)"


def _fastest_at_largest(rows: pd.DataFrame, xcol: str) -> str:
    """The backend with the smallest median time on the largest size these rows measured."""
    largest = rows[rows[xcol] == rows[xcol].max()]
    return str(largest.loc[largest["time_median_s"].idxmin(), "backend"])


def crossover_lines(frame: pd.DataFrame, fitted: dict) -> list[str]:
    """Per axis: where the fastest sparse backend overtakes the fastest dense one."""
    lines = []
    m = frame[frame["status"] == "measured"]
    for axis, (xcol, _) in AXES.items():
        a = m[m["axis"] == axis]
        dense = a[a["matrix_format"] == "dense"]
        sparse = a[a["matrix_format"] == "sparse"]
        if dense.empty or sparse.empty:
            lines.append(f"- {axis} axis: no dense and sparse backend both measured")
            continue
        best_d = dense.groupby("size")["time_median_s"].min()
        best_s = sparse.groupby("size")["time_median_s"].min()
        sizes = a.drop_duplicates("size").set_index("size")[xcol].sort_values()
        names = list(sizes.index)
        at = crossing(sizes.values, best_d.reindex(names).values, best_s.reindex(names).values)
        name = None if at is None else names[list(sizes.values).index(at)]
        text = f"- {axis} axis: sparse overtakes dense at {_size_label(frame, name)}"
        if name is None:
            bd, bs = _fastest_at_largest(dense, xcol), _fastest_at_largest(sparse, xcol)
            fd, fs = fitted.get((bd, axis)), fitted.get((bs, axis))
            meet = extrapolated_crossing(fd, fs) if fd and fs else None
            if meet is not None and meet > sizes.max():
                text += f"; the fitted lines of {bd} and {bs} meet near {xcol} = {meet:,.0f} (extrapolated)"
            elif fd and fs:
                text += (
                    f" (fastest dense {bd}, slope {fd.text()}; fastest sparse {bs}, slope {fs.text()}: "
                    "their fitted lines do not meet beyond the grid)"
                )
        lines.append(text)
    return lines


def deadline_table(frame: pd.DataFrame) -> pd.DataFrame:
    """Per backend and axis: the first size whose build + solve exceeds :data:`TICK_S`, at p99 and at the median."""
    out = []
    m = frame[frame["status"] == "measured"]
    for (backend, axis), g in m.groupby(["backend", "axis"]):
        xcol = AXES.get(axis, ("n",))[0]
        g = g.sort_values(xcol)
        row = {"backend": backend, "axis": axis}
        for stat in ("p99", "median"):
            tick = (
                g[f"build_{'p99' if stat == 'p99' else 'median'}_s"].fillna(0) + g[f"time_{stat}_s"]
            )
            at = first_above(g[xcol].values, tick.values, TICK_S)
            row[stat] = _size_label(frame, None if at is None else g[g[xcol] == at]["size"].iloc[0])
            row[f"largest {stat}"] = tick.max()
        out.append(row)
    return pd.DataFrame(out)


def plot(frame: pd.DataFrame, fitted: dict, path: Path) -> Path:
    """Two log-log panels (module docstring) as a PNG at ``path``.

    Each backend in its colour (:func:`qpbench.report.style.look`); squares
    dense, circles sparse; more than :data:`qpbench.report.style.MAX_SERIES` backends:
    one row of panels per group of them, the others grey behind. Legends outside,
    on the right.
    """
    import matplotlib.ticker

    from ..report import style

    m = frame[frame["status"] == "measured"]
    backends = sorted(m["backend"].unique())
    groups = style.groups(backends) or [("", [])]
    fig, axes = style.pyplot().subplots(
        len(groups),
        len(AXES),
        figsize=(14, 4.6 * len(groups) + 0.6),
        squeeze=False,
        layout="constrained",
    )
    for row, (_, group) in enumerate(groups):
        for ax, (axis, (xcol, label)) in zip(axes[row], AXES.items()):
            a = m[m["axis"] == axis]
            for b, lit in style.highlighted(backends, group):
                _scaling_series(
                    ax, a[a["backend"] == b].sort_values(xcol), xcol, b, lit, fitted.get((b, axis))
                )
            ax.axhline(TICK_S * 1e6, color="k", lw=0.8, ls=":")
            ax.set_xscale("log")
            ax.set_yscale("log")
            ticks = sorted(a[xcol].unique())
            if ticks:  # the measured sizes as plain numbers
                ax.set_xticks(ticks, [f"{int(v):,}" for v in ticks])
                ax.xaxis.set_minor_formatter(matplotlib.ticker.NullFormatter())
            ax.set_xlabel(label)
            ax.set_ylabel("median solve time per tick [us]")
            ax.set_title(
                f"{axis} axis (slope +- standard error; squares: dense, circles: sparse)",
                fontsize=9,
            )
            if ax.get_legend_handles_labels()[0]:
                ax.legend(loc="upper left", bbox_to_anchor=(1.01, 1.0), fontsize=7, frameon=False)
            ax.grid(True, which="both", alpha=0.3)
    return style.save(fig, path)


def _scaling_series(ax, g: pd.DataFrame, xcol: str, b: str, lit: bool, fit) -> None:
    """One backend's medians (square: dense, circle: sparse) and its fitted power law (dashed)."""
    from ..report import style

    if g.empty:
        return
    colour = style.look(b).colour if lit else style.GREY
    marker = "o" if g["matrix_format"].iloc[0] == "sparse" else "s"
    tag = f"{b} ({fit.text()})" if fit is not None else b
    ax.plot(
        g[xcol],
        g["time_median_s"] * 1e6,
        marker,
        color=colour,
        label=tag if lit else None,
        zorder=3 if lit else 1,
    )
    if fit is not None and not math.isnan(fit.slope):
        xs = np.geomspace(g[xcol].min(), g[xcol].max(), 20)
        ax.plot(xs, fit.predict(xs) * 1e6, "--", color=colour, lw=1, zorder=3 if lit else 1)


def _fmt_us(v) -> str:
    return "-" if v is None or not math.isfinite(v) else f"{v * 1e6:,.1f}"


def markdown(frame: pd.DataFrame, fitted: dict, image: str | None) -> str:
    """The text of ``scaling.md``."""
    m = frame[frame["status"] == "measured"]
    first = frame.iloc[0]
    lines = [
        "# Scaling: solve time against QP size",
        "",
        f"Closed loop solved by `{first['driver']}`, ticks dumped and solved by each backend "
        f"(min of {first['repeat']} timed solves per tick, seed {first['seed']}); medians and p99 over each "
        "size's ticks. Rows are constraint rows (2 task equalities + one row per key point and cloud point); "
        "the 2n bounds are not counted.",
        "",
    ]
    if image:
        lines += [f"![scaling]({image})", ""]
    sizes = frame.drop_duplicates("size")[
        ["size", "axis", "n", "key_points", "cloud_points", "rows", "build_median_s", "build_p99_s"]
    ]
    lines += [
        "## Sizes",
        "",
        "| size | axis | variables | key points | cloud points | rows | build p50 [us] | build p99 [us] |",
        "|:--|:--|--:|--:|--:|--:|--:|--:|",
    ]
    for _, r in sizes.iterrows():
        lines.append(
            f"| {r['size']} | {r['axis']} | {int(r['n'])} | {int(r['key_points'])} | {int(r['cloud_points'])} "
            f"| {int(r['rows']):,} | {_fmt_us(r['build_median_s'])} | {_fmt_us(r['build_p99_s'])} |"
        )
    lines += [
        "",
        "## Slopes",
        "",
        "Least squares of log10(median time) on log10(size) per axis; +- one standard error.",
        "",
        "| backend | format | slope vs variables (arm axis) | slope vs rows (cloud axis) |",
        "|:--|:--|--:|--:|",
    ]
    for b in sorted(m["backend"].unique()):
        fmt = m[m["backend"] == b]["matrix_format"].iloc[0]
        cells = [fitted[(b, ax)].text() if (b, ax) in fitted else "-" for ax in AXES]
        lines.append(f"| {b} | {fmt} | {cells[0]} | {cells[1]} |")
    lines += ["", "## Sparse against dense", ""] + crossover_lines(frame, fitted)
    lines += [
        "",
        "## The 1 ms tick",
        "",
        "First size from which build + solve stays above 1 ms: p99 build + p99 solve (every tick must fit), "
        "and median build + median solve (a typical tick fits); largest tick over the axis in brackets [us].",
        "",
        "| backend | axis | p99 tick over 1 ms from | median tick over 1 ms from |",
        "|:--|:--|:--|:--|",
    ]
    for _, r in deadline_table(frame).iterrows():
        lines.append(
            f"| {r['backend']} | {r['axis']} | {r['p99']} (largest {r['largest p99'] * 1e6:,.0f}) "
            f"| {r['median']} (largest {r['largest median'] * 1e6:,.0f}) |"
        )
    lines.append("")
    lines += [
        "## Every size and backend",
        "",
        "| size | backend | median [us] | p99 [us] | success % | gap max | status |",
        "|:--|:--|--:|--:|--:|--:|:--|",
    ]
    for _, r in frame.iterrows():
        status = r["status"] if r["status"] == "measured" else f"skipped: {r['skip_reason']}"
        succ = "-" if not math.isfinite(r["success_rate"]) else f"{100 * r['success_rate']:.0f}"
        gap = "-" if not math.isfinite(r["gap_max"]) else f"{r['gap_max']:.1e}"
        lines.append(
            f"| {r['size']} | {r['backend']} | {_fmt_us(r['time_median_s'])} | {_fmt_us(r['time_p99_s'])} "
            f"| {succ} | {gap} | {status} |"
        )
    return "\n".join(lines) + "\n"


def write_scaling_report(
    folder: str | Path,
    out: str | Path,
    force: bool = False,
    plots: bool = True,
    quiet: bool = False,
) -> Path:
    """Write ``scaling.md`` (and ``scaling.png``) for the study in ``folder`` into ``out``; return the .md path.

    Raises:
        InputError: ``folder`` holds no scaling.csv or no row.
        OutputExistsError: ``out/scaling.md`` exists and not ``force``.
    """
    from ..atomic import check_output
    from ..exceptions import InputError

    if not is_scaling_dir(folder):
        raise InputError("not a scaling folder (no scaling.csv)", path=folder)
    frame = load(folder)
    if frame.empty:
        raise InputError("no rows", path=Path(folder) / "scaling.csv")
    out = Path(out)
    md = out / "scaling.md"
    check_output(out, force=True, kind="dir")  # a folder or nothing yet
    if md.exists():
        check_output(md, force=force)
    out.mkdir(parents=True, exist_ok=True)
    fitted = fits(frame)
    image = None
    if plots and (frame["status"] == "measured").any():
        plot(frame, fitted, out / "scaling.png")
        image = "scaling.png"
    write_text(md, markdown(frame, fitted, image))
    return md
