"""Verdict of a closed-loop run and, beside it, whether the run kept real time.

:func:`judge` decides (called by :func:`qpbench.sim.summary.summarize`) on the scenario's
``[verdict]`` thresholds; the rules, worst first (:data:`VERDICTS`), are in
``docs/verdicts.md``. :func:`failed_run` gives ``incomplete`` to a run that produced no result.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import TYPE_CHECKING

import numpy as np

from ..robot.body import link_label
from . import log

if TYPE_CHECKING:
    import pandas as pd

    from ..control.terms import EscapeVelocityLimits

#: Verdicts, from the worst: the verdict of a run is the first whose rule holds.
VERDICTS = ("failed", "unsafe", "limits", "incomplete", "diverged", "ok")
#: Every verdict but ``ok``.
BAD_VERDICTS = VERDICTS[:-1]

#: Tolerance of the joint-angle [rad] and joint-velocity [rad/s] limit checks.
VIOLATION_TOL = 1e-6

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

        def bad(key, rule, unit=""):  # NaN fails every rule below
            value = getattr(self, key)
            raise InputError(f"must be {rule}{unit}, got {value!r}", key=f"verdict.{key}")

        if not self.settle_time >= 0:
            bad("settle_time", ">= 0", " [s]")
        for key, unit in (("max_tracking_error", " [m]"), ("max_force_error", " [N]")):
            if not getattr(self, key) > 0:
                bad(key, "> 0", unit)
        if not self.safety_margin >= 0:
            bad("safety_margin", ">= 0", " [m]")
        if not 0 < self.max_p99_fraction_of_dt <= 1:
            bad("max_p99_fraction_of_dt", "> 0 and <= 1 (a fraction of dt)")
        if not 0 <= self.max_over_dt_share < 1:
            bad("max_over_dt_share", ">= 0 and < 1 (a share of the ticks)")


@dataclass(frozen=True)
class Verdict:
    """A verdict and why (``reasons`` empty for a clean ``ok``), and the key-point rule
    reported beside it (``held``, ``broken`` with its reason, ``-`` without obstacles)."""

    verdict: str
    reasons: tuple[str, ...] = ()
    key_point_rule: str = "-"
    key_point_rule_reason: str = ""

    @property
    def ok(self) -> bool:
        return self.verdict == "ok"

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


def _unsafe_reasons(frame, n: int, obstacle_kinds: dict[str, str] | None) -> list[str]:
    """The body rule: a link's capsule inside an obstacle (``d_body_min < 0``) at some tick."""
    d = frame[log.D_BODY_MIN].to_numpy(dtype=float)
    inside = d < 0.0
    if not inside.any():
        return []
    t = frame[log.T].to_numpy(dtype=float)
    k = int(np.argmin(np.where(inside, d, np.inf)))
    link = int(frame[log.D_BODY_LINK].iloc[k])
    name = str(frame[log.D_BODY_OBSTACLE].iloc[k])
    kind = (obstacle_kinds or {}).get(name, "obstacle")
    rows = np.flatnonzero(inside)
    return [
        f"{link_label(link, n)} {-d[k] * 1e3:.1f} mm inside {kind} '{name}' at {t[k]:.2f} s "
        f"(the body inside an obstacle on {_n(rows.size, 'tick')} from {t[rows[0]]:.3f} s)"
    ]


def key_point_rule(
    frame, d_safe: float, margin: float, columns: list[tuple[str, str]]
) -> tuple[str, str]:
    """The paper's guarantee, every key point kept ``d_safe - margin`` [m] from every obstacle:
    ``("held", "")``, ``("broken", reason)`` or ``("-", "")`` without obstacles."""
    if not columns:
        return "-", ""
    if not len(frame):
        return "held", ""
    D = frame[[log.distance_column(a, o) for a, o in columns]].to_numpy(dtype=float)
    t = frame[log.T].to_numpy(dtype=float)
    limit = d_safe - margin
    below = ~(D >= limit)  # a NaN distance counts as below
    if not below.any():
        return "held", ""
    rows = np.flatnonzero(below.any(axis=1))
    filled = np.where(np.isnan(D), -np.inf, D)
    k, c = divmod(int(np.argmin(filled)), D.shape[1])
    a, o = columns[c]
    value = D[k, c]
    shown = f"{value * 1e3:.1f} mm" if math.isfinite(value) else "not finite"
    first = f", below from {t[rows[0]]:.3f} s" if rows[0] != k else ""
    return "broken", (
        f"d_min {shown} < d_safe - {margin * 1e3:g} mm = {limit * 1e3:.1f} mm "
        f"({a}/{o} at {t[k]:.3f} s{first}; {rows.size} ticks)"
    )


