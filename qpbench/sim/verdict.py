"""Verdict of a closed-loop run and, beside it, whether the run kept real time.

:func:`judge` decides (called by :func:`qpbench.sim.summary.summarize`) on the scenario's
``[verdict]`` thresholds; the rules, worst first (:data:`VERDICTS`), are in
``docs/verdicts.md``. :func:`failed_run` gives ``incomplete`` to a run that produced no result.
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import dataclass

from ..exceptions import InputError
from ..robot.body import link_label
from . import log

#: Verdicts, from the worst: the verdict of a run is the first whose rule holds.
VERDICTS = ("failed", "unsafe", "limits", "incomplete", "diverged", "ok")
#: Every verdict but ``ok``.
BAD_VERDICTS = VERDICTS[:-1]

#: Default of ``[verdict] safety_margin`` [m] (``d_safe / 2`` when that is smaller).
DEFAULT_SAFETY_MARGIN = 5e-4


@dataclass(frozen=True)
class VerdictSettings:
    """Thresholds of the verdict and of real time (the scenario's ``[verdict]`` table, checked
    here): ``settle_time`` [s], from which ``max_tracking_error`` [m] and ``max_force_error`` [N]
    are judged; ``safety_margin`` [m] below ``d_safe``; real time: docs/verdicts.md."""

    settle_time: float = 2.0
    max_tracking_error: float = 1e-3
    max_force_error: float = 2.0
    safety_margin: float = DEFAULT_SAFETY_MARGIN
    max_p99_fraction_of_dt: float = 0.5
    max_over_dt_share: float = 1e-3

    def __post_init__(self):
        for key, holds, rule in (  # NaN fails every rule
            ("settle_time", lambda x: x >= 0, ">= 0 [s]"),
            ("max_tracking_error", lambda x: x > 0, "> 0 [m]"),
            ("max_force_error", lambda x: x > 0, "> 0 [N]"),
            ("safety_margin", lambda x: x >= 0, ">= 0 [m]"),
            ("max_p99_fraction_of_dt", lambda x: 0 < x <= 1, "> 0 and <= 1 (a fraction of dt)"),
            ("max_over_dt_share", lambda x: 0 <= x < 1, ">= 0 and < 1 (a share of the ticks)"),
        ):
            value = getattr(self, key)
            if not holds(value):
                raise InputError(f"must be {rule}, got {value!r}", key=f"verdict.{key}")


@dataclass(frozen=True)
class Verdict:
    """A verdict and why (``reasons`` empty for a clean ``ok``), and the key-point rule
    reported beside it (``held``, ``broken`` with its reason, ``-`` without obstacles)."""

    verdict: str
    reasons: tuple[str, ...] = ()
    key_point_rule: str = "-"
    key_point_rule_reason: str = ""

    @property
    def text(self) -> str:
        """The reasons as one line, ``"; "`` between them."""
        return "; ".join(self.reasons)


def _g(x: float) -> str:
    return f"{x:.3g}"


def _n(count: int, noun: str) -> str:
    return f"{count} {noun}{'s' if count > 1 else ''}"


def _failed_reasons(summary: dict) -> list[str]:
    get = summary.get
    first, t, limit = get("first_error"), get("first_error_t"), get("deadline_s")
    where = f" (first at {t:.3f} s: {first})" if first and t is not None else ""
    within = f" ({_g(limit)} s)" if limit is not None else ""
    zero = " without a command (no answer, no soft fallback: zero velocity)"
    kinds = (
        ("error_ticks", "tick", f" with an error{where}"),
        ("invalid_ticks", "non-finite answer", ""),
        ("time_limit_ticks", "answer", f" dropped past the per-tick deadline{within}"),
        ("fallback_errors", "fallback solve", " raised"),
        ("zero_velocity_ticks", "tick", zero),
    )
    return [_n(n, noun) + rest for key, noun, rest in kinds if (n := int(get(key) or 0))]


def _unsafe_reasons(s: dict) -> list[str]:
    """The body rule: a link's capsule inside an obstacle (``d_body_min < 0``) at some tick, or
    between two ticks at which it was clear of it (``body_crossings``)."""
    out = []
    if s["body_inside_ticks"]:
        where = link_label(s["min_body_distance_link"], s["joints"])
        name, kind = s["min_body_distance_obstacle"], s["min_body_distance_kind"]
        out.append(
            f"{where} {-s['min_body_distance'] * 1e3:.1f} mm inside {kind} '{name}' at "
            f"{s['min_body_distance_t']:.2f} s (the body inside an obstacle on "
            f"{_n(s['body_inside_ticks'], 'tick')} from {s['body_inside_first_t']:.3f} s)"
        )
    if s.get("body_crossings"):
        where = link_label(s["body_crossing_link"], s["joints"])
        name, kind = s["body_crossing_obstacle"], s["body_crossing_kind"]
        out.append(
            f"{where} inside {kind} '{name}' at {s['body_crossing_t']:.4f} s, between two ticks "
            f"clear of it ({_n(s['body_crossings'], 'such interval')})"
        )
    return out


def key_point_rule(s: dict, margin: float) -> tuple[str, str]:
    """The paper's guarantee, every key point kept ``d_safe - margin`` [m] from every obstacle:
    ``("held", "")``, ``("broken", reason)`` or ``("-", "")`` without obstacles."""
    ticks = s["key_point_below_ticks"]
    if not ticks:
        return ("-" if ticks is None else "held"), ""
    value, t = s["min_obstacle_distance"], s["min_obstacle_distance_t"]
    first = s["key_point_below_first_t"]
    limit = s["d_safe"] - margin
    shown = f"{value * 1e3:.1f} mm" if value is not None else "not finite"
    since = f", below from {first:.3f} s" if first != t else ""
    pair = f"{s['min_obstacle_distance_key_point']}/{s['min_obstacle_distance_obstacle']}"
    return "broken", (
        f"d_min {shown} < d_safe - {margin * 1e3:g} mm = {limit * 1e3:.1f} mm "
        f"({pair} at {t:.3f} s{since}; {ticks} ticks)"
    )


def _limit_reasons(s: dict) -> list[str]:
    out = []
    for name, sym, unit, what in (
        ("joint_limit", "theta", "rad", "angle"),
        ("joint_velocity_limit", "v", "rad/s", "speed"),
    ):
        if count := s[f"{name}_violations"]:
            i, x, limit, t = s[f"{name}_worst"]
            bound = f"{'<' if x < limit else '>'} {_g(limit)}"
            out.append(
                f"joint {what} limit broken on {_n(count, 'tick')} "
                f"(worst {sym}_{i} = {_g(x)} {unit} {bound} {unit} at {t:.3f} s)"
            )
    return out


def _diverged_reasons(s: dict, settings: VerdictSettings) -> list[str]:
    out = []
    for column, limit, unit, scale, what in (
        (log.TRACKING_ERROR, settings.max_tracking_error, "mm", 1e3, "tracking error"),
        (log.FORCE_ERROR, settings.max_force_error, "N", 1.0, "force error"),
    ):
        worst = s[f"{column}_worst"]
        if worst is None or not worst[0] > limit:
            continue
        e, t = worst
        shown = f"{e * scale:.3g} {unit}" if math.isfinite(e) else "not finite"
        out.append(
            f"{what} {shown} > {limit * scale:g} {unit} after {settings.settle_time:g} s "
            f"(at {t:.3f} s)"
        )
    return out


def judge(summary: dict, settings: VerdictSettings) -> Verdict:
    """The verdict of one simulated run on the figures of :func:`qpbench.sim.summary.summarize`
    (missing counts of failures are 0) and the scenario's thresholds."""
    found = {
        "failed": _failed_reasons(summary),
        "unsafe": _unsafe_reasons(summary),
        "limits": _limit_reasons(summary),
        "diverged": _diverged_reasons(summary, settings),
    }
    found["incomplete"], notes = _incomplete_reasons(summary, settings)
    reasons = [r for v in BAD_VERDICTS for r in found[v]]
    worst = next((v for v in BAD_VERDICTS if found[v]), "ok")
    return Verdict(worst, tuple(reasons + notes), *key_point_rule(summary, settings.safety_margin))


