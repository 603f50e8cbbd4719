"""The compiled engine: a whole closed-loop run in one compiled function, no Python per tick.

Each tick, as :mod:`qpbench.sim.loop` describes it and with the same compiled pieces: the build
(:mod:`qpbench.control.build_kernel`), the backend's compiled solve, the soft fallback, the step
and log row (:mod:`qpbench.sim.tick_kernel`), the sensor noise drawn before the run, the
adaptive law. The engine body (:func:`_run_py`) is compiled once per compiled ``solve``, with
it and its ``reset`` bound (:func:`qpbench.native.compile_with`), so a C API call is a direct
call; backends whose solve is one function choosing by its state (``noop``, ``pinv`` and the
network; ``daqp`` and ``daqp-stateless``) share one engine, compiled once. The build and the
step are inlined into the body (numba's IR): called, each would be passed the model, flattened
to a few words per array, every tick. They allocate nothing per tick (scratch in the state and
the controller model). A backend joins by a :class:`CompiledSolver` in :data:`SOLVERS`.

Times are read from ``CLOCK_MONOTONIC`` in compiled code (:func:`qpbench.native.clock`); what
each clock spans: docs/methodology.md, "Closed-loop engines and their clocks".

The engine, DAQP's compiled solves, the chain's kinematics and the obstacle distances are
compiled without numba's runtime (``_nrt=False``): they allocate nothing, so no array costs a
reference count each tick (bench/README.md, "The engine today: no reference counts"); a
function that allocates fails there at compile time, never at run time.
"""

from __future__ import annotations

import importlib
from dataclasses import dataclass
from functools import cache
from typing import TYPE_CHECKING, NamedTuple

import numpy as np

from ..control.adaptive import compiled_law
from ..control.build_kernel import compiled_build_kernel, packed_layout
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


def engine_for(name: str) -> Callable:
    """The engine compiled (or loaded from numba's cache) with backend ``name``'s solve (one
    engine per compiled solve: backends sharing a solve share it)."""
    fns = SOLVERS[name].functions()
    return _engine(fns.compiled_solve(name), fns.compiled_reset(name))


@cache
def _engine(solve, reset) -> Callable:
    bindings = {
        "solve": solve,
        "reset": reset,
        "now": clock(),
        "build": compiled_build_kernel(),
        "post": get_post_kernel(),
        "adapt": compiled_law(),
        "_views": compile_with(_views, name="tick_views", inline="always"),
        "_finite": compile_with(_finite, name="all_finite", inline="always"),
    }
    name = f"engine_{solve.py_func.__name__.strip('_')}"
    return compile_with(_run_py, bindings, name=name, _nrt=False)


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


# Numba compiles it as one function, with the solve and reset, the clock, the build, the step
# and the adaptive law bound by engine_for().
def _run_py(model, cols, st, fst, ls, data, codes, k0, k1, stop_at):  # pragma: no cover - compiled
    """Run ticks ``k0 .. k1-1`` of ``model`` (state ``ls``, the backend's ``st`` and its
    fallback instance's ``fst``), writing rows of ``data`` and status codes; returns the next
    tick (earlier than ``k1`` when the clock passed ``stop_at`` [s] between ticks; ``stop_at <=
    0``: no budget)."""
    cm = model.controller
    n = model.theta0.shape[0]
    nr = cm.row_key.shape[0]
    dt, deadline, noise, law = model.dt, model.deadline, model.noise, model.law
    online, soft, adaptive, fd = model.online, model.soft, model.adaptive, cm.desired_force
    theta, sensed, gains, ts, v, counts = ls.theta, ls.sensed, ls.gains, ls.ts, ls.v, ls.counts
    buf, fbuf, sol, fsol, info, finfo = ls.buf, ls.fbuf, ls.sol, ls.fsol, ls.info, ls.finfo
    zeros = ls.zeros
    J, b0, ee, dist, xd = _views(buf, n, nr, cm.normal.shape[0])
    empty = zeros[:0]
    x, fx, fz = sol[:n], fsol[:n], fsol[n : n + nr]
    tick0 = now(ts)  # then each tick's end is the next one's start: one clock read fewer
    for k in range(k0, k1):
        if stop_at > 0.0 and k > 0 and tick0 >= stop_at:
            return k
        t = k * dt
        kp, kd = gains[0], gains[1]
        build(cm, theta, t, kp, kd, soft, buf)
        t1 = now(ts)
        code = solve(st, buf, v, sol, info)
        t2 = now(ts)
        row = data[k]
        row[cols.build_time] = t1 - tick0
        row[cols.solve_time] = t2 - t1
        row[cols.solver_time] = info[0]
        mode = APPLIED
        # an answer: optimal, or any but an error of an online backend (applied as it is)
        answered = code == OPTIMAL or (online and code != ERROR)
        if not (answered and t2 - t1 <= deadline and _finite(x)):
            if answered and not _finite(x):
                code = INVALID
            elif t2 - t1 > deadline:
                code = TIME_LIMIT
                counts[0] += 1
            if code == ERROR and counts[2] < 0:
                counts[2] = k
                counts[3] = info[2]
            if code == ERROR or code == INVALID:
                reset(st)  # its state can no longer be trusted
            mode = ZERO
            if not online and not soft:
                t3 = now(ts)
                build(cm, theta, t, kp, kd, not soft, fbuf)  # True, not a literal: one build
                t4 = now(ts)
                fcode = solve(fst, fbuf, v, fsol, finfo)
                t5 = now(ts)
                row[cols.fallback_build_time] = t4 - t3
                row[cols.fallback_solve_time] = t5 - t4
                if np.isfinite(finfo[0]):  # the fallback's own time adds to the tick's
                    own = row[cols.solver_time]
                    row[cols.solver_time] = finfo[0] + (own if np.isfinite(own) else 0.0)
                if fcode == OPTIMAL and t5 - t4 <= deadline and _finite(fx):
                    mode = FALLBACK
        if mode == APPLIED:
            me = int(buf[1])
            vel, y, z = x, sol[n : n + me], sol[n + me : n + me + nr]
        elif mode == FALLBACK:
            vel, y, z = fx, empty, fz
        else:
            vel, y, z = zeros, empty, empty
        force = post(
            model, cols, theta, vel, ee, sensed, J, b0, dist, xd, y, z, data, k, t, mode, kp, kd
        )
        for i in range(n):
            v[i] = vel[i]
        codes[k] = code
        force += noise[k]
        row[cols.force] = force
        row[cols.force + 1] = force - fd
        if adaptive:
            adapt(law, dt, sensed, xd, force, gains)
        end = now(ts)
        row[cols.tick_time] = end - tick0
        tick0 = end
    return k1
