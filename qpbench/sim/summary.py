"""The figures of a closed-loop run and its verdict, computed here and nowhere else:
:func:`summarize` turns a tick log (:mod:`qpbench.sim.log`) into a JSON-able dict (``None``
where a figure does not exist); what each holds: docs/methodology.md, "A run's figures"."""

from __future__ import annotations

import math

import numpy as np
import pandas as pd

from ..control.controller import Controller
from ..robot.body import body_crossings
from ..statuses import INFEASIBLE_OR_UNCLASSIFIED
from . import log
from .scenario import Scenario
from .verdict import TICK_KINDS, VerdictSettings, judge, judge_realtime_run

#: Time from which the ``*_after_2s`` figures are taken [s].
SETTLE_TIME = 2.0

#: A key point within this of ``d_safe`` [m] counts as touching its obstacle row (summary intervals).
ACTIVE_MARGIN = 1e-4

#: One tick's solve longer than this misses a 1 kHz loop's deadline [s].
KHZ_DEADLINE_S = 1e-3

#: Tolerance of the joint-angle [rad] and joint-velocity [rad/s] limit checks.
VIOLATION_TOL = 1e-6

#: At most this many intervals per list in a summary.
MAX_INTERVALS = 20

#: The p99 call time's confidence interval (:func:`block_bootstrap_quantile`): its level, the
#: length of a block of consecutive ticks [s], the resamples and their seed (docs/methodology.md,
#: "How sure a p99 is").
P99_LEVEL = 0.95
BOOTSTRAP_BLOCK_S = 0.05
BOOTSTRAP_RESAMPLES = 1000
BOOTSTRAP_SEED = 0

#: Figures of a summary that are lists or dicts (JSON text in a CSV cell).
STRUCTURED_FIGURES = (
    "infeasible_intervals",
    "obstacle_active_intervals",
    "scenario_overrides",
    "status_counts",
    "verdict_overrides",
)


def jsonable(overrides: dict) -> dict:
    """Scenario overrides as JSON-able values (arrays as lists)."""
    return {k: (v.tolist() if isinstance(v, np.ndarray) else v) for k, v in overrides.items()}


def _none(x):
    x = float(x)
    return None if not math.isfinite(x) else x


def _intervals(mask: np.ndarray, t: np.ndarray) -> list[list[float]]:
    """Runs of consecutive True ticks as ``[first t, last t]`` pairs [s]."""
    edges = np.flatnonzero(np.diff(np.r_[False, mask, False]))  # each run's first, last + 1
    return [[round(float(t[s]), 9), round(float(t[e - 1]), 9)] for s, e in edges.reshape(-1, 2)]


def _first(mask: np.ndarray, t: np.ndarray) -> tuple[int, float | None]:
    """How many ticks ``mask`` holds on, and the first of them [s] (``None``: none)."""
    rows = np.flatnonzero(mask)
    return rows.size, (float(t[rows[0]]) if rows.size else None)


def summarize(
    frame: pd.DataFrame,
    scenario: Scenario,
    controller: Controller,
    backend: str,
    formulation: str,
    wall_time_s: float,
    run_info: dict | None = None,
    p99_interval: bool = True,
) -> dict:
    """Figures of a run and its verdict (module docstring); ``run_info`` from the loop's own."""
    t = frame[log.T].to_numpy()
    dt, settings = scenario.dt, scenario.verdict
    ticks = len(frame)
    out = {
        "scenario": scenario.name,
        "scenario_overrides": jsonable(scenario.overrides),
        "verdict_overrides": scenario.verdict_overrides,
        "backend": backend,
        "formulation": formulation,
        "dt": dt,
        "duration": scenario.duration,
        "ticks": ticks,
        "simulated_s": ticks * dt,
    }
    out.update(_status_figures(frame, t))
    errors, judged = _error_figures(frame, t, settings.settle_time)
    out.update(errors)
    closest, active, below = _obstacle_figures(frame, t, controller, settings.safety_margin)
    out.update(closest)
    judged.update(below)
    body, inside = _body_figures(frame, t, controller, dt)
    out.update(body)
    judged.update(inside, joints=controller.n)
    out["key_points_kind"] = controller.key_points.kind
    limits, worst = _limit_figures(frame, t, controller.limits)
    out.update(limits)
    judged.update(worst)
    out.update(_effort_figures(frame, controller.n, dt, t >= SETTLE_TIME - 1e-12))
    out.update(_time_figures(frame))
    out.update(
        wall_time_s=float(wall_time_s),
        real_time_factor=_none(ticks * dt / wall_time_s) if wall_time_s > 0 else None,
        wall_budget_s=None,
        stopped_early=False,
    )
    out.update(active)
    out.update(run_info or {})
    out.update(_rank_figures(frame, dt, out.get("engine", "python"), p99_interval))
    verdict = judge({**out, **judged}, settings)
    out["verdict"] = verdict.verdict
    out["verdict_reasons"] = verdict.text
    out["key_point_rule"] = verdict.key_point_rule
    out["key_point_rule_reason"] = verdict.key_point_rule_reason
    out.update(realtime_figures(frame, dt, settings))
    return out


