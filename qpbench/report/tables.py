"""The statistics a report shows, from the rows :mod:`.inputs` read.

Aggregates follow qpbenchmark (``qpbenchmark/report.py``, ``results.py``):

- success rate: percentage of rows whose ``success`` is true (found, and
  residuals and gaps within the profile's tolerance, see :mod:`qpbench.metrics`);
- shifted geometric mean (:func:`qpbenchmark.shgeom.shgeom`) with qpbenchmark's
  shift ``sh = 10`` for every metric. A row whose solution was not found counts
  with the *not-found value*: the profile's time limit for runtime, the
  profile's tolerance for residuals and gaps. One departure, because our sets
  hold infeasible problems (qpbenchmark's do not): a backend that reports the
  infeasibility the reference found has answered right, and its runtime
  counts as measured. Residuals and gaps are floored at
  their tolerance, so over-accuracy is neither rewarded nor penalised. A value
  that is missing (NaN: e.g. no reference objective) counts as not found; an
  infinite residual (a backend that returns no duals) stays infinite.
- ratios to the best: each backend's mean divided by the smallest mean.

Honest ratios: a residual or gap mean over a backend that never found a
solution would be the not-found value floored at the tolerance, the smallest
value possible, and its ratio 1 ("best"); such a backend gets NaN (``-`` in the
report) for every residual and gap mean and ratio, and the best is taken over
the backends that found something.

Runtime is ``wall_time_min_s`` (the harness's timing of the backend call and
the reading of its answer, the minimum over the ``repeat`` timed solves, in
[s]; ``wall_time_median_s`` for a CSV without it). With ``sh = 10`` s and
runtimes of microseconds the shifted geometric
mean is practically the arithmetic mean, dominated by failures (each counted
as the full time limit): read it with the success rate, and the medians and
tails of the per-scenario tables.
"""

from __future__ import annotations

import math
from typing import TYPE_CHECKING

import numpy as np
import pandas as pd

from ..exceptions import InputError
from ..profiles import Tolerance, get_profile
from ..statuses import CERTIFIED_INFEASIBLE

# Reading the CSVs lives in .inputs; Results and read_results stay reachable from here,
# where the report's modules look for their rows.
from .inputs import Results, group_label, read_results, scenario_key, slug  # noqa: F401

if TYPE_CHECKING:
    from collections.abc import Iterator

#: Shift of the shifted geometric means (qpbenchmark uses 10 for every metric).
SHIFT = 10.0

#: Metrics whose mean means nothing without a found solution (NaN for a backend with none).
FOUND_ONLY_METRICS = ("primal_residual", "dual_residual", "duality_gap", "optimality_gap")


#: Metric -> (bench column, Tolerance attribute giving the not-found value, floored?): the
#: columns of the report's summary tables (a per-tick metric that deserves one is one entry here).
SHGEOM_METRICS: dict[str, tuple[str, str, bool]] = {
    "runtime": ("wall_time_min_s", "runtime", False),
    "primal_residual": ("primal_residual", "primal", True),
    "dual_residual": ("dual_residual", "dual", True),
    "duality_gap": ("duality_gap", "gap", True),
    "optimality_gap": ("optimality_gap", "gap", True),
}


def profile_tolerance(profile: str, path: str | None = None) -> Tolerance:
    """The success thresholds of a profile named in a CSV's ``profile`` column."""
    try:
        return get_profile(str(profile)).tolerance
    except InputError as exc:
        raise InputError(exc.message, path=path, key="profile") from None


def metric_values(df: pd.DataFrame, metric: str, tolerance: Tolerance) -> np.ndarray:
    """The values entering the shifted geometric mean of ``metric`` (see module doc)."""
    column, tol_attr, floored = SHGEOM_METRICS[metric]
    if column not in df.columns and metric == "runtime":
        column = "wall_time_median_s"
    not_found = float(getattr(tolerance, tol_attr))
    values = pd.to_numeric(df[column], errors="coerce").to_numpy(dtype=float)
    if metric != "runtime":
        values = np.abs(values)
    answered = df["found"].to_numpy(dtype=bool)
    if metric == "runtime":
        answered = answered | correct_infeasibility(df)
    values = np.where(answered & ~np.isnan(values), values, not_found)
    if floored:
        values = np.maximum(values, not_found)
    return values