def _limit_reasons(frame, limits, n: int) -> list[str]:
    if not len(frame):
        return []
    t = frame[log.T].to_numpy(dtype=float)
    out = []
    for sym, columns, lo, hi, unit, what in (
        ("theta", log.theta_columns(n), limits.theta_min, limits.theta_max, "rad", "angle"),
        ("v", log.velocity_columns(n), limits.v_min, limits.v_max, "rad/s", "speed"),
    ):
        X = frame[columns].to_numpy(dtype=float)
        excess = np.maximum(lo - X, X - hi)  # > 0 beyond a limit
        excess = np.where(np.isnan(X), np.inf, excess)
        bad = (excess > VIOLATION_TOL).any(axis=1)
        if not bad.any():
            continue
        k, i = divmod(int(np.argmax(excess)), n)
        x = X[k, i]
        bound = f"< {_g(lo[i])}" if x < lo[i] else f"> {_g(hi[i])}"
        out.append(
            f"joint {what} limit broken on {_n(int(bad.sum()), 'tick')} "
            f"(worst {sym}_{i} = {_g(x)} {unit} {bound} {unit} at {t[k]:.3f} s)"
        )
    return out


def _diverged_reasons(frame, settings: VerdictSettings) -> list[str]:
    t = frame[log.T].to_numpy(dtype=float)
    after = t >= settings.settle_time - 1e-12
    if not after.any():
        return []
    out = []
    for column, limit, unit, scale, what in (
        (log.TRACKING_ERROR, settings.max_tracking_error, "mm", 1e3, "tracking error"),
        (log.FORCE_ERROR, settings.max_force_error, "N", 1.0, "force error"),
    ):
        e = np.abs(frame[column].to_numpy(dtype=float)[after])
        e = np.where(np.isnan(e), np.inf, e)
        if not (e > limit).any():
            continue
        k = int(np.argmax(e))
        shown = f"{e[k] * scale:.3g} {unit}" if math.isfinite(e[k]) else "not finite"
        out.append(
            f"{what} {shown} > {limit * scale:g} {unit} after {settings.settle_time:g} s "
            f"(at {t[after][k]:.3f} s)"
        )
    return out


def judge(
    frame: pd.DataFrame,
    settings: VerdictSettings,
    *,
    d_safe: float,
    limits: EscapeVelocityLimits,
    obstacle_columns: list[tuple[str, str]],
    summary: dict,
    obstacle_kinds: dict[str, str] | None = None,
) -> Verdict:
    """The verdict of one simulated run: ``frame`` the tick log, ``d_safe`` [m], ``limits`` the
    joint limits [rad, rad/s], ``obstacle_columns`` the ``(key point, obstacle)`` of each
    distance column, ``summary`` the run's figures (:mod:`qpbench.sim.summary`; missing counts
    are 0), ``obstacle_kinds`` each obstacle's kind by name."""
    n = len(limits.theta_min)
    found = {
        "failed": _failed_reasons(summary),
        "unsafe": _unsafe_reasons(frame, n, obstacle_kinds),
        "limits": _limit_reasons(frame, limits, n),
        "diverged": _diverged_reasons(frame, settings) if len(frame) else [],
    }
    found["incomplete"], notes = _incomplete_reasons(summary, settings)
    reasons = [r for v in BAD_VERDICTS for r in found[v]]
    worst = next((v for v in BAD_VERDICTS if found[v]), "ok")
    rule, why = key_point_rule(frame, d_safe, settings.safety_margin, obstacle_columns)
    return Verdict(worst, tuple(reasons + notes), rule, why)


def _incomplete_reasons(summary: dict, settings: VerdictSettings) -> tuple[list[str], list[str]]:
    """``(reasons, notes)``: where a run stopped early stopped, and whether tracking and force
    went unjudged (part of that reason; a note for a run that reached its duration)."""
    simulated = float(summary.get("simulated_s") or 0.0)
    unjudged = (
        f"tracking and force not judged (settle time {settings.settle_time:g} s not reached)"
        if simulated <= settings.settle_time
        else ""
    )
    if not summary.get("stopped_early"):
        return [], [unjudged] if unjudged else []
    budget = summary.get("wall_budget_s")
    why = f" (wall-time budget {_g(float(budget))} s)" if budget is not None else ""
    where = (
        f"stopped at {simulated:.2f} s of {_g(float(summary.get('duration') or math.nan))} s{why}"
    )
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