def time_to_converge(t: np.ndarray, error: np.ndarray, band: float) -> float | None:
    """First time [s] from which ``|error| <= band`` holds to the end (``None``: not at the end)."""
    if len(t) == 0:
        return None
    outside = ~(np.abs(np.asarray(error, dtype=float)) <= band)
    if outside[-1]:
        return None
    idx = np.flatnonzero(outside)
    return float(t[0]) if idx.size == 0 else float(t[idx[-1] + 1])


def convergence_figures(frame: pd.DataFrame, force_band: float, tracking_band: float) -> dict:
    """Times to converge [s] into the force band [N] and the tracking band [m], and the ticks
    whose solve missed a 1 kHz loop's deadline (a sweep's figures)."""
    t = frame[log.T].to_numpy(dtype=float)
    force, tracking = frame[log.FORCE_ERROR], frame[log.TRACKING_ERROR]
    return {
        "t_converge_force_s": time_to_converge(t, force.to_numpy(), force_band),
        "t_converge_tracking_s": time_to_converge(t, tracking.to_numpy(), tracking_band),
        "ticks_over_1ms": int(np.count_nonzero(judged_tick_times(frame) > KHZ_DEADLINE_S)),
    }


def judged_tick_times(frame: pd.DataFrame) -> pd.Series:
    """The per-tick time [s] real time is judged on: ``solve_time_s`` plus
    ``fallback_solve_time_s`` (0 where none ran or no column)."""
    if log.FALLBACK_SOLVE_TIME not in frame:
        return frame[log.SOLVE_TIME]
    return frame[log.SOLVE_TIME] + frame[log.FALLBACK_SOLVE_TIME].fillna(0.0)


def tick_kinds(frame: pd.DataFrame) -> dict[str, np.ndarray]:
    """A mask per kind of :data:`~qpbench.sim.verdict.TICK_KINDS`; each tick is of exactly one."""
    status = frame[log.STATUS].astype(str).to_numpy()
    infeasible = np.isin(status, INFEASIBLE_OR_UNCLASSIFIED)
    optimal = status == "optimal"
    rest = ~(infeasible | optimal)
    dropped = (frame[log.FALLBACK] | frame[log.ZERO_VELOCITY]).to_numpy(dtype=bool)
    fallback = rest & dropped
    return {
        "optimal": optimal,
        "infeasible": infeasible,
        "fallback": fallback,
        "other": rest & ~fallback,
    }


def tick_time_figures(
    times: np.ndarray, kinds: dict[str, np.ndarray], certify: np.ndarray, dt: float
) -> dict:
    """Per-tick times [s] by kind (:func:`tick_kinds`): ``timed_ticks``; per kind ``ticks_<kind>``,
    ``over_dt_<kind>`` (longer than ``dt`` [s]), ``time_p99_<kind>_s``; without and of the
    infeasible ticks; ``certify_time_median_s``, ``_max_s`` of ``certify`` (the times [s] of the
    ``primal_infeasible`` ticks); ``None`` where no tick is of the kind."""
    out = {"timed_ticks": int(times.size)}
    for kind, mask in kinds.items():
        t = times[mask]
        out[f"ticks_{kind}"] = int(t.size)
        out[f"over_dt_{kind}"] = int(np.count_nonzero(t > dt))
        out[f"time_p99_{kind}_s"] = _quantile(t, 0.99)
    out["time_p99_without_infeasible_s"] = _quantile(times[~kinds["infeasible"]], 0.99)
    out["time_median_infeasible_s"] = _quantile(times[kinds["infeasible"]], 0.5)
    out["certify_time_median_s"] = _quantile(certify, 0.5)
    out["certify_time_max_s"] = _none(certify.max()) if certify.size else None
    return out


