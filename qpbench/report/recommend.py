"""Which backends to trust in the loop: a *candidate* for a scenario when every run of it there
has verdict ``ok`` and was real time, overall when in every scenario; *recommended* overall when
also, in every scenario with perturbed runs (a sweep of it), the Wilson lower bound of its share
of ``ok`` runs is at least ``min_ok_bound`` (:func:`recommend`); ranked by the p99 per-tick
time a C controller would pay (the largest over its runs) with its confidence interval,
overlapping intervals sharing a rank (:func:`ranked`); every other backend listed with its
reasons (docs/verdicts.md, "Which backends are recommended")."""

from __future__ import annotations

import json
import math
from dataclasses import dataclass, field, replace
from pathlib import Path

import pandas as pd

from .inputs import noise_floor_runs
from .markdown_table import MM, US, fmt, md_table
from .tables import wilson, worst_first

#: Least Wilson lower bound (95 % interval) of a backend's share of ``ok`` perturbed runs in
#: every swept scenario (``--min-ok-bound``).
MIN_OK_BOUND = 0.95
#: Perturbed runs a scenario a backend is given: the least number whose bound reaches the
#: threshold with this many of them not ``ok`` (:func:`least_runs`; the controller itself fails a
#: few perturbed instances whatever the solver).
TOLERATED_NOT_OK = 2

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
    "A backend is recommended where every run of it was `ok` and real time and, in every "
    "scenario with perturbed instances, the lower bound of its share of `ok` perturbed runs "
    "reaches the threshold; ranked by the p99 per-tick time a C controller would pay (the solve "
    "timed in compiled code, else the solver's own) with a 95 % interval, backends whose "
    "intervals overlap sharing a rank (`2=`); the closed-loop section below gives every run's "
    "figures.",
    "The per-tick benchmark solves each QP exported from the loop with every backend and judges "
    "success against reference solutions; times are the minimum of the timed repeats.",
    "Units: times in us, distances and tracking errors in mm, forces in N; `-` is a value that "
    "does not exist (a backend that reports no time of its own, a run without a solution).",
)

#: Columns of a run's p99 ranking-time interval [s] (:func:`qpbench.sim.summary.block_bootstrap_quantile`).
INTERVAL = ("rank_time_p99_lo_s", "rank_time_p99_hi_s")

#: Row statuses of a run that produced no result (as in :mod:`qpbench.harness.closed_loop`).
_NO_RESULT = ("error", "crashed", "time_limit")


@dataclass(frozen=True)
class Evidence:
    """A backend's perturbed runs of one scenario: ``runs`` of valid instances, ``ok`` of them
    with verdict ``ok``, ``bound`` the Wilson lower bound of the share (NaN without runs), and
    its worst run (a row of the sweep table with ``folder``; ``None`` without runs)."""

    scenario: str
    runs: int
    ok: int
    bound: float
    worst: dict | None = None


@dataclass(frozen=True)
class Pick:
    """A backend that passed every run: its p99 ranking time
    (:func:`qpbench.sim.summary.rank_times`), that p99's interval [s] (NaN: none) and the
    solver's own p99 [s] (NaN: not reported); ``rank`` (1 = fastest; backends whose
    intervals overlap share one, ``tied``); ``evidence``: per swept scenario."""

    backend: str
    call_p99_s: float
    solver_p99_s: float
    call_p99_lo_s: float = math.nan
    call_p99_hi_s: float = math.nan
    rank: int = 0
    tied: bool = False
    evidence: tuple[Evidence, ...] = ()

    @property
    def rank_text(self) -> str:
        return f"{self.rank}=" if self.tied else str(self.rank)

    @property
    def weakest(self) -> Evidence | None:
        """The swept scenario with the lowest bound (no runs first)."""
        key = lambda e: -1.0 if math.isnan(e.bound) else e.bound  # noqa: E731
        return min(self.evidence, key=key, default=None)


