"""Closed-loop simulation: the controller's QP solved every tick by a backend, a kinematic plant.

One tick at ``t_k = k dt`` (k = 0 .. ticks-1):

1. sense: end-effector position ``x_k`` (forward kinematics), velocity
   ``xdot_k = (x_k - x_{k-1}) / dt`` (0 at k = 0), contact force ``F_k`` of the
   environment's spring-damper (with the scenario's sensor noise);
2. build the tick's QP (eq. 11, the chosen formulation) with the current
   ``Kp_hat, Kd_hat``;
3. solve it with the backend (warm-started from the previous command). If the
   backend returns no solution (infeasible, failure), solve the
   ``soft`` formulation of the same tick with the same backend (fallback); if
   that fails too, command zero velocity. An *online* backend (class attribute
   ``online = True``, the RNN) is its own controller: its ``x`` is applied
   whatever its status, with no fallback. A non-finite ``x`` counts as no
   solution. (A backend that cannot classify infeasibility and stops on a
   budget, like ``rnn-converged``, spends that budget on every infeasible
   tick of the ``paper`` formulation; on the scenarios' infeasible start its
   soft fallback fails too and the arm stops: see results/rnn/README.md).
   Every solve is guarded, so a faulty backend cannot stop the loop: a
   Python exception escaping the backend makes the tick's status ``error``
   (the backend is reset, the first exception's ``"Type: message"`` is kept
   in the summary as ``first_error``); an ``x`` holding a NaN or an infinity
   is ``invalid`` (the backend is reset). Each of these is a tick without a
   solution: soft fallback, else zero velocity (an online backend: zero
   velocity). An exception of the fallback's own solve counts as a failed
   fallback (zero velocity; ``fallback_errors`` in the summary).
   Time never changes the trajectory unless asked to: an answer is applied
   however long it took (its time is in ``solve_time_s`` and the summary's
   ``deadline_misses`` counts the ticks slower than ``dt``), so a run is the
   same on a fresh machine (kernels compiled first, before the clock:
   :func:`qpbench.jit.warmup`) and on the next. With a ``deadline``
   (``--deadline``) an answer, or a fallback's, that arrives later is
   dropped (status ``time_limit``, counted in ``deadline_dropped``), as a
   real-time controller would. A solve is never interrupted, so a backend
   that hangs (in native code) hangs the loop; ``qpbench closed-loop``
   guards against that (and against a crash of the process) by running such
   a backend's simulation in a worker process with a deadline for the whole
   run (:mod:`qpbench.harness.closed_loop`);
4. adaptive scenarios: one Euler step of the law of section 4.4 from ``F_k``;
5. plant: ``theta_{k+1} = theta_k + dt v_k``.

Per tick the Python side does the least it can: one call of the controller's
compiled build kernel (which also returns the end-effector position, the
key-point distances and ``x_d``: nothing is recomputed), the backend's
``solve``, and one call of a compiled kernel that senses, writes the tick's
log row into a preallocated array (by index; no dict, no pandas) and
advances the plant. Statuses are collected as strings and coded once at the
end, when the log becomes a :class:`pandas.DataFrame`, one row per tick:

=================== ===========================================================
t                   time [s]
theta_i, v_i        joint angles [rad] and commanded velocities [rad/s]
ee_x, ee_y          end-effector position [m]
xd_x, xd_y          desired position x_d(t) [m]
tracking_error      tangential error t . (x - x_d) [m], t the surface tangent
force               measured contact force [N]; force_error = force - Fd [N]
d_<A>_<obstacle>    distance of key point A to the obstacle [m] (min over a
                    point cloud's points; link radius subtracted)
d_min               smallest of those [m]
v_sq                ``|v|^2`` [rad^2/s^2]
task_residual       ``|J v - b0|`` [m/s]
status              the backend's status on the tick's QP, one of
                    :data:`TICK_STATUSES` (the backends' statuses, plus
                    ``invalid``: a non-finite answer; ``error`` is also an
                    exception, ``time_limit`` also an answer dropped past
                    the ``deadline``)
fallback            the soft fallback's answer was applied
zero_velocity       zero velocity was commanded (fallback failed too)
solve_time_s        wall time of the tick's solve call(s) [s]
y_0, y_1            equality duals of the applied solution (paper formulation)
z_max               largest inequality (obstacle row) dual
kp_hat, kd_hat      interaction coefficients the tick's QP used
=================== ===========================================================
"""

from __future__ import annotations

import logging
import math
import time
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
import pandas as pd

