"""The report's sweep section (``docs/sweeps.md``), every number recomputed from ``sweep.csv``:
per backend each bad verdict's rate with its 95 % Wilson score interval (``report.tables.wilson``), every
pair of backends with McNemar's exact test (:func:`mcnemar_exact`), ECDFs and quantiles of the
per-run figures, the worst runs with the command that re-runs each.
"""

from __future__ import annotations

import itertools
import json
from pathlib import Path

import numpy as np
import pandas as pd
from scipy.stats import binomtest

from ..exceptions import InputError
from ..formats import sha256_file
from ..report.inputs import CSV_ERRORS, ResultFile, expand_paths, noise_floor_runs
from ..report.markdown_table import md_table, slug, titled
from ..report.recommend import WORST_HEADER, read_sweeps, rerun_command
from ..report.tables import wilson, worst_first

#: Leading columns of ``sweep.csv`` that tell a sweep table from other result CSVs.
IDENTIFYING = 6
#: Verdicts whose rates are tabulated, in the table's order (every verdict but ``ok``).
RATED = ("unsafe", "diverged", "limits", "incomplete", "failed")
#: x label of the d_min panel when the sweep has a ``d_safe``: its values are d_min - d_safe.
MARGIN_LABEL = "d_min - d_safe [mm] (runs further away leave on the right)"
#: Right edge of the d_min panel [mm beyond d_safe].
ZOOM_MM = 2.0
#: Runs listed per backend among the worst.
WORST = 5
#: ECDF panels: column, label, scale, header of its median in the distributions table.
ECDF_PANELS = (
    ("tracking_max_after_2s", "max |tracking error| after 2 s [mm]", 1e3, "track p50 mm"),
    ("force_error_max_after_2s", "max |force error| after 2 s [N]", 1.0, "force err p50 N"),
    ("min_obstacle_distance", "d_min [mm]", 1e3, "d_min p50 mm"),
    ("solve_time_p99_s", "p99 solve time [us]", 1e6, "p99 solve p50 us"),
)
RATE_HEADER = ["backend", "runs", "invalid instances", "ok", *RATED, "of which error/crashed"]
PAIRED_HEADER = [
    *("A", "B", "instances", "both ok"),
    *("A ok, B not", "B ok, A not", "neither", "p (McNemar)"),
]
QUANTILE_HEADER = [
    "backend",
    *(h for *_, median in ECDF_PANELS for h in (median, "p90", "max")),
    *("t conv. force s", "not conv.", "t conv. track s", "not conv.", "runs with ticks > 1 ms"),
]


def mcnemar_exact(b: int, c: int) -> float:
    """Two-sided exact McNemar p-value of ``b`` and ``c`` discordant pairs (1 when there are none)."""
    return float(binomtest(b, b + c, 0.5).pvalue) if b + c else 1.0


def is_sweep_csv(path: Path) -> bool:
    """``path`` starts with the sweep table's identifying columns (``instance`` to
    ``base_scenario``): a table of this version or of an earlier one, which lacks columns
    added since (read as empty by :func:`_read`)."""
    from .runner import COLUMNS

    with open(path, encoding="utf-8", errors="replace") as fh:
        head = fh.readline().rstrip("\n").split(",")
    return head[:IDENTIFYING] == list(COLUMNS[:IDENTIFYING])


def split_sweep_paths(paths: list[str | Path]) -> tuple[list[Path], list[ResultFile]]:
    """The report's inputs as (other result CSVs, sweep tables); folders are searched."""
    files = expand_paths(paths)
    sweeps = [p for p in files if p.suffix == ".csv" and is_sweep_csv(p)]
    tables = [ResultFile(p, "sweep", sha256_file(p), len(_read(p))) for p in sweeps]
    return [p for p in files if p not in sweeps], tables


def _read(path: Path) -> pd.DataFrame:
    try:
        df = read_sweeps([path])  # the last row of each (instance, backend), with ``folder``
    except CSV_ERRORS as exc:
        raise InputError(f"not a readable sweep CSV ({exc})", path=path) from None
    from .runner import COLUMNS

    df = df.reindex(columns=[*df.columns, *(c for c in COLUMNS if c not in df.columns)])
    df = df[~noise_floor_runs(df)]  # the machine's, not a candidate's
    df["verdict"] = df["verdict"].fillna("").astype(str)
    return df