def _quantile(x: np.ndarray, q: float) -> float | None:
    return _none(np.quantile(x, q)) if x.size else None


def realtime_figures(
    frame: pd.DataFrame,
    dt: float,
    settings: VerdictSettings,
    times: np.ndarray | None = None,
    what: str = "call",
) -> dict:
    """Real time at ``dt`` [s] (docs/verdicts.md, "Real time"): the figures of ``times`` [s] per
    tick (default :func:`judged_tick_times`) by kind (:func:`tick_time_figures`), the thresholds
    they are judged on, ``deadline_misses`` (ticks over ``dt``) and ``over_dt_share``, and the
    judgement of the solver's own times (``realtime_solver``: ``unknown`` unless every tick
    has one); ``what`` names the times in the reasons."""
    calls = np.asarray(judged_tick_times(frame) if times is None else times, dtype=float)
    kinds = tick_kinds(frame)
    primal = (frame[log.STATUS].astype(str) == "primal_infeasible").to_numpy()
    t = frame[log.T].to_numpy()[kinds["infeasible"]]
    base = {
        "dt": dt,
        "max_p99_fraction_of_dt": settings.max_p99_fraction_of_dt,
        "max_over_dt_share": settings.max_over_dt_share,
        "first_infeasible_t": _none(t[0]) if t.size else None,
        "last_infeasible_t": _none(t[-1]) if t.size else None,
    }
    certify = frame[log.SOLVE_TIME].to_numpy(dtype=float)[primal]  # the tick's own solve
    out = {**base, **tick_time_figures(calls, kinds, certify, dt)}
    misses = sum(out[f"over_dt_{k}"] for k in TICK_KINDS)
    out["deadline_misses"] = misses
    out["over_dt_share"] = misses / calls.size if calls.size else None
    out["realtime"], out["realtime_reason"] = judge_realtime_run(out, what)
    own = frame[log.SOLVER_TIME].to_numpy(dtype=float)
    whole = np.isfinite(own)
    out["solver_time_ticks"] = int(whole.sum())
    out["solver_time_p99_s"] = out["solver_over_dt_share"] = None
    if not whole.any():
        out["realtime_solver"], out["realtime_solver_reason"] = "unknown", "no solver time reported"
    elif not whole.all():
        out["realtime_solver"] = "unknown"
        out["realtime_solver_reason"] = (
            f"reports its own time on {int(whole.sum())} of {own.size} ticks only: not judged on "
            "that subset"
        )
    else:
        mine = {**base, **tick_time_figures(own, kinds, own[primal], dt)}
        out["solver_time_p99_s"] = _quantile(own, 0.99)
        out["solver_over_dt_share"] = int(np.count_nonzero(own > dt)) / own.size
        out["realtime_solver"], out["realtime_solver_reason"] = judge_realtime_run(mine, "solver")
    return out


def _rms(x: np.ndarray) -> float | None:
    return _none(np.sqrt(np.mean(np.square(x)))) if x.size else None


def _amax(x: np.ndarray) -> float | None:
    return _none(np.max(np.abs(x))) if x.size else None


def _status_figures(frame: pd.DataFrame, t: np.ndarray) -> dict:
    """Counts by tick status (:mod:`qpbench.statuses`), fallbacks, and when the QP was infeasible."""
    status = frame[log.STATUS]
    infeasible = status.isin(INFEASIBLE_OR_UNCLASSIFIED).to_numpy()
    return {
        "infeasible_ticks": int(infeasible.sum()),
        "non_optimal_ticks": int((status != "optimal").to_numpy().sum()),
        "fallback_ticks": int(frame[log.FALLBACK].sum()),
        "zero_velocity_ticks": int(frame[log.ZERO_VELOCITY].sum()),
        "first_infeasible_t": _none(t[infeasible][0]) if infeasible.any() else None,
        "last_infeasible_t": _none(t[infeasible][-1]) if infeasible.any() else None,
        "infeasible_intervals": _intervals(infeasible, t),
        "status_counts": {str(k): int(v) for k, v in status.value_counts().items() if v},
        **{f"{s}_ticks": int((status == s).sum()) for s in ("error", "time_limit", "invalid")},
    }