from ..backends import STATUSES, Backend, get_backend
from ..exceptions import ParamError
from ..control.controller import FORMULATIONS, Controller
from .scenario import Scenario, load_scenario
from .verdict import VIOLATION_TOL, judge

__all__ = [
    "INFEASIBLE_STATUSES", "SimResult", "TICK_STATUSES", "VIOLATION_TOL", "resolve_backend", "simulate", "summarize",
]

log = logging.getLogger(__name__)

#: Time from which tracking and force errors are judged [s] (paper: transient about 1 s).
SETTLE_TIME = 2.0

#: A key point within this of ``d_safe`` [m] counts as touching its obstacle row (summary intervals).
ACTIVE_MARGIN = 1e-4

#: At most this many intervals per list in a summary.
MAX_INTERVALS = 20

#: Statuses counted as ``infeasible_ticks`` in a summary (see :func:`summarize`).
INFEASIBLE_STATUSES = ("primal_infeasible", "dual_infeasible", "not_solved")

#: Categories of the tick log's ``status`` column: the backends' statuses plus
#: ``invalid`` (the answer held a NaN or an infinity).
TICK_STATUSES = tuple(STATUSES) + ("invalid",)


class _Raised:
    """Stands for the solution of a solve that raised (status ``error``, no answer)."""

    __slots__ = ("status", "x", "y", "z", "error")

    def __init__(self, error: str):
        self.status = "error"
        self.x = self.y = self.z = None
        self.error = error


def _describe(exc: BaseException) -> str:
    """``"Type: message"`` on one line (the harness's wording)."""
    from ..harness.guard import describe_exception

    return describe_exception(exc)


def _reset(backend: Backend) -> None:
    """Reset a backend after a failed tick; a reset that raises shows up at the next solve."""
    try:
        backend.reset()
    except Exception:  # noqa: BLE001
        log.debug("reset of %s raised", backend.name, exc_info=True)



@dataclass
class SimResult:
    """What :func:`simulate` returns.

    Attributes:
        log: One row per tick (columns in the module docstring).
        summary: Figures of the whole run (see :func:`summarize`).
        records: The dumped ticks' QPs (:class:`qpbench.formats.ProblemRecord`),
            when ``dump`` or ``every`` was given.
    """

    log: pd.DataFrame
    summary: dict
    records: list = field(default_factory=list)


#: Backends built with the scenario's ``[rnn]`` table (``rnn-tuned`` keeps its own).
SCENARIO_RNN_BACKENDS = ("rnn", "rnn-converged")


def resolve_backend(backend: str | Backend, scenario: Scenario, dt: float, profile: str = "default") -> Backend:
    """A backend instance for ``scenario``: by name, or the given instance checked.

    ``rnn`` and ``rnn-converged`` get the scenario's ``[rnn]`` settings; an
    online backend (``rnn``, ``rnn-tuned``) also the control period ``dt``. An instance with a ``dt`` of its own
    must match the loop's ``dt``.
    """
    if isinstance(backend, str):
        from ..backends import backend_class

        settings = {}
        if backend in SCENARIO_RNN_BACKENDS:
            settings.update(scenario.rnn)
        if backend_class(backend).online:
            settings.setdefault("dt", dt)
        return get_backend(backend, profile=profile, **settings)
    if not isinstance(backend, Backend):
        raise ParamError(f"expected a backend name or instance, got {type(backend).__name__}", key="backend")
    own_dt = getattr(backend, "dt", None)
    if own_dt is not None and abs(float(own_dt) - dt) > 1e-15:
        raise ParamError(f"the backend integrates dt = {own_dt} s per call but the loop's dt is {dt} s", key="dt")
    return backend


_post_kernel = None


def _get_post_kernel():
    global _post_kernel
    if _post_kernel is None:
        import numba

        _post_kernel = numba.njit(cache=True, nogil=True)(_post_py)
    return _post_kernel


#: ``mode`` argument of the post kernel: the tick's own answer applied, the
#: soft fallback's, or zero velocity.
_APPLIED, _FALLBACK, _ZERO = 0, 1, 2

# Layout of the kernel's constant float block ``cf``: tangent (2), surface (6), dt.
_CF_TANGENT, _CF_SURF, _CF_DT = 0, 2, 8
# Layout of the kernel's constant int block ``ci``: 12 column indices, then the
# obstacle columns' [start, end) ranges in the flat distance array.
_CI_COLS = 12


