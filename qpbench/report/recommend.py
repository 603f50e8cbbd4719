"""Which backends to trust in the loop: *recommended* for a scenario when every run of it there
has verdict ``ok`` and was real time, overall when in every scenario; ranked by p99 call time
(the largest over its runs); every other backend listed with its reasons."""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import pandas as pd

from .markdown_table import US, md_table

#: Reasons shown per backend in the overall list; the rest are counted ("and 3 more").
MAX_REASONS = 2

#: The report's "How to read this", five lines under the recommendation.
HOW_TO_READ = (
    "A run's *verdict*, worst first: `failed` (the backend gave no usable answer), `unsafe` "
    "(the arm's body, every link a capsule, inside an obstacle; the paper's key-point rule is "
    "reported beside it), `limits` (a joint angle or speed beyond its limit), `incomplete` (the "
    "run stopped before its end: budget, crash, error), `diverged` (tracking or force error "
    "beyond its threshold), else `ok`; the reasons are in the closed-loop tables.",
    "*Real time* is judged at each scenario's control period dt from the measured call times "
    "(their p99 and the share of ticks over dt, beyond what this machine's own loop missed "
    "without a solver; the infeasible ticks by their median); the solver's own time is what a "
    "controller calling its C or C++ library would pay.",
    "A backend is recommended where every run of it was `ok` and real time, ranked by its p99 "
    "call time; the closed-loop section below gives every run's figures.",
    "The per-tick benchmark solves each QP exported from the loop with every backend and judges "
    "success against reference solutions; times are the minimum of the timed repeats.",
    "Units: times in us, distances and tracking errors in mm, forces in N; `-` is a value that "
    "does not exist (a backend that reports no time of its own, a run without a solution).",
)

#: Row statuses of a run that produced no result (as in :mod:`qpbench.harness.closed_loop`).
_NO_RESULT = ("error", "crashed", "time_limit")


@dataclass(frozen=True)
class Pick:
    """A recommended backend: its p99 call time and the solver's own p99 [s] (NaN: not reported)."""

    backend: str
    call_p99_s: float
    solver_p99_s: float


@dataclass(frozen=True)
class Scope:
    """The answer for one scenario, or for all of them: the backends ok and real time in every
    run, fastest first, and every other one -> its reasons."""

    name: str
    recommended: tuple[Pick, ...] = ()
    not_recommended: dict[str, tuple[str, ...]] = field(default_factory=dict)

    @property
    def backends(self) -> list[str]:
        return [p.backend for p in self.recommended]


@dataclass(frozen=True)
class Recommendation:
    """:func:`recommend`'s answer: overall, then per scenario in the table's order."""

    overall: Scope
    scenarios: tuple[Scope, ...]
    runs: int
    noise_floor: tuple[str, ...] = ()


def read_runs(table: pd.DataFrame) -> pd.DataFrame:
    """The closed-loop (or sweep) table with the columns the answer reads; a table written
    before verdicts and real time were judged reads as no verdict, real time ``unknown``."""
    missing = {
        "verdict": "",
        "realtime": "unknown",
        "realtime_reason": "",
        "solver_time_p99_s": math.nan,
        "verdict_reasons": "",
        "error": "",
        "simulated_s": math.nan,
    }
    return table.assign(**{c: v for c, v in missing.items() if c not in table.columns})


def noise_floor_runs(table: pd.DataFrame) -> pd.Series:
    """Which rows are the noise floor's runs (``noise_floor`` true; none in a table without the
    column): measured beside the candidates, never one of them."""
    if "noise_floor" not in table.columns:
        return pd.Series(False, index=table.index)
    return table["noise_floor"].map(lambda v: str(v).strip().lower() in ("true", "1", "1.0"))


def floor_lines(table: pd.DataFrame) -> tuple[str, ...]:
    """One line per noise floor run of ``table``: the machine's own loop, tick to tick."""
    out = []
    for row in table[noise_floor_runs(table)].to_dict("records"):
        p99 = float(pd.to_numeric(row.get("time_p99_without_infeasible_s"), errors="coerce"))
        over = pd.to_numeric(row.get("deadline_misses"), errors="coerce")
        ticks = pd.to_numeric(row.get("timed_ticks"), errors="coerce")
        if math.isnan(p99) or math.isnan(over) or math.isnan(ticks):
            out.append(f"{row['scenario']}: {_text(row.get('error')) or 'no result'}")
            continue
        out.append(
            f"{row['scenario']}: p99 tick {_us(p99)} us, {int(over)} of {int(ticks)} ticks over "
            f"dt, real time {_text(row.get('realtime'))}"
        )
    return tuple(out)


