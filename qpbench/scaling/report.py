"""The scaling study's report, ``scaling.md`` and ``scaling.png`` from ``scaling.csv``: median
solve time per tick against variables (``arm`` and ``spatial`` axes) and constraint rows
(``cloud`` axis), log-log, fitted as ``T = C s^k`` (least squares of ``log10 T`` on ``log10 s``, the slope's standard
error ``sqrt(RSS / (N - 2) / sum((x - mean x)^2))``, NaN for N = 2 sizes); where the fastest
sparse backend overtakes the fastest dense one; where build + solve stops fitting a 1 ms tick.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import pandas as pd

from ..report.markdown_table import US, Column, table
from .runner import SUMMARY_NAME

#: The control period a tick must fit in [s].
TICK_S = 1e-3
#: ``axis -> (column on x, label)`` of the two panels and fits.
AXES = {
    "arm": ("n", "variables n (arm axis: 4-64 links, 16 cloud points)"),
    "cloud": ("rows", "constraint rows (cloud axis: 4 links, 1-1,000 cloud points)"),
    "spatial": (
        "n",
        "variables n (spatial axis: Panda, iiwa 14, chains of 14 and 28 joints, 4 balls)",
    ),
}


@dataclass(frozen=True)
class PowerFit:
    """``T = 10**intercept * s**slope``; ``slope_se`` the slope's standard error."""

    slope: float
    slope_se: float
    intercept: float

    def predict(self, s: float | np.ndarray) -> np.ndarray:
        """Fitted time at size(s) ``s`` (same units as the data)."""
        return 10.0 ** (self.intercept + self.slope * np.log10(np.asarray(s, dtype=float)))

    def text(self) -> str:
        """``1.23 +- 0.05`` (``+- n/a`` with two points)."""
        if math.isnan(self.slope):
            return "-"
        se = "n/a" if math.isnan(self.slope_se) else f"{self.slope_se:.2f}"
        return f"{self.slope:.2f} +- {se}"


def fit_power_law(sizes: np.ndarray, times: np.ndarray) -> PowerFit:
    """Least squares of ``log10 times`` on ``log10 sizes``, non-positive or non-finite pairs left
    out (NaN with fewer than two distinct sizes)."""
    s, t = np.asarray(sizes, dtype=float), np.asarray(times, dtype=float)
    keep = np.isfinite(s) & np.isfinite(t) & (s > 0) & (t > 0)
    x, y = np.log10(s[keep]), np.log10(t[keep])
    if x.size < 2 or np.ptp(x) == 0:
        return PowerFit(math.nan, math.nan, math.nan)
    xm = x.mean()
    sxx = float(((x - xm) ** 2).sum())
    slope = float(((x - xm) * (y - y.mean())).sum() / sxx)
    intercept = float(y.mean() - slope * xm)
    rss = float(((y - intercept - slope * x) ** 2).sum())
    se = math.sqrt(rss / (x.size - 2) / sxx) if x.size > 2 else math.nan
    return PowerFit(slope, se, intercept)


def first_above(sizes: np.ndarray, values: np.ndarray, limit: float) -> float | None:
    """The first size (in increasing order) from which every value exceeds ``limit``, else None."""
    order = np.argsort(np.asarray(sizes, dtype=float), kind="stable")
    s = np.asarray(sizes)[order]
    below = np.flatnonzero(~(np.asarray(values, dtype=float)[order] > limit))
    i = below[-1] + 1 if below.size else 0  # the first after the last value not above
    return s[i].item() if i < s.size else None


def crossing(sizes: np.ndarray, slower: np.ndarray, faster: np.ndarray) -> float | None:
    """The first size from which time ``faster`` stays strictly below ``slower`` (NaN: not
    measured, left out), else None."""
    a, b = np.asarray(slower, dtype=float), np.asarray(faster, dtype=float)
    keep = np.isfinite(a) & np.isfinite(b)
    return first_above(np.asarray(sizes, dtype=float)[keep], (a - b)[keep], 0.0)


def extrapolated_crossing(fit_a: PowerFit, fit_b: PowerFit) -> float | None:
    """Size where two fitted lines meet (``None`` when parallel or not fitted)."""
    if any(math.isnan(v) for v in (fit_a.slope, fit_b.slope)) or fit_a.slope == fit_b.slope:
        return None
    return float(10.0 ** ((fit_b.intercept - fit_a.intercept) / (fit_a.slope - fit_b.slope)))