def correct_infeasibility(df: pd.DataFrame) -> np.ndarray:
    """Rows where the backend reported the infeasibility the reference found (a right answer)."""
    if "status" not in df.columns or "reference_status" not in df.columns:
        return np.zeros(len(df), dtype=bool)
    status = df["status"].astype(str).to_numpy()
    ref = df["reference_status"].astype(str).to_numpy()
    return (status == ref) & np.isin(ref, CERTIFIED_INFEASIBLE)


def shgeom_of(values: np.ndarray) -> float:
    """qpbenchmark's shifted geometric mean with ``sh = SHIFT`` (inf if any value is)."""
    from qpbenchmark.shgeom import shgeom

    if len(values) == 0:
        return math.nan
    if np.isinf(values).any():
        return math.inf
    return float(shgeom(np.asarray(values, dtype=float), SHIFT))


def bench_groups(bench: pd.DataFrame) -> Iterator[tuple[str, Tolerance, pd.DataFrame]]:
    """Yield ``(label, tolerance, rows)`` per (profile, mode) of the bench rows."""
    if bench.empty:
        return
    keys = ["profile", "mode"] if "mode" in bench.columns else ["profile"]
    df = bench.copy()
    if "mode" in df.columns:
        df["mode"] = df["mode"].fillna("")
    for key, rows in df.groupby(keys, sort=True):
        key = key if isinstance(key, tuple) else (key,)
        profile = key[0]
        mode = key[1] if len(key) > 1 else None
        tolerance = profile_tolerance(profile, rows["source"].iloc[0])
        yield group_label(profile, mode), tolerance, rows


def runtime_column(df: pd.DataFrame) -> str:
    """The runtime column of bench rows: ``wall_time_min_s`` (``wall_time_median_s`` without it)."""
    return "wall_time_min_s" if "wall_time_min_s" in df.columns else "wall_time_median_s"


def isolated_rows(rows: pd.DataFrame) -> dict[str, int]:
    """Per backend, rows solved in a worker process (only backends with some)."""
    if "isolated" not in rows.columns:
        return {}
    counts = rows.groupby("backend", sort=True)["isolated"].sum()
    return {str(b): int(n) for b, n in counts.items() if n}


def backend_summary(rows: pd.DataFrame, tolerance: Tolerance) -> pd.DataFrame:
    """Per backend: success rate [%] and shifted geometric mean of each metric.

    Columns: ``problems``, ``success_rate`` (%), ``found_rate`` (%),
    ``found`` (rows), ``isolated`` (rows solved in a worker process), and for
    each metric of :data:`SHGEOM_METRICS` the absolute mean (``<metric>``,
    runtime in [s]) and the ratio to the best backend (``<metric>_ratio``);
    the metrics of :data:`FOUND_ONLY_METRICS` are NaN for a backend that never
    found a solution, and the best is taken over the others; plus
    ``overhead_median_s``: median of wall time minus solver-reported time, the
    harness's own overhead (NaN when fewer than half of the rows report a
    solver time), and
    ``runtime_feasible`` (+ ``_ratio``): the runtime mean over the problems whose
    reference is optimal only, so that ticks where the right answer is
    "infeasible" (the paper formulation's start) do not decide the ranking.
    """
    out = {}
    tcol = runtime_column(rows)
    for backend, g in rows.groupby("backend", sort=True):
        found = int(g["found"].astype(bool).sum())
        rec = {
            "problems": len(g),
            "success_rate": 100.0 * g["success"].astype(float).mean(),
            "found_rate": 100.0 * g["found"].astype(float).mean(),
            "found": found,
            "isolated": int(g["isolated"].sum()) if "isolated" in g.columns else 0,
        }
        for metric in SHGEOM_METRICS:
            if metric in FOUND_ONLY_METRICS and not found:
                rec[metric] = math.nan
            else:
                rec[metric] = shgeom_of(metric_values(g, metric, tolerance))
        if "reference_status" in g.columns:
            feasible = g[g["reference_status"].astype(str) == "optimal"]
            rec["runtime_feasible"] = shgeom_of(metric_values(feasible, "runtime", tolerance))
        else:
            rec["runtime_feasible"] = math.nan
        if "solver_time_s" in g.columns:
            diff = pd.to_numeric(g[tcol], errors="coerce") - pd.to_numeric(
                g["solver_time_s"], errors="coerce"
            )
            diff = diff[np.isfinite(diff)]
            # Only when most solves report a time: a median over a few rows
            # (e.g. Clarabel, which reports its time only when freshly built,
            # set-up included) would not describe the backend.
            rec["overhead_median_s"] = (
                float(diff.median()) if len(diff) >= 0.5 * len(g) else math.nan
            )
        else:
            rec["overhead_median_s"] = math.nan
        out[backend] = rec
    df = pd.DataFrame.from_dict(out, orient="index")
    for metric in (*SHGEOM_METRICS, "runtime_feasible"):
        best = df[metric].replace([np.inf], np.nan).min()
        df[f"{metric}_ratio"] = df[metric] / best if best and best > 0 else math.nan
    return df