@dataclass(frozen=True)
class Scope:
    """The answer for one scenario, or for all of them: the backends recommended, fastest first;
    those ok and real time in every run whose perturbed runs are too few (``short``); every other
    one -> its reasons; ``passed``: the backends ok and real time in every run, before the
    perturbed runs were looked at."""

    name: str
    recommended: tuple[Pick, ...] = ()
    not_recommended: dict[str, tuple[str, ...]] = field(default_factory=dict)
    short: tuple[Pick, ...] = ()
    passed: tuple[str, ...] = ()

    @property
    def backends(self) -> list[str]:
        return [p.backend for p in self.recommended]


@dataclass(frozen=True)
class Recommendation:
    """:func:`recommend`'s answer: overall, then per scenario in the table's order; the perturbed
    runs' threshold and whether there were any (``swept``: the scenarios with a sweep); with
    more than one arm family, each family's own answer (``families``)."""

    overall: Scope
    scenarios: tuple[Scope, ...]
    runs: int
    min_ok_bound: float = MIN_OK_BOUND
    swept: tuple[str, ...] = ()
    noise_floor: tuple[str, ...] = ()
    families: tuple[Scope, ...] = ()


def read_runs(table: pd.DataFrame) -> pd.DataFrame:
    """The closed-loop (or sweep) table with the columns the answer reads; a table written
    before verdicts and real time were judged reads as no verdict, real time ``unknown``."""
    text = ("verdict", "realtime_reason", "rank_time_source", "verdict_reasons", "error")
    numbers = ("solver_time_p99_s", "rank_time_p99_s", *INTERVAL, "simulated_s")
    missing = dict.fromkeys(text, "") | dict.fromkeys(numbers, math.nan) | {"realtime": "unknown"}
    return table.assign(**{c: v for c, v in missing.items() if c not in table.columns})


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
    missing = value is None or (isinstance(value, float) and math.isnan(value))
    return "" if missing else str(value).strip()


def _first(reasons: object) -> str:
    """The first of ``"; "``-separated reasons (a ``"; "`` inside parentheses is part of one)."""
    text, depth = _text(reasons), 0
    for i, c in enumerate(text):
        depth += {"(": 1, ")": -1}.get(c, 0)
        if depth == 0 and text.startswith("; ", i):
            return text[:i]
    return text


def _numbers(runs: pd.DataFrame, column: str) -> pd.Series:
    return pd.to_numeric(runs[column], errors="coerce")


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
    """One scope's answer from its runs; ``place(row)`` names a run's scenario in a reason. A
    backend's p99 is the largest of its runs', its interval ``[largest low, largest high]``: the
    largest of several values each in its own interval lies in that one."""
    picks, rejected = [], {}
    for backend, mine in runs.groupby(runs["backend"].astype(str), sort=False):
        reasons = [r for row in mine.to_dict("records") for r in _reasons(row, place(row))]
        if reasons:
            rejected[backend] = tuple(dict.fromkeys(reasons))
            continue
        call, solver = (_numbers(mine, c).max() for c in ("rank_time_p99_s", "solver_time_p99_s"))
        lo, hi = (_numbers(mine, c).max(skipna=False) for c in INTERVAL)
        picks.append(Pick(backend, float(call), float(solver), float(lo), float(hi)))
    return Scope(name, ranked(picks), rejected, passed=tuple(p.backend for p in picks))


