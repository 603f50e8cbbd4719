"""``report.md``: the recommendation (:mod:`.recommend`), the result files, machine and package
versions, per (profile, mode) of the bench rows its tables, the closed loop: the runs that failed
their verdict, per scenario each run's figures (:data:`CLOSED_LOOP_TABLE`) and the figures.
Each table follows a one-line caption ending in ``:``."""

from __future__ import annotations

import datetime
import math
import os
import platform
from operator import attrgetter
from pathlib import Path

import pandas as pd

from ..formats import package_versions
from ..profiles import PROFILES
from ..sim.verdict import BAD_VERDICTS
from . import tables
from .arm import ROLES
from .inputs import Results
from .markdown_table import MM, US, Column, fmt, md_table, slug, table
from .recommend import MIN_OK_BOUND, opening

#: Distributions whose versions every report lists.
PACKAGES = (
    "qpbench",
    "numpy",
    "scipy",
    "pandas",
    "numba",
    "qpsolvers",
    "qpbenchmark",
    "osqp",
    "proxsuite",
    "clarabel",
    "cvxpy",
    "daqp",
    "quadprog",
    "piqp",
    "cmeel-qpoases",
    "highspy",
    "scs",
    "qpalm",
    "ecos",
    "cvxopt",
    "gurobipy",
    "matplotlib",
)


def cpu_name() -> str:
    """Model name of the CPU (``/proc/cpuinfo``'s ``model name``), or the platform's guess."""
    try:
        for line in Path("/proc/cpuinfo").read_text().splitlines():
            if line.lower().startswith("model name"):
                return line.split(":", 1)[1].strip()
    except OSError:
        pass
    return platform.processor() or platform.machine() or "unknown"


def machine_info() -> dict[str, str]:
    """CPU, core counts, OS and Python of the current machine, as display strings."""
    from ..runner import default_jobs

    return {
        "CPU": cpu_name(),
        "Cores (usable / logical)": f"{default_jobs()} / {os.cpu_count()}",
        "OS": platform.platform(),
        "Python": f"{platform.python_implementation()} {platform.python_version()}",
    }


#: Mark of a backend with rows solved in a worker process.
ISOLATED_MARK = "\u2020"


#: The profiles table: settings asked of every backend and success tolerances.
PROFILE_COLUMNS = tuple(
    Column(header, cell=attrgetter(attribute), text=header == "profile")
    for header, attribute in (
        ("profile", "name"),
        ("eps_abs", "eps_abs"),
        ("eps_rel", "eps_rel"),
        ("max_iter", "max_iter"),
        ("time limit (s)", "time_limit"),
        ("primal tol", "tolerance.primal"),
        ("dual tol", "tolerance.dual"),
        ("gap tol", "tolerance.gap"),
    )
)


def _records(frame: pd.DataFrame, names: dict[str, str]) -> list[dict]:
    """A per-backend frame's rows as records, ``backend`` its name as shown (``names``)."""
    return [{"backend": names.get(b, b), **r} for b, r in frame.iterrows()]


_BACKEND = Column("backend", "backend", text=True)
_BACKEND_PROBLEMS = (
    _BACKEND,
    Column("problems", "problems"),
    Column("success (%)", "success_rate"),
)
#: The per-scenario runtime table.
SCENARIO_COLUMNS = (
    *_BACKEND_PROBLEMS,
    Column("runtime shm ratio", "runtime_ratio"),
    Column("runtime p50 (us)", "runtime_p50_s", US),
    Column("runtime p99 (us)", "runtime_p99_s", US),
    Column("runtime max (us)", "runtime_max_s", US),
    Column("max optimality gap", "optimality_gap_max"),
)
#: The solver's own time against the timed call.
SOLVER_TIME_COLUMNS = (
    _BACKEND,
    Column("rows", "rows"),
    *(
        Column(f"{what} {q} (us)", f"{key}_{q}", US)
        for what, key in (("call", "call"), ("solver", "solver"), ("call - solver", "around"))
        for q in ("p50", "p99")
    ),
)
#: Constraint violation per backend.
VIOLATION_COLUMNS = (
    _BACKEND,
    Column("problems", "problems"),
    Column("found", "found"),
    Column("rows with x", "with_x"),
    Column("max", "max"),
    Column("p99", "p99"),
    Column("max (feasible)", "feasible_max"),
    Column("p99 (feasible)", "feasible_p99"),
)