def _error_figures(frame: pd.DataFrame, t: np.ndarray, settle_time: float) -> tuple[dict, dict]:
    """Tracking [m] and force [N] errors after :data:`SETTLE_TIME`, the last force [N]; for the
    verdict, each error's largest ``(|error|, t)`` after ``settle_time`` [s] (NaN as ``inf``;
    ``None``: no tick after it)."""
    after, settled = t >= SETTLE_TIME - 1e-12, t >= settle_time - 1e-12
    out, worst = {}, {}
    for name, column in (("tracking", log.TRACKING_ERROR), ("force_error", log.FORCE_ERROR)):
        error = frame[column].to_numpy(dtype=float)
        out[f"{name}_rms_after_2s"] = _rms(error[after])
        out[f"{name}_max_after_2s"] = _amax(error[after])
        e = np.abs(error[settled])
        e = np.where(np.isnan(e), np.inf, e)
        k = int(np.argmax(e)) if e.size else -1
        worst[f"{column}_worst"] = (float(e[k]), float(t[settled][k])) if e.size else None
    out["force_final"] = _none(frame[log.FORCE].iloc[-1])
    return out, worst


def _obstacle_figures(
    frame: pd.DataFrame, t: np.ndarray, controller: Controller, margin: float
) -> tuple[dict, dict, dict]:
    """The closest approach of a key point to an obstacle [m]; when each pair's row was about
    active (within :data:`ACTIVE_MARGIN` of ``d_safe``; ``{}`` without obstacles); for the
    key-point rule, the ticks with a key point below ``d_safe - margin`` [m] (a NaN distance
    counts) and the first of them [s] (``None`` without obstacles)."""
    dcols, d_safe = [(a, o) for a, o, _ in controller.obstacle_columns()], controller.d_safe
    if not dcols:
        none = dict.fromkeys(
            f"min_obstacle_distance{s}" for s in ("", "_key_point", "_obstacle", "_t")
        )
        return {**none, "d_safe": d_safe}, {}, {"key_point_below_ticks": None}
    D = frame[[log.distance_column(a, o) for a, o in dcols]].to_numpy()
    k, c = divmod(int(np.argmin(D)), D.shape[1])
    closest = {
        "min_obstacle_distance": _none(D[k, c]),
        "min_obstacle_distance_key_point": dcols[c][0],
        "min_obstacle_distance_obstacle": dcols[c][1],
        "min_obstacle_distance_t": _none(t[k]),
        "d_safe": d_safe,
    }
    near = D <= d_safe + ACTIVE_MARGIN
    active = {
        f"{a}/{o}": _intervals(near[:, c], t)[:MAX_INTERVALS]
        for c, (a, o) in enumerate(dcols)
        if near[:, c].any()
    }
    below, first = _first(~(D >= d_safe - margin).all(axis=1), t)
    rule = {"key_point_below_ticks": below, "key_point_below_first_t": first}
    return closest, {"obstacle_active_intervals": active}, rule


def _body_figures(
    frame: pd.DataFrame, t: np.ndarray, controller: Controller, dt: float
) -> tuple[dict, dict]:
    """The body's closest approach to an obstacle (``d_body_*`` columns of the log): the
    clearance [m], its link (1-based), its obstacle and when [s] (``None`` without obstacles),
    and :func:`_crossing_figures`. For the verdict, the obstacles' kinds, the ticks with the
    body inside an obstacle and the first of them [s]."""
    d = frame[log.D_BODY_MIN].to_numpy(dtype=float)
    crossed = _crossing_figures(frame, t, controller, dt)
    if not np.isfinite(d).any():
        none = dict.fromkeys(f"min_body_distance{s}" for s in ("", "_link", "_obstacle", "_t"))
        return {**none, **crossed}, {"body_inside_ticks": 0}
    kinds = {o.name: o.KIND for o in controller.obstacles}
    k = int(np.nanargmin(d))
    name = str(frame[log.D_BODY_OBSTACLE].iloc[k])
    out = {
        "min_body_distance": _none(d[k]),
        "min_body_distance_link": int(frame[log.D_BODY_LINK].iloc[k]),
        "min_body_distance_obstacle": name,
        "min_body_distance_t": _none(t[k]),
        **crossed,
    }
    inside, first = _first(d < 0.0, t)
    judged = {"body_inside_ticks": inside, "body_inside_first_t": first}
    judged["min_body_distance_kind"] = kinds[name]
    judged["body_crossing_kind"] = kinds.get(crossed["body_crossing_obstacle"])
    return out, judged