def rate_rows(df: pd.DataFrame) -> list[list]:
    """Per backend: runs, invalid instances, ok, and each bad verdict's rate with its 95 % interval."""
    out = []
    for backend, g in df.groupby("backend", sort=True):
        valid = g[g["status"] != "invalid_scenario"]
        n = len(valid)
        row = [backend, n, len(g) - n, int((valid["verdict"] == "ok").sum())]
        for verdict in RATED:
            k = int((valid["verdict"] == verdict).sum())
            lo, hi = wilson(k, n)
            row.append(f"{k} ({100 * k / n:.1f} %, {100 * lo:.1f}-{100 * hi:.1f})" if n else "-")
        row.append(int(valid["status"].isin(["error", "crashed"]).sum()))
        out.append(row)
    return out


def paired_rows(df: pd.DataFrame) -> list[list]:
    """Every pair of backends on the instances both ran: counts and McNemar's exact p-value."""
    ok = df[df["status"] != "invalid_scenario"].pivot_table(
        index="instance", columns="backend", values="verdict", aggfunc=lambda v: v.iloc[-1] == "ok"
    )
    out = []
    for a, b in itertools.combinations(sorted(ok.columns), 2):
        both = ok[[a, b]].dropna()
        if both.empty:
            continue
        xa, xb = both[a].astype(bool).to_numpy(), both[b].astype(bool).to_numpy()
        n10, n01 = int((xa & ~xb).sum()), int((~xa & xb).sum())
        both_ok, neither = int((xa & xb).sum()), int((~xa & ~xb).sum())
        out.append([a, b, len(both), both_ok, n10, n01, neither, mcnemar_exact(n10, n01)])
    return out


def _quantile_rows(df: pd.DataFrame) -> list[list]:
    """Per backend, over the runs with a result: median, p90 and max of each ECDF's figure."""
    out = []
    for backend, g in df[df["status"] == "ok"].groupby("backend", sort=True):
        row = [backend]
        for col, _, scale, _ in ECDF_PANELS:
            v = g[col].dropna().to_numpy() * scale
            row += [np.median(v), np.quantile(v, 0.9), np.max(v)] if len(v) else [None] * 3
        for col in ("t_converge_force_s", "t_converge_tracking_s"):
            row += [g[col].median() if g[col].notna().any() else None, int(g[col].isna().sum())]
        row += [int((g["ticks_over_1ms"] > 0).sum())]
        out.append(row)
    return out


def worst_rows(df: pd.DataFrame, k: int = WORST) -> list[list]:
    """Per backend the ``k`` worst runs: worst verdict first, then the smallest margin to ``d_safe``."""
    out = []
    for backend, g in worst_first(df).groupby("backend", sort=True):
        for r in g.head(k).to_dict("records"):
            if r["verdict"] == "ok":
                continue
            why = r["verdict_reasons"] if isinstance(r["verdict_reasons"], str) else r["error"]
            distance = r["min_obstacle_distance"] * 1e3
            rerun = rerun_command(r, backend)
            out.append([backend, r["instance"], r["verdict"], distance, str(why)[:160], rerun])
    return out