def is_scaling_dir(path: str | Path) -> bool:
    """Whether ``path`` is a folder written by ``qpbench scaling`` (it holds ``scaling.csv``)."""
    return Path(path).is_dir() and (Path(path) / SUMMARY_NAME).is_file()


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
        sizes = a.drop_duplicates("size").set_index("size")[xcol].sort_values()
        names = list(sizes.index)
        best = [f.groupby("size")["time_median_s"].min().reindex(names) for f in (dense, sparse)]
        at = crossing(sizes.values, best[0].values, best[1].values)
        name = None if at is None else names[list(sizes.values).index(at)]
        text = f"- {axis} axis: sparse overtakes dense at {_size_label(frame, name)}"
        if name is None:
            bd, bs = _fastest_at_largest(dense, xcol), _fastest_at_largest(sparse, xcol)
            fd, fs = fitted[(bd, axis)], fitted[(bs, axis)]
            meet = extrapolated_crossing(fd, fs)
            if meet is not None and meet > sizes.max():
                text += f"; the fitted lines of {bd} and {bs} meet near {xcol} = {meet:,.0f} (extrapolated)"
            else:
                text += (
                    f" (fastest dense {bd}, slope {fd.text()}; fastest sparse {bs}, slope {fs.text()}: "
                    "their fitted lines do not meet beyond the grid)"
                )
        lines.append(text)
    return lines


def deadline_table(frame: pd.DataFrame) -> list[dict]:
    """Per backend and axis: the first size whose build + solve exceeds :data:`TICK_S`, at p99
    and at the median, and the largest such tick [us] in brackets."""
    out = []
    for (backend, axis), g in frame[frame["status"] == "measured"].groupby(["backend", "axis"]):
        xcol = AXES[axis][0]
        g = g.sort_values(xcol)
        row = {"backend": backend, "axis": axis}
        for stat in ("p99", "median"):
            tick = g[f"build_{stat}_s"].fillna(0) + g[f"time_{stat}_s"]
            at = first_above(g[xcol].values, tick.values, TICK_S)
            label = _size_label(frame, None if at is None else g[g[xcol] == at]["size"].iloc[0])
            row[f"{stat} tick over 1 ms from"] = f"{label} (largest {tick.max() * US:,.0f})"
        out.append(row)
    return out


def plot(frame: pd.DataFrame, fitted: dict, path: Path) -> Path:
    """A log-log panel per axis (module docstring) as a PNG at ``path``: squares dense, circles sparse,
    one row of panels per group of backends (:func:`qpbench.report.style.groups`)."""
    import matplotlib.ticker

    from ..report import style

    m = frame[frame["status"] == "measured"]
    backends = sorted(m["backend"].unique())
    groups = style.groups(backends) or [("", [])]
    # a panel per axis the study ran (a study of planar sizes only has no spatial panel)
    shown = {k: v for k, v in AXES.items() if (m["axis"] == k).any()} or AXES
    fig, axes = style.subplots(len(groups), len(shown), 7 * len(shown), 4.6 * len(groups) + 0.6)
    for row, (_, group) in enumerate(groups):
        for ax, (axis, (xcol, label)) in zip(axes[row], shown.items()):
            a = m[m["axis"] == axis]
            for b, lit in style.highlighted(backends, group):
                g, fit = a[a["backend"] == b].sort_values(xcol), fitted.get((b, axis))
                if g.empty:
                    continue
                colour, z = (style.look(b).colour, 3) if lit else (style.GREY, 1)
                marker = "o" if g["matrix_format"].iloc[0] == "sparse" else "s"
                tag = f"{b} ({fit.text()})" if fit is not None else b
                times = g["time_median_s"] * 1e6
                ax.plot(g[xcol], times, marker, color=colour, zorder=z, label=tag if lit else None)
                if fit is not None and not math.isnan(fit.slope):  # the fitted power law, dashed
                    xs = np.geomspace(g[xcol].min(), g[xcol].max(), 20)
                    ax.plot(xs, fit.predict(xs) * 1e6, "--", color=colour, lw=1, zorder=z)
            ax.axhline(TICK_S * 1e6, color="k", lw=0.8, ls=":")
            ax.set(
                xscale="log", yscale="log", xlabel=label, ylabel="median solve time per tick [us]"
            )
            ticks = sorted(a[xcol].unique())
            if ticks:  # the measured sizes as plain numbers
                ax.set_xticks(ticks, [f"{int(v):,}" for v in ticks])
                ax.xaxis.set_minor_formatter(matplotlib.ticker.NullFormatter())
            ax.set_title(
                f"{axis} axis (slope +- standard error; squares: dense, circles: sparse)",
                fontsize=9,
            )
            style.legend_beside(ax, fontsize=7)
            ax.grid(True, which="both", alpha=0.3)
    return style.save(fig, path)