def _incomplete_reasons(summary: dict, settings: VerdictSettings) -> tuple[list[str], list[str]]:
    """``(reasons, notes)``: where a run stopped early stopped, and whether tracking and force
    went unjudged (part of that reason; a note for a run that reached its duration)."""
    simulated = summary["simulated_s"]
    unjudged = (
        f"tracking and force not judged (settle time {settings.settle_time:g} s not reached)"
        if simulated <= settings.settle_time
        else ""
    )
    if not summary["stopped_early"]:
        return [], [unjudged] if unjudged else []
    budget = summary["wall_budget_s"]
    why = f" (wall-time budget {_g(float(budget))} s)" if budget is not None else ""
    where = f"stopped at {simulated:.2f} s of {_g(summary['duration'])} s{why}"
    return [f"{where}: {unjudged or 'judged on what was simulated'}"], []


#: Kinds of tick the real-time figures are split by (docs/verdicts.md, "Ticks by kind").
TICK_KINDS = ("optimal", "infeasible", "fallback", "other")
#: Kinds of tick whose times the p99 and share rules judge: every tick not declared infeasible.
_JUDGED_KINDS = ("optimal", "fallback", "other")


def judge_realtime_run(f: Mapping, what: str, floor: Mapping | None = None) -> tuple[str, str]:
    """Whether a run's per-tick times keep its loop, ``(yes|no|unknown, why)``, by the three
    criteria of docs/verdicts.md, "Real time", on the figures of
    :func:`qpbench.sim.summary.tick_time_figures` (with ``dt`` [s] and the two thresholds) of one
    clock, ``what`` naming it; ``f`` may be a row read back from a table (NaN for ``None``).
    ``floor``: the noise floor's figures (:func:`floor_fields`); a criterion the floor itself
    fails (the share, or the p99 for the other two) is ``unknown`` where the run fails it too."""
    f = {k: _counted(k, v) for k, v in f.items()}
    dt, frac, share = f["dt"], f["max_p99_fraction_of_dt"], f["max_over_dt_share"]
    ticks, infeasible = f["timed_ticks"], f["ticks_infeasible"]
    if not ticks:
        return "unknown", f"no {what} time reported"
    limit, judged = frac * dt, ticks - infeasible
    machine = floor is not None and {k: _counted(k, v) for k, v in floor.items()}
    share_held = not machine or machine["over_dt_share"] <= share
    p99_held = not machine or machine["time_p99_without_infeasible_s"] <= limit
    allowance = machine["over_dt_share"] if machine and share_held else 0.0
    checks = []  # (yes|no|unknown, text)
    which = f" of the {judged} ticks not declared infeasible" if infeasible else ""
    if judged:
        p99 = f["time_p99_without_infeasible_s"]
        ok = p99 <= limit
        text = f"p99 {what}{which} {_us(p99)} {_le(ok)} {frac:.0%} of dt {_us(dt)}"
        checks.append((_held(ok, p99_held), text))
        over = sum(f[f"over_dt_{k}"] for k in _JUDGED_KINDS)
        excess = max(0, over - round(allowance * judged))
        allowed = math.ceil(share * judged - 1e-9)  # a share of 0.1 % of 885 ticks allows 1
        ok = excess <= allowed
        beyond = (
            f", {excess} beyond the {allowance:.2%} this machine's own loop missed"
            if allowance
            else ""
        )
        text = (
            f"{over} of {judged} ticks{which and ' not declared infeasible'} over dt{beyond} "
            f"({excess / judged:.2%}; {_le(ok)} {allowed} allowed: {share:.2%} rounded up)"
        )
        checks.append((_held(ok, share_held), text))
    if infeasible:
        median = f["time_median_infeasible_s"]
        ok = median <= limit
        text = f"the {infeasible} infeasible ticks: median {what} {_us(median)} {_le(ok)} "
        checks.append((_held(ok, p99_held), text + f"{frac:.0%} of dt {_us(dt)}"))
    outcomes = {o for o, _ in checks}
    verdict = "no" if "no" in outcomes else "unknown" if "unknown" in outcomes else "yes"
    texts = [t for o, t in checks if o != "yes"] + [t for o, t in checks if o == "yes"]
    if verdict == "unknown":
        rate = 1.0 / dt
        hz = f"{rate / 1e3:g} kHz" if rate >= 1e3 else f"{rate:g} Hz"
        texts.insert(
            0,
            f"this machine's own loop (no solver) missed {machine['over_dt_share']:.2%} of ticks "
            f"at {hz} (p99 tick {_us(machine['time_p99_without_infeasible_s'])}): not judged",
        )
    return verdict, "; ".join(texts + _over_dt_cause(f, what))


