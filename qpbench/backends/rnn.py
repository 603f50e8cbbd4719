"""Backends ``rnn`` and ``rnn-converged``: the paper's recurrent neural network (eq. 15).

``rnn`` is the paper's online use. The network's state ``(v, l1, l2)`` lives
across successive :meth:`~Backend.solve` calls (the control ticks of one
sequence). Each call integrates the network for one tick of ``dt`` seconds
on that tick's QP and returns the state's ``v`` as ``x``. It never reports
infeasibility: its answer is a compromise that the metrics judge. Its status
is ``optimal`` when the KKT residuals at the end of the tick are within the
profile's ``eps_abs`` and ``max_iter`` otherwise; the class attribute
``online = True`` tells a closed loop to apply ``x`` whatever the status (the
network's own state is the controller; no fallback solver).

``rnn-converged`` integrates from the state the previous call left (cold after
:meth:`reset`) until primal residual, dual residual and complementarity are
all within the profile's ``eps_abs``, or ``max_iter`` steps (then
``found=False``, status ``max_iter``). ``iterations`` counts integration steps.

Settings (keyword arguments of :func:`qpbench.backends.get_backend`):

================ ========================================================
eps              gain of eq. 15 in [s] (default 0.02, the paper's); only
                 ``rnn`` depends on it (it sets ``r = dt / eps`` per tick)
dt               time integrated per call in [s] (default 1e-3, one control
                 tick; a per-tick benchmark of a set that keeps every K-th
                 tick passes K ticks); ``rnn`` only
substeps         steps per ``tick`` of integrated time (``rnn``): a fixed
                 step ``h = tick / substeps``, so a call of ``dt`` takes
                 ``dt / h`` steps (rounded up); default: the fewest steps
                 with ``h / eps <= safety * bound`` (:mod:`qpbench.rnn.network`)
tick             the duration in [s] ``substeps`` divides (default 1e-3, the
                 control period of every shipped scenario)
safety           fraction of the stability bound per step, in (0, 1]
                 (default 0.9; on the robot's QPs the steps to converge fall
                 as r grows up to the bound)
l1_clip          clip ``l1`` to +-l1_clip after every step (anti-windup);
                 default none
method           ``euler`` (default of ``rnn``: the note's reading) or
                 ``semi-implicit`` (default of ``rnn-converged``: fewer
                 steps to 1e-6 on the robot's QPs, same cost a step)
use_numba        compiled loop (default when numba is installed) or numpy
max_iter         step budget of ``rnn-converged`` (default: profile's)
tol              residual tolerance (default: profile's ``eps_abs``)
================ ========================================================

No setting exceeds the stability bound silently: a step ``h = tick /
substeps`` with ``h / eps`` above ``safety`` times the bound of the call's
QP is shortened to it (more steps), and the solution says so in ``error``
(``step clamped to the stability bound: ...``; a bench row carries it in its
``error`` column; ``last.clamped``). The bound is computed only when the
step is above a cheap lower estimate of it (module :mod:`qpbench.rnn.network`).

When the problem's shape changes between calls the state is re-initialised
part by part: ``v`` (and everything) when ``n`` changes, ``l1`` when the
number of equalities changes, ``l2`` when the number of inequalities does.
"""

from __future__ import annotations

import time
from typing import TYPE_CHECKING

import numpy as np

from ..packed import PackedProblem
from ..rnn import network as nw
from . import register
from ._rnn_base import SETTING_NAMES, NetworkBackend
from .base import BackendSolution

if TYPE_CHECKING:
    import qpsolvers

__all__ = [
    "SETTING_NAMES",
    "WORKING_SETTINGS",
    "RNNConverged",
    "RNNOnline",
    "RNNTuned",
    "TickSolution",
]

#: A setting that works in the closed loop of every shipped scenario (the
#: paper's ``eps = 0.02`` does not): ``eps = 0.1 ms``, 20 semi-implicit steps
#: per 1 ms (a step of 50 us, r = 0.5) and ``l1`` clipped to +-10. It keeps
#: every key point within the bar (``d_safe - 0.5 mm``) in every shipped
#: scenario, where eps = 1 ms with 5 Euler steps does not (narrow); the
#: frontier of settings: results/rnn/README.md, ``python bench/rnn_frontier.py``.
WORKING_SETTINGS = {"eps": 1e-4, "substeps": 20, "method": "semi-implicit", "l1_clip": 10.0}