def _labels(rows: pd.DataFrame) -> tuple[dict[str, str], list[str]]:
    """Backend -> name shown in tables showing times, and the footnote lines for isolated rows."""
    counts = rows.groupby("backend", sort=True)["isolated"].sum()
    isolated = {b: int(n) for b, n in counts.items() if n}
    totals = rows.groupby("backend", sort=True).size()
    labels = {b: f"{b} {ISOLATED_MARK}" if b in isolated else b for b in totals.index}
    notes = []
    if isolated:
        parts = ", ".join(f"{b} {n} of {int(totals[b])} rows" for b, n in isolated.items())
        notes.append(
            f"{ISOLATED_MARK} solved in a worker process ({parts}): the time is taken inside the worker "
            "around the same call, but a worker's caches are not the main process's, so its single-shot "
            "times are not directly comparable with in-process ones.\n"
        )
    return labels, notes


def _bench_section(results: Results, plot_files: dict[str, str]) -> list[str]:
    """The per-tick benchmark's section: what a success and the means are, then one part per profile."""
    bench = results.bench
    out = [
        "## Per-tick benchmark\n",
        f"{bench['problem'].nunique()} problems, {bench['backend'].nunique()} backends, "
        f"{len(bench)} rows. A solve is a *success* when the backend found a solution whose "
        "primal residual, dual residual, duality gap and optimality gap (against the "
        "reference solution) are within the profile's tolerances. Shifted geometric means "
        f"(shm) use qpbenchmark's shift sh = {tables.SHIFT:g} for every metric; a solve "
        "without a solution counts as the profile's time limit (runtime) or its tolerance "
        "(residuals, gaps), and residuals and gaps are floored at their tolerance, as in "
        "qpbenchmark; a backend that reports the infeasibility the reference found (the "
        "paper formulation's first ticks) answered right and its runtime counts as measured. "
        "Runtime is the harness's wall time of the backend call and the reading of its answer "
        "(x and duals), the minimum over the row's timed repeats (`repeat` column). With sh = "
        "10 s the runtime shm of microsecond solves is close to their arithmetic mean and a single "
        "failure dominates it: read it with the success rate and the per-scenario percentiles. "
        "Each problem is solved by the backends in an order drawn for it from a recorded seed "
        "(`position`, `order_seed` columns), so the cold caches the harness leaves between "
        "problems do not fall on one backend. *runtime (feasible)* is the same mean over the "
        "problems whose reference solution is optimal only: on the paper formulation's "
        "infeasible ticks the right answer "
        'is "infeasible", and a backend that cannot say so (qpsolvers\' interface reports '
        "not_solved) is charged the time limit for it in the plain column.\n",
        *(f"Note: {note}.\n" for note in results.notes),
    ]
    out.extend(_reference_agreement_part(bench))
    for label, tol, rows in tables.bench_groups(bench):
        out.extend(_profile_part(label, tol, rows, plot_files))
    return out


def _reference_agreement_part(bench: pd.DataFrame) -> list[str]:
    """How far the two reference solvers' objectives are apart, per problem."""
    agreement = pd.to_numeric(bench["reference_agreement"], errors="coerce")
    per_problem = agreement.groupby([bench["scenario"], bench["problem"]], sort=False).max()
    per_problem = per_problem.dropna()
    if not len(per_problem):
        return []
    return [
        f"Reference solutions: Clarabel and PIQP both optimal on {len(per_problem)} problems, relative "
        f"objective difference max {fmt(per_problem.max())}, "
        f"{int((per_problem > 1e-7).sum())} above 1e-7 (the kept answer is the one with the smaller "
        "KKT residuals; `reference_agreement` column).\n"
    ]