def _text(value: object) -> str:
    if value is None or (isinstance(value, float) and math.isnan(value)):
        return ""
    return str(value).strip()


def _first(reasons: object) -> str:
    """The first of ``"; "``-separated reasons (a ``"; "`` inside parentheses is part of one)."""
    text, depth = _text(reasons), 0
    for i, c in enumerate(text):
        depth += {"(": 1, ")": -1}.get(c, 0)
        if depth == 0 and text.startswith("; ", i):
            return text[:i]
    return text


def _reasons(row: dict, place: str) -> list[str]:
    """Why one run does not count for a recommendation, in a few words each (empty: it counts)."""
    out = []
    status, verdict = _text(row.get("status")), _text(row.get("verdict"))
    if status == "skipped":
        return [f"skipped in {place}: {_text(row.get('error')) or 'not run'}"]
    if verdict == "incomplete":
        simulated = float(pd.to_numeric(row["simulated_s"], errors="coerce"))
        how = [status] if status not in ("ok", "budget", "") else []
        if math.isfinite(simulated):
            how.append(f"stopped at {simulated:.3g} s")
        out.append(f"incomplete in {place}" + (f" ({', '.join(how)})" if how else ""))
    elif verdict == "failed" and status in _NO_RESULT:
        error = _text(row.get("error"))
        out.append(f"failed in {place}: run {status}" + (f" ({error})" if error else ""))
    elif verdict != "ok":
        why = _first(row.get("verdict_reasons"))
        out.append(f"{verdict or 'no verdict'} in {place}" + (f": {why}" if why else ""))
    realtime = _text(row.get("realtime"))
    if realtime == "no":
        why = _text(row.get("realtime_reason"))  # both criteria: p99 and ticks over dt
        out.append(f"not real time in {place}" + (f": {why}" if why else ""))
    elif realtime == "unknown" and _text(row.get("realtime_reason")):
        out.append(f"real time unknown in {place}: {_first(row.get('realtime_reason'))}")
    elif realtime != "yes" and verdict == "ok":
        out.append(f"real time not judged in {place}")
    return out


def _scope(name: str, runs: pd.DataFrame, place) -> Scope:
    """One scope's answer from its runs; ``place(row)`` names a run's scenario in a reason."""
    picks, rejected = [], {}
    for backend, mine in runs.groupby(runs["backend"].astype(str), sort=False):
        reasons = [r for row in mine.to_dict("records") for r in _reasons(row, place(row))]
        if reasons:
            rejected[backend] = tuple(dict.fromkeys(reasons))
            continue
        call = pd.to_numeric(mine["solve_time_p99_s"], errors="coerce").max()
        solver = pd.to_numeric(mine["solver_time_p99_s"], errors="coerce").max()
        picks.append(Pick(backend, float(call), float(solver)))
    picks.sort(key=lambda p: (math.isnan(p.call_p99_s), p.call_p99_s, p.backend))
    return Scope(name, tuple(picks), rejected)


def recommend(table: pd.DataFrame) -> Recommendation:
    """Per scenario and overall: the backends ok and real time in every run of ``table`` (one
    row per run, any number per scenario and backend), fastest first, and why not the others."""
    floor = floor_lines(table)
    runs = read_runs(table[~noise_floor_runs(table)])
    if runs.empty:
        return Recommendation(Scope("all scenarios"), (), 0, floor)
    runs["scenario"] = runs["scenario"].astype(str)
    several = runs["formulation"].nunique(dropna=True) > 1

    def place(row: dict) -> str:
        return f"{row['scenario']} ({row['formulation']})" if several else row["scenario"]

    scenarios = tuple(_scope(s, g, place) for s, g in runs.groupby("scenario", sort=False))
    every = _scope("all scenarios", runs, place)
    rejected = dict(every.not_recommended)
    for pick in every.recommended:
        missing = [s.name for s in scenarios if pick.backend not in s.backends]
        if missing:  # ok wherever it ran, but not run everywhere
            rejected[pick.backend] = (f"not run in {', '.join(missing)}",)
    picks = tuple(p for p in every.recommended if p.backend not in rejected)
    names = ", ".join(s.name for s in scenarios)
    overall = Scope(f"all scenarios ({names})", picks, rejected)
    return Recommendation(overall, scenarios, len(runs), floor)


