"""Agreement of qpbench's metrics with qpbenchmark's own run, on a whole shipped problem set.

Same method as ``tests/test_qpbenchmark_agreement.py``, on every problem of a
set: qpbenchmark's runner (:func:`qpbenchmark.run` on a ``ParquetTestSet``
subclass, in this process) and qpbench's :func:`~qpbench.harness.bench.run_bench`
(``independent`` mode, ``qpsolvers:<name>`` backends) on the same Parquet file,
one run per (settings, solver) on each side.

Two comparisons:

- ``named`` (always): qpbenchmark's ``low_accuracy``, ``mid_accuracy`` and
  ``high_accuracy`` settings against qpbench's profiles ``qpbenchmark:<settings>``,
  which pass qpbenchmark's keyword arguments verbatim, so both sides make the
  same ``qpsolvers.solve_problem`` call (checked: the options are compared key
  by key), and judge success by its rule (``success differs (our column)``:
  our ``success`` column against qpbenchmark's rule on its own rows);
- ``profile`` (``--profiles``): our profile's own options (what ``qpbench bench
  --profile P`` runs) against qpbenchmark with settings built by its API from
  P's numbers. Solvers marked ``other run`` get options from us beyond limits
  (OSQP's polishing), so their solutions differ.

Columns: rows compared; ``found`` in qpbenchmark's run and ours; rows where
``found`` differs; rows where qpbenchmark's success rule (found and each
residual below the tolerance) differs when evaluated on either side's rows;
max ``|qpbenchmark - ours|`` of the primal residual, dual residual and
duality gap over rows where both found a solution (inf on both sides counts as
equal); the largest of those in units of ``eps * s``, ``s`` the largest finite
magnitude in the problem's data (rounding of a residual evaluated on the same
solution is a few of these units; residuals themselves are often at rounding
level, so a difference relative to them says nothing).

Usage::

    python bench/qpbenchmark_agreement.py [--set problems/wall] [--count N]
        [--solvers clarabel,daqp,...] [--profiles default,high_accuracy]
"""

from __future__ import annotations

import argparse
import contextlib
import io
import logging
import sys
import tempfile
import time
import warnings
from pathlib import Path

import numpy as np
import pandas as pd
import qpsolvers

from qpbench.backends import backend_names, get_backend
from qpbench.formats import load_problems
from qpbench.harness.bench import BenchConfig, run_bench
from qpbench.profiles import get_profile
from qpbench.reference import reference_solutions

METRICS = ("primal_residual", "dual_residual", "duality_gap")
EPS = float(np.finfo(float).eps)
#: qpbenchmark's named settings and the qpbench profile judged at the same tolerances.
NAMED_SETTINGS = {
    "low_accuracy": "low_accuracy",
    "mid_accuracy": "default",
    "high_accuracy": "high_accuracy",
}
#: Native option names that only limit a run (a solve that converges before them is unchanged).
LIMIT_KEYS = frozenset(
    {"max_iter", "iter_limit", "max_iters", "time_limit", "time_limit_secs", "TimeLimit"}
)


def import_qpbenchmark():
    """Import qpbenchmark, undoing the root-logger set-up it does at import."""
    root = logging.getLogger()
    handlers, level = list(root.handlers), root.level
    import qpbenchmark

    root.handlers[:] = handlers
    root.setLevel(level)
    return qpbenchmark


def run_qpbenchmark(qpb, test_set, solver: str, settings: str, csv_path: Path) -> pd.DataFrame:
    test_set.solvers = {solver}
    results = qpb.Results(csv_path, test_set)
    with warnings.catch_warnings(), contextlib.redirect_stderr(io.StringIO()):
        warnings.simplefilter("ignore")
        qpb.run(test_set, results, only_settings=settings)
    return results.df.reset_index(drop=True)


def run_ours(
    problem_set, references, solver: str, profile, settings: dict, out: Path
) -> pd.DataFrame:
    config = BenchConfig(
        backends=[f"qpsolvers:{solver}"],
        profile=profile,
        mode="independent",
        isolate="never",
        settings=settings,
    )
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        run_bench(problem_set, config, out, force=True, references=references)
    df = pd.read_csv(out)
    df["solver"] = solver
    return df