def _profile_part(label: str, tol, rows: pd.DataFrame, plot_files: dict[str, str]) -> list[str]:
    """One profile's tables: success and shifted geometric means, violations, then per scenario
    its runtimes, the solver's own time against the whole call, and its per-tick figure."""
    out = [
        f"### Profile {label}\n",
        f"Tolerances: primal {tol.primal:g}, dual {tol.dual:g}, gap {tol.gap:g}, "
        f"time limit {tol.runtime:g} s.\n",
    ]
    summary = tables.backend_summary(rows, tol)
    names, isolated_notes = _labels(rows)
    never = [str(b) for b, r in summary.iterrows() if int(r["found"]) == 0]
    notes = list(isolated_notes)
    if never:
        notes.append(
            f"A `-` in a residual or gap column: {', '.join(never)} never found a solution (0 rows "
            "with status optimal), so there is no residual or gap to average; counted with the "
            "not-found value, floored at the tolerance, they would score as the best.\n"
        )
    accuracy = [m for m in tables.SHGEOM_METRICS if m != "runtime"]  # residuals and gaps, in order
    records = _records(summary, names)
    out.append("Success rate and shifted geometric means as ratios to the best (1 is the best):\n")
    out += table(
        [
            *_BACKEND_PROBLEMS,
            Column("runtime", "runtime_ratio"),
            Column("runtime (feasible)", "runtime_feasible_ratio"),
            *(Column(m.replace("_", " "), f"{m}_ratio") for m in accuracy),
        ],
        records,
    )
    out += [*notes, "Shifted geometric means, absolute values:\n"]
    out += table(
        [
            _BACKEND,
            Column("runtime (us)", "runtime", US),
            Column("runtime feasible (us)", "runtime_feasible", US),
            *(Column(m.replace("_", " "), m) for m in accuracy),
            Column("harness overhead p50 (us)", "overhead_median_s", US),
        ],
        records,
    )
    out += notes + _violation_part(rows, never)
    key = f"perf_profile_{slug(label)}"
    if key in plot_files:
        out.append(
            "Dolan-More performance profile of runtime (fraction of problems a backend "
            "solves successfully within tau times the best backend's time):\n"
        )
        out.append(f"![performance profile, {label}]({plot_files[key]})\n")
    for scenario, frame in tables.scenario_summary(rows, tol).items():
        out += [
            f"#### Scenario {scenario} ({label})\n",
            "Per backend, runtime over every problem of the scenario:\n",
            *table(SCENARIO_COLUMNS, _records(frame, names)),
        ]
        if any(names[b] != b for b in frame.index):
            out.extend(isolated_notes)
        times = tables.solver_time_summary(rows[rows["scenario"] == scenario])
        if not times.empty:
            out.append(
                "What the solver reports for its own work (`solver_time_s`: what a controller "
                "calling its C or C++ library pays) against the timed call, and their difference "
                "per tick (what the Python layers add); backends that report no time of their own "
                "are not listed:\n"
            )
            out += table(SOLVER_TIME_COLUMNS, _records(times, names))
        key = f"per_tick_{slug(label)}_{slug(scenario)}"
        if key in plot_files:
            out.append(f"![time and gap against t, {scenario}]({plot_files[key]})\n")
    return out


def _violation_part(rows: pd.DataFrame, never: list[str]) -> list[str]:
    """Constraint violation per backend, and a sentence for each backend that never found a solution."""
    frame = tables.violation_summary(rows)
    out = [
        "Constraint violation of the answers, max(0, Gx - h), |Ax - b| and bound violation, the "
        "largest of the three per row (absolute, in the problem's units), over the rows with an x "
        "(found or not), and over those whose reference is optimal:\n",
        *table(VIOLATION_COLUMNS, _records(frame, {})),
    ]
    for b in never:
        r = frame.loc[b]
        no_x = f"{b} never found a solution and returned no x: it has no accuracy figure.\n"
        if int(r["with_x"]) == 0:
            out.append(no_x)
            continue
        out.append(
            f"{b} never found a solution (0 of {int(r['problems'])} rows): its constraint violation is the "
            f"only accuracy figure it has: max {fmt(r['max'])}, p99 {fmt(r['p99'])} over its "
            f"{int(r['with_x'])} answers; max {fmt(r['feasible_max'])}, p99 {fmt(r['feasible_p99'])} on "
            "the problems whose reference is optimal.\n"
        )
    return out


#: Marks a verdict judged on thresholds set on the command line (footnote :data:`FOOTNOTE`).
OVERRIDDEN = "\u2020"
FOOTNOTE = (
    f"{OVERRIDDEN} judged on `[verdict]` thresholds set on the command line, not the scenario "
    "file's (the row's `verdict_overrides` says which).\n"
)


def _overridden(row) -> bool:
    """The row's verdict was judged on thresholds set over the scenario file's (a summary's
    dict, or its JSON text in a CSV)."""
    value = row["verdict_overrides"]
    if isinstance(value, dict):
        return bool(value)
    return isinstance(value, str) and value.strip() not in ("", "{}")


def _verdict(row) -> str:
    return f"{row['verdict']}{OVERRIDDEN}" if _overridden(row) else row["verdict"]