def ecdf_plot(df: pd.DataFrame, path: Path, title: str) -> None:
    """Four ECDF panels (:data:`ECDF_PANELS`), one line per backend (runs with a result), one
    row of panels per group of backends (:func:`qpbench.report.style.groups`): the group in its
    look over the other backends in grey; d_min as its margin to ``d_safe`` [mm] if there is one."""
    from ..report import style

    ok = df[df["status"] == "ok"]
    everyone = sorted(ok["backend"].unique())
    groups = style.groups(everyone) or [("", [])]
    size = (3.6 * len(ECDF_PANELS) + 2.0, 3.0 * len(groups) + 0.8)
    fig, axes = style.subplots(len(groups), len(ECDF_PANELS), *size)
    d_safe = float(ok["d_safe"].dropna().iloc[0]) * 1e3 if ok["d_safe"].notna().any() else None
    for row, (group_title, group) in enumerate(groups):
        for ax, (col, label, scale, _) in zip(axes[row], ECDF_PANELS):
            margin = col == "min_obstacle_distance" and d_safe is not None
            shift = d_safe if margin else 0.0
            for backend, lit in style.highlighted(everyone, group):
                v = np.sort(ok.loc[ok["backend"] == backend, col].dropna().to_numpy() * scale)
                if not len(v):
                    continue
                y = np.r_[0.0, np.arange(1, len(v) + 1) / len(v)]
                kw = style.series(backend, lit, np.arange(len(v) + 1), 1.3, 0.8)
                ax.step(np.r_[v[0], v] - shift, y, where="post", **kw)
            if margin:  # zoomed to -1..+2 mm, further left when a run went deeper
                ax.axvline(0.0, color="k", lw=0.8, ls="--", label=f"d_safe {d_safe:g} mm")
                ax.axvline(-0.5, color="red", lw=0.9, ls=":", label="d_safe - 0.5 mm")
                lowest = float(ok[col].min()) * scale - d_safe
                left = min(-1.0, 1.1 * lowest) if np.isfinite(lowest) else -1.0
                ax.axvspan(left, -0.5, color="red", alpha=0.06, lw=0)
                ax.set_xlim(left, ZOOM_MM)
            elif col != "min_obstacle_distance" and ax.has_data() and (ok[col] > 0).any():
                ax.set_xscale("log")
            ax.set(ylim=(0.0, 1.02), xlabel=MARGIN_LABEL if margin else label)
            ax.grid(alpha=0.3)
        axes[row, 0].set_ylabel((f"{group_title}\n" if group_title else "") + "fraction of runs")
        handles, labels = axes[row, 2].get_legend_handles_labels()  # d_min's: with d_safe
        style.legend_beside(axes[row, -1], handles, labels)
    fig.suptitle(title)
    style.save(fig, path)


def _manifest_lines(folder: Path) -> list[str]:
    try:
        m = json.loads((folder / "sweep.json").read_text())
    except (OSError, ValueError):
        return []
    duration = f"{m['duration']} s (the sweep's)" if m.get("duration") else "the base scenario's"
    return [
        f"Sweep file `{m.get('sweep_file')}` (sha256 {str(m.get('sweep_sha256'))[:16]}), base scenario "
        f"`{m.get('base')}`, seed {m.get('seed')}, {m.get('samples')} instances, duration {duration}; "
        f"time to converge: within {m.get('force_band_n')} N and {m.get('tracking_band_m')} m to the end.\n"
    ]


def sweep_section(tables: list[ResultFile], out: Path, plots: bool = True) -> list[str]:
    """Markdown lines of the sweep section for the sweep tables (plots into ``out/plots``)."""
    lines = [
        "## Sweeps\n",
        "Randomised instances of a scenario, each in closed loop with each backend "
        "(`qpbench sweep`). Rates among the runs of valid instances, 95 % Wilson intervals in brackets.\n",
    ]
    for table in tables:
        if table.rows:
            lines += _one_sweep(table.path, out, plots)
        else:  # a budget that ran no instance: the table is a header
            lines.append(f"`{table.path.parent.name}`: no run in this table.\n")
    return lines


def _one_sweep(path: Path, out: Path, plots: bool) -> list[str]:
    """One sweep table's lines: rates, paired comparisons, distributions, ECDFs, worst runs."""
    df = _read(path)
    name = str(df["sweep"].iloc[0])
    lines = [f"### Sweep {name}\n", *_manifest_lines(path.parent)]
    lines.append(md_table(RATE_HEADER, rate_rows(df)))
    lines += titled(
        "Paired on the same instances (ok = verdict ok; McNemar's exact test of the discordant "
        "pairs):\n",
        PAIRED_HEADER,
        paired_rows(df),
    )
    lines.append(
        "Distributions over the runs with a result (median, p90, max; time to converge: median, "
        "runs not converged at the end):\n"
    )
    lines.append(md_table(QUANTILE_HEADER, _quantile_rows(df)))
    concurrent = df["concurrent_solves"].max()
    if concurrent > 1:
        lines.append(
            f"Timing columns were taken with up to {int(concurrent)} closed loops solving at once on a "
            "host: they are disturbed; take timings with `--jobs 1`.\n"
        )
    if plots:
        key = f"sweep_ecdf_{slug(path.parent.name)}_{slug(name)}"
        ecdf_plot(df, out / "plots" / f"{key}.png", f"sweep {name}")
        lines.append(f"![ECDFs, sweep {name}](plots/{key}.png)\n")
    lines += titled(
        "Worst runs (worst verdict, then the smallest margin to d_safe), each re-run alone by its "
        "command:\n",
        WORST_HEADER,
        worst_rows(df),
    )
    return lines