def _why(reasons: tuple[str, ...]) -> str:
    more = len(reasons) - MAX_REASONS
    return "; ".join(reasons[:MAX_REASONS]) + (f" (and {more} more)" if more > 0 else "")


def _us(seconds: float) -> str:
    return "-" if math.isnan(seconds) else f"{seconds * US:.4g}"


def render(answer: Recommendation, markdown: bool = False) -> str:
    """The answer as text: Markdown (``report.md``) or plain (a terminal), the same lines;
    the tables are padded Markdown tables, aligned on a terminal too."""
    head = "## Recommendation\n" if markdown else "Recommendation"
    if not answer.runs:
        return f"{head}\nNo closed-loop run: nothing to recommend.\n"
    gap = "\n" if markdown else ""
    overall = answer.overall
    lines = [head]
    if overall.recommended:
        lines.append(
            f"Backends ok and real time in every run of {overall.name}, fastest first "
            f"(p99 call time, the largest over their runs; the solver's own p99 beside, "
            f"- when it reports none):{gap}"
        )
        header = ["rank", "backend", "call p99 (us)", "solver p99 (us)"]
        rows = [
            [str(i), p.backend, _us(p.call_p99_s), _us(p.solver_p99_s)]
            for i, p in enumerate(overall.recommended, 1)
        ]
        lines.append(md_table(header, rows, pad=True, left=2).rstrip("\n") + gap)
    else:
        lines.append(f"No backend was ok and real time in every run of {overall.name}.{gap}")
    if len(answer.scenarios) > 1:
        lines.append(f"Per scenario, ok and real time in every run, fastest first:{gap}")
        for scope in answer.scenarios:
            picks = ", ".join(
                f"{p.backend} {_us(p.call_p99_s)} us (solver {_us(p.solver_p99_s)})"
                for p in scope.recommended
            )
            lines.append(f"- {scope.name}: {picks or 'none'}")
        lines[-1] += gap
    if overall.not_recommended:
        lines.append(f"Not recommended:{gap}")
        rows = [[b, _why(reasons)] for b, reasons in overall.not_recommended.items()]
        lines.append(md_table(["backend", "why"], rows, pad=True, left=2).rstrip("\n") + gap)
    if answer.noise_floor:
        lines.append(
            f"This machine's noise floor (the loop with the `noop` backend, no solver, in the "
            f"same run set; real time is judged against it):{gap}"
        )
        lines.extend(f"- {line}" for line in answer.noise_floor)
        lines[-1] += gap
    return "\n".join(lines).rstrip("\n") + "\n"


def opening(
    closed_loop: pd.DataFrame, has_bench: bool = False, noise_floor: pd.DataFrame | None = None
) -> list[str]:
    """The opening of ``report.md``: the recommendation (or why there is none) with the noise
    floor's runs (``noise_floor``), How to read this."""
    out = []
    if not closed_loop.empty:
        runs = closed_loop if noise_floor is None else pd.concat([closed_loop, noise_floor])
        out.append(render(recommend(runs), markdown=True))
    elif has_bench:
        out.append(
            "## Recommendation\n\nNo closed-loop results here: a recommendation needs runs in "
            "the loop (`qpbench closed-loop` or `qpbench run`).\n"
        )
    return [*out, "## How to read this\n", "\n".join(f"- {line}" for line in HOW_TO_READ) + "\n"]


def shortfalls(runs: pd.DataFrame | None = None, failed_solves: int = 0) -> list[str]:
    """What makes a ``--strict`` run exit 1, one phrase each (empty: nothing): failed solves of
    a bench, runs whose verdict is not ``ok``, runs not real time."""
    out = []
    if failed_solves:
        out.append(f"{failed_solves} failed solves")
    if runs is not None and len(runs):
        runs = read_runs(runs[~noise_floor_runs(runs)])
        verdict = runs["verdict"].map(_text)
        bad = verdict[verdict != "ok"].replace("", "no verdict")
        if len(bad):
            counts = ", ".join(f"{v} {n}" for v, n in bad.value_counts(sort=False).items())
            out.append(f"{len(bad)} of {len(runs)} runs not ok ({counts})")
        slow = int((runs["realtime"].map(_text) == "no").sum())
        if slow:
            out.append(f"{slow} of {len(runs)} runs not real time")
    return out
