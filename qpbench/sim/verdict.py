"""Verdict of a closed-loop run and, beside it, whether the run kept real time.

:func:`judge` decides (called by :func:`qpbench.sim.summary.summarize`) on the scenario's
``[verdict]`` thresholds; the rules, worst first (:data:`VERDICTS`), are in
``docs/verdicts.md``. :func:`failed_run` gives ``incomplete`` to a run that produced no result.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

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
    """Thresholds of the verdict and of real time (the scenario's ``[verdict]`` table), checked
    here (``verdict.<key>``).

    ``settle_time`` [s]: start of the judged span of tracking and force errors;
    ``max_tracking_error`` [m], ``max_force_error`` [N]: largest errors after it;
    ``safety_margin`` [m]: the key-point rule's margin below ``d_safe``; real time: the p99 of
    the tick times at most ``max_p99_fraction_of_dt`` of ``dt`` and at most
    ``max_over_dt_share`` of the ticks longer than ``dt``.
    """

    settle_time: float = 2.0
    max_tracking_error: float = 1e-3
    max_force_error: float = 2.0
    safety_margin: float = DEFAULT_SAFETY_MARGIN
    max_p99_fraction_of_dt: float = 0.5
    max_over_dt_share: float = 1e-3

    def __post_init__(self):
        from ..exceptions import InputError

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
    value, t, first = (
        s["min_obstacle_distance"],
        s["min_obstacle_distance_t"],
        s["key_point_below_first_t"],
    )
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
    rule, why = key_point_rule(summary, settings.safety_margin)
    return Verdict(worst, tuple(reasons + notes), rule, why)


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


def judge_realtime(
    p99: float | None, over: int, ticks: int, dt: float, settings: VerdictSettings, what: str
) -> tuple[str, str]:
    """Whether per-tick times keep a loop of period ``dt`` [s], from their p99 [s] and the count
    ``over`` of the ``ticks`` times longer than ``dt`` (figures of :mod:`qpbench.sim.summary`):
    ``(yes|no|unknown, why)``; ``unknown`` without times. ``what`` names the times."""
    if not ticks:
        return "unknown", f"no {what} time reported"
    share = over / ticks
    limit = settings.max_p99_fraction_of_dt * dt
    frac = f"{settings.max_p99_fraction_of_dt:.0%}"
    p99_ok, share_ok = p99 <= limit, share <= settings.max_over_dt_share
    p99_text = f"p99 {what} {_us(p99)} {'<=' if p99_ok else '>'} {frac} of dt {_us(dt)}"
    share_text = (
        f"{over} of {ticks} ticks over dt ({share:.2%}; "
        f"{'<=' if share_ok else '>'} {settings.max_over_dt_share:.2%})"
    )
    # the criterion that failed first: the reason's first part says why a run is not real time
    parts = [share_text, p99_text] if p99_ok and not share_ok else [p99_text, share_text]
    return ("yes" if p99_ok and share_ok else "no"), "; ".join(parts)


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