def violation_summary(rows: pd.DataFrame) -> pd.DataFrame:
    """Per backend: constraint violation of its answers (absolute, problem units).

    Columns: ``problems``, ``found`` (rows), ``with_x`` (rows with a
    violation, i.e. with an ``x``), ``max``, ``p99`` over those rows, and
    ``feasible_max``, ``feasible_p99`` over the rows whose reference is
    optimal (on an infeasible problem every answer violates something).
    Empty when the rows have no ``constraint_violation`` column.
    """
    if "constraint_violation" not in rows.columns:
        return pd.DataFrame()
    out = {}
    for backend, g in rows.groupby("backend", sort=True):
        v = pd.to_numeric(g["constraint_violation"], errors="coerce").to_numpy(dtype=float)
        ok = ~np.isnan(v)
        feasible = (
            (g["reference_status"].astype(str) == "optimal").to_numpy()
            if "reference_status" in g.columns
            else np.zeros(len(g), dtype=bool)
        )
        vf = v[ok & feasible]
        out[backend] = {
            "problems": len(g),
            "found": int(g["found"].astype(bool).sum()),
            "with_x": int(ok.sum()),
            "max": float(v[ok].max()) if ok.any() else math.nan,
            "p99": float(np.percentile(v[ok], 99)) if ok.any() else math.nan,
            "feasible_max": float(vf.max()) if vf.size else math.nan,
            "feasible_p99": float(np.percentile(vf, 99)) if vf.size else math.nan,
        }
    return pd.DataFrame.from_dict(out, orient="index")


def solver_time_summary(rows: pd.DataFrame) -> pd.DataFrame:
    """Per backend: the call's wall time against the time the solver reports for itself [s].

    Over the rows where both are known: ``rows`` (count), ``call_p50``,
    ``call_p99`` (the harness's timed call, minimum over repeats),
    ``solver_p50``, ``solver_p99`` (``solver_time_s``: what a controller
    calling the solver's C or C++ library would pay) and ``around_p50``,
    ``around_p99`` (per row, call minus solver: what the Python layers add).
    Backends that report no time of their own (pinv, the network, Clarabel
    after an ``update()``, whose figure is not the solve's) have no row.
    """
    if "solver_time_s" not in rows.columns:
        return pd.DataFrame()
    tcol = runtime_column(rows)
    out = {}
    for backend, g in rows.groupby("backend", sort=True):
        call = pd.to_numeric(g[tcol], errors="coerce").to_numpy(dtype=float)
        solver = pd.to_numeric(g["solver_time_s"], errors="coerce").to_numpy(dtype=float)
        ok = np.isfinite(call) & np.isfinite(solver)
        if not ok.any():
            continue
        call, solver = call[ok], solver[ok]
        around = call - solver
        out[backend] = {
            "rows": int(ok.sum()),
            "call_p50": float(np.percentile(call, 50)),
            "call_p99": float(np.percentile(call, 99)),
            "solver_p50": float(np.percentile(solver, 50)),
            "solver_p99": float(np.percentile(solver, 99)),
            "around_p50": float(np.percentile(around, 50)),
            "around_p99": float(np.percentile(around, 99)),
        }
    return pd.DataFrame.from_dict(out, orient="index")