def common_solvers(qpb) -> list[str]:
    """Solvers qpsolvers finds, qpbenchmark has settings for and qpbench can drive."""
    ours = {name.split(":", 1)[1] for name in backend_names() if name.startswith("qpsolvers:")}
    return sorted(
        s
        for s in qpsolvers.available_solvers
        if qpb.solver_settings.SolverSettings.is_implemented(s) and s in ours
    )


def data_scale(problem) -> float:
    """Largest finite magnitude in the problem's data (at least 1)."""
    scale = 1.0
    for M in problem.unpack():
        if M is not None:
            v = np.abs(np.asarray(M.toarray() if hasattr(M, "toarray") else M, dtype=float))
            v = v[np.isfinite(v)]
            scale = max(scale, float(v.max())) if v.size else scale
    return scale


def qpbenchmark_success(df: pd.DataFrame, tol) -> pd.Series:
    """qpbenchmark's success rule (``Results.build_success_rate_df``) on rows of either side."""
    return (
        df["found"].astype(bool)
        & (df["primal_residual"] < tol.primal)
        & (df["dual_residual"] < tol.dual)
        & (df["duality_gap"] < tol.gap)
    )


def side(merged: pd.DataFrame, suffix: str) -> pd.DataFrame:
    """The columns of a merged frame that end in ``suffix``, without it (one side's rows)."""
    return merged.rename(columns=lambda c: c.removesuffix(suffix))


def compare(theirs: pd.DataFrame, ours: pd.DataFrame, tol, scales: dict) -> dict:
    m = theirs.merge(ours, on=["problem", "solver"], suffixes=("_qpb", "_ours"), validate="1:1")
    fq, fo = m["found_qpb"].astype(bool), m["found_ours"].astype(bool)
    row = {
        "rows": len(m),
        "found qpb": int(fq.sum()),
        "found ours": int(fo.sum()),
        "found differs": int((fq != fo).sum()),
        "success differs": int(
            (
                qpbenchmark_success(side(m, "_qpb"), tol)
                != qpbenchmark_success(side(m, "_ours"), tol)
            ).sum()
        ),
    }
    both = fq & fo
    scale = m.loc[both, "problem"].map(scales).to_numpy(float)
    ulps = 0.0
    for k in METRICS:
        a = m.loc[both, f"{k}_qpb"].to_numpy(float)
        b = m.loc[both, f"{k}_ours"].to_numpy(float)
        d = np.abs(a - b)
        row[k] = float(d.max()) if d.size else float("nan")
        if d.size:
            ulps = max(ulps, float((d / (EPS * scale)).max()))
    row["max |d|/(eps s)"] = ulps
    return row