class _Duals:
    """``y``, ``z`` and ``z_box`` of a :class:`TickSolution`, made on the first read of any.

    A non-data descriptor: the first read puts views of the tick's output
    array for all three into the instance (those not set already), and
    later reads find them there without calling this.
    """

    __slots__ = ("name",)

    def __init__(self, name: str):
        self.name = name

    def __get__(self, sol, owner=None):
        if sol is None:
            return self
        d = sol.__dict__
        out = d["_out"]
        _, sy, sz, sb = d["_slices"]
        if "y" not in d:
            d["y"] = None if sy is None else out[sy]
        if "z" not in d:
            d["z"] = None if sz is None else out[sz]
        if "z_box" not in d:
            d["z_box"] = out[sb]
        return d[self.name]


class TickSolution(BackendSolution):
    """The online network's answer to one tick (a :class:`BackendSolution`).

    The kernel writes ``[x; y; z; z_box]`` into one fresh array. ``x`` is a
    view of it made at once; ``y``, ``z`` and ``z_box`` are views made on the
    first read of any of them (a controller applying ``x`` does not need
    them, and on this path the views are a sizeable part of a tick). The
    values are fixed when :meth:`RNNOnline.solve` returns: the array is never
    written again. The bench's timed region reads every field
    of the answer (:func:`qpbench.harness.timing.timed_call`), so there the
    three views are paid for inside the timing, as other backends pay for
    the duals they build.
    """

    y = _Duals("y")
    z = _Duals("z")
    z_box = _Duals("z_box")