def _post_py(theta, v, ee, sensed, J, b0, dist, xd, y, z, data, k, ci, cf, t, mode, kp, kd, solve_time):  # pragma: no cover - compiled
    """Log tick ``k`` into ``data[k]`` and advance the plant ``theta += dt v``.

    Returns the noise-free contact force [N] (the law of
    :meth:`ContactSurface.force`, ``surf = [nx, ny, n . point, stiffness,
    damping, Fd]`` in ``cf``), and leaves the sensed end-effector position
    [m] in ``sensed[0:2]`` and its finite-difference velocity [m/s] in
    ``sensed[2:4]``. When ``v`` holds a NaN or an infinity nothing is written
    or advanced and -1.0 is returned (the caller falls back).
    """
    n = theta.shape[0]
    for i in range(n):
        if not math.isfinite(v[i]):
            return -1.0
    row = data[k]
    dt = cf[_CF_DT]
    c_theta = ci[0]
    c_v = ci[1]
    c_ee = ci[2]
    c_d = ci[3]
    c_force = ci[4]
    row[0] = t
    row[ci[5]] = 1.0 if mode == _FALLBACK else 0.0
    row[ci[6]] = 1.0 if mode == _ZERO else 0.0
    row[ci[7]] = solve_time
    if y.shape[0] == 2:
        row[ci[8]] = y[0]
        row[ci[8] + 1] = y[1]
    if z.shape[0] > 0:
        zmax = z[0]
        for i in range(1, z.shape[0]):
            if z[i] > zmax:
                zmax = z[i]
        row[ci[9]] = zmax
    row[ci[10]] = kp
    row[ci[11]] = kd
    # sense: velocity by finite difference, spring-damper force
    if k == 0:
        xd0 = 0.0
        xd1 = 0.0
    else:
        xd0 = (ee[0] - sensed[0]) / dt
        xd1 = (ee[1] - sensed[1]) / dt
    sensed[0] = ee[0]
    sensed[1] = ee[1]
    sensed[2] = xd0
    sensed[3] = xd1
    nx = cf[_CF_SURF]
    ny = cf[_CF_SURF + 1]
    delta = nx * ee[0] + ny * ee[1] - cf[_CF_SURF + 2]
    force = 0.0
    if delta > 0.0:
        force = cf[_CF_SURF + 3] * delta + cf[_CF_SURF + 4] * (nx * xd0 + ny * xd1)
        if force < 0.0:
            force = 0.0
    row[c_force] = force
    row[c_force + 1] = force - cf[_CF_SURF + 5]
    vsq = 0.0
    for i in range(n):
        row[c_theta + i] = theta[i]
        row[c_v + i] = v[i]
        vsq += v[i] * v[i]
        theta[i] += dt * v[i]
    row[c_ee] = ee[0]
    row[c_ee + 1] = ee[1]
    row[c_ee + 2] = xd[0]
    row[c_ee + 3] = xd[1]
    row[c_ee + 4] = cf[_CF_TANGENT] * (ee[0] - xd[0]) + cf[_CF_TANGENT + 1] * (ee[1] - xd[1])
    r0 = b0[0]
    r1 = b0[1]
    for j in range(n):
        r0 -= J[0, j] * v[j]
        r1 -= J[1, j] * v[j]
    ncol = (ci.shape[0] - _CI_COLS) // 2
    dmin = np.inf
    for c in range(ncol):
        m = np.inf
        for j in range(ci[_CI_COLS + c], ci[_CI_COLS + ncol + c]):
            if dist[j] < m:
                m = dist[j]
        row[c_d + c] = m
        if m < dmin:
            dmin = m
    row[c_d + ncol] = dmin if ncol > 0 else np.nan
    row[c_d + ncol + 1] = vsq
    row[c_d + ncol + 2] = math.sqrt(r0 * r0 + r1 * r1)
    return force


def _columns(controller: Controller) -> tuple[list[str], dict[str, int]]:
    n = controller.n
    cols = ["t"] + [f"theta_{i}" for i in range(n)] + [f"v_{i}" for i in range(n)]
    cols += ["ee_x", "ee_y", "xd_x", "xd_y", "tracking_error", "force", "force_error"]
    cols += [f"d_{a}_{o}" for a, o, _ in controller.obstacle_columns()]
    cols += ["d_min", "v_sq", "task_residual", "fallback", "zero_velocity", "solve_time_s", "y_0", "y_1", "z_max", "kp_hat", "kd_hat"]
    return cols, {c: i for i, c in enumerate(cols)}


