"""The statistics a report shows, from the rows :mod:`.inputs` read; aggregates as qpbenchmark's.

- success rate: percentage of rows whose ``success`` is true (:mod:`qpbench.metrics`);
- shifted geometric mean with qpbenchmark's shift ``sh = 10`` for every metric
  (:func:`qpbenchmark.shgeom.shgeom`). A row without a found solution counts with the
  *not-found value*: the profile's time limit for runtime, its tolerance for residuals and
  gaps; a missing value (NaN) counts as not found, an infinite residual (no duals) stays
  infinite. A backend that reports the infeasibility the reference found answered right and
  its runtime counts as measured. Residuals and gaps are floored at their tolerance;
- ratios to the best: each backend's mean over the smallest. A backend that never found a
  solution would score best on residuals and gaps (the floor); it gets NaN there instead.

Runtime is ``wall_time_min_s`` [s]: the harness's timing of the backend call and the reading
of its answer, the minimum over the ``repeat`` timed solves.
"""

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
#: Metric -> (bench column, Tolerance attribute giving the not-found value, floored?): the
#: columns of the report's summary tables; a floored mean means nothing without a found
#: solution (NaN for a backend with none).
SHGEOM_METRICS: dict[str, tuple[str, str, bool]] = {
    "runtime": (RUNTIME, "runtime", False),
    "primal_residual": ("primal_residual", "primal", True),
    "dual_residual": ("dual_residual", "dual", True),
    "duality_gap": ("duality_gap", "gap", True),
    "optimality_gap": ("optimality_gap", "gap", True),
}


def _percentile(values: np.ndarray, q: float) -> float:
    return float(np.percentile(values, q)) if values.size else math.nan


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
    for (profile, mode), rows in bench.groupby(["profile", "mode"], sort=True):
        try:
            tolerance = get_profile(str(profile)).tolerance
        except InputError as exc:
            raise InputError(exc.message, path=rows["source"].iloc[0], key="profile") from None
        yield group_label(profile, mode), tolerance, rows


def isolated_rows(rows: pd.DataFrame) -> dict[str, int]:
    """Per backend, rows solved in a worker process (only backends with some)."""
    counts = rows.groupby("backend", sort=True)["isolated"].sum()
    return {str(b): int(n) for b, n in counts.items() if n}


def backend_summary(rows: pd.DataFrame, tolerance: Tolerance) -> pd.DataFrame:
    """Per backend: success rate [%] and the shifted geometric mean (``<metric>``, runtime [s])
    and its ratio to the best (``<metric>_ratio``) of each metric of :data:`SHGEOM_METRICS`.

    ``runtime_feasible``: the runtime mean over the problems whose reference is optimal only;
    ``overhead_median_s``: median of wall time minus solver-reported time, NaN when fewer than
    half of the rows report a solver time (a median of a few would not describe the backend).
    """

    def record(g: pd.DataFrame) -> dict:
        found = int(g["found"].astype(bool).sum())
        rec = {
            "problems": len(g),
            "success_rate": 100.0 * g["success"].astype(float).mean(),
            "found_rate": 100.0 * g["found"].astype(float).mean(),
            "found": found,
            "isolated": int(g["isolated"].sum()),
        }
        for metric, (_, _, floored) in SHGEOM_METRICS.items():
            values = metric_values(g, metric, tolerance)
            rec[metric] = math.nan if floored and not found else shgeom_of(values)
        feasible = g[g["reference_status"].astype(str) == "optimal"]
        rec["runtime_feasible"] = shgeom_of(metric_values(feasible, "runtime", tolerance))
        diff = numbers(g, RUNTIME) - numbers(g, "solver_time_s")
        diff = diff[np.isfinite(diff)]
        rec["overhead_median_s"] = float(np.median(diff)) if len(diff) >= 0.5 * len(g) else math.nan
        return rec

    df = _per_backend(rows, record)
    for metric in (*SHGEOM_METRICS, "runtime_feasible"):
        df[f"{metric}_ratio"] = _ratio_to_best(df[metric])
    return df


def violation_summary(rows: pd.DataFrame) -> pd.DataFrame:
    """Per backend: constraint violation of its answers (absolute, problem units): ``max`` and
    ``p99`` over the rows with an ``x`` (``with_x``), and ``feasible_max``, ``feasible_p99`` over
    those whose reference is optimal (on an infeasible problem every answer violates something).
    """

    def record(g: pd.DataFrame) -> dict:
        v = numbers(g, "constraint_violation")
        v = v[~np.isnan(v)]
        feasible = numbers(
            g[g["reference_status"].astype(str) == "optimal"], "constraint_violation"
        )
        vf = feasible[~np.isnan(feasible)]
        return {
            "problems": len(g),
            "found": int(g["found"].astype(bool).sum()),
            "with_x": len(v),
            "max": float(v.max()) if v.size else math.nan,
            "p99": _percentile(v, 99),
            "feasible_max": float(vf.max()) if vf.size else math.nan,
            "feasible_p99": _percentile(vf, 99),
        }

    return _per_backend(rows, record)


def solver_time_summary(rows: pd.DataFrame) -> pd.DataFrame:
    """Per backend, over the rows where both are known: the timed call (``call_*``) against
    the time the solver reports for itself (``solver_*``: what a controller calling its C or
    C++ library pays) and their difference per row (``around_*``) [s]. A backend reporting no
    time of its own has no row.
    """

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
    """Per scenario, per backend: problems, success [%], runtime shifted geometric mean as a
    ratio to the scenario's best, runtime percentiles over every row, found or not (the time a
    controller waits) [s], and the largest |optimality gap| of a found solution.
    """

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
            "runtime_max_s": float(t.max()) if len(t) else math.nan,
            "optimality_gap_max": float(gap.max()) if len(gap) else math.nan,
        }

    tables = {}
    for scenario, g in rows.groupby("scenario", sort=True):
        table = _per_backend(g, record)
        table["runtime_ratio"] = _ratio_to_best(table["runtime_shgeom"])
        tables[scenario] = table
    return tables


def performance_profile(
    rows: pd.DataFrame, taus: np.ndarray | None = None
) -> tuple[np.ndarray, dict[str, np.ndarray]]:
    """Dolan-More performance profile of runtime: ``(taus, {backend: rho(taus)})``.

    ``r[p, s] = t[p, s] / min_s t[p, s]`` over the successful solves (a failure: ``inf``);
    ``rho_s(tau) = |{p : r[p, s] <= tau}| / |P|``.
    """
    rows = rows.assign(
        _key=rows["problem"].astype(str) + "\x00" + rows["scenario"].map(scenario_key)
    )
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