@register
class RNNOnline(NetworkBackend):
    """The network integrated for one tick of ``dt`` per call (the paper's use).

    Per-tick path. A control loop calls this once per tick with problems of
    one shape (what the controller builds). Once a first call has set up the
    state, :meth:`solve` hands the kernel

    - a :class:`~qpbench.packed.PackedProblem` (the controller's): its one
      buffer, to :func:`qpbench.rnn.network.packed_kernel`, which reads the
      header and checks it against the buffer and the state;
    - any other problem: its eight arrays, to a kernel compiled for exactly
      C-contiguous float64 arrays (:func:`qpbench.rnn.network.online_kernel`),
      numba's dispatcher being the type check.

    The kernel returns the step count, the status and whether the step was
    clamped to the stability bound in one integer; the
    answer is a :class:`TickSolution`. Anything the kernel refuses (absent
    parts, sparse matrices, another dtype or layout, a shape change) goes to
    the general path, which converts, checks, re-shapes the state and raises
    what is wrong. All paths give the same numbers bit for bit (tested);
    ``obj`` is computed from ``x`` on first read (a controller does not read
    it). ``bench/rnn_speed.py`` measures the cost of a tick and its parts.
    """

    name = "rnn"
    online = True
    _kernel_obj = False

    def __init__(self, profile="default", **settings):
        self._fast = None
        super().__init__(profile, **settings)
        # P's eigenvalues are read by the kernel only when it picks the sub-steps itself
        self._needs_p = self.substeps is None

    def _r_total(self) -> float:
        return self.dt / self.eps

    def _stop_tol(self) -> float:
        return -1.0

    def _state_changed(self) -> None:
        """Arm the per-tick path for the state's shape (disarm without a state)."""
        st = self._state
        if st is None or not self.use_numba:
            self._fast = None
            return
        n, me, mi = st.n, st.me, st.mi
        slices = (
            slice(0, n),
            slice(n, n + me) if me else None,
            slice(n + me, n + me + mi) if mi else None,
            slice(n + me + mi, 2 * n + me + mi),
        )
        # the strict kernel takes arrays only: absent parts (None) go to the general path
        strict = nw.online_kernel(strict=True) if me and mi else None
        self._fast = (
            self._needs_p,
            nw.packed_kernel(),
            st.xi,
            self._prm,
            3 * n + 2 * (me + mi),
            slices[0],
            slices,
            self.name,
            strict,
        )

    def solve(
        self, problem: qpsolvers.Problem, warm_start: np.ndarray | None = None
    ) -> BackendSolution:
        """One tick of integration; see :meth:`Backend.solve` (same fields)."""
        start = _perf()
        fast = self._fast
        if fast is not None:
            needs_p, packed, xi, prm, size, sx, slices, name, strict = fast
            if needs_p:
                P = problem.P
                if type(P) is not _ndarray or P.dtype != _f64:
                    packed = strict = None
                else:
                    p_key = P.tobytes()
                    if p_key != self._p_key:
                        prm[nw.PMIN], prm[nw.PMAX] = nw.p_eigen_range(P)
                        self._p_key = p_key
            out = _alloc(size)
            if type(problem) is _Packed and packed is not None:
                code = packed(problem.buffer, xi, prm, out)
            elif strict is None:
                code = nw.SHAPE_MISMATCH
            else:
                try:
                    code = strict(
                        problem.P,
                        problem.q,
                        problem.A,
                        problem.b,
                        problem.G,
                        problem.h,
                        problem.lb,
                        problem.ub,
                        xi,
                        prm,
                        out,
                    )
                except TypeError:  # numba's dispatcher: not the one argument type compiled
                    code = nw.SHAPE_MISMATCH
            if code >= 0:
                sol = _new(TickSolution)
                sol.problem = problem
                sol.x = out[sx]
                sol._out = out
                sol._slices = slices
                sol.iterations = code >> 2
                if code & 2:  # the step was clamped to the bound (or none is proven stable)
                    sol.error = nw.step_note(prm)
                if code & 1:
                    sol.status = "optimal"
                    sol.found = True
                else:
                    sol.status = "max_iter"
                    sol.found = False
                sol.backend = name
                sol.wall_time_s = _perf() - start
                return sol
            if code == nw.DIVERGED:
                sol = self._diverged(problem, int(prm[nw.STEPS]))
            else:  # refused before touching the state: the general path says why or copes
                sol = self._run(problem, warm_start)
        else:  # first call, odd input: the general path converts, checks, sets up the state
            sol = self._run(problem, warm_start)
        sol.wall_time_s = _perf() - start
        sol.backend = self.name
        sol.found = sol.status == "optimal"
        return sol

    def _solve(self, problem, warm_start):
        return self._run(problem, warm_start)


_perf = time.perf_counter
_ndarray = np.ndarray
_f64 = np.dtype(np.float64)
_alloc = np.empty
_new = object.__new__
_Packed = PackedProblem


@register
class RNNConverged(NetworkBackend):
    """The network integrated until its KKT residuals are within tolerance."""

    name = "rnn-converged"
    default_method = "semi-implicit"

    def _r_total(self) -> float:
        return 0.0

    def _stop_tol(self) -> float:
        return self.tol

    def _solve(self, problem, warm_start):
        if (
            warm_start is not None
            and self.state is not None
            and self.state.n == np.size(warm_start)
        ):
            self.state.v = np.asarray(warm_start, dtype=np.float64).reshape(-1)
        return self._run(problem, warm_start)


@register
class RNNTuned(RNNOnline):
    """The online network with :data:`WORKING_SETTINGS`, not the paper's ``eps``.

    ``eps = 1e-4`` s, 20 semi-implicit sub-steps per 1 ms of integrated time
    (a step of 50 us whatever ``dt``) and ``l1`` clipped to +-10 (anti-windup
    during the infeasible start): the setting with which the network keeps
    ``d_safe - 0.5 mm`` in every shipped scenario (results/rnn/README.md).
    It ignores a scenario's ``[rnn]`` table, which carries the paper's values;
    settings given explicitly still override.
    """

    name = "rnn-tuned"
    scenario_table = None  # its own settings, not the scenario's (the paper's values)

    def __init__(self, profile="default", **settings):
        super().__init__(profile, **{**WORKING_SETTINGS, **settings})
