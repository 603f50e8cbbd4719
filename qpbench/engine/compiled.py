"""The compiled engine: a whole closed-loop run in one compiled function, no Python per tick.

Each tick, as :mod:`qpbench.sim.loop` describes it and with the same compiled pieces: the build
(:mod:`qpbench.control.build_kernel`), the backend's compiled solve, the soft fallback, the step
and log row (:mod:`qpbench.sim.tick_kernel`), the sensor noise drawn before the run, the
adaptive law. The engine body (:func:`_run_py`) is compiled once per backend with that backend's
``solve`` and ``reset`` bound (:func:`qpbench.native.compile_with`), so a C API call is a direct
call. A backend joins by a :class:`CompiledSolver` in :data:`SOLVERS`.

Times are read from ``CLOCK_MONOTONIC`` in compiled code (:func:`qpbench.native.clock`): the
build, the solve (the call with the tick's QP until x, duals and status are in the engine's
memory), the fallback's build and solve, and the whole tick.
"""

from __future__ import annotations

import importlib
from dataclasses import dataclass
from functools import cache
from typing import TYPE_CHECKING, NamedTuple

import numpy as np

from ..control.build_kernel import packed_layout
from ..native import clock, compile_with
from ..packed import HEADER as PACKED_HEADER
from ..sim.tick_kernel import APPLIED, FALLBACK, ZERO, get_post_kernel

if TYPE_CHECKING:
    from collections.abc import Callable

    from ..backends.base import Backend
    from .model import RunModel

#: ``TICK_STATUSES`` codes the engine gives itself (the solves return the others).
OPTIMAL, TIME_LIMIT, ERROR, INVALID = 0, 4, 5, 7

# The functions :func:`_run_py` calls, bound in each compiled copy by :func:`engine_for`.
solve = reset = now = build = post = adapt = None


class LoopState(NamedTuple):
    """The engine's memory, owned by the caller: ``theta`` [rad], ``v`` the applied velocity
    [rad/s], ``sensed = [x, xdot]`` [m, m/s], ``gains = [Kp_hat, Kd_hat]``, the tick's and the
    fallback's packed QPs ``buf``, ``fbuf``, their answers ``sol``, ``fsol`` (``[x; y; z]``) and
    ``info``, ``finfo`` (own time [s], iterations, raw flag), ``zeros`` (n,), the clock's
    ``ts``, and ``counts = [dropped, fallback errors, first error tick (-1: none), its raw
    flag]``."""

    theta: np.ndarray
    v: np.ndarray
    sensed: np.ndarray
    gains: np.ndarray
    buf: np.ndarray
    fbuf: np.ndarray
    sol: np.ndarray
    fsol: np.ndarray
    info: np.ndarray
    finfo: np.ndarray
    zeros: np.ndarray
    ts: np.ndarray
    counts: np.ndarray


def loop_state(model: RunModel, n_rows: int) -> LoopState:
    """Fresh :class:`LoopState` for ``model``'s arm with ``n_rows`` obstacle rows."""
    n, dim = model.theta0.shape[0], model.controller.normal.shape[0]
    size, _ = packed_layout(n, n_rows, dim)
    return LoopState(
        theta=model.theta0.copy(),
        v=np.zeros(n),
        sensed=np.zeros(2 * dim),
        gains=np.array([model.kp0, model.kd0]),
        buf=np.zeros(size),
        fbuf=np.zeros(size),
        sol=np.zeros(n + dim + n_rows),
        fsol=np.zeros(n + dim + n_rows),
        info=np.zeros(4),
        finfo=np.zeros(4),
        zeros=np.zeros(n),
        ts=np.zeros(2, dtype=np.int64),
        counts=np.array([0, 0, -1, 0], dtype=np.float64),
    )


@dataclass(frozen=True)
class CompiledSolver:
    """A backend's compiled solve, by module: ``module`` holds ``solve(st, buf, warm, sol,
    info) -> status code``, ``reset(st)``, ``make_state(backend, model, n_rows) -> st``,
    ``close_state(st)``, ``unavailable_reason(backend) -> str | None`` and ``error_text(raw)``
    (the message of a raw exit flag)."""

    module: str
    #: Formulations it runs (a backend whose compiled solve needs P constant runs ``paper`` only).
    formulations: tuple[str, ...] = ("paper", "soft")

    def functions(self):
        return importlib.import_module(self.module, __package__)


#: Backends with a compiled solve, by name.
SOLVERS: dict[str, CompiledSolver] = {
    "noop": CompiledSolver(".solvers"),
    "pinv": CompiledSolver(".solvers"),
    "rnn": CompiledSolver(".solvers", ("paper",)),
    "rnn-tuned": CompiledSolver(".solvers"),
    "qpoases": CompiledSolver(".native_solvers"),
    "daqp": CompiledSolver(".native_solvers"),
    "daqp-stateless": CompiledSolver(".native_solvers"),
}


def unsupported_reason(backend: Backend, formulation: str) -> str | None:
    """Why ``backend`` runs on the Python engine here (``None``: it runs compiled)."""
    spec = SOLVERS.get(backend.name)
    if spec is None:
        return "no compiled solve"
    if formulation not in spec.formulations:
        return f"no compiled solve of the {formulation} formulation"
    return spec.functions().unavailable_reason(backend)