def _post_constants(controller: Controller, surface, dt: float):
    """The tick log's columns and the post kernel's constant blocks ``(cols, cidx, ci, cf)``."""
    cols, cidx = _columns(controller)
    normal = controller.task.normal
    tangent = np.array([-normal[1], normal[0]])
    obstacle_cols = controller.obstacle_columns()
    n_pts = controller.n_obstacle_points
    n_obs = max(len(controller.obstacles), 1)
    # log column c is key point c // n_obs against one obstacle: its points in the flat distance array
    col_start = [(c // n_obs) * n_pts + s.start for c, (_, _, s) in enumerate(obstacle_cols)]
    col_end = [(c // n_obs) * n_pts + s.stop for c, (_, _, s) in enumerate(obstacle_cols)]
    names = ("theta_0", "v_0", "ee_x", None, "force", "fallback", "zero_velocity", "solve_time_s", "y_0", "z_max", "kp_hat", "kd_hat")
    ci = np.array(
        [cidx["d_min"] - len(obstacle_cols) if c is None else cidx[c] for c in names] + col_start + col_end, dtype=np.int64
    )
    cf = np.array([tangent[0], tangent[1], normal[0], normal[1], float(normal @ surface.point), surface.stiffness,
                   surface.damping, controller.task.desired_force, dt])
    return cols, cidx, ci, cf


def warm_post_kernel(controller: Controller, surface, dt: float, theta: np.ndarray, arrays) -> None:
    """Compile (or load) the post kernel for the argument types :func:`simulate` passes.

    ``arrays`` is a :meth:`Controller.build_arrays` result; ``theta`` is not changed.
    """
    cols, _, ci, cf = _post_constants(controller, surface, dt)
    post = _get_post_kernel()
    none = np.zeros(0)
    row = np.zeros((1, len(cols)))
    kp, kd = controller.kp, controller.kd
    # an applied answer with duals, and a fallback/zero-velocity tick without
    for y, z, mode in ((np.zeros(2), np.zeros(max(controller.n_rows, 1)), _APPLIED), (none, none, _ZERO)):
        post(theta.copy(), np.zeros(controller.n), arrays[8], np.zeros(4), arrays[4], arrays[5], arrays[9], arrays[10],
             y, z, row, 0, ci, cf, 0.0, mode, kp, kd, 0.0)


def simulate(
    scenario: Scenario | str | Path,
    backend: str | Backend,
    formulation: str = "paper",
    duration: float | None = None,
    dt: float | None = None,
    every: int | None = None,
    dump: str | Path | None = None,
    progress: bool = False,
    profile: str = "default",
    deadline: float | None = None,
    wall_budget_s: float | None = None,
) -> SimResult:
    """Run the closed loop of ``scenario`` with ``backend`` solving every tick.

    Args:
        scenario: A :class:`Scenario`, a shipped scenario's name or a file path.
        backend: A backend name (``"qpsolvers:daqp"``, ``"clarabel"``, ``"rnn"``) or instance.
        formulation: ``paper`` (hard task, eq. 11) or ``soft``.
        duration: Simulated time in [s] (default: the scenario's).
        dt: Control period in [s] (default: the scenario's).
        every: Keep every K-th tick's QP as a record (default 1 when dumping).
        dump: Folder to write the kept QPs to as a problem set
            (:func:`qpbench.formats.write_problem_set`).
        progress: Show a tqdm progress bar.
        profile: Settings profile of a backend given by name.
        deadline: Per-tick deadline in [s], ``None`` (the default) for none.
            Without one, every answer is applied whenever it arrives: the
            trajectory does not depend on how long a solve took (a compile, a
            loaded machine). With one, an answer that arrives later is
            dropped: status ``time_limit``, and the tick goes on as a tick
            without a solution (soft fallback, else zero velocity); the run then
            depends on the machine's speed. A solve is never interrupted.
        wall_budget_s: Wall-time budget of the loop in [s] (default: none).
            Checked between ticks: once spent, the run stops and the log
            holds the ticks simulated so far, the same rows an uncut run
            has (nothing simulated depends on how long a solve took, only
            how far the run gets); the summary says ``stopped_early``.

    Returns:
        The per-tick log, the summary and the kept records. Besides
        :func:`summarize`'s figures the summary holds ``deadline_s`` (the
        deadline or ``None``), ``deadline_misses`` (ticks whose solve calls
        took longer than the control period ``dt``: the ticks a 1/dt loop
        would not have kept up with; a time figure, like ``solve_time_*``),
        ``deadline_dropped`` (ticks whose answer was dropped for arriving
        after the deadline; ``None`` without a deadline), ``raised_ticks``,
        ``fallback_errors``, ``first_error`` and ``first_error_t``.
    """
    if not isinstance(scenario, Scenario):
        scenario = load_scenario(scenario)
    if formulation not in FORMULATIONS:
        raise ParamError(f"unknown formulation '{formulation}' (choose from {', '.join(FORMULATIONS)})", key="formulation")
    if every is not None and (not isinstance(every, (int, np.integer)) or every < 1):
        raise ParamError(f"must be an integer >= 1, got {every!r}", key="every")
    if deadline is not None and not (
        isinstance(deadline, (int, float, np.floating)) and not isinstance(deadline, bool)
        and math.isfinite(deadline) and deadline > 0
    ):
        raise ParamError(f"must be a positive number of seconds, got {deadline!r}", key="deadline")
    if dt is not None or duration is not None:
        scenario = scenario.with_overrides(dt=dt, duration=duration)
    dt = scenario.dt
    duration = scenario.duration
    ticks = int(round(duration / dt))
    keep_every = every if every is not None else (1 if dump is not None else None)
    # a late answer is dropped only past a deadline
    limit = math.inf if deadline is None else float(deadline)

    be = resolve_backend(backend, scenario, dt, profile)
    if wall_budget_s is not None and not (isinstance(wall_budget_s, (int, float, np.floating)) and wall_budget_s > 0):
        raise ParamError(f"must be a positive number of seconds, got {wall_budget_s!r}", key="wall_budget_s")
    online = bool(getattr(be, "online", False))
    be.reset()

    ctrl = scenario.make_controller()
    surface = scenario.make_surface()
    adaptive = scenario.make_adaptive()
    n = ctrl.n
    soft_primary = formulation == "soft"
    fd = ctrl.task.desired_force

    cols, cidx, ci, cf = _post_constants(ctrl, surface, dt)
    data = np.full((ticks, len(cols)), np.nan)
    c_force, c_ferr = cidx["force"], cidx["force_error"]

    theta = scenario.theta0.astype(float)
    v = np.zeros(n)
    zeros = np.zeros(n)  # zero velocity (never written; writable so numba sees one array type)
    kp, kd = ctrl.kp, ctrl.kd
    records = []
    statuses = []
    post = _get_post_kernel()
    build = ctrl.build_arrays
    make_problem = ctrl.make_problem
    solve = be.solve
    perf = time.perf_counter
    none = np.zeros(0)
    noisy = surface.noise_std > 0.0
    sensed = np.zeros(4)  # end-effector position [m] and velocity [m/s] of the tick
    f64 = np.dtype(np.float64)

    # compile (or load from the numba cache) every kernel before the clock starts
    from ..jit import warmup

    warmup()
    warm_post_kernel(ctrl, surface, dt, theta, build(theta, 0.0, kp, kd, soft_primary))

    bar = None
    if progress:
        from tqdm import tqdm

        bar = tqdm(total=ticks, unit="tick", desc=f"{scenario.name} {be.name}", mininterval=0.5)
    n_fallback = n_zero = n_dropped = 0
    n_raised = n_fallback_errors = 0
    first_error = first_error_t = None
    start = perf()
    stop_at = None if wall_budget_s is None else start + float(wall_budget_s)
    for k in range(ticks):
        if stop_at is not None and k and perf() >= stop_at:
            break  # budget spent: the log keeps the ticks done
        t = k * dt
        arrays = build(theta, t, kp, kd, soft_primary)
        problem = make_problem(arrays, soft_primary)
        if keep_every is not None and k % keep_every == 0:
            records.append((k, t, problem))
        t0 = perf()
        try:
            sol = solve(problem, v)
        except Exception as exc:  # noqa: BLE001 - a backend's exception is the tick's status
            sol = _Raised(_describe(exc))
        solve_s = perf() - t0
        status = sol.status
        x = sol.x
        force = -1.0
        if x is not None and (online or status == "optimal") and solve_s <= limit:
            if type(x) is not np.ndarray or x.dtype != f64:
                x = np.asarray(x, dtype=np.float64)
            y = sol.y
            z = sol.z
            # -1.0 when x is not finite: nothing logged, the plant not moved
            force = post(theta, x, arrays[8], sensed, arrays[4], arrays[5], arrays[9], arrays[10],
                         none if y is None else y, none if z is None else z,
                         data, k, ci, cf, t, _APPLIED, kp, kd, solve_s)
            if force >= 0.0:
                v = x
            else:
                status = "invalid"
        if force < 0.0:
            # the tick's own answer is not applied: say why
            if type(sol) is _Raised:
                n_raised += 1
                if first_error is None:
                    first_error, first_error_t = sol.error, t
                _reset(be)  # its state can no longer be trusted
            elif status == "invalid":
                _reset(be)
            elif solve_s > limit:
                status = "time_limit"  # arrived after the deadline: dropped
                n_dropped += 1
            elif status == "error" and first_error is None and getattr(sol, "error", None):
                first_error, first_error_t = str(sol.error), t  # reported by the backend, not raised
            # no usable answer: the soft formulation's (same backend), else zero velocity
            mode, x, z = _ZERO, zeros, none
            if not online and not soft_primary:
                t1 = perf()
                try:
                    fb = solve(make_problem(build(theta, t, kp, kd, True), True), v)
                except Exception as exc:  # noqa: BLE001 - a failed fallback: zero velocity
                    fb = _Raised(_describe(exc))
                    n_fallback_errors += 1
                    if first_error is None:
                        first_error, first_error_t = f"fallback: {fb.error}", t
                    _reset(be)
                if fb.status == "optimal" and fb.x is not None and perf() - t1 <= limit:
                    mode, x = _FALLBACK, np.asarray(fb.x, dtype=np.float64)
                    z = none if fb.z is None else fb.z
            force = post(theta, x, arrays[8], sensed, arrays[4], arrays[5], arrays[9], arrays[10], none, z,
                         data, k, ci, cf, t, mode, kp, kd, perf() - t0)
            if force < 0.0:  # the fallback's answer was not finite either
                mode, x = _ZERO, zeros
                force = post(theta, x, arrays[8], sensed, arrays[4], arrays[5], arrays[9], arrays[10], none, none,
                             data, k, ci, cf, t, mode, kp, kd, perf() - t0)
            if mode == _FALLBACK:
                n_fallback += 1
            else:
                n_zero += 1
            v = x if mode == _FALLBACK else zeros.copy()
        statuses.append(status)
        if noisy:
            force += surface.noise()
            data[k, c_force] = force
            data[k, c_ferr] = force - fd
        if adaptive is not None:
            xd = arrays[10]
            kp, kd = adaptive.update(dt, sensed, xd, sensed[2:], xd[2:], force)
        if bar is not None and (k + 1) % 500 == 0:
            bar.update(500)
    wall = perf() - start
    if bar is not None:
        bar.update(ticks - bar.n)
        bar.close()

    done = len(statuses)
    codes = {s: i for i, s in enumerate(TICK_STATUSES)}
    status_codes = np.fromiter((codes.get(s, codes["error"]) for s in statuses), dtype=np.int8, count=done)
    misses = int(np.count_nonzero(data[:done, cidx["solve_time_s"]] > dt))
    frame = pd.DataFrame(data[:done], columns=cols)
    frame["fallback"] = frame["fallback"].astype(bool)
    frame["zero_velocity"] = frame["zero_velocity"].astype(bool)
    frame.insert(cols.index("fallback"), "status", pd.Categorical.from_codes(status_codes, categories=list(TICK_STATUSES)))
    summary = summarize(frame, scenario, ctrl, be.name, formulation, wall, run_info=dict(
        deadline_s=deadline if deadline is None else float(deadline), deadline_misses=misses,
        deadline_dropped=None if deadline is None else n_dropped,
        raised_ticks=n_raised, fallback_errors=n_fallback_errors,
        first_error=first_error, first_error_t=first_error_t, wall_budget_s=wall_budget_s,
        stopped_early=done < ticks))
    recs = []
    if keep_every is not None:
        from ..formats import ProblemRecord

        recs = [
            ProblemRecord(problem=p, name=f"{scenario.name}_{formulation}_{k:06d}", scenario=scenario.name, tick=k, t=t, formulation=formulation)
            for k, t, p in records
        ]
    if dump is not None:
        write_dump(dump, recs, scenario, be.name, formulation, keep_every, duration, dt)
    return SimResult(frame, summary, recs)


def write_dump(folder, records, scenario: Scenario, backend_name: str, formulation: str, every, duration, dt) -> Path:
    """Write the kept ticks' QPs as a problem set; the manifest holds the scenario file's full text."""
    from ..formats import write_problem_set

    generator = {
        "name": "qpbench simulate",
        "scenario": scenario.name,
        "backend": backend_name,
        "formulation": formulation,
        "every": every,
        "duration": duration,
        "dt": dt,
    }
    extra = {
        "scenario_file": scenario.path.name if scenario.path is not None else None,
        "scenario_toml": scenario.source,
        "ticks_per_record": every,
    }
    if scenario.overrides:  # values set over the file's (the TOML above is the file as it is)
        extra["scenario_overrides"] = _jsonable(scenario.overrides)
    return write_problem_set(folder, records, generator=generator, extra=extra)


def _jsonable(overrides: dict) -> dict:
    return {k: (v.tolist() if isinstance(v, np.ndarray) else v) for k, v in overrides.items()}


def _none(x):
    x = float(x)
    return None if not math.isfinite(x) else x


def _intervals(mask: np.ndarray, t: np.ndarray, dt: float) -> list[list[float]]:
    """Runs of consecutive True ticks as ``[first t, last t]`` pairs [s]."""
    if not mask.any():
        return []
    idx = np.flatnonzero(mask)
    breaks = np.flatnonzero(np.diff(idx) > 1)
    starts = np.r_[idx[0], idx[breaks + 1]]
    ends = np.r_[idx[breaks], idx[-1]]
    return [[round(float(t[s]), 9), round(float(t[e]), 9)] for s, e in zip(starts, ends)]


def summarize(frame: pd.DataFrame, scenario: Scenario, controller: Controller, backend: str, formulation: str,
              wall_time_s: float, run_info: dict | None = None) -> dict:
    """Figures of a run (JSON-able; ``None`` where a figure does not exist) and its verdict.

    Statuses are those of the QP of the run's formulation at each tick:

    - ``infeasible_ticks``: ticks the backend declared infeasible (status
      ``primal_infeasible`` or ``dual_infeasible``), plus ticks with status
      ``not_solved``: a backend that cannot classify a failure (qpsolvers'
      route to DAQP, quadprog or HiGHS keeps only ``found=False``) reports
      that, and on the controller's QPs such a failure is the infeasible
      start. ``first_infeasible_t``, ``last_infeasible_t`` and
      ``infeasible_intervals`` (runs as ``[first t, last t]``) are of these
      ticks. A backend that stops on a budget (``max_iter``, ``time_limit``)
      or fails (``error``) is not counted here.
    - ``non_optimal_ticks``: ticks whose QP was not solved to ``optimal``,
      whatever the reason (a superset of the above; for the online ``rnn``
      nearly every tick, since its state is applied after one tick of
      integration, not at convergence).
    - ``status_counts``: the breakdown by status; ``error_ticks``,
      ``time_limit_ticks`` and ``invalid_ticks`` count the guarded failures
      (an exception or an ``error`` status, an answer dropped past the
      deadline or a budget, a non-finite answer). :func:`simulate` adds, in
      ``run_info``, ``deadline_s`` (the per-tick deadline [s], ``None``:
      none, every answer applied), ``deadline_misses`` (ticks whose solve
      calls took longer than ``dt``: the loop did not keep up with its rate
      there), ``deadline_dropped`` (answers dropped past the deadline;
      ``None`` without one), ``raised_ticks`` (ticks whose
      solve raised), ``fallback_errors`` (fallback solves that raised),
      ``first_error`` (``"Type: message"`` of the first exception, else the
      first error a backend reported; ``None`` when none), ``first_error_t``
      [s], ``wall_budget_s`` (the loop's wall-time budget [s], ``None`` when
      none) and ``stopped_early`` (the budget ran out before ``duration``).
    - ``duration`` is the simulated time asked for [s], ``simulated_s`` the
      time simulated (``ticks * dt``, less than ``duration`` when stopped
      early); ``real_time_factor`` is ``simulated_s / wall_time_s``.
    - ``verdict`` (``ok``, ``diverged``, ``limits``, ``unsafe``, ``failed``)
      and ``verdict_reasons`` (plain text, ``"; "`` between reasons): see
      :func:`qpbench.sim.verdict.judge`, with the scenario's ``[verdict]``
      thresholds.

    ``scenario_overrides`` holds the values set over the scenario file's
    (``qpbench simulate --set``), empty when none. ``fallback_ticks``
    applied the soft formulation's answer,
    ``zero_velocity_ticks`` commanded zero. Errors "after 2 s" use the ticks
    with ``t >= 2`` s; limit violations count ticks with an angle or a
    commanded speed beyond its limit by more than :data:`VIOLATION_TOL`;
    ``obstacle_active_intervals`` lists, per (key point, obstacle), when it
    was within :data:`ACTIVE_MARGIN` of ``d_safe``.
    """
    t = frame["t"].to_numpy()
    dt = scenario.dt
    ticks = len(frame)
    status = frame["status"]
    infeasible = status.isin(INFEASIBLE_STATUSES).to_numpy()
    non_optimal = (status != "optimal").to_numpy()
    after = t >= SETTLE_TIME - 1e-12
    n = controller.n
    theta = frame[[f"theta_{i}" for i in range(n)]].to_numpy()
    v = frame[[f"v_{i}" for i in range(n)]].to_numpy()
    lim = controller.limits
    tol = VIOLATION_TOL
    angle_viol = ((theta < lim.theta_min - tol) | (theta > lim.theta_max + tol)).any(axis=1)
    speed_viol = ((v < lim.v_min - tol) | (v > lim.v_max + tol)).any(axis=1)

    def rms(x):
        return _none(np.sqrt(np.mean(np.square(x)))) if x.size else None

    def amax(x):
        return _none(np.max(np.abs(x))) if x.size else None

    te = frame["tracking_error"].to_numpy()
    fe = frame["force_error"].to_numpy()
    out = {
        "scenario": scenario.name,
        "scenario_overrides": _jsonable(scenario.overrides),
        "backend": backend,
        "formulation": formulation,
        "dt": dt,
        "duration": scenario.duration,
        "ticks": ticks,
        "simulated_s": ticks * dt,
        "infeasible_ticks": int(infeasible.sum()),
        "non_optimal_ticks": int(non_optimal.sum()),
        "fallback_ticks": int(frame["fallback"].sum()),
        "zero_velocity_ticks": int(frame["zero_velocity"].sum()),
        "first_infeasible_t": _none(t[infeasible][0]) if infeasible.any() else None,
        "last_infeasible_t": _none(t[infeasible][-1]) if infeasible.any() else None,
        "infeasible_intervals": _intervals(infeasible, t, dt),
        "status_counts": {str(k): int(v) for k, v in frame["status"].value_counts().items() if v},
        "error_ticks": int((status == "error").sum()),
        "time_limit_ticks": int((status == "time_limit").sum()),
        "invalid_ticks": int((status == "invalid").sum()),
        "tracking_rms_after_2s": rms(te[after]),
        "tracking_max_after_2s": amax(te[after]),
        "force_error_rms_after_2s": rms(fe[after]),
        "force_error_max_after_2s": amax(fe[after]),
        "force_final": _none(frame["force"].iloc[-1]) if ticks else None,
        "min_obstacle_distance": None,
        "min_obstacle_distance_key_point": None,
        "min_obstacle_distance_obstacle": None,
        "min_obstacle_distance_t": None,
        "d_safe": controller.d_safe,
        "joint_limit_violations": int(angle_viol.sum()),
        "joint_velocity_limit_violations": int(speed_viol.sum()),
        "max_abs_theta": _none(np.max(np.abs(theta))) if ticks else None,
        "max_abs_v": _none(np.max(np.abs(v))) if ticks else None,
        "v_sq_max": _none(frame["v_sq"].max()),
        "task_residual_max_after_2s": amax(frame["task_residual"].to_numpy()[after]),
        "kp_hat_final": _none(frame["kp_hat"].iloc[-1]) if ticks else None,
        "kd_hat_final": _none(frame["kd_hat"].iloc[-1]) if ticks else None,
        "solve_time_median_s": _none(frame["solve_time_s"].median()),
        "solve_time_p99_s": _none(frame["solve_time_s"].quantile(0.99)),
        "solve_time_max_s": _none(frame["solve_time_s"].max()),
        "wall_time_s": float(wall_time_s),
        "real_time_factor": _none(ticks * dt / wall_time_s) if wall_time_s > 0 else None,
        "wall_budget_s": None,
        "stopped_early": False,
    }
    dcols = [(a, o) for a, o, _ in controller.obstacle_columns()]
    if dcols:
        D = frame[[f"d_{a}_{o}" for a, o in dcols]].to_numpy()
        flat = int(np.argmin(D))
        k, c = divmod(flat, D.shape[1])
        out["min_obstacle_distance"] = _none(D[k, c])
        out["min_obstacle_distance_key_point"] = dcols[c][0]
        out["min_obstacle_distance_obstacle"] = dcols[c][1]
        out["min_obstacle_distance_t"] = _none(t[k])
        # when each (key point, obstacle) pair is at its safety distance (row about active)
        near = D <= controller.d_safe + ACTIVE_MARGIN
        out["obstacle_active_intervals"] = {
            f"{a}/{o}": _intervals(near[:, c], t, dt)[:MAX_INTERVALS] for c, (a, o) in enumerate(dcols) if near[:, c].any()
        }
    out.update(run_info or {})
    verdict = judge(frame, scenario.verdict, d_safe=controller.d_safe, limits=lim, obstacle_columns=dcols, summary=out)
    out["verdict"] = verdict.verdict
    out["verdict_reasons"] = verdict.text
    return out
