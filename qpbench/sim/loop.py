"""Closed-loop simulation: the controller's QP solved every tick by a backend, a kinematic plant.

One tick at ``t_k = k dt``:

1. sense: end-effector position ``x_k``, velocity ``(x_k - x_{k-1}) / dt`` (0 at k = 0) and the
   contact force ``F_k`` of the environment's spring-damper (plus the scenario's sensor noise);
2. build the tick's QP (eq. 11, the chosen formulation) with the current ``Kp_hat, Kd_hat``;
3. solve it, warm-started from the previous command. A tick without a usable answer (no
   solution, a non-finite ``x``, an exception: ``error``, an answer later than ``deadline``:
   ``time_limit``) solves the ``soft`` formulation with the same backend (fallback), else
   commands zero velocity; an online backend (the RNN) is its own controller: its ``x`` is
   applied whatever its status. After a failure the backend is reset. A solve is never
   interrupted;
4. adaptive scenarios: one Euler step of the law of section 4.4 from ``F_k``;
5. plant: ``theta_{k+1} = theta_k + dt v_k`` (steps 1 and 5 and the log row:
   :mod:`qpbench.sim.tick_kernel`).

The body's clearance (``d_body_*``) is computed after the loop for every tick at once.
"""

from __future__ import annotations

import logging
import math
import time
from collections import namedtuple
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
import pandas as pd

from ..backends import Backend, backend_class, get_backend
from ..control.controller import check_formulation
from ..exceptions import ParamError, positive_count, positive_seconds
from ..robot.body import body_clearance
from ..statuses import FAILURE_STATUSES, classify, describe_exception
from . import log as tick_log
from .scenario import Scenario, load_scenario
from .summary import jsonable, summarize
from .tick_kernel import APPLIED, FALLBACK, ZERO, get_post_kernel, post_constants, warm_post_kernel

log = logging.getLogger(__name__)
#: One line per solve, shown by ``qpbench -vv`` (the CLI sets its level).
solve_log = logging.getLogger("qpbench.solves")


#: Stands for the solution of a solve that raised (status ``error``, no answer).
_Raised = namedtuple(
    "_Raised", "error status x y z solver_time_s", defaults=("error",) + (None,) * 4
)


def resolve_backend(
    backend: str | Backend, scenario: Scenario, profile: str = "default"
) -> Backend:
    """A backend instance for ``scenario``: by name, or the given instance checked.

    A backend class whose ``scenario_table`` names a table of the scenario (the ``rnn``
    backends) gets that table's settings; an online backend also the control period ``dt``
    [s], which an instance's own ``dt`` must match.
    """
    dt = scenario.dt
    if isinstance(backend, str):
        cls = backend_class(backend)
        settings = {}
        if cls.scenario_table:
            settings.update(getattr(scenario, cls.scenario_table))
        if cls.online:
            settings.setdefault("dt", dt)
        return get_backend(backend, profile=profile, **settings)
    if not isinstance(backend, Backend):
        raise ParamError(
            f"expected a backend name or instance, got {type(backend).__name__}", key="backend"
        )
    own_dt = getattr(backend, "dt", None)
    if own_dt is not None and abs(float(own_dt) - dt) > 1e-15:
        raise ParamError(
            f"the backend integrates dt = {own_dt} s per call but the loop's dt is {dt} s", key="dt"
        )
    return backend


def _reset(backend: Backend) -> None:
    """Reset a backend after a failed tick; a reset that raises shows up at the next solve."""
    try:
        backend.reset()
    except Exception:  # noqa: BLE001
        log.debug("reset of %s raised", backend.name, exc_info=True)