def _crossing_figures(
    frame: pd.DataFrame, t: np.ndarray, controller: Controller, dt: float
) -> dict:
    """``body_crossings`` (intervals) and the first one's ``body_crossing_t`` [s],
    ``body_crossing_link`` (1-based) and ``body_crossing_obstacle`` (``None`` without one)."""
    n = controller.n
    theta = frame[log.theta_columns(n)].to_numpy(dtype=float)
    v = frame[log.velocity_columns(n)].to_numpy(dtype=float)
    end = theta[-1] + dt * v[-1] if len(theta) else None  # after the last command
    d, obstacles = frame[log.D_BODY_MIN].to_numpy(float), controller.obstacles
    radius = controller.key_points.radius
    found = body_crossings(
        controller.arm, theta, t, dt, obstacles, radius, controller.exempt, theta_end=end, d_min=d
    )
    if not found.tick.size:
        none = dict.fromkeys(f"body_crossing_{s}" for s in ("t", "link", "obstacle"))
        return {"body_crossings": 0, **none}
    first = int(np.argmin(found.t))
    return {
        "body_crossings": int(found.tick.size),
        "body_crossing_t": float(found.t[first]),
        "body_crossing_link": int(found.link[first]),
        "body_crossing_obstacle": controller.obstacles[found.obstacle[first]].name,
    }


def _limit_figures(frame: pd.DataFrame, t: np.ndarray, limits) -> tuple[dict, dict]:
    """Ticks with a joint angle [rad] or velocity [rad/s] beyond its limit by more than
    :data:`VIOLATION_TOL` (a NaN counts); for the verdict, the worst of each as ``(joint,
    value, the limit it is beyond, t [s])``."""
    n = len(limits.theta_min)
    counts, worst = {}, {}
    for name, columns, lo, hi in (
        ("joint_limit", log.theta_columns(n), limits.theta_min, limits.theta_max),
        ("joint_velocity_limit", log.velocity_columns(n), limits.v_min, limits.v_max),
    ):
        X = frame[columns].to_numpy(dtype=float)
        excess = np.where(np.isnan(X), np.inf, np.maximum(lo - X, X - hi))  # > 0 beyond
        counts[f"{name}_violations"] = int((excess > VIOLATION_TOL).any(axis=1).sum())
        k, i = divmod(int(np.argmax(excess)), n)
        x = X[k, i]
        worst[f"{name}_worst"] = (i, float(x), float(lo[i] if x < lo[i] else hi[i]), float(t[k]))
    return counts, worst


def _effort_figures(frame: pd.DataFrame, n: int, dt: float, after: np.ndarray) -> dict:
    """Joint motion and effort, the task residual after :data:`SETTLE_TIME` and the last
    ``Kp_hat, Kd_hat``."""
    theta = frame[log.theta_columns(n)].to_numpy()
    v = frame[log.velocity_columns(n)].to_numpy()
    v_sq = frame[log.V_SQ].to_numpy()
    return {
        "max_abs_theta": _none(np.max(np.abs(theta))),
        "max_abs_v": _none(np.max(np.abs(v))),
        "v_sq_max": _none(v_sq.max()),
        "v2_integral": float(np.sum(v_sq) * dt),
        "task_residual_max_after_2s": _amax(frame[log.TASK_RESIDUAL].to_numpy()[after]),
        "kp_hat_final": _none(frame[log.KP_HAT].iloc[-1]),
        "kd_hat_final": _none(frame[log.KD_HAT].iloc[-1]),
    }


#: The tick log's clocks and their figures' prefixes (docs/methodology.md says what each holds).
CLOCKS = {
    "build_time": log.BUILD_TIME,
    "solve_time": log.SOLVE_TIME,
    "fallback_solve_time": log.FALLBACK_SOLVE_TIME,
    "tick_time": log.TICK_TIME,
}