def _body_where(row) -> str:
    """``"link 4 / blob at 3.14 s"``: where and when the body came closest to an obstacle."""
    t = float(row.get("min_body_distance_t", math.nan))  # figures of a run with a result only
    if math.isnan(t):
        return "-"
    link = int(float(row["min_body_distance_link"]))
    return f"link {link} / {row['min_body_distance_obstacle']} at {t:.2f} s"


#: The closed-loop table: one column per figure of a run, in display units (right-aligned).
CLOSED_LOOP_TABLE = (
    Column("status", "status"),
    Column("verdict", "verdict", cell=_verdict),
    Column("real time", "realtime"),
    Column("real time (solver's own)", "realtime_solver"),
    Column("simulated (s)", "simulated_s", 1.0),
    Column("tracking RMS (mm)", "tracking_rms_after_2s", MM),
    Column("tracking max (mm)", "tracking_max_after_2s", MM),
    Column("force err RMS (N)", "force_error_rms_after_2s", 1.0),
    Column("force err max (N)", "force_error_max_after_2s", 1.0),
    Column("min body dist (mm)", "min_body_distance", MM),
    Column("body closest at", "min_body_where", cell=_body_where),
    Column("min key-point dist (mm)", "min_obstacle_distance", MM),
    Column("key-point rule", "key_point_rule"),
    Column("joint-limit violations", "joint_limit_violations", 1.0),
    Column("infeasible ticks", "infeasible_ticks", 1.0),
    Column("fallback ticks", "fallback_ticks", 1.0),
    Column("int v^2 dt", "v2_integral", 1.0),
    Column("solve p50 (us)", "solve_time_median_s", US),
    Column("solve p99 (us)", "solve_time_p99_s", US),
    Column("solve max (us)", "solve_time_max_s", US),
    Column("ticks over dt (%)", "over_dt_share", 100.0),
    Column("solver's own p99 (us)", "solver_time_p99_s", US),
    Column("real-time factor", "real_time_factor", 1.0),
)


#: The closed-loop figures of a scenario: key prefix and alt text.
LOOP_FIGURES = (("", "closed loop"), ("v_", "joint velocities"), ("d_", "key-point distances"))
#: The runs that failed their verdict.
FAILED_TABLE = (
    Column("scenario", "scenario", text=True),
    Column("backend", "backend"),
    Column("formulation", "formulation"),
    Column("verdict", cell=_verdict),
    Column("reasons", "verdict_reasons"),
)


def failed_verdicts(df: pd.DataFrame) -> list[str]:
    """The "Runs that failed their verdict" table (a line saying so when every run is ``ok``)."""
    bad = df[df["verdict"].astype(str).isin(BAD_VERDICTS)]
    if bad.empty:
        return ["Every run's verdict is ok.\n"]
    heading = ["### Runs that failed their verdict\n", "Runs whose verdict is not ok, and why:\n"]
    return heading + table(FAILED_TABLE, bad.to_dict("records"))