@dataclass
class SimResult:
    """The tick log, the summary and the kept ticks' QPs (:class:`qpbench.formats.ProblemRecord`)."""

    log: pd.DataFrame
    summary: dict
    records: list = field(default_factory=list)


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

    ``scenario`` is a :class:`Scenario`, a shipped scenario's name or a file; ``backend`` a name
    or an instance; ``formulation`` ``paper`` (eq. 11) or ``soft``; ``duration``, ``dt`` [s]
    override the scenario's. ``every`` keeps every K-th tick's QP (default 1 with ``dump``, a
    folder the kept QPs are written to as a problem set). ``deadline`` [s]: a later answer is
    dropped (``time_limit``). ``wall_budget_s`` [s]: checked between ticks; once spent the run
    stops with the ticks done (``stopped_early``).
    """
    if not isinstance(scenario, Scenario):
        scenario = load_scenario(scenario)
    check_formulation(formulation)
    if every is not None:
        positive_count(every, "every")
    for key, value in (("deadline", deadline), ("wall_budget_s", wall_budget_s)):
        if isinstance(value, str):  # float() would read it, but the API takes numbers
            raise ParamError(f"expected a positive number of seconds, got {value!r}", key=key)
        if value is not None:
            positive_seconds(value, key)
    if dt is not None or duration is not None:
        scenario = scenario.with_overrides(dt=dt, duration=duration)
    keep_every = every if every is not None else (1 if dump is not None else None)
    be = resolve_backend(backend, scenario, profile)
    run = _Run(scenario, be, formulation, keep_every, deadline)
    run.warm()
    run.loop(progress, wall_budget_s)
    result = run.result(wall_budget_s)
    if dump is not None:
        _write_dump(dump, result.records, scenario, be.name, formulation, keep_every)
    return result


def _write_dump(folder, records, scenario: Scenario, backend_name, formulation, every) -> None:
    """Write the kept ticks' QPs as a problem set; the manifest holds the scenario file's text."""
    from ..formats import write_problem_set

    generator = {
        "name": "qpbench simulate",
        "scenario": scenario.name,
        "backend": backend_name,
        "formulation": formulation,
        "every": every,
        "duration": scenario.duration,
        "dt": scenario.dt,
    }
    extra = {
        "scenario_file": scenario.path.name if scenario.path is not None else None,
        "scenario_toml": scenario.source,
        "ticks_per_record": every,
    }
    if scenario.overrides:  # values set over the file's (the TOML above is the file as it is)
        extra["scenario_overrides"] = jsonable(scenario.overrides)
    write_problem_set(folder, records, generator=generator, extra=extra)


class _Run:
    """One closed-loop run: set up, warm the kernels, loop over the ticks, tabulate."""

    def __init__(
        self,
        scenario: Scenario,
        backend: Backend,
        formulation: str,
        keep_every: int | None,
        deadline: float | None,
    ):
        self.scenario, self.be = scenario, backend
        self.formulation, self.keep_every = formulation, keep_every
        self.deadline = deadline
        # a late answer is dropped only past a deadline
        self.limit = math.inf if deadline is None else float(deadline)
        self.dt = dt = scenario.dt
        self.ticks = int(round(scenario.duration / dt))
        self.online = bool(getattr(backend, "online", False))
        backend.reset()
        self.ctrl = ctrl = scenario.make_controller()
        self.surface = scenario.make_surface()
        self.adaptive = scenario.make_adaptive()
        self.soft_primary = formulation == "soft"
        self.cols, self.cidx, self.ci, self.cf = post_constants(ctrl, self.surface, dt)
        self.post = get_post_kernel()
        self.data = np.full((self.ticks, len(self.cols)), np.nan)
        self.theta = scenario.theta0.astype(float)
        self.sensed = np.zeros(4)  # end-effector position [m] and velocity [m/s] of the tick
        # zero velocity (never written; writable so numba sees one array type)
        self.zeros = np.zeros(ctrl.n)
        self.none = np.zeros(0)
        self.records: list = []
        self.statuses: list[str] = []
        self.n_dropped = self.n_raised = self.n_fallback_errors = 0
        self.first_error = self.first_error_t = None

    def warm(self) -> None:
        """Compile (or load) the loop's own kernels before the clock starts; the backend's are
        the caller's (:func:`qpbench.jit.warmup`)."""
        ctrl = self.ctrl
        arrays = ctrl.build_arrays(self.theta, 0.0, ctrl.kp, ctrl.kd, self.soft_primary)
        warm_post_kernel(ctrl, self.surface, self.dt, self.theta, arrays)

    def loop(self, progress: bool, wall_budget_s: float | None) -> None:
        """The ticks (module docstring, steps 1-5), until ``duration`` or the wall-time budget."""
        ctrl, be, dt, ticks, limit = self.ctrl, self.be, self.dt, self.ticks, self.limit
        data, sensed, adaptive = self.data, self.sensed, self.adaptive
        theta, records, statuses = self.theta, self.records, self.statuses
        c_force = self.cidx[tick_log.FORCE]
        online, soft_primary, keep_every = self.online, self.soft_primary, self.keep_every
        build, make_problem = ctrl.build_arrays, ctrl.make_problem
        solve, perf, surface = be.solve, time.perf_counter, self.surface
        noisy, fd, f64 = surface.noise_std > 0.0, ctrl.task.desired_force, np.dtype(np.float64)
        kp, kd, v, c_own = ctrl.kp, ctrl.kd, np.zeros(ctrl.n), self.cidx[tick_log.SOLVER_TIME]
        run_name = f"{self.scenario.name} {be.name}"
        verbose = solve_log.isEnabledFor(logging.DEBUG)  # checked once: the tick loop stays lean
        bar = None
        if progress:
            from tqdm import tqdm

            bar = tqdm(total=ticks, unit="tick", desc=run_name, mininterval=0.5)
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
                sol = _Raised(describe_exception(exc))
            solve_s = perf() - t0
            status, x = sol.status, sol.x
            data[k, c_own] = getattr(sol, "solver_time_s", None)  # its own time [s]; None: NaN
            force = -1.0
            # the fast path: an answer classify() would call optimal (finite x, in time), or an online one
            if x is not None and (online or status == "optimal") and solve_s <= limit:
                if type(x) is not np.ndarray or x.dtype != f64:
                    x = np.asarray(x, dtype=np.float64)
                # -1.0 when x is not finite: nothing logged, the plant not moved
                force = self._post(k, t, arrays, x, sol.y, sol.z, APPLIED, kp, kd, solve_s)
                if force >= 0.0:
                    v = x
            if force < 0.0:
                status, v, force = self._without_answer(k, t, sol, solve_s, t0, arrays, kp, kd, v)
            statuses.append(status)
            if verbose:
                solve_log.debug(
                    "%s tick %d (t = %.3f s): %s in %.1f µs", run_name, k, t, status, solve_s * 1e6
                )
            if noisy:
                force += surface.noise()
                data[k, c_force], data[k, c_force + 1] = force, force - fd  # force, force_error
            if adaptive is not None:
                xd = arrays.xd
                kp, kd = adaptive.update(dt, sensed, xd, sensed[2:], xd[2:], force)
            if bar is not None and (k + 1) % 500 == 0:
                bar.update(500)
        self.wall = perf() - start
        if bar is not None:  # to the ticks simulated
            bar.update(bar.total - bar.n)
            bar.close()

    def _without_answer(self, k, t, sol, solve_s, t0, arrays, kp, kd, v):
        """A tick whose own answer is not applied: classify it (:func:`~qpbench.statuses.classify`),
        then apply the soft formulation's answer (same backend), else zero velocity.

        Returns the tick's status, the velocity applied [rad/s] and the noise-free force [N].
        """
        be, limit, none, zeros = self.be, self.limit, self.none, self.zeros
        if type(sol) is _Raised:
            status, error = "error", sol.error
            self.n_raised += 1
        else:
            status, error = classify(sol, solve_s, limit)
            if status == "time_limit" and solve_s > limit:
                self.n_dropped += 1  # arrived after the deadline: dropped
        if status == "error" and error and self.first_error is None:
            self.first_error, self.first_error_t = str(error), t
        if status in FAILURE_STATUSES and status != "time_limit":
            _reset(be)  # its state can no longer be trusted
        mode, x, z = ZERO, zeros, none
        if not self.online and not self.soft_primary:
            ctrl = self.ctrl
            t1 = time.perf_counter()
            try:
                fb = be.solve(
                    ctrl.make_problem(ctrl.build_arrays(self.theta, t, kp, kd, True), True), v
                )
                fb_status = classify(fb, time.perf_counter() - t1, limit)[0]
            except Exception as exc:  # noqa: BLE001 - a failed fallback: zero velocity
                fb, fb_status = _Raised(describe_exception(exc)), "error"
                self.n_fallback_errors += 1
                if self.first_error is None:
                    self.first_error, self.first_error_t = f"fallback: {fb.error}", t
                _reset(be)
            if (own := getattr(fb, "solver_time_s", None)) is not None:
                c = self.cidx[tick_log.SOLVER_TIME]  # the fallback's own time adds to the tick's
                self.data[k, c] = np.nansum([self.data[k, c], own])
            if fb_status == "optimal":
                mode, x = FALLBACK, np.asarray(fb.x, dtype=np.float64)
                z = none if fb.z is None else fb.z
        force = self._post(k, t, arrays, x, None, z, mode, kp, kd, time.perf_counter() - t0)
        if force < 0.0:  # the fallback's answer was not finite either
            mode, x = ZERO, zeros
            force = self._post(k, t, arrays, x, None, None, mode, kp, kd, time.perf_counter() - t0)
        return status, (x if mode == FALLBACK else zeros.copy()), force

    def _post(self, k, t, arrays, x, y, z, mode, kp, kd, solve_s) -> float:
        """The tick kernel (:mod:`qpbench.sim.tick_kernel`) on tick ``k`` with velocity ``x``
        [rad/s], duals ``y, z`` (``None``: none) and the tick's solve time ``solve_s`` [s]."""
        a, none = arrays, self.none
        return self.post(
            self.theta,
            x,
            a.ee,
            self.sensed,
            a.J,
            a.b0,
            a.dist,
            a.xd,
            none if y is None else y,
            none if z is None else z,
            self.data,
            k,
            self.ci,
            self.cf,
            t,
            mode,
            kp,
            kd,
            solve_s,
        )  # arguments spelled out: no tuples built on the per-tick path

    def result(self, wall_budget_s: float | None) -> SimResult:
        """The tick log, the summary and the kept records of the ticks simulated."""
        scenario, deadline, ctrl = self.scenario, self.deadline, self.ctrl
        done = len(self.statuses)
        frame = tick_log.to_frame(self.data, self.cols, self.statuses)
        body = body_clearance(
            ctrl.arm,
            frame[tick_log.theta_columns(ctrl.n)].to_numpy(),
            frame[tick_log.T].to_numpy(),
            ctrl.obstacles,
            ctrl.key_points.radius,
            ctrl.exempt,
        )
        tick_log.add_body_columns(frame, body, [o.name for o in ctrl.obstacles])
        run_info = dict(
            deadline_s=deadline if deadline is None else float(deadline),
            deadline_dropped=None if deadline is None else self.n_dropped,
            raised_ticks=self.n_raised,
            fallback_errors=self.n_fallback_errors,
            first_error=self.first_error,
            first_error_t=self.first_error_t,
            wall_budget_s=wall_budget_s,
            stopped_early=done < self.ticks,
        )
        summary = summarize(
            frame, scenario, ctrl, self.be.name, self.formulation, self.wall, run_info=run_info
        )
        from ..formats import ProblemRecord

        name = f"{scenario.name}_{self.formulation}"
        recs = [
            ProblemRecord(
                problem=p,
                name=f"{name}_{k:06d}",
                scenario=scenario.name,
                tick=k,
                t=t,
                formulation=self.formulation,
            )
            for k, t, p in self.records  # none unless keep_every
        ]
        return SimResult(frame, summary, recs)
