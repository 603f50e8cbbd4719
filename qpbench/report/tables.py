"""The statistics a report shows, aggregated as qpbenchmark does: success rate [%]; shifted
geometric means (``sh = 10``) where a row without a found solution (or a NaN) counts as the
*not-found value* (the profile's time limit for runtime, its tolerance for residuals and gaps,
which are floored at it), a right report of infeasibility as measured runtime; ratios to the
best (NaN on residuals and gaps for a backend that never found a solution). Runtime:
``wall_time_min_s`` [s], the minimum over the timed repeats."""

from __future__ import annotations

import math
from typing import TYPE_CHECKING

import numpy as np
import pandas as pd

from ..exceptions import InputError
from ..profiles import Tolerance, get_profile
from ..statuses import CERTIFIED_INFEASIBLE
from .inputs import group_label, numbers, scenario_key

if TYPE_CHECKING:
    from collections.abc import Iterator

#: Shift of the shifted geometric means (qpbenchmark uses 10 for every metric).
SHIFT = 10.0

#: The runtime column of bench rows [s].
RUNTIME = "wall_time_min_s"
#: Metric -> (bench column, Tolerance attribute giving the not-found value, floored?).
SHGEOM_METRICS: dict[str, tuple[str, str, bool]] = {
    "runtime": (RUNTIME, "runtime", False),
    "primal_residual": ("primal_residual", "primal", True),
    "dual_residual": ("dual_residual", "dual", True),
    "duality_gap": ("duality_gap", "gap", True),
    "optimality_gap": ("optimality_gap", "gap", True),
}


def wilson(k: int, n: int, level: float = 0.95) -> tuple[float, float]:
    """Wilson score interval at ``level`` of a proportion ``k / n`` (``(nan, nan)`` when
    ``n = 0``)."""
    if n == 0:
        return math.nan, math.nan
    from scipy.stats import binomtest

    ci = binomtest(k, n).proportion_ci(level, method="wilson")
    return max(0.0, float(ci.low)), min(1.0, float(ci.high))


def worst_first(runs: pd.DataFrame) -> pd.DataFrame:
    """The runs of valid instances of a sweep table (status not ``invalid_scenario``), worst
    first: worst verdict, then the smallest margin of a key point to ``d_safe``, then the largest
    tracking error."""
    from ..sim.verdict import VERDICTS

    valid = runs[runs["status"] != "invalid_scenario"]
    severity = valid["verdict"].map({v: i for i, v in enumerate(VERDICTS)}).fillna(0)
    margin = (valid["min_obstacle_distance"] - valid["d_safe"]).fillna(np.inf)
    tracking = -valid["tracking_max_after_2s"].fillna(0)
    return valid.iloc[np.lexsort((tracking.to_numpy(), margin.to_numpy(), severity.to_numpy()))]


def _percentile(values: np.ndarray, q: float) -> float:
    return float(np.percentile(values, q)) if values.size else math.nan


def _max(values: np.ndarray) -> float:
    return float(values.max()) if values.size else math.nan


def _optimal(rows: pd.DataFrame) -> pd.DataFrame:
    return rows[rows["reference_status"].astype(str) == "optimal"]


def _ratio_to_best(values: pd.Series) -> pd.Series | float:
    """``values`` over the smallest finite positive one (NaN without one)."""
    best = values.replace([np.inf], np.nan).min()
    return values / best if best and best > 0 else math.nan


def _per_backend(rows: pd.DataFrame, record) -> pd.DataFrame:
    """One row per backend (sorted) of the dicts ``record(its rows)`` (``None``: no row)."""
    out = {b: record(g) for b, g in rows.groupby("backend", sort=True)}
    return pd.DataFrame.from_dict({b: r for b, r in out.items() if r is not None}, orient="index")


def metric_values(df: pd.DataFrame, metric: str, tolerance: Tolerance) -> np.ndarray:
    """The values entering the shifted geometric mean of ``metric`` (see module doc)."""
    column, tol_attr, floored = SHGEOM_METRICS[metric]
    not_found = float(getattr(tolerance, tol_attr))
    values = numbers(df, column)
    answered = df["found"].to_numpy(dtype=bool)
    if metric == "runtime":  # or the backend reported the infeasibility the reference found
        ref = df["reference_status"].astype(str).to_numpy()
        right = (df["status"].astype(str).to_numpy() == ref) & np.isin(ref, CERTIFIED_INFEASIBLE)
        answered = answered | right
    else:
        values = np.abs(values)
    values = np.where(answered & ~np.isnan(values), values, not_found)
    return np.maximum(values, not_found) if floored else values


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
    for (profile, mode), rows in bench.groupby(["profile", "mode"], sort=True):
        try:
            tolerance = get_profile(str(profile)).tolerance
        except InputError as exc:
            raise InputError(exc.message, path=rows["source"].iloc[0], key="profile") from None
        yield group_label(profile, mode), tolerance, rows