def scenario_summary(rows: pd.DataFrame, tolerance: Tolerance) -> dict[str, pd.DataFrame]:
    """Per scenario, per backend: problems, success [%], runtime statistics.

    Columns: ``problems``, ``success_rate`` (%), ``runtime_ratio`` (shifted
    geometric mean of runtime over the best backend of that scenario),
    ``runtime_p50_s``, ``runtime_p99_s``, ``runtime_max_s`` (over every row,
    found or not: the time a controller waits), ``optimality_gap_max``
    (largest absolute gap among found solutions, NaN when none has one).
    """
    df = rows.copy()
    df["_scenario"] = [scenario_key(v) for v in df["scenario"]] if "scenario" in df.columns else "-"
    tables = {}
    tcol = runtime_column(df)
    for scenario, g in df.groupby("_scenario", sort=True):
        rec = {}
        for backend, b in g.groupby("backend", sort=True):
            t = pd.to_numeric(b[tcol], errors="coerce").to_numpy(dtype=float)
            t = t[np.isfinite(t)]
            gap = np.abs(pd.to_numeric(b["optimality_gap"], errors="coerce").to_numpy(dtype=float))
            gap = gap[b["found"].to_numpy(dtype=bool) & np.isfinite(gap)]
            rec[backend] = {
                "problems": len(b),
                "success_rate": 100.0 * b["success"].astype(float).mean(),
                "runtime_shgeom": shgeom_of(metric_values(b, "runtime", tolerance)),
                "runtime_p50_s": float(np.percentile(t, 50)) if len(t) else math.nan,
                "runtime_p99_s": float(np.percentile(t, 99)) if len(t) else math.nan,
                "runtime_max_s": float(t.max()) if len(t) else math.nan,
                "optimality_gap_max": float(gap.max()) if len(gap) else math.nan,
            }
        table = pd.DataFrame.from_dict(rec, orient="index")
        best = table["runtime_shgeom"].replace([np.inf], np.nan).min()
        table["runtime_ratio"] = table["runtime_shgeom"] / best if best and best > 0 else math.nan
        tables[scenario] = table
    return tables


def performance_profile(
    rows: pd.DataFrame, taus: np.ndarray | None = None
) -> tuple[np.ndarray, dict[str, np.ndarray]]:
    """Dolan-More performance profile of runtime.

    For problem p and backend s, ``r[p, s] = t[p, s] / min_s t[p, s]`` over the
    successful solves (a failure has ``r = inf``); the profile of s is
    ``rho_s(tau) = |{p : r[p, s] <= tau}| / |P|``.

    Returns:
        ``(taus, {backend: rho(taus)})``.
    """
    rows = rows.assign(
        _key=rows["problem"].astype(str)
        + "\x00"
        + (rows["scenario"].map(scenario_key) if "scenario" in rows.columns else "")
    )
    t = rows.pivot_table(
        index="_key", columns="backend", values=runtime_column(rows), aggfunc="first"
    )
    ok = rows.pivot_table(index="_key", columns="backend", values="success", aggfunc="first")
    ok = ok.reindex_like(t).fillna(False).astype(bool)
    times = t.to_numpy(dtype=float)
    times = np.where(ok.to_numpy() & np.isfinite(times), times, np.inf)
    best = times.min(axis=1, keepdims=True)
    with np.errstate(invalid="ignore", divide="ignore"):
        ratios = np.where(np.isfinite(best), times / best, np.inf)
    if taus is None:
        finite = ratios[np.isfinite(ratios)]
        top = max(2.0, float(finite.max()) * 1.05) if finite.size else 2.0
        taus = np.logspace(0, np.log10(top), 200)
    profiles = {
        str(b): (ratios[:, j][None, :] <= taus[:, None]).mean(axis=1)
        for j, b in enumerate(t.columns)
    }
    return taus, profiles