def ranked(picks: list[Pick]) -> tuple[Pick, ...]:
    """``picks`` fastest first (p99 ranking time, then name), each with its rank: backends whose
    intervals overlap, directly or through others, share the rank of the first of them (``2=``);
    a pick without an interval has its p99 as one. The groups are runs of neighbours in this
    order (an interval holds its p99, so a group's intervals cover the p99s between them)."""
    order = sorted(picks, key=lambda p: (math.isnan(p.call_p99_s), p.call_p99_s, p.backend))

    def span(p: Pick) -> tuple[float, float]:
        lo, hi = p.call_p99_lo_s, p.call_p99_hi_s
        return (lo, hi) if math.isfinite(lo) and math.isfinite(hi) else (p.call_p99_s,) * 2

    groups: list[list[Pick]] = []
    for p in order:
        lo, hi = span(p)
        # joins the group before when it overlaps it (the group's intervals chain together);
        # a later pick may join both: merge them
        touching = [g for g in groups if any(lo <= span(q)[1] and span(q)[0] <= hi for q in g)]
        for g in touching[1:]:
            touching[0].extend(g)
            groups.remove(g)
        if touching:
            touching[0].append(p)
        else:
            groups.append([p])
    out, rank = [], 1
    for g in groups:
        g.sort(key=order.index)
        out += [replace(p, rank=rank, tied=len(g) > 1) for p in g]
        rank += len(g)
    return tuple(out)


def check_bound(value, key: str = "--min-ok-bound") -> float:
    """``value`` as a least share bound if a number in (0, 1), else a :class:`ParamError` naming
    ``key``."""
    from ..exceptions import ParamError

    try:
        bound = float(value)
    except (TypeError, ValueError):
        bound = math.nan
    if isinstance(value, bool) or not 0.0 < bound < 1.0:
        raise ParamError(f"must be a number between 0 and 1 (exclusive), got {value!r}", key=key)
    return bound


def least_runs(bound: float, not_ok: int = 0, level: float = 0.95) -> int:
    """The least number of runs whose share of ``ok`` has a Wilson lower bound (``level``
    interval) of at least ``bound`` when ``not_ok`` of them are not ``ok`` (73 at 0.95 with none,
    142 with two)."""
    bound = check_bound(bound)
    lo, hi = not_ok + 1, not_ok + 2
    while wilson(hi - not_ok, hi, level)[0] < bound:  # the bound grows with the runs
        lo, hi = hi, 2 * hi
    while lo < hi:
        mid = (lo + hi) // 2
        lo, hi = (lo, mid) if wilson(mid - not_ok, mid, level)[0] >= bound else (mid + 1, hi)
    return lo


def read_sweeps(paths: list, relative_to: Path | None = None) -> pd.DataFrame:
    """Sweep tables (``sweep.csv``) as one frame, the last row of each (instance, backend) of
    each, with ``folder`` (the table's folder, relative to ``relative_to`` when inside it) and
    ``seed`` (the sweep's, from its ``sweep.json``; NaN without one). ``attrs["swept"]``: the
    base scenarios of the tables, those without a row too (a sweep no backend could afford)."""
    frames, bases = [], []
    for path in map(Path, paths):
        df = pd.read_csv(path).drop_duplicates(["instance", "backend"], keep="last")
        folder = path.parent
        if relative_to is not None and folder.resolve().is_relative_to(Path(relative_to).resolve()):
            folder = folder.resolve().relative_to(Path(relative_to).resolve())
        try:
            manifest = json.loads((path.parent / "sweep.json").read_text())
        except (OSError, ValueError):
            manifest = {}
        bases += [str(manifest["base"])] if "base" in manifest else []
        bases += [str(b) for b in df["base_scenario"].dropna().unique()]
        frames.append(df.assign(folder=str(folder), seed=manifest.get("seed", math.nan)))
    out = pd.concat(frames, ignore_index=True) if frames else pd.DataFrame()
    out.attrs["swept"] = list(dict.fromkeys(bases))
    return out


def _evidence(sweeps: pd.DataFrame, backend: str, scenarios: list[str]):
    """Per swept scenario, ``backend``'s perturbed runs (:class:`Evidence`)."""
    out = []
    for s in scenarios:
        if sweeps.empty:
            out.append(Evidence(s, 0, 0, math.nan))
            continue
        mine = sweeps[(sweeps["base_scenario"] == s) & (sweeps["backend"] == backend)]
        valid = worst_first(mine.assign(verdict=mine["verdict"].fillna("").astype(str)))
        n, k = len(valid), int((valid["verdict"] == "ok").sum())
        out.append(Evidence(s, n, k, wilson(k, n)[0], valid.iloc[0].to_dict() if n else None))
    return tuple(out)


