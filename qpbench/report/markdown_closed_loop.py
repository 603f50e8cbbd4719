"""The closed-loop section of ``report.md``: the runs that failed their verdict, then per
scenario each backend's figures (:data:`CLOSED_LOOP_TABLE`) and the scenario's figures."""

from __future__ import annotations

import math

import pandas as pd

from ..sim.verdict import BAD_VERDICTS
from .inputs import Results
from .markdown_table import MM, US, Column, fmt, md_table, slug, table

#: Marks a verdict judged on thresholds set on the command line (footnote :data:`FOOTNOTE`).
OVERRIDDEN = "\u2020"
FOOTNOTE = (
    f"{OVERRIDDEN} judged on `[verdict]` thresholds set on the command line, not the scenario "
    "file's (the row's `verdict_overrides` says which).\n"
)


def _overridden(row) -> bool:
    """The row's verdict was judged on thresholds set over the scenario file's."""
    value = row["verdict_overrides"]
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
        "the verdict: `yes` when the p99 of the per-tick times is at most the scenario's "
        "`max_p99_fraction_of_dt` of dt and at most `max_over_dt_share` of the ticks took "
        "longer than dt; judged on the measured call times (what a Python controller sees) "
        "and on the solver's own reported times (what a C or C++ controller calling the "
        "solver sees; `unknown` when the backend reports none).\n",
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
        out += table(
            (Column("backend", "backend", text=True), *CLOSED_LOOP_TABLE), g.to_dict("records")
        )
        errors = g[~g["status"].isin(("ok", "budget"))].to_dict("records")
        out += [f"- {r['backend']}: {fmt(r['error'])}\n" for r in errors]
        for kind, alt in (
            ("", "closed loop"),
            ("v_", "joint velocities"),
            ("d_", "key-point distances"),
        ):
            key = f"closed_loop_{kind}{slug(scenario)}_{slug(formulation)}"
            if key in plot_files:
                out.append(f"![{alt}, {scenario}]({plot_files[key]})\n")
        out.extend(_snapshot_row(scenario, formulation, plot_files))
    return out


def _snapshot_row(scenario: str, formulation: str, plot_files: dict[str, str]) -> list[str]:
    """The arm's snapshots of a scenario side by side (:mod:`qpbench.report.plots`), when drawn."""
    from .plots import ROLES

    keys = {role: f"snapshot_{role}_{slug(scenario)}_{slug(formulation)}" for role in ROLES}
    shown = [role for role, key in keys.items() if key in plot_files]
    if not shown:
        return []
    return [
        f"The arm, {scenario}:\n",
        md_table(
            [ROLES[r] for r in shown],
            [[f"![{ROLES[r]}, {scenario}]({plot_files[keys[r]]})" for r in shown]],
        ),
    ]
