"""The statistics a report shows, from the rows :mod:`.inputs` read; aggregates as qpbenchmark's.

- success rate: percentage of rows whose ``success`` is true (:mod:`qpbench.metrics`);
- shifted geometric mean with qpbenchmark's shift ``sh = 10`` for every metric
  (:func:`qpbenchmark.shgeom.shgeom`). A row without a found solution counts with the
  *not-found value*: the profile's time limit for runtime, its tolerance for residuals and
  gaps; a missing value (NaN) counts as not found, an infinite residual (no duals) stays
  infinite. One departure, as our sets hold infeasible problems: a backend that reports the
  infeasibility the reference found answered right and its runtime counts as measured.
  Residuals and gaps are floored at their tolerance (over-accuracy neither rewarded nor
  penalised);
- ratios to the best: each backend's mean over the smallest. A backend that never found a
  solution would score best on residuals and gaps (the floor); it gets NaN there instead.

Runtime is ``wall_time_min_s`` [s]: the harness's timing of the backend call and the reading
of its answer, the minimum over the ``repeat`` timed solves. With ``sh = 10`` s the mean of
microsecond runtimes is practically the arithmetic mean, dominated by failures: read it with
the success rate and the per-scenario percentiles.
"""

from __future__ import annotations

import math
from typing import TYPE_CHECKING

import numpy as np
import pandas as pd

from ..exceptions import InputError
from ..profiles import Tolerance, get_profile
from ..statuses import CERTIFIED_INFEASIBLE
from .inputs import group_label, scenario_key

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


def metric_values(df: pd.DataFrame, metric: str, tolerance: Tolerance) -> np.ndarray:
    """The values entering the shifted geometric mean of ``metric`` (see module doc)."""
    column, tol_attr, floored = SHGEOM_METRICS[metric]
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
    df = bench.assign(mode=bench["mode"].fillna(""))
    for (profile, mode), rows in df.groupby(["profile", "mode"], sort=True):
        try:
            tolerance = get_profile(str(profile)).tolerance
        except InputError as exc:
            raise InputError(exc.message, path=rows["source"].iloc[0], key="profile") from None
        yield group_label(profile, mode or None), tolerance, rows


def isolated_rows(rows: pd.DataFrame) -> dict[str, int]:
    """Per backend, rows solved in a worker process (only backends with some)."""
    counts = rows.groupby("backend", sort=True)["isolated"].sum()
    return {str(b): int(n) for b, n in counts.items() if n}


def backend_summary(rows: pd.DataFrame, tolerance: Tolerance) -> pd.DataFrame:
    """Per backend: success rate [%] and the shifted geometric mean (``<metric>``, runtime [s])
    and its ratio to the best (``<metric>_ratio``) of each metric of :data:`SHGEOM_METRICS`.

    ``runtime_feasible``: the runtime mean over the problems whose reference is optimal only
    (so the paper formulation's infeasible first ticks do not decide the ranking);
    ``overhead_median_s``: median of wall time minus solver-reported time, NaN when fewer than
    half of the rows report a solver time.
    """
    out = {}
    for backend, g in rows.groupby("backend", sort=True):
        found = int(g["found"].astype(bool).sum())
        rec = {
            "problems": len(g),
            "success_rate": 100.0 * g["success"].astype(float).mean(),
            "found_rate": 100.0 * g["found"].astype(float).mean(),
            "found": found,
            "isolated": int(g["isolated"].sum()),
        }
        for metric in SHGEOM_METRICS:
            if SHGEOM_METRICS[metric][2] and not found:
                rec[metric] = math.nan
            else:
                rec[metric] = shgeom_of(metric_values(g, metric, tolerance))
        feasible = g[g["reference_status"].astype(str) == "optimal"]
        rec["runtime_feasible"] = shgeom_of(metric_values(feasible, "runtime", tolerance))
        diff = pd.to_numeric(g[RUNTIME], errors="coerce") - pd.to_numeric(
            g["solver_time_s"], errors="coerce"
        )
        diff = diff[np.isfinite(diff)]
        # Only when most solves report a time: a median over a few rows (e.g. Clarabel, which
        # reports its time only when freshly built, set-up included) would not describe it.
        rec["overhead_median_s"] = float(diff.median()) if len(diff) >= 0.5 * len(g) else math.nan
        out[backend] = rec
    df = pd.DataFrame.from_dict(out, orient="index")
    for metric in (*SHGEOM_METRICS, "runtime_feasible"):
        best = df[metric].replace([np.inf], np.nan).min()
        df[f"{metric}_ratio"] = df[metric] / best if best and best > 0 else math.nan
    return df


def violation_summary(rows: pd.DataFrame) -> pd.DataFrame:
    """Per backend: constraint violation of its answers (absolute, problem units): ``max`` and
    ``p99`` over the rows with an ``x`` (``with_x``), and ``feasible_max``, ``feasible_p99`` over
    those whose reference is optimal (on an infeasible problem every answer violates something).
    """
    out = {}
    for backend, g in rows.groupby("backend", sort=True):
        v = pd.to_numeric(g["constraint_violation"], errors="coerce").to_numpy(dtype=float)
        ok = ~np.isnan(v)
        feasible = (g["reference_status"].astype(str) == "optimal").to_numpy()
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
    """Per backend, over the rows where both are known: the timed call (``call_*``) against
    the time the solver reports for itself (``solver_*``: what a controller calling its C or
    C++ library pays) and their difference per row (``around_*``) [s]. A backend reporting no
    time of its own has no row.
    """
    out = {}
    for backend, g in rows.groupby("backend", sort=True):
        call = pd.to_numeric(g[RUNTIME], errors="coerce").to_numpy(dtype=float)
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
    """Per scenario, per backend: problems, success [%], runtime shifted geometric mean as a
    ratio to the scenario's best, runtime percentiles over every row, found or not (the time a
    controller waits) [s], and the largest |optimality gap| of a found solution.
    """
    df = rows.assign(_scenario=rows["scenario"].map(scenario_key))
    tables = {}
    for scenario, g in df.groupby("_scenario", sort=True):
        rec = {}
        for backend, b in g.groupby("backend", sort=True):
            t = pd.to_numeric(b[RUNTIME], errors="coerce").to_numpy(dtype=float)
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