def _judge_evidence(overall: Scope, sweeps, scenarios: list[str], bound: float) -> Scope:
    """``overall`` with its picks judged on their perturbed runs in ``scenarios``: recommended
    when every bound reaches ``bound``; too few runs (``short``) when below it with fewer runs
    than :func:`least_runs` gives for :data:`TOLERATED_NOT_OK`; else not recommended."""
    target = least_runs(bound, TOLERATED_NOT_OK)
    keep, short, rejected = [], [], dict(overall.not_recommended)
    for pick in overall.recommended:
        pick = replace(pick, evidence=_evidence(sweeps, pick.backend, scenarios))
        below = [e for e in pick.evidence if not e.bound >= bound]
        if not below:
            keep.append(pick)
        elif all(e.runs >= target for e in below):
            rejected[pick.backend] = tuple(
                f"perturbed {e.scenario}: {e.ok} of {e.runs} ok, bound {e.bound:.3f} < {bound:g}"
                for e in below
            )
        else:
            short.append(pick)
    return replace(overall, recommended=ranked(keep), not_recommended=rejected, short=tuple(short))


def recommend(
    table: pd.DataFrame, sweeps: pd.DataFrame | None = None, min_ok_bound: float = MIN_OK_BOUND
) -> Recommendation:
    """Per scenario and overall: the backends ok and real time in every run of ``table`` (one
    row per run, any number per scenario and backend), fastest first, and why not the others;
    overall, with ``sweeps`` (:func:`read_sweeps`), a backend is recommended only when in every
    scenario of ``table`` with perturbed runs (a sweep whose base is that scenario) the Wilson
    lower bound of its share of ``ok`` runs is at least ``min_ok_bound``. With runs of more than
    one arm family (column ``family``: planar, spatial), each family is also answered alone, the
    same way on its own scenarios (``families``); overall is then what both recommend."""
    floor = floor_lines(table)
    runs = read_runs(table[~noise_floor_runs(table)])
    if runs.empty:
        return Recommendation(Scope("all scenarios"), (), 0, min_ok_bound, noise_floor=floor)
    runs["scenario"] = runs["scenario"].astype(str)
    several = runs["formulation"].nunique(dropna=True) > 1

    def place(row: dict) -> str:
        return f"{row['scenario']} ({row['formulation']})" if several else row["scenario"]

    scenarios = tuple(_scope(s, g, place) for s, g in runs.groupby("scenario", sort=False))
    bases = set()
    if sweeps is not None:
        bases = set(
            sweeps.attrs.get("swept") or sweeps.get("base_scenario", pd.Series()).astype(str)
        )
    swept = tuple(s.name for s in scenarios if s.name in bases)
    judge = (sweeps, swept, min_ok_bound, place)
    overall = _across("all scenarios", runs, scenarios, *judge)
    families = tuple(
        _across(name, runs[runs["scenario"].isin(names)], scenarios, *judge)
        for name, names in _families(runs).items()
    )
    return Recommendation(overall, scenarios, len(runs), min_ok_bound, swept, floor, families)


def _families(runs: pd.DataFrame) -> dict[str, list[str]]:
    """The scenarios of each arm family of ``runs``, named with the arm's joints (``planar (n =
    4)``); none from runs of one family, or a table without the column ``family``."""
    if "family" not in runs.columns:
        return {}
    out: dict[str, list[str]] = {}
    groups = runs.dropna(subset=["family"]).groupby(["family", "joints"], sort=False)
    for (family, joints), g in groups:
        out.setdefault(f"{family} (n = {int(joints)})", []).extend(g["scenario"].unique())
    return out if len(out) > 1 else {}