def backend_summary(rows: pd.DataFrame, tolerance: Tolerance) -> pd.DataFrame:
    """Per backend: success rate [%], each metric's shifted geometric mean (``<metric>``,
    runtime [s]; ``runtime_feasible`` over the problems whose reference is optimal) and its ratio
    to the best (``<metric>_ratio``); ``overhead_median_s``: median of wall time minus solver
    time [s], NaN when fewer than half of the rows report a solver time."""

    def record(g: pd.DataFrame) -> dict:
        found = int(g["found"].sum())
        rec = {
            "problems": len(g),
            "success_rate": 100.0 * g["success"].astype(float).mean(),
            "found": found,
        }
        for metric, (_, _, floored) in SHGEOM_METRICS.items():
            values = metric_values(g, metric, tolerance)
            rec[metric] = math.nan if floored and not found else shgeom_of(values)
        rec["runtime_feasible"] = shgeom_of(metric_values(_optimal(g), "runtime", tolerance))
        diff = numbers(g, RUNTIME) - numbers(g, "solver_time_s")
        diff = diff[np.isfinite(diff)]
        rec["overhead_median_s"] = float(np.median(diff)) if len(diff) >= 0.5 * len(g) else math.nan
        return rec

    df = _per_backend(rows, record)
    for metric in (*SHGEOM_METRICS, "runtime_feasible"):
        df[f"{metric}_ratio"] = _ratio_to_best(df[metric])
    return df


def violation_summary(rows: pd.DataFrame) -> pd.DataFrame:
    """Per backend: constraint violation of its answers (problem units), ``max`` and ``p99``
    over the ``with_x`` rows with an x, ``feasible_*`` over those whose reference is optimal."""

    def record(g: pd.DataFrame) -> dict:
        rec = {"problems": len(g), "found": int(g["found"].sum())}
        for prefix, rows in (("", g), ("feasible_", _optimal(g))):
            v = numbers(rows, "constraint_violation")
            v = v[~np.isnan(v)]
            rec |= {
                f"{prefix}with_x": len(v),
                f"{prefix}max": _max(v),
                f"{prefix}p99": _percentile(v, 99),
            }
        return rec

    return _per_backend(rows, record)


def solver_time_summary(rows: pd.DataFrame) -> pd.DataFrame:
    """Per backend reporting a time of its own, over the rows where both are known: p50 and p99
    of the timed call (``call_*``), of the solver's time (``solver_*``) and of their difference
    (``around_*``) [s]."""

    def record(g: pd.DataFrame) -> dict | None:
        call, solver = numbers(g, RUNTIME), numbers(g, "solver_time_s")
        ok = np.isfinite(call) & np.isfinite(solver)
        if not ok.any():
            return None
        times = {"call": call[ok], "solver": solver[ok], "around": call[ok] - solver[ok]}
        rec = {"rows": int(ok.sum())}
        for name, values in times.items():
            rec |= {f"{name}_p{q}": _percentile(values, q) for q in (50, 99)}
        return rec

    return _per_backend(rows, record)


def scenario_summary(rows: pd.DataFrame, tolerance: Tolerance) -> dict[str, pd.DataFrame]:
    """Per scenario, per backend: problems, success [%], runtime shifted geometric mean and its
    ratio to the best, runtime percentiles over every row [s], largest |optimality gap| found."""

    def record(b: pd.DataFrame) -> dict:
        t = numbers(b, RUNTIME)
        t = t[np.isfinite(t)]
        gap = np.abs(numbers(b, "optimality_gap"))
        gap = gap[b["found"].to_numpy(dtype=bool) & np.isfinite(gap)]
        return {
            "problems": len(b),
            "success_rate": 100.0 * b["success"].astype(float).mean(),
            "runtime_shgeom": shgeom_of(metric_values(b, "runtime", tolerance)),
            "runtime_p50_s": _percentile(t, 50),
            "runtime_p99_s": _percentile(t, 99),
            "runtime_max_s": _max(t),
            "optimality_gap_max": _max(gap),
        }

    tables = {s: _per_backend(g, record) for s, g in rows.groupby("scenario", sort=True)}
    for table in tables.values():
        table["runtime_ratio"] = _ratio_to_best(table["runtime_shgeom"])
    return tables


def performance_profile(
    rows: pd.DataFrame, taus: np.ndarray | None = None
) -> tuple[np.ndarray, dict[str, np.ndarray]]:
    """Dolan-More performance profile of runtime: ``(taus, {backend: rho(taus)})``, ``rho_s(tau)
    = |{p : r[p, s] <= tau}| / |P|``, ``r[p, s] = t[p, s] / min_s t[p, s]`` (a failure: inf)."""
    key = rows["problem"].astype(str) + "\x00" + rows["scenario"].map(scenario_key)
    rows = rows.assign(_key=key)
    t = rows.pivot_table(index="_key", columns="backend", values=RUNTIME, aggfunc="first")
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