def print_table(title: str, rows: list[dict]) -> None:
    print(f"\n{title}\n")
    cols = list(rows[0])
    fmt = {k: (lambda v: f"{v:.1e}") for k in METRICS}
    fmt["max |d|/(eps s)"] = lambda v: f"{v:.2g}"
    cells = [[fmt.get(c, str)(r[c]) for c in cols] for r in rows]
    widths = [max(len(c), *(len(x[i]) for x in cells)) for i, c in enumerate(cols)]
    print("| " + " | ".join(c.ljust(w) for c, w in zip(cols, widths)) + " |")
    print("|" + "|".join("-" * (w + 2) for w in widths) + "|")
    for x in cells:
        print("| " + " | ".join(v.ljust(w) for v, w in zip(x, widths)) + " |")


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument(
        "--set", default="problems/wall", help="problem-set folder (default problems/wall)"
    )
    parser.add_argument(
        "--count", type=int, default=None, help="first N problems only (default: all)"
    )
    parser.add_argument(
        "--solvers", default=None, help="comma-separated qpsolvers names (default: all common)"
    )
    parser.add_argument(
        "--profiles",
        default="",
        help="also compare these qpbench profiles (e.g. default,high_accuracy)",
    )
    args = parser.parse_args(argv)

    qpb = import_qpbenchmark()
    SolverSettings = qpb.solver_settings.SolverSettings
    solvers = common_solvers(qpb)
    if args.solvers:
        solvers = [s for s in args.solvers.split(",") if s in solvers]

    started = time.perf_counter()
    with tempfile.TemporaryDirectory() as tmp:
        tmp = Path(tmp)
        df = pd.read_parquet(Path(args.set) / "problems.parquet")
        if args.count:
            df = df.iloc[: args.count]
        path = tmp / "set.parquet"
        df[list(qpb.ProblemList.KEYS)].to_parquet(path, index=False)
        problem_set = load_problems(path)
        references = reference_solutions(problem_set, cache=False)
        scales = {r.name: data_scale(r.problem) for r in problem_set.records}
        statuses = pd.Series([r.status for r in references]).value_counts().to_dict()
        print(
            f"{args.set}: {len(problem_set)} problems (reference statuses {statuses}); solvers {', '.join(solvers)}"
        )

        class Slice(qpb.ParquetTestSet):
            title = "qpbench problem set"
            description = "A qpbench problem set"
            sparse_only = False

        test_set = Slice(path)
        rows = []
        for settings_name in NAMED_SETTINGS:
            tol = test_set.tolerances[settings_name]
            # qpbench's profile qpbenchmark:<settings>: its arguments verbatim, its time limit, its success rule
            profile = get_profile(f"qpbenchmark:{settings_name}").with_time_limit(tol.runtime)
            for solver in solvers:
                kwargs = dict(test_set.solver_settings[settings_name][solver])
                options = get_backend(f"qpsolvers:{solver}", profile).solver_options
                same_call = options == kwargs
                theirs = run_qpbenchmark(
                    qpb, test_set, solver, settings_name, tmp / f"qpb-{settings_name}-{solver}.csv"
                )
                ours = run_ours(
                    problem_set,
                    references,
                    solver,
                    profile,
                    {},
                    tmp / f"ours-{settings_name}-{solver}.csv",
                )
                rows.append(
                    {
                        "settings": settings_name,
                        "solver": solver,
                        "same call": same_call,
                        "success differs (our column)": int(
                            (
                                theirs.merge(ours, on=["problem", "solver"]).pipe(
                                    lambda m: (
                                        qpbenchmark_success(side(m, "_x"), tol)
                                        != m["success"].astype(bool)
                                    )
                                )
                            ).sum()
                        ),
                        **compare(theirs, ours, tol, scales),
                    }
                )
        print_table("qpbenchmark's named settings, identical solver calls on both sides", rows)

        for profile_name in [p for p in args.profiles.split(",") if p]:
            profile = get_profile(profile_name)
            s = SolverSettings()
            s.set_eps_abs(profile.eps_abs)
            s.set_eps_rel(profile.eps_rel)
            s.set_param("piqp", "check_duality_gap", True)
            s.set_param("proxqp", "check_duality_gap", True)
            s.set_time_limit(profile.time_limit)
            t = profile.tolerance
            test_set.solver_settings = {profile.name: s}
            test_set.tolerances = {
                profile.name: qpb.Tolerance(t.primal, t.dual, t.gap, profile.time_limit)
            }
            rows = []
            for solver in solvers:
                options = get_backend(f"qpsolvers:{solver}", profile).solver_options
                extra = sorted(set(options) - set(s[solver]))
                differs = sorted(k for k, v in s[solver].items() if options.get(k) != v)
                run = "same" if set(extra) <= LIMIT_KEYS and not differs else "other"
                theirs = run_qpbenchmark(
                    qpb,
                    test_set,
                    solver,
                    profile.name,
                    tmp / f"qpb-profile-{profile.name}-{solver}.csv",
                )
                ours = run_ours(
                    problem_set,
                    references,
                    solver,
                    profile,
                    {},
                    tmp / f"ours-profile-{profile.name}-{solver}.csv",
                )
                note = ",".join(k for k in extra if k not in LIMIT_KEYS) + (
                    f" differs:{differs}" if differs else ""
                )
                rows.append(
                    {
                        "solver": solver,
                        "run": run,
                        "our extra options": note or "-",
                        **compare(theirs, ours, t, scales),
                    }
                )
            print_table(
                f"qpbench profile {profile.name} (CLI options) vs qpbenchmark settings from its numbers",
                rows,
            )
    print(f"\n{time.perf_counter() - started:.0f} s")
    return 0


if __name__ == "__main__":
    sys.exit(main())