def _across(name, runs, scopes, sweeps, swept, bound, place) -> Scope:
    """The answer over the scenarios of ``runs`` (their ``scopes`` among ``scopes``): ok and real
    time in every run and run in every one of them, then judged on the perturbed runs of those
    of them in ``swept``."""
    mine = list(dict.fromkeys(runs["scenario"]))
    every = _scope(name, runs, place)
    rejected = dict(every.not_recommended)
    for pick in every.recommended:
        missing = [s.name for s in scopes if s.name in mine and pick.backend not in s.backends]
        if missing:  # ok wherever it ran, but not run everywhere
            rejected[pick.backend] = (f"not run in {', '.join(missing)}",)
    picks = tuple(p for p in every.recommended if p.backend not in rejected)
    passed = tuple(p.backend for p in picks)
    overall = Scope(f"{name} ({', '.join(mine)})", picks, rejected, passed=passed)
    judged = [s for s in swept if s in mine]
    return _judge_evidence(overall, sweeps, judged, bound) if judged else overall


def _why(reasons: tuple[str, ...]) -> str:
    more = len(reasons) - MAX_REASONS
    return "; ".join(reasons[:MAX_REASONS]) + (f" (and {more} more)" if more > 0 else "")


def _us(seconds: float) -> str:
    """[s] as [us]: four significant digits, whole microseconds from 10 ms on."""
    us = seconds * US
    return "-" if math.isnan(seconds) else f"{us:.4g}" if us < 1e4 else f"{us:.0f}"


def _interval(p: Pick) -> str:
    lo, hi = p.call_p99_lo_s, p.call_p99_hi_s
    return "-" if math.isnan(lo) or math.isnan(hi) else f"{_us(lo)}-{_us(hi)}"


def _rate(p: Pick) -> list[str]:
    """The perturbed-run cells of a pick: ok of runs over every swept scenario, and the lowest
    bound with its scenario."""
    if not p.evidence:
        return ["-", "-"]
    ok, runs = sum(e.ok for e in p.evidence), sum(e.runs for e in p.evidence)
    e = p.weakest
    bound = "-" if math.isnan(e.bound) else f"{e.bound:.3f}"
    return [f"{ok}/{runs}", f"{bound} ({e.scenario})"]


#: Columns of the worst perturbed runs' table (the recommendation's and a sweep's).
WORST_HEADER = ["backend", "instance", "verdict", "d_min mm", "why", "re-run"]


def rerun_command(run: dict, backend: str) -> str:
    """The command that runs one perturbed instance (a sweep row with ``folder``) alone, as code."""
    path = Path(str(run["folder"])) / str(run["instance_file"])
    return f"`qpbench simulate --scenario {path} --backend {backend}`"


def _worst_rows(picks: list[Pick]) -> list[list]:
    """Per pick, its worst perturbed run: scenario, instance (sample and sweep seed), verdict,
    the closest key point to an obstacle [mm], why, the command that re-runs it."""
    rows = []
    for p in picks:
        runs = [e.worst | {"scenario": e.scenario} for e in p.evidence if e.worst is not None]
        if not runs:
            continue
        w = worst_first(pd.DataFrame(runs)).iloc[0].to_dict()
        seed = "" if pd.isna(w.get("seed")) else f"seed {int(w['seed'])}, "
        where = f"{w['scenario']} {w['instance']} ({seed}sample {int(w['sample'])})"
        d_min = fmt(float(pd.to_numeric(w["min_obstacle_distance"], errors="coerce")) * MM)
        why = _first(w.get("verdict_reasons")) or _text(w.get("error")) or "-"
        verdict = _text(w["verdict"]) or "-"
        rows.append([p.backend, where, verdict, d_min, why, rerun_command(w, p.backend)])
    return rows


