"""Verdict of a closed-loop run (``ok``, ``diverged``, ``incomplete``, ``limits``, ``unsafe``,
``failed``) and, beside it, whether the run kept real time.

One function, :func:`judge`, decides; :func:`qpbench.sim.summary.summarize` calls
it and puts ``verdict`` and ``verdict_reasons`` into the summary, which the
closed-loop table (:mod:`qpbench.harness.closed_loop`) copies as they are.
:func:`failed_run` gives the verdict of a run that produced no result at all
(a crash, an overrun deadline, an exception outside the ticks): ``incomplete``.

Rules, thresholds from the scenario's ``[verdict]`` table (:class:`VerdictSettings`):

- ``failed``: the backend did not answer usably: a tick whose solve raised or
  reported ``error``, a non-finite answer (``invalid``), an answer later than
  the per-tick deadline (``time_limit``, with ``--deadline``), a fallback solve that raised, or a
  tick left without any command (zero velocity: no answer and no soft
  fallback);
- ``unsafe``: the body went into an obstacle: the clearance of a link's
  capsule to an obstacle (tick-log column ``d_body_min``, exact at every tick,
  :mod:`qpbench.robot.body`) was below 0. The reason names the link, the
  obstacle, the depth and the time: ``link 4 (end effector) 30.0 mm inside
  disk 'blob' at 7.21 s``. The end effector's link is not judged against an
  obstacle that is the contact surface (it presses into it by design);
  every other link is;
- ``limits``: a joint angle or a commanded joint speed went beyond its limit
  by more than :data:`VIOLATION_TOL`;
- ``incomplete``: the run stopped before its ``duration``: its wall-time
  budget ran out (the reason says how far it got), or it produced no result
  at all (crash, the run's own deadline, an exception outside the ticks:
  :func:`failed_run`);
- ``diverged``: for ``t >= settle_time`` [s], ``|tracking_error|`` exceeded
  ``max_tracking_error`` [m] or ``|force_error|`` exceeded ``max_force_error``
  [N] (or either was not finite).

The paper's own guarantee is a separate rule, reported beside the verdict
(``key_point_rule``: ``held``, ``broken``, ``-`` without obstacles, and
``key_point_rule_reason``): every key point (``[key_points] kind``: the
paper's fixed points, or each link's closest point) kept
``d_safe - safety_margin`` [m] from every obstacle. A broken key-point rule
alone does not make a run ``unsafe``: ``d_safe`` is a margin the controller
keeps, not a collision, and the key points are not the body (the paper's
leave the end effector and most of each link unguarded, so a run can hold
the rule and still drive the end effector into an obstacle). A key point
inside an obstacle is part of the body inside it, so such a run is
``unsafe`` by the body rule as well.

When several hold, the verdict is the first of :data:`VERDICTS` (failed >
unsafe > limits > incomplete > diverged) and ``verdict_reasons`` lists every
one, in that order, ``"; "`` between them. A run stopped early is judged on the
ticks it simulated (a simulated trajectory does not depend on how long its
solves took, only how far it got does). A run whose simulated time does not
reach ``settle_time`` (stopped early, or asked for a shorter ``duration``)
says that tracking and force were not judged; for a run that did reach its
duration that note does not change the verdict.

Real time is judged beside the verdict, never in it (the verdict is about
what the run did, real time about the machine it ran on): :func:`judge_realtime`
gives ``realtime`` (``yes``/``no``) from the measured call times of every tick
(``solve_time_s``: what a Python controller calling the backend would see) and
``realtime_solver`` (``yes``/``no``/``unknown``) from the time the solver
itself reports (``solver_time_s``: what a C or C++ controller calling the
solver directly would see; ``unknown`` when the backend reports none). Each
is ``yes`` when the p99 of the tick times is at most ``max_p99_fraction_of_dt``
of ``dt`` and at most ``max_over_dt_share`` of the ticks took longer than
``dt``.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import TYPE_CHECKING

import numpy as np

from . import log

if TYPE_CHECKING:
    import pandas as pd

    from ..control.terms import EscapeVelocityLimits

__all__ = [
    "BAD_VERDICTS",
    "DEFAULT_SAFETY_MARGIN",
    "VERDICTS",
    "VIOLATION_TOL",
    "Verdict",
    "VerdictSettings",
    "failed_run",
    "judge",
    "judge_realtime",
    "key_point_rule",
]

#: Verdicts, from the worst: the verdict of a run is the first whose rule holds.
VERDICTS = ("failed", "unsafe", "limits", "incomplete", "diverged", "ok")
#: Every verdict but ``ok``.
BAD_VERDICTS = VERDICTS[:-1]

#: Tolerance of the joint-angle [rad] and joint-velocity [rad/s] limit checks
#: (solvers meet bounds to their own accuracy, about 1e-9 here).
VIOLATION_TOL = 1e-6

#: Default of ``[verdict] safety_margin`` [m]: how far below ``d_safe`` a key
#: point may come before the run is unsafe (the velocity damper acts one tick
#: late, so exact QP solutions dip below ``d_safe`` by far less). A scenario
#: whose ``d_safe`` is not above it defaults to half its ``d_safe``.
DEFAULT_SAFETY_MARGIN = 5e-4


@dataclass(frozen=True)
class VerdictSettings:
    """Thresholds of the verdict and of real time (the scenario's ``[verdict]`` table).

    Every field has a default (the shipped scenarios' values; why each, in
    ``docs/verdicts.md``); values are checked here, where they are held
    (:class:`~qpbench.exceptions.InputError` naming ``verdict.<key>``); the
    rules that involve other tables (``settle_time < duration``,
    ``safety_margin < d_safe``) in :mod:`qpbench.sim.scenario_schema`.

    Attributes:
        settle_time: Start of the judged span of tracking and force errors [s]
            (default 2: twice the paper's transient of about 1 s).
        max_tracking_error: Largest ``|tangential tracking error|`` after it [m]
            (default 0.001).
        max_force_error: Largest ``|contact force - Fd|`` after it [N] (default 2).
        safety_margin: A key point closer than ``d_safe - safety_margin`` to
            an obstacle is unsafe [m] (default :data:`DEFAULT_SAFETY_MARGIN`).
        max_p99_fraction_of_dt: Real time: the p99 of the per-tick times may
            be at most this fraction of ``dt`` (default 0.5: the QP is not the
            only work of a tick).
        max_over_dt_share: Real time: at most this share of the ticks may take
            longer than ``dt`` (default 0.001: one tick in a thousand).
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


def _verdict(found: dict[str, list[str]], notes: list[str]) -> Verdict:
    reasons = [r for v in VERDICTS[:-1] for r in found.get(v, [])]
    worst = next((v for v in VERDICTS[:-1] if found.get(v)), "ok")
    return Verdict(worst, tuple(reasons + notes))


def _g(x: float) -> str:
    return f"{x:.3g}"


def _failed_reasons(summary: dict) -> list[str]:
    out = []
    # One branch per kind of tick that did not go as planned, each with its own sentence and
    # details (first error, deadline): alike in shape, kept apart so each reads as its sentence.
    n = int(summary.get("error_ticks") or 0)
    if n:
        first = summary.get("first_error")
        t = summary.get("first_error_t")
        where = f" (first at {t:.3f} s: {first})" if first and t is not None else ""
        out.append(f"{n} tick{'s' if n > 1 else ''} with an error{where}")
    n = int(summary.get("invalid_ticks") or 0)
    if n:
        out.append(f"{n} non-finite answer{'s' if n > 1 else ''}")
    n = int(summary.get("time_limit_ticks") or 0)
    if n:
        limit = summary.get("deadline_s")
        what = f" ({_g(limit)} s)" if limit is not None else ""
        out.append(f"{n} answer{'s' if n > 1 else ''} dropped past the per-tick deadline{what}")
    n = int(summary.get("fallback_errors") or 0)
    if n:
        out.append(f"{n} fallback solve{'s' if n > 1 else ''} raised")
    n = int(summary.get("zero_velocity_ticks") or 0)
    if n:
        out.append(
            f"{n} tick{'s' if n > 1 else ''} without a command (no answer, no soft fallback: zero velocity)"
        )
    return out


def _unsafe_reasons(frame, n: int, obstacle_kinds: dict[str, str] | None) -> list[str]:
    """The body rule: a link's capsule inside an obstacle (``d_body_min < 0``) at some tick."""
    if log.D_BODY_MIN not in frame.columns or not len(frame):
        return []
    d = frame[log.D_BODY_MIN].to_numpy(dtype=float)
    inside = d < 0.0
    if not inside.any():
        return []
    from ..robot.body import link_label

    t = frame[log.T].to_numpy(dtype=float)
    k = int(np.argmin(np.where(inside, d, np.inf)))
    link = int(frame[log.D_BODY_LINK].iloc[k])
    name = str(frame[log.D_BODY_OBSTACLE].iloc[k])
    kind = (obstacle_kinds or {}).get(name, "obstacle")
    rows = np.flatnonzero(inside)
    ticks = f"{rows.size} tick{'s' if rows.size > 1 else ''}"
    return [
        f"{link_label(link, n)} {-d[k] * 1e3:.1f} mm inside {kind} '{name}' at {t[k]:.2f} s "
        f"(the body inside an obstacle on {ticks} from {t[rows[0]]:.3f} s)"
    ]


def key_point_rule(
    frame, d_safe: float, margin: float, columns: list[tuple[str, str]]
) -> tuple[str, str]:
    """The paper's guarantee: every key point kept ``d_safe - margin`` [m] from every obstacle.

    Returns:
        ``("held", "")``, ``("broken", reason)`` or ``("-", "")`` without obstacles.
    """
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
        ticks = int(bad.sum())
        out.append(
            f"joint {what} limit broken on {ticks} tick{'s' if ticks > 1 else ''} "
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
    """The verdict of one simulated run (rules in the module docstring).

    Args:
        frame: The run's tick log (:func:`qpbench.sim.loop.simulate`; columns
            ``t``, ``theta_i``, ``v_i``, ``tracking_error`` [m],
            ``force_error`` [N], ``d_<key point>_<obstacle>`` [m]).
        settings: The scenario's thresholds.
        d_safe: The controller's safety distance [m].
        limits: The controller's joint limits (``theta_min``, ``theta_max``
            [rad], ``v_min``, ``v_max`` [rad/s]).
        obstacle_columns: ``(key point, obstacle)`` of each distance column
            (the key-point rule).
        obstacle_kinds: Kind (``disk``, ``line``, ...) of each obstacle, by name,
            for the body rule's reason (``obstacle`` when not given); the body rule
            reads the log's ``d_body_min``, ``d_body_link``, ``d_body_obstacle``.
        summary: The run's counts: ``error_ticks``, ``invalid_ticks``,
            ``time_limit_ticks``, ``zero_velocity_ticks``, ``fallback_errors``,
            ``first_error``, ``first_error_t`` [s], ``deadline_s`` [s];
            ``stopped_early``, ``simulated_s``, ``duration`` [s] and
            ``wall_budget_s`` [s] for a run cut by a wall-time budget. Missing
            counts are 0.
    """
    n = len(limits.theta_min)
    found = {
        "failed": _failed_reasons(summary),
        "unsafe": _unsafe_reasons(frame, n, obstacle_kinds),
        "limits": _limit_reasons(frame, limits, n),
        "diverged": _diverged_reasons(frame, settings) if len(frame) else [],
    }
    found["incomplete"], notes = _incomplete_reasons(summary, settings)
    verdict = _verdict(found, notes)
    rule, why = key_point_rule(frame, d_safe, settings.safety_margin, obstacle_columns)
    return Verdict(verdict.verdict, verdict.reasons, rule, why)


def _incomplete_reasons(summary: dict, settings: VerdictSettings) -> tuple[list[str], list[str]]:
    """``(reasons, notes)``: where a run stopped early stopped (an ``incomplete`` reason), and
    whether tracking and force went unjudged (part of that reason; a note for a run that
    reached its duration)."""
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
    times: np.ndarray, dt: float, settings: VerdictSettings, what: str = "call"
) -> tuple[str, str]:
    """Whether per-tick times [s] keep a loop of period ``dt`` [s]: ``(yes|no|unknown, why)``.

    ``yes`` when the p99 of the finite ``times`` is at most
    ``settings.max_p99_fraction_of_dt * dt`` and at most ``settings.max_over_dt_share``
    of them exceed ``dt``; ``unknown`` when no time is finite (a backend that reports
    no solve time of its own). ``what`` names the times in the reason.
    """
    times = np.asarray(times, dtype=float)
    times = times[np.isfinite(times)]
    if not times.size:
        return "unknown", f"no {what} time reported"
    p99 = float(np.quantile(times, 0.99))
    over = int(np.count_nonzero(times > dt))
    share = over / times.size
    limit = settings.max_p99_fraction_of_dt * dt
    frac = f"{settings.max_p99_fraction_of_dt:.0%}"
    p99_ok, share_ok = p99 <= limit, share <= settings.max_over_dt_share
    p99_text = f"p99 {what} {_us(p99)} {'<=' if p99_ok else '>'} {frac} of dt {_us(dt)}"
    share_text = (
        f"{over} of {times.size} ticks over dt ({share:.2%}; "
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
    """The verdict of a run that produced no result: ``status`` (``error``,
    ``crashed``, ``time_limit``) and the harness's message; ``incomplete``,
    nothing of it could be judged."""
    what = {
        "crashed": "run crashed",
        "time_limit": "run overran its deadline",
        "error": "run raised",
    }.get(status, f"run {status}")
    message = " ".join(str(message).split())
    return Verdict("incomplete", (f"{what}: {message}" if message else what,))