def _time_figures(frame: pd.DataFrame) -> dict:
    """Median, p99 and max [s] of each clock over the ticks it timed (``fallback_solve_time``:
    the ticks whose fallback ran; ``None`` when none did)."""
    out = {}
    for name, column in CLOCKS.items():
        times = frame[column].dropna() if column in frame else pd.Series(dtype=float)
        values = (times.median(), times.quantile(0.99), times.max())
        for stat, value in zip(("median", "p99", "max"), values):
            out[f"{name}_{stat}_s"] = _none(value) if times.size else None
    return out


def rank_times(frame: pd.DataFrame, engine: str) -> tuple[pd.Series, str]:
    """The per-tick time [s] a C or C++ controller would pay for the solver, and its source
    (``compiled``, ``solver`` or ``python``: docs/methodology.md, "How sure a p99 is")."""
    solve = judged_tick_times(frame)
    if engine == "compiled":
        return solve, "compiled"
    own = frame[log.SOLVER_TIME]
    if len(own) and own.notna().all():
        return own, "solver"
    return solve, "python"


def _rank_figures(frame: pd.DataFrame, dt: float, engine: str, interval: bool) -> dict:
    """``rank_time_source`` and the p99 [s] of :func:`rank_times` with its interval (``None``
    without ``interval``: a sweep's instance, whose time ranks nothing)."""
    times, source = rank_times(frame, engine)
    lo = hi = None
    if len(times) and interval:  # blocks of BOOTSTRAP_BLOCK_S at the control period dt [s]
        block = max(1, round(BOOTSTRAP_BLOCK_S / dt))
        lo, hi = map(_none, block_bootstrap_quantile(times.to_numpy(dtype=float), 0.99, block))
    return {
        "rank_time_source": source,
        "rank_time_p99_s": _none(times.quantile(0.99)) if len(times) else None,
        "rank_time_p99_lo_s": lo,
        "rank_time_p99_hi_s": hi,
    }


def block_bootstrap_quantile(
    x: np.ndarray,
    q: float,
    block: int,
    level: float = P99_LEVEL,
    resamples: int = BOOTSTRAP_RESAMPLES,
    seed: int = BOOTSTRAP_SEED,
) -> tuple[float, float]:
    """Percentile interval at ``level`` of the ``q``-quantile of the series ``x`` by the circular
    block bootstrap (docs/methodology.md, "How sure a p99 is"); non-finite values left out
    (``(nan, nan)`` without any). Only the values at or above a resample's quantile decide it,
    so resamples are counted on the largest values of ``x``."""
    x = np.asarray(x, dtype=float)
    x = x[np.isfinite(x)]
    n = x.size
    if n == 0:
        return math.nan, math.nan
    block = int(min(max(1, block), n))
    k = max(1, round(n / block))
    m = k * block
    top_rank = m - math.ceil(round(q * m, 9)) + 1  # the quantile's rank from the largest, 1-based
    rng = np.random.default_rng(seed)
    starts = np.sort(rng.integers(0, n, size=(resamples, k)), axis=1)  # sorted: a faster search
    # the ticks of the largest values, enough for about three times the resample's need
    tail = min(n, math.ceil(3 * top_rank * n / m) + block)
    ticks = np.argsort(x, kind="stable")[::-1][:tail]
    # copies of tick j in a resample: blocks started in (j - block, j], around the circle
    before = (ticks - block) % n
    points, where = np.unique(np.r_[ticks, before], return_inverse=True)
    slot = np.searchsorted(points, starts) + (np.arange(resamples) * (points.size + 1))[:, None]
    per_slot = np.bincount(slot.ravel(), minlength=resamples * (points.size + 1))
    started = np.cumsum(per_slot.reshape(resamples, -1), axis=1, dtype=np.int32)  # at <= points[i]
    upto, below = started[:, where[:tail]], started[:, where[tail:]]
    copies = upto - below + k * (ticks < block)[None, :]
    reached = np.cumsum(copies, axis=1) >= top_rank
    stats = np.empty(resamples)
    found = reached.any(axis=1)
    stats[found] = x[ticks[np.argmax(reached[found], axis=1)]]
    for b in np.flatnonzero(~found):  # too few large values drawn: the whole resample
        picks = (starts[b][:, None] + np.arange(block)[None, :]).ravel() % n
        stats[b] = np.sort(x[picks])[m - top_rank]
    alpha = (1.0 - level) / 2
    lo, hi = np.quantile(stats, [alpha, 1.0 - alpha])
    return float(lo), float(hi)