def _held(ok: bool, machine_held: bool) -> str:
    """A criterion's outcome: ``no`` only where the machine's own loop meets it."""
    return "yes" if ok else "no" if machine_held else "unknown"


def _le(ok: bool) -> str:
    return "<=" if ok else ">"


def _counted(key: str, value):
    """A figure of a row read back from a table: NaN as ``None``, counts as ``int``."""
    if isinstance(value, float) and math.isnan(value):
        return None
    if key == "timed_ticks" or key.startswith(("ticks_", "over_dt_")) and key != "over_dt_share":
        return int(value)
    return value


def _over_dt_cause(f: Mapping, what: str) -> list[str]:
    """The ticks over ``dt`` by kind, in words (empty without any)."""
    total = sum(f[f"over_dt_{k}"] for k in TICK_KINDS)
    if not total:
        return []
    parts = []
    if n := f["over_dt_infeasible"]:
        first, last = f.get("first_infeasible_t"), f.get("last_infeasible_t")
        span = f", {first:.3f}-{last:.3f} s" if first is not None and last is not None else ""
        text = f"{n} infeasible (of {f['ticks_infeasible']} infeasible ticks{span}"
        if f.get("certify_time_median_s") is not None:
            text += (
                f"; {_us(f['certify_time_median_s'])} median solve to certify infeasibility, "
                f"at most {_us(f['certify_time_max_s'])}"
            )
        parts.append(text + ")")
    for kind, note in (
        ("optimal", ""),
        ("fallback", ", own answer not applied: the soft fallback ran"),
        ("other", ", a non-optimal answer applied"),
    ):
        if n := f[f"over_dt_{kind}"]:
            parts.append(f"{n} {kind} (p99 {what} {_us(f[f'time_p99_{kind}_s'])}{note})")
    return [f"over dt on {total} of {f['timed_ticks']} ticks: {', '.join(parts)}"]


def floor_fields(row: Mapping) -> dict:
    """What :func:`judge_realtime_run` reads of the noise floor's run (its row or summary)."""
    return {k: row[k] for k in ("over_dt_share", "time_p99_without_infeasible_s")}


def _us(seconds: float) -> str:
    """A time [s] in the unit that reads best (µs below 1 ms)."""
    if seconds < 1e-3:
        return f"{seconds * 1e6:.3g} µs"
    return f"{seconds * 1e3:.3g} ms" if seconds < 1 else f"{seconds:.3g} s"


def failed_run(status: str, message: str) -> Verdict:
    """``incomplete``: the verdict of a run that produced no result (``status`` ``error``,
    ``crashed`` or ``time_limit``, and the harness's message)."""
    what = {
        "crashed": "run crashed",
        "time_limit": "run overran its deadline",
        "error": "run raised",
    }.get(status, f"run {status}")
    message = " ".join(str(message).split())
    return Verdict("incomplete", (f"{what}: {message}" if message else what,))
