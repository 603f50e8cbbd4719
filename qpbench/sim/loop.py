"""Closed-loop simulation: the controller's QP solved every tick by a backend, a kinematic plant.

One tick at ``t_k = k dt``:

1. sense: end-effector position ``x_k``, velocity ``(x_k - x_{k-1}) / dt`` (0 at k = 0) and the
   contact force ``F_k`` of the environment's spring-damper (plus the scenario's sensor noise);
2. build the tick's QP (eq. 11, the chosen formulation) with the current ``Kp_hat, Kd_hat``;
3. solve it, warm-started from the previous command. A tick without a usable answer (no
   solution, a non-finite ``x``, an exception: ``error``, an answer later than ``deadline``:
   ``time_limit``) solves the ``soft`` formulation (fallback) with a second instance of the
   backend, as a controller keeps one solver per QP it solves (the same instance when the
   caller gives one), else commands zero velocity; an online backend (the RNN) is its own
   controller: its ``x`` is applied whatever its status. After a failure the instance that
   failed is reset. A solve is never interrupted;
4. adaptive scenarios: one Euler step of the law of section 4.4 from ``F_k``;
5. plant: ``theta_{k+1} = theta_k + dt v_k`` (steps 1 and 5 and the log row:
   :mod:`qpbench.sim.tick_kernel`).

Two engines run these ticks on the same model of the run and give the same trajectory:
``compiled`` (:mod:`qpbench.engine.compiled`) and ``python`` (this module's loop); their
clocks: docs/methodology.md, "Closed-loop engines and their clocks".

The body's clearance (``d_body_*``) is computed after the loop for every tick at once.
"""

from __future__ import annotations

import gc
import logging
import time
from collections import namedtuple
from dataclasses import dataclass, field, replace
from functools import partial
from pathlib import Path

import numpy as np
import pandas as pd

from ..backends import Backend, backend_class, get_backend
from ..backends.base import timed_call
from ..control.adaptive import compiled_law
from ..control.controller import check_formulation
from ..engine.model import run_model
from ..exceptions import ParamError, check_choice, positive_count, positive_seconds
from ..native import entry_point
from ..robot.body import body_clearance
from ..statuses import FAILURE_STATUSES, classify, describe_exception
from . import log as tick_log
from .log import STATUS_CODES
from .scenario import Scenario, load_scenario
from .summary import jsonable, summarize
from .tick_kernel import APPLIED, FALLBACK, ZERO, get_post_kernel, log_columns