def _table(lines: list[str], header: list[str], rows: list[list], gap: str, left=2) -> None:
    lines.append(md_table(header, rows, pad=True, left=left).rstrip("\n") + gap)


def no_answer(answer: Recommendation) -> str:
    """One sentence: why nothing is recommended (empty when something is)."""
    overall, bound = answer.overall, answer.min_ok_bound
    if overall.recommended:
        return ""
    if overall.short:
        p = overall.short[0]
        e = p.weakest
        names = ", ".join(q.backend for q in overall.short)
        return (
            f"No recommendation: {names} passed every run of {overall.name} but had too few "
            f"perturbed runs for a bound of {bound:g} ({p.backend} in {e.scenario}: {e.ok} of "
            f"{e.runs} ok, bound {0.0 if math.isnan(e.bound) else e.bound:.3f}; at least "
            f"{least_runs(bound)} all ok are needed): a larger --sweep-budget gives more."
        )
    rejected = overall.not_recommended
    late = [b for b, why in rejected.items() if all(r.startswith("not real time") for r in why)]
    if late:
        return (
            f"No recommendation from this machine: {', '.join(late)} had verdict ok in every run "
            f"of {overall.name} but missed real time ({late[0]} "
            f"{rejected[late[0]][0].removeprefix('not real time ')}); "
            "short runs on a busy machine are judged on its load as much as on the solver: "
            "run again on an idle machine, or with longer runs."
        )
    if overall.passed:
        return (
            f"No backend held a bound of {bound:g} on its share of ok perturbed runs in every "
            f"swept scenario of {overall.name}."
        )
    return f"No backend was ok and real time in every run of {overall.name}."


def _family_rows(families: tuple[Scope, ...]) -> list[list[str]]:
    """One row per backend recommended or short of evidence in some family, in the order of the
    first family's ranking: per family its rank and p99, ``too few perturbed runs``, or the
    first reason it is not recommended there."""
    cells: dict[str, list[str]] = {}
    for k, f in enumerate(families):
        shown = [(p, p.rank_text) for p in f.recommended]
        for p, what in shown + [(p, "too few perturbed runs") for p in f.short]:
            cells.setdefault(p.backend, ["-"] * len(families))[k] = f"{what}: {_us(p.call_p99_s)}"
    for b, row in cells.items():
        for k, f in enumerate(families):
            if b in f.not_recommended:
                row[k] = _first(f.not_recommended[b][0])
    return [[b, *row] for b, row in cells.items()]


def _ranked_lines(answer: Recommendation, lines: list[str], gap: str) -> None:
    """The recommended backends' table (or why there are none) and the short of evidence."""
    overall, bound = answer.overall, answer.min_ok_bound
    swept = ", ".join(answer.swept)
    if overall.recommended:
        lines.append(
            f"Backends ok and real time in every run of {overall.name}"
            + (
                f" and whose share of ok perturbed runs has a lower bound of at least {bound:g} "
                f"in every swept scenario ({swept})"
                if swept
                else " (no perturbed runs: on the nominal runs alone)"
            )
            + ", fastest first by what a C or C++ controller would pay per tick (p99 over the "
            "ticks, the largest over their runs, with its 95 % interval): the solve timed in "
            "compiled code where the backend runs on the compiled engine, else the solver's own "
            "time; overlapping intervals share a rank, `2=`; the solver's own p99 beside, - when "
            f"it reports none; perturbed runs: ok of all, the lowest bound):{gap}"
        )
        header = ["rank", "backend", "controller p99 (us)", "95 % interval (us)", "solver p99 (us)"]
        header += ["perturbed ok", "ok bound"]
        rows = [
            [p.rank_text, p.backend, _us(p.call_p99_s), _interval(p), _us(p.solver_p99_s)]
            + _rate(p)
            for p in overall.recommended
        ]
        _table(lines, header, rows, gap)
    else:
        lines.append(no_answer(answer) + gap)
    if overall.short:
        lines.append(
            f"Not enough evidence (ok and real time in every run, too few perturbed runs for a "
            f"bound of {bound:g}; never recommended):{gap}"
        )
        header = ["backend", "controller p99 (us)", "95 % interval (us)", "perturbed ok"]
        header.append("ok bound")
        rows = [[p.backend, _us(p.call_p99_s), _interval(p), *_rate(p)] for p in overall.short]
        _table(lines, header, rows, gap, left=1)