def _text(key: str) -> Column:
    return Column(key, key, text=True)


#: The tables of ``scaling.md``, as typed columns of the rows they show.
SIZE_COLUMNS = (
    _text("size"),
    _text("axis"),
    Column("variables", "n"),
    Column("key points", "key_points"),
    Column("cloud points", "cloud_points"),
    Column("rows", "rows", form=",.0f"),
    Column("build p50 [us]", "build_median_s", US, ",.1f"),
    Column("build p99 [us]", "build_p99_s", US, ",.1f"),
)
SLOPE_COLUMNS = (
    _text("backend"),
    _text("format"),
    Column("slope vs variables (arm axis)", "arm"),
    Column("slope vs rows (cloud axis)", "cloud"),
    Column("slope vs variables (spatial axis)", "spatial"),
)
DEADLINE_COLUMNS = tuple(
    _text(key)
    for key in ("backend", "axis", "p99 tick over 1 ms from", "median tick over 1 ms from")
)
ROW_COLUMNS = (
    _text("size"),
    _text("backend"),
    Column("median [us]", "time_median_s", US, ",.1f"),
    Column("p99 [us]", "time_p99_s", US, ",.1f"),
    Column("success %", "success_rate", 100.0, ".0f"),
    Column("gap max", "gap_max", form=".1e"),
    Column(
        "status",
        cell=lambda r: r["status"] if r["status"] == "measured" else f"skipped: {r['skip_reason']}",
        text=True,
    ),
)


def markdown(frame: pd.DataFrame, fitted: dict, image: str | None) -> str:
    """The text of ``scaling.md``."""
    m = frame[frame["status"] == "measured"]
    first = frame.iloc[0]
    lines = [
        "# Scaling: solve time against QP size",
        "",
        f"Closed loop solved by `{first['driver']}`, ticks dumped and solved by each backend "
        f"(min of {first['repeat']} timed solves per tick, seed {first['seed']}); medians and p99 over each "
        "size's ticks. Rows are constraint rows (2 task equalities, 3 on a spatial arm, + one row per key point "
        "and cloud point, per link and ball on a spatial arm); the 2n bounds are not counted.",
        "",
    ]
    if image:
        lines += [f"![scaling]({image})", ""]
    lines += ["## Sizes", ""]
    lines += table(SIZE_COLUMNS, frame.drop_duplicates("size").to_dict("records"))
    lines += [
        "## Slopes",
        "",
        "Least squares of log10(median time) on log10(size) per axis; +- one standard error.",
        "",
    ]
    slopes = [
        {
            "backend": b,
            "format": g["matrix_format"].iloc[0],
            **{ax: fitted[(b, ax)].text() if (b, ax) in fitted else "-" for ax in AXES},
        }
        for b, g in m.groupby("backend", sort=True)
    ]
    lines += table(SLOPE_COLUMNS, slopes)
    lines += ["## Sparse against dense", ""] + crossover_lines(frame, fitted)
    lines += [
        "",
        "## The 1 ms tick",
        "",
        "First size from which build + solve stays above 1 ms: p99 build + p99 solve (every tick must fit), "
        "and median build + median solve (a typical tick fits); largest tick over the axis in brackets [us].",
        "",
    ]
    lines += table(DEADLINE_COLUMNS, deadline_table(frame))
    lines += ["## Every size and backend", ""]
    lines += table(ROW_COLUMNS, frame.to_dict("records"))
    return "\n".join(lines)


def write_scaling_report(
    folder: str | Path, out: str | Path, force: bool = False, plots: bool = True
) -> Path:
    """Write ``scaling.md`` (and ``scaling.png``) for the study in ``folder`` into ``out``.

    Raises:
        InputError: ``folder``'s scaling.csv holds no row.
        OutputExistsError: ``out/scaling.md`` exists and not ``force``.
    """
    from ..exceptions import InputError
    from ..report.write import publish

    frame = pd.read_csv(Path(folder) / SUMMARY_NAME)
    if frame.empty:
        raise InputError("no rows", path=Path(folder) / SUMMARY_NAME)
    measured = frame[frame["status"] == "measured"]
    fitted = {  # (backend, axis) -> PowerFit of its median solve times
        (backend, axis): fit_power_law(g[AXES[axis][0]], g["time_median_s"])
        for (backend, axis), g in measured.groupby(["backend", "axis"])
    }

    def figures(out: Path) -> str | None:
        if not plots or measured.empty:
            return None
        plot(frame, fitted, out / "scaling.png")
        return "scaling.png"

    return publish(out, "scaling.md", force, lambda out: markdown(frame, fitted, figures(out)))