@cache
def engine_for(name: str) -> Callable:
    """The engine compiled (or loaded from numba's cache) with backend ``name``'s solve."""
    fns = SOLVERS[name].functions()
    bindings = {
        "solve": fns.compiled_solve(name),
        "reset": fns.compiled_reset(name),
        "now": clock(),
        "build": _build(),
        "post": get_post_kernel(),
        "adapt": _adapt(),
        "_views": compile_with(_views, name="tick_views"),
        "_finite": compile_with(_finite, name="all_finite"),
    }
    return compile_with(_run_py, bindings, name=f"engine_{name.replace('-', '_')}")


def _build():
    from ..control.build_kernel import compiled_build_kernel

    return compiled_build_kernel()


def _adapt():
    from ..control.adaptive import compiled_law

    return compiled_law()


def _views(buf, n, nr, dim):  # pragma: no cover - compiled (inlined as plain arithmetic)
    """J, b0, ee, dist and x_d in a packed tick buffer (:func:`packed_layout`)."""
    oJ = PACKED_HEADER + n * n + n + nr * n + nr
    ob = oJ + dim * n
    oee = ob + dim + 2 * n
    od = oee + dim
    return (
        buf[oJ:ob].reshape((dim, n)),
        buf[ob : ob + dim],
        buf[oee:od],
        buf[od : od + nr],
        buf[od + nr : od + nr + 2 * dim],
    )


def _finite(x):  # pragma: no cover - compiled
    for i in range(x.shape[0]):
        if not np.isfinite(x[i]):
            return False
    return True


# Over 80 lines, kept whole on purpose: numba compiles it as one function, with the backend's
# solve and reset, the clock, the build, the step and the adaptive law bound by engine_for().
def _run_py(model, cols, st, fst, ls, data, codes, k0, k1, stop_at):  # pragma: no cover - compiled
    """Run ticks ``k0 .. k1-1`` of ``model`` (state ``ls``, the backend's ``st`` and its
    fallback instance's ``fst``), writing rows
    of ``data`` and status codes; returns the next tick (earlier than ``k1`` when the clock
    passed ``stop_at`` [s] between ticks; ``stop_at <= 0``: no budget)."""
    cm = model.controller
    n = model.theta0.shape[0]
    nr = cm.row_key.shape[0]
    dt = model.dt
    theta, sensed, gains, ts = ls.theta, ls.sensed, ls.gains, ls.ts
    J, b0, ee, dist, xd = _views(ls.buf, n, nr, cm.normal.shape[0])
    empty = ls.zeros[:0]
    geometry = (ee, sensed, J, b0, dist, xd)
    for k in range(k0, k1):
        tick0 = now(ts)
        if stop_at > 0.0 and k > 0 and tick0 >= stop_at:
            return k
        t = k * dt
        kp, kd = gains[0], gains[1]
        build(cm, theta, t, kp, kd, model.soft, ls.buf)
        t1 = now(ts)
        me = int(ls.buf[1])
        code = solve(st, ls.buf, ls.v, ls.sol, ls.info)
        t2 = now(ts)
        row = data[k]
        row[cols.build_time] = t1 - tick0
        row[cols.solve_time] = t2 - t1
        row[cols.solver_time] = ls.info[0]
        x = ls.sol[:n]
        force = -1.0
        # an answer: optimal, or any but an error of an online backend (applied as it is)
        answered = code == OPTIMAL or (model.online and code != ERROR)
        if answered and t2 - t1 <= model.deadline and _finite(x):
            y = ls.sol[n : n + me]
            z = ls.sol[n + me : n + me + nr]
            force = post(model, cols, theta, x, *geometry, y, z, data, k, t, APPLIED, kp, kd)
            for i in range(n):
                ls.v[i] = x[i]
        if force < 0.0:
            if answered and not _finite(x):
                code = INVALID
            elif t2 - t1 > model.deadline:
                code = TIME_LIMIT
                ls.counts[0] += 1
            if code == ERROR and ls.counts[2] < 0:
                ls.counts[2] = k
                ls.counts[3] = ls.info[2]
            if code == ERROR or code == INVALID:
                reset(st)  # its state can no longer be trusted
            mode = ZERO
            if not model.online and not model.soft:
                t3 = now(ts)
                build(cm, theta, t, kp, kd, True, ls.fbuf)
                t4 = now(ts)
                fcode = solve(fst, ls.fbuf, ls.v, ls.fsol, ls.finfo)
                t5 = now(ts)
                row[cols.fallback_build_time] = t4 - t3
                row[cols.fallback_solve_time] = t5 - t4
                if np.isfinite(ls.finfo[0]):  # the fallback's own time adds to the tick's
                    own = row[cols.solver_time]
                    row[cols.solver_time] = ls.finfo[0] + (own if np.isfinite(own) else 0.0)
                if fcode == OPTIMAL and t5 - t4 <= model.deadline and _finite(ls.fsol[:n]):
                    mode = FALLBACK
            if mode == FALLBACK:
                fx = ls.fsol[:n]
                fz = ls.fsol[n : n + nr]
                force = post(
                    model, cols, theta, fx, *geometry, empty, fz, data, k, t, FALLBACK, kp, kd
                )
                for i in range(n):
                    ls.v[i] = fx[i]
            else:
                force = post(
                    model, cols, theta, ls.zeros, *geometry, empty, empty, data, k, t, ZERO, kp, kd
                )
                for i in range(n):
                    ls.v[i] = 0.0
        codes[k] = code
        force += model.noise[k]
        row[cols.force] = force
        row[cols.force + 1] = force - cm.desired_force
        if model.adaptive:
            adapt(model.law, dt, sensed, xd, force, gains)
        row[cols.tick_time] = now(ts) - tick0
    return k1