def _scenario_lines(answer: Recommendation, lines: list[str], gap: str) -> None:
    """Each scenario's own answer, the backends not recommended and why, the noise floor."""
    overall = answer.overall
    if len(answer.scenarios) > 1:
        lines.append(f"Per scenario, ok and real time in every run, fastest first:{gap}")
        for scope in answer.scenarios:
            picks = ", ".join(
                f"{p.backend} {_us(p.call_p99_s)} us"
                + (f" [{_interval(p)}]" if _interval(p) != "-" else "")
                + f" (solver {_us(p.solver_p99_s)})"
                for p in scope.recommended
            )
            lines.append(f"- {scope.name}: {picks or 'none'}")
        lines[-1] += gap
    if overall.not_recommended:
        lines.append(f"Not recommended:{gap}")
        rows = [[b, _why(reasons)] for b, reasons in overall.not_recommended.items()]
        _table(lines, ["backend", "why"], rows, gap)
    if answer.noise_floor:
        lines.append(
            f"This machine's noise floor (the loop with the `noop` backend, no solver, in the "
            f"same run set; real time is judged against it):{gap}"
        )
        lines.extend(f"- {line}" for line in answer.noise_floor)
        lines[-1] += gap


def render(answer: Recommendation, markdown: bool = False) -> str:
    """The answer as text: Markdown (``report.md``) or plain (a terminal), the same lines;
    the tables are padded Markdown tables, aligned on a terminal too."""
    head = "## Recommendation\n" if markdown else "Recommendation"
    if not answer.runs:
        return f"{head}\nNo closed-loop run: nothing to recommend.\n"
    gap = "\n" if markdown else ""
    lines = [head]
    _ranked_lines(answer, lines, gap)
    worst = _worst_rows([*answer.overall.recommended, *answer.overall.short])
    if worst:
        where = " (paths from this report's folder)" if markdown else ""
        lines.append(f"Worst perturbed run of each{where}:{gap}")
        _table(lines, WORST_HEADER, worst, gap, left=(0, 1, 2, 4, 5))
    if answer.families:
        lines.append(
            "Per arm family, each answered alone on its own scenarios and their perturbed runs "
            "as above, on its nominal runs alone where none of its scenarios is swept (the rank, "
            "the controller p99 in us; a backend recommended in every family is recommended "
            f"above, ranked on its slowest family):{gap}"
        )
        # a family's scope "planar (n = 4) (free, wall)" titles its column "planar (n = 4)"
        header = ["backend", *(f.name.rsplit(" (", 1)[0] for f in answer.families)]
        _table(lines, header, _family_rows(answer.families), gap, left=len(header))
    _scenario_lines(answer, lines, gap)
    return "\n".join(lines).rstrip("\n") + "\n"


def opening(
    closed_loop: pd.DataFrame,
    has_bench: bool = False,
    sweeps: pd.DataFrame | None = None,
    min_ok_bound: float = MIN_OK_BOUND,
    noise_floor: pd.DataFrame | None = None,
) -> list[str]:
    """The opening of ``report.md``: the recommendation (or why there is none; ``sweeps`` and
    ``min_ok_bound`` as :func:`recommend` takes them) with the noise floor's runs
    (``noise_floor``), How to read this."""
    out = []
    if not closed_loop.empty:
        runs = closed_loop if noise_floor is None else pd.concat([closed_loop, noise_floor])
        out.append(render(recommend(runs, sweeps, min_ok_bound), markdown=True))
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