#: The engines a closed loop runs on (``compiled``: where the backend has a compiled solve).
ENGINES = ("compiled", "python")
#: Ticks of the discarded warm-up run before every timed run (one-off costs out of the clock).
WARMUP_TICKS = 3

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
        settings = dict(getattr(scenario, cls.scenario_table)) if cls.scenario_table else {}
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
    engine: str = "compiled",
    warmup_ticks: int = WARMUP_TICKS,
    p99_interval: bool = True,
) -> SimResult:
    """Run the closed loop of ``scenario`` with ``backend`` solving every tick.

    ``scenario`` is a :class:`Scenario`, a shipped scenario's name or a file; ``backend`` a name
    or an instance; ``formulation`` ``paper`` (eq. 11) or ``soft``; ``duration``, ``dt`` [s]
    override the scenario's. ``every`` keeps every K-th tick's QP (default 1 with ``dump``, a
    folder the kept QPs are written to as a problem set). ``deadline`` [s]: a later answer is
    dropped (``time_limit``). ``wall_budget_s`` [s]: checked between ticks; once spent the run
    stops with the ticks done (``stopped_early``). ``engine``: ``compiled`` where the backend
    has a compiled solve (else, and with ``python``, the Python loop; the summary's ``engine``
    says which ran). ``warmup_ticks``: a discarded run of that many ticks first, with a backend
    of its own, so one-off costs stay off the clock (a backend given by name only: an
    instance's state is the caller's). ``p99_interval``: the summary bounds the p99 of the
    ranking time (a bootstrap; a sweep's instances go without).
    """
    check_choice(engine, ENGINES, "engine", "engine")
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
    if warmup_ticks and isinstance(backend, str):  # an instance's own state is the caller's
        warm = resolve_backend(backend, scenario, profile)
        # the discarded warm-up is not judged: the thresholds set over the file's are not its
        short = replace(scenario, overrides={}).with_overrides(duration=warmup_ticks * scenario.dt)
        spare = resolve_backend(backend, scenario, profile)
        _Run(short, warm, formulation, None, deadline, engine, spare).run(False, None)
    be = resolve_backend(backend, scenario, profile)
    be.reset()
    fallback = resolve_backend(backend, scenario, profile) if isinstance(backend, str) else be
    run = _Run(scenario, be, formulation, keep_every, deadline, engine, fallback)
    run.run(progress, wall_budget_s)
    result = run.result(wall_budget_s, p99_interval)
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
    """One closed-loop run: the model of the run, the log, the loop on one engine, the result."""

    #: Ticks per call of the engine between progress updates.
    CHUNK = 500

    def __init__(
        self,
        scenario: Scenario,
        backend: Backend,
        formulation: str,
        keep_every: int | None,
        deadline: float | None,
        engine: str,
        fallback: Backend,
    ):
        from ..engine import compiled

        self.scenario, self.be, self.fb_be = scenario, backend, fallback
        self.formulation, self.keep_every = formulation, keep_every
        self.deadline = deadline
        self.soft = formulation == "soft"
        self.online = bool(getattr(backend, "online", False))
        self.ctrl = ctrl = scenario.make_controller()
        self.model = model = run_model(scenario, ctrl, self.soft, self.online, deadline)
        self.ticks = model.ticks
        self.names, self.cols = log_columns(ctrl)
        self.data = np.full((self.ticks, len(self.names)), np.nan)
        self.codes = np.zeros(self.ticks, dtype=np.int8)
        self.state = compiled.loop_state(model, ctrl.n_rows)
        self.records: list = []
        self.n_raised = 0
        self.first_error = self.first_error_t = None
        why = "python engine asked for" if engine == "python" else None
        if why is None and keep_every is not None:
            why = "the tick QPs are kept (every, dump)"
        if why is None:
            why = compiled.unsupported_reason(backend, formulation)
        self.engine, self.engine_note = ("python", why) if why else ("compiled", None)
        self.wall = 0.0
        self._post_kernel = None

    def run(self, progress: bool, wall_budget_s: float | None) -> None:
        """The ticks, in chunks between progress updates, until ``duration`` or the budget."""
        from tqdm import tqdm

        ticks, name = self.ticks, f"{self.scenario.name} {self.be.name}"
        bar = tqdm(total=ticks, unit="tick", desc=name, mininterval=0.5, disable=not progress)
        enabled = gc.isenabled()
        gc.disable()  # one clock, no collector's pauses inside it (the compiled engine has none)
        try:
            chunk = self._compiled() if self.engine == "compiled" else self._python
            start = time.perf_counter()
            stop_at = 0.0 if wall_budget_s is None else start + float(wall_budget_s)
            k = 0
            while k < ticks:
                end = min(k + self.CHUNK, ticks)
                done = chunk(k, end, stop_at)
                bar.update(done - k)
                k = done
                if done < end:
                    break  # budget spent: the log keeps the ticks done
            self.wall = time.perf_counter() - start
        finally:
            for close, st in getattr(self, "_close", ()):  # the compiled solves' memory, once
                close(st)
            self._close = []
            if enabled:
                gc.enable()
            bar.close()
        self.done = k

    def _compiled(self):
        """The compiled engine's chunk function, with the backend's state (freed at the end)."""
        from ..engine.compiled import SOLVERS, engine_for

        fns = SOLVERS[self.be.name].functions()
        st = fst = fns.make_state(self.be, self.model, self.ctrl.n_rows)
        self._close = [(fns.close_state, st)]
        if self.fb_be is not self.be:
            fst = fns.make_state(self.fb_be, self.model, self.ctrl.n_rows)
            self._close.append((fns.close_state, fst))
        self._error_text = fns.error_text
        args = (self.model, self.cols, st, fst, self.state, self.data, self.codes)
        return partial(engine_for(self.be.name), *args)  # then (k0, k1, stop_at)

    def _python(self, k0: int, k1: int, stop_at: float) -> int:
        """Ticks ``k0 .. k1-1`` on the Python engine (:mod:`qpbench.engine.compiled` does the
        same in compiled code); returns the next tick (earlier when ``stop_at`` passed)."""
        model, cols, be, ls = self.model, self.cols, self.be, self.state
        data, codes, records = self.data, self.codes, self.records
        theta, gains, noise = ls.theta, ls.gains, model.noise
        build, make_problem = self.ctrl.build_arrays, self.ctrl.make_problem
        law, adaptive, soft, keep = compiled_law(), model.adaptive, self.soft, self.keep_every
        perf, dt, limit = time.perf_counter, model.dt, model.deadline
        online, fd, error = self.online, model.controller.desired_force, STATUS_CODES["error"]
        for k in range(k0, k1):
            tick0 = perf()
            if stop_at and k and tick0 >= stop_at:
                return k
            t = k * dt
            kp, kd = float(gains[0]), float(gains[1])
            arrays = build(theta, t, kp, kd, soft)
            problem = make_problem(arrays, soft)
            if keep is not None and k % keep == 0:
                records.append((k, t, problem))
            t1 = perf()
            try:
                sol, ns = timed_call(be, problem, ls.v)
                solve_s = ns * 1e-9
            except Exception as exc:  # noqa: BLE001 - a backend's exception is the tick's status
                solve_s = perf() - t1
                sol = _Raised(describe_exception(exc))
            row = data[k]
            row[cols.build_time], row[cols.solve_time] = t1 - tick0, solve_s
            row[cols.solver_time] = getattr(sol, "solver_time_s", None)  # its own [s]; None: NaN
            status, x, force = sol.status, sol.x, -1.0
            # an answer classify() would call optimal (finite x, in time), or an online one
            if x is not None and (online or status == "optimal") and solve_s <= limit:
                if type(x) is not np.ndarray or x.dtype != np.float64:
                    x = np.asarray(x, dtype=np.float64)
                # -1.0 when x is not finite: nothing logged, the plant not moved
                force = self._post(k, t, arrays, x, sol.y, sol.z, APPLIED, kp, kd)
                if force >= 0.0:
                    ls.v[:] = x
            if force < 0.0:
                status, force = self._without_answer(k, t, sol, solve_s, arrays, kp, kd)
            codes[k] = STATUS_CODES.get(status, error)
            force += noise[k]
            row[cols.force], row[cols.force + 1] = force, force - fd
            if adaptive:
                law(model.law, dt, ls.sensed, arrays.xd, force, gains)
            row[cols.tick_time] = perf() - tick0
        return k1

    def _without_answer(self, k, t, sol, solve_s, arrays, kp, kd):
        """A tick whose own answer is not applied: classify it (:func:`~qpbench.statuses.classify`),
        then apply the soft formulation's answer (same backend), else zero velocity.

        Returns the tick's status and the noise-free force [N]; leaves the applied velocity
        [rad/s] in the loop's state.
        """
        be, limit, ls, cols = self.be, self.model.deadline, self.state, self.cols
        if type(sol) is _Raised:
            status, error = "error", sol.error
            self.n_raised += 1
        else:
            status, error = classify(sol, solve_s, limit)
            if status == "time_limit" and solve_s > limit:
                ls.counts[0] += 1  # arrived after the deadline: dropped
        if status == "error" and error and self.first_error is None:
            self.first_error, self.first_error_t = str(error), t
        if status in FAILURE_STATUSES and status != "time_limit":
            _reset(be)  # its state can no longer be trusted
        mode, x, z = ZERO, ls.zeros, None
        if not self.online and not self.soft:
            ctrl, row, perf = self.ctrl, self.data[k], time.perf_counter
            t1 = perf()
            problem = ctrl.make_problem(ctrl.build_arrays(ls.theta, t, kp, kd, True), True)
            t2 = perf()
            try:
                fb, ns = timed_call(self.fb_be, problem, ls.v)
                fb_s = ns * 1e-9
                fb_status = classify(fb, fb_s, limit)[0]
            except Exception as exc:  # noqa: BLE001 - a failed fallback: zero velocity
                fb_s = perf() - t2
                fb, fb_status = _Raised(describe_exception(exc)), "error"
                ls.counts[1] += 1
                if self.first_error is None:
                    self.first_error, self.first_error_t = f"fallback: {fb.error}", t
                _reset(self.fb_be)
            row[cols.fallback_build_time], row[cols.fallback_solve_time] = t2 - t1, fb_s
            if (own := getattr(fb, "solver_time_s", None)) is not None:
                c = cols.solver_time  # the fallback's own time adds to the tick's
                row[c] = np.nansum([row[c], own])
            if fb_status == "optimal":
                mode, x = FALLBACK, np.asarray(fb.x, dtype=np.float64)
                z = fb.z
        force = self._post(k, t, arrays, x, None, z, mode, kp, kd)
        if force < 0.0:  # the fallback's answer was not finite either
            mode, x = ZERO, ls.zeros
            force = self._post(k, t, arrays, x, None, None, mode, kp, kd)
        ls.v[:] = x if mode == FALLBACK else 0.0
        return status, force

    def _post(self, k, t, arrays, x, y, z, mode, kp, kd) -> float:
        """The tick kernel (:mod:`qpbench.sim.tick_kernel`) on tick ``k`` with velocity ``x``
        [rad/s] and duals ``y, z`` (``None``: none)."""
        a, none, ls, f64 = arrays, self.state.zeros[:0], self.state, np.float64
        y = none if y is None else np.ascontiguousarray(y, dtype=f64)
        z = none if z is None else np.ascontiguousarray(z, dtype=f64)
        x = np.ascontiguousarray(x, dtype=f64)
        geometry = (a.ee, ls.sensed, a.J, a.b0, a.dist, a.xd)
        args = (self.model, self.cols, ls.theta, x, *geometry, y, z, self.data, k, t, mode, kp, kd)
        if self._post_kernel is None:  # one type signature a run: no type dispatch per tick
            self._post_kernel = entry_point(get_post_kernel(), *args)
        return self._post_kernel(*args)

    def result(self, wall_budget_s: float | None, p99_interval: bool = True) -> SimResult:
        """The tick log, the summary and the kept records of the ticks simulated (the compiled
        engine's state freed first)."""
        scenario, deadline, ctrl, ls = self.scenario, self.deadline, self.ctrl, self.state
        done = self.done
        frame = tick_log.to_frame(self.data, self.names, self.codes[:done])
        body = body_clearance(
            ctrl.arm,
            frame[tick_log.theta_columns(ctrl.n)].to_numpy(),
            frame[tick_log.T].to_numpy(),
            ctrl.obstacles,
            ctrl.key_points.radius,
            ctrl.exempt,
        )
        tick_log.add_body_columns(frame, body, [o.name for o in ctrl.obstacles])
        if solve_log.isEnabledFor(logging.DEBUG):  # -vv: one line per solve, from the log
            name = f"{scenario.name} {self.be.name}"
            ticks = zip(frame[tick_log.T], frame[tick_log.STATUS], frame[tick_log.SOLVE_TIME])
            for k, (t, status, solve_s) in enumerate(ticks):
                solve_log.debug(
                    "%s tick %d (t = %.3f s): %s in %.1f µs", name, k, t, status, solve_s * 1e6
                )
        if self.engine == "compiled" and ls.counts[2] >= 0:  # the engine's first error tick
            k = int(ls.counts[2])
            self.first_error = self._error_text(self.be.name, ls.counts[3])
            self.first_error_t = k * self.model.dt
        run_info = dict(
            deadline_s=deadline if deadline is None else float(deadline),
            deadline_dropped=None if deadline is None else int(ls.counts[0]),
            raised_ticks=self.n_raised,
            fallback_errors=int(ls.counts[1]),
            first_error=self.first_error,
            first_error_t=self.first_error_t,
            wall_budget_s=wall_budget_s,
            stopped_early=done < self.ticks,
            engine=self.engine,
            engine_note=self.engine_note,
        )
        summary = summarize(
            frame, scenario, ctrl, self.be.name, self.formulation, self.wall, run_info, p99_interval
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