def closed_loop_section(results: Results, plot_files: dict[str, str]) -> list[str]:
    """The closed loop's section: the failed verdicts, then per scenario its table and figures."""
    df = results.closed_loop
    out = [
        "## Closed loop\n",
        "Each scenario with each backend solving every tick's QP in the loop. Tracking and "
        "force errors are taken after the transient (t >= 2 s); `int v^2 dt` is the integral "
        "of the joint-velocity norm squared [rad^2/s]; solve times are per tick; the real-time "
        "factor is simulated time over wall time. Each run's *verdict* (thresholds in the "
        "scenario file's `[verdict]` table) is `failed` (the backend raised, answered with "
        "NaN, too late or not at all), `unsafe` (the arm's body, its links as capsules with the "
        "end effector's, went into an obstacle: `min body dist` below 0), `limits` (a joint "
        "angle or speed beyond its limit), `incomplete` (the run stopped before its duration: "
        "wall-time budget, crash, the run's deadline or an error), `diverged` (tracking or "
        "force error beyond its threshold after the settle time), else `ok`; the first that "
        "holds, every reason listed. Status `budget`: the run stopped when its wall-time "
        "budget was spent, after `simulated (s)`; its figures are of what it simulated. Beside "
        "the verdict, the paper's own guarantee: the `key-point rule` is `held` when every key "
        "point kept d_safe minus the safety margin from every obstacle, `broken` when one did "
        "not (`-`: no obstacles); the paper's key points leave the end effector and most of "
        "each link unguarded, so a run can hold it and still be `unsafe`. *Real time*, beside "
        "the verdict: `yes` when, on the ticks not declared infeasible, the p99 of the "
        "per-tick times is at most the scenario's `max_p99_fraction_of_dt` of dt and at most "
        "`max_over_dt_share` of them took longer than dt beyond the share this machine's own "
        "loop missed without a solver (the `noop` run of the same scenario, the noise floor), "
        "and the infeasible ticks' median is at most `max_p99_fraction_of_dt` of dt; `unknown` "
        "where the noise floor fails a criterion the run fails too; judged on the measured "
        "call times (what a Python controller sees) and on the solver's own reported times "
        "(what a C or C++ controller calling the solver sees; `unknown` when the backend "
        "reports none or reports it on some ticks only).\n",
        *failed_verdicts(df),
    ]
    if df.apply(_overridden, axis=1).any():
        out.append(FOOTNOTE)
    kinds = df.get("key_points_kind", pd.Series("paper", index=df.index)).fillna("paper")
    for (scenario, formulation, kind), g in df.groupby(
        [df["scenario"].astype(str), df["formulation"].fillna("-").astype(str), kinds], sort=False
    ):
        duration = pd.to_numeric(g["duration_s"], errors="coerce").max()
        shown = formulation if kind == "paper" else f"{formulation}, key points: {kind}"
        out += [
            f"### Scenario {scenario} ({shown})\n",
            f"Closed-loop metrics per backend (runs of {fmt(duration)} s):\n",
        ]
        out += table((_BACKEND, *CLOSED_LOOP_TABLE), g.to_dict("records"))
        errors = g[~g["status"].isin(("ok", "budget"))].to_dict("records")
        out += [f"- {r['backend']}: {fmt(r['error'])}\n" for r in errors]
        for prefix, alt in LOOP_FIGURES:
            key = f"closed_loop_{prefix}{slug(scenario)}_{slug(formulation)}"
            if key in plot_files:
                out.append(f"![{alt}, {scenario}]({plot_files[key]})\n")
        keys = {r: f"snapshot_{r}_{slug(scenario)}_{slug(formulation)}" for r in ROLES}
        drawn = [r for r, key in keys.items() if key in plot_files]
        if drawn:  # the arm's pictures side by side
            pictures = [f"![{ROLES[r]}, {scenario}]({plot_files[keys[r]]})" for r in drawn]
            out += [f"The arm, {scenario}:\n", md_table([ROLES[r] for r in drawn], [pictures])]
    return out


def render(
    results: Results,
    plot_files: dict[str, str],
    sweeps: pd.DataFrame | None = None,
    min_ok_bound: float = MIN_OK_BOUND,
) -> str:
    """The text of ``report.md``; ``plot_files``: figure key -> path relative to the report (keys
    of :mod:`.plots`, a missing one not shown); ``sweeps``, ``min_ok_bound``: the perturbed runs
    the recommendation reads (:func:`.recommend.recommend`)."""
    date = datetime.datetime.now(datetime.timezone.utc).strftime("%Y-%m-%d %H:%M UTC")
    lines = [
        "# qpbench report\n",
        *opening(
            results.closed_loop,
            not results.bench.empty,
            sweeps,
            min_ok_bound,
            noise_floor=results.noise_floor,
        ),
        "Per-tick QPs of the compliant redundant manipulator of Zhou, Xu & Li (2019), "
        "benchmarked per tick and in the closed loop. Every number below is recomputed "
        "from the result files listed here.\n",
        f"Date: {date}\n",
        "Result files:\n",
        md_table(
            ["file", "kind", "rows", "sha256"],
            [[f.path.name, f.kind, f.rows, f.sha256[:16]] for f in results.files],
        ),
        "## Machine\n",
        "Machine the report was written on:\n",
        md_table(["property", "value"], list(machine_info().items())),
        "Package versions:\n",
        md_table(["package", "version"], list(package_versions(PACKAGES).items())),
    ]
    if not results.bench.empty:
        lines.extend(_bench_section(results, plot_files))
        used = set(results.bench["profile"].astype(str))
        lines += ["## Profiles\n", "Settings asked of every backend and success tolerances:\n"]
        lines += table(PROFILE_COLUMNS, [p for n, p in PROFILES.items() if n in used])
    if not results.closed_loop.empty:
        lines.extend(closed_loop_section(results, plot_files))
    return "\n".join(lines)
