"""Test-only backends: faults on purpose, and stateful backends whose answers reveal their state.

Loaded by the harness tests with ``--plugin tests/faulty_backends.py`` (or
``QPBENCH_PLUGINS``); never registered by qpbench itself.

Faulty (names ``faulty:<kind>``):

- ``raise``: raises ``RuntimeError("solver exploded")``;
- ``sleep``: sleeps :data:`SLEEP_S` in Python, then answers (past a short
  time limit: ``time_limit`` by its wall time; the solve is not interrupted);
- ``busy``: a Python loop of :data:`BUSY_S`, then answers; counts the solves
  that ran to their last line (``completed``) and its ``finally`` blocks
  (``cleanups``): a guard that raised into it would leave ``completed`` behind;
- ``hang``: sleeps 60 s, like a hang in native code that nothing but
  killing the process stops (``risky``: isolated under ``auto``);
- ``segfault``: ``os.kill(os.getpid(), SIGSEGV)`` (``risky``);
- ``nan``: returns ``x`` full of NaN with status ``optimal``;
- ``segfault-once``: segfaults on the problem named in ``QPBENCH_TEST_SEGV``
  only, solves the others (not marked risky: the harness must learn it).

A worker that dies while it starts: while the file named by :data:`DIE_AT_IMPORT_ENV`
exists, the next process to import this module removes it and SIGKILLs itself (a
worker pool's workers import the module of their task, :func:`double`, before they
say they are ready).

Stateful (they solve the QP exactly with qpsolvers' ``clarabel`` and report
their state in ``iterations``), names ``stateful:<kind>``:

- ``count-state`` / ``count-copy``: ``iterations`` = solves since the last
  reset, including this one (two names of one behaviour, kept for the tests
  that name them);
- ``count-fail2``: ``count-copy`` that raises on tick 2 (``q[-1] == 2``);
- ``last-native``: ``iterations`` = ``round(q[-1])`` of the previously solved
  problem + 1 (0 after a reset); holds a lock, like a native handle that
  cannot be copied.
- ``shared``: ``iterations`` = solves by any instance of the class since the
  import (instances share their state: ``--repeat``'s replicas disagree);
- ``single``: ``count-copy`` of which a second instance cannot be made
  (:meth:`~qpbench.backends.base.Backend.fresh` raises).
- ``kernels``: ``iterations`` = specialisations of the network's general
  integrator the solving process holds in memory (a worker's inheritance).
"""

from __future__ import annotations

import os
import signal
import threading
import time
import warnings

import numpy as np
import qpsolvers

from qpbench.backends import Backend, BackendSolution, register


def exact_solution(problem) -> BackendSolution:
    """Solve ``problem`` with qpsolvers' clarabel; a :class:`BackendSolution`."""
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        sol = qpsolvers.solve_problem(
            problem, solver="clarabel", tol_gap_abs=1e-10, tol_feas=1e-10, tol_gap_rel=1e-10
        )
    out = BackendSolution(problem=problem)
    out.x, out.y, out.z, out.z_box = sol.x, sol.y, sol.z, sol.z_box
    out.status = "optimal" if sol.found else "primal_infeasible"
    return out


#: Environment variable naming the flag file of a death at import.
DIE_AT_IMPORT_ENV = "QPBENCH_TEST_DIE_AT_IMPORT"


def _die_at_import_once() -> None:
    flag = os.environ.get(DIE_AT_IMPORT_ENV)
    if flag:
        try:
            os.unlink(flag)  # one process takes the flag, however many start at once
        except FileNotFoundError:
            return
        os.kill(os.getpid(), signal.SIGKILL)


_die_at_import_once()


def double(x):
    """A task of the worker pool's tests: ``2 * x``."""
    return 2 * x


class _Faulty(Backend):
    family = "test fault"

    def _solve(self, problem, warm_start):
        raise NotImplementedError


@register
class RaiseBackend(_Faulty):
    name = "faulty:raise"

    def _solve(self, problem, warm_start):
        raise RuntimeError("solver exploded\non two lines")


#: Sleep of ``faulty:sleep`` [s].
SLEEP_S = 1.0
#: Length of ``faulty:busy``'s Python loop [s].
BUSY_S = 0.5


@register
class SleepBackend(_Faulty):
    name = "faulty:sleep"

    def _solve(self, problem, warm_start):
        time.sleep(SLEEP_S)
        return exact_solution(problem)


@register
class BusyBackend(_Faulty):
    name = "faulty:busy"

    def __init__(self, profile="default", **settings):
        super().__init__(profile, **settings)
        self.completed = self.cleanups = 0

    def _solve(self, problem, warm_start):
        try:
            end = time.perf_counter() + BUSY_S
            spins = 0
            while time.perf_counter() < end:
                spins += 1
            sol = exact_solution(problem)
            self.completed += 1  # the solve's last line
            return sol
        finally:
            self.cleanups += 1


@register
class HangBackend(_Faulty):
    name = "faulty:hang"
    risky = True

    def _solve(self, problem, warm_start):
        time.sleep(60.0)
        return exact_solution(problem)


@register
class SegfaultBackend(_Faulty):
    name = "faulty:segfault"
    risky = True

    def _solve(self, problem, warm_start):
        os.kill(os.getpid(), signal.SIGSEGV)
        time.sleep(5.0)  # the signal is delivered before this returns
        raise RuntimeError("still alive after SIGSEGV")


@register
class SegfaultOnceBackend(_Faulty):
    name = "faulty:segfault-once"

    def __init__(self, profile="default", **settings):
        super().__init__(profile, **settings)
        self.names_seen = 0

    def _solve(self, problem, warm_start):
        self.names_seen += 1
        target = os.environ.get("QPBENCH_TEST_SEGV")
        if target is not None and abs(float(problem.q[-1]) - float(target)) < 1e-9:
            os.kill(os.getpid(), signal.SIGSEGV)
            time.sleep(5.0)
        return exact_solution(problem)


@register
class NanBackend(_Faulty):
    name = "faulty:nan"

    def _solve(self, problem, warm_start):
        out = BackendSolution(problem=problem)
        out.x = np.full(problem.q.shape[0], np.nan)
        out.status = "optimal"
        return out


class _Stateful(Backend):
    family = "test state"

    def __init__(self, profile="default", **settings):
        super().__init__(profile, **settings)
        self.count = 0

    def reset(self):
        self.count = 0

    def _solve(self, problem, warm_start):
        self.count += 1
        sol = exact_solution(problem)
        sol.iterations = self.count
        return sol


@register
class CountState(_Stateful):
    name = "stateful:count-state"


@register
class CountCopy(_Stateful):
    name = "stateful:count-copy"


@register
class CountFail(_Stateful):
    """``count-copy`` that raises on the problem whose ``q[-1]`` is 2 (tick 2)."""

    name = "stateful:count-fail2"

    def _solve(self, problem, warm_start):
        if abs(float(problem.q[-1]) - 2.0) < 1e-12:
            self.count += 100  # a failure leaves the state corrupt: the harness must reset it
            raise ValueError("tick two")
        return super()._solve(problem, warm_start)


@register
class Shared(Backend):
    name = "stateful:shared"
    family = "test state"
    calls = 0

    def _solve(self, problem, warm_start):
        type(self).calls += 1
        sol = exact_solution(problem)
        sol.iterations = type(self).calls
        return sol


@register
class Single(_Stateful):
    name = "stateful:single"

    def fresh(self):
        raise RuntimeError("one instance only")


@register
class LastNative(Backend):
    name = "stateful:last-native"
    family = "test state"

    def __init__(self, profile="default", **settings):
        super().__init__(profile, **settings)
        self._lock = threading.Lock()  # cannot be copied, like a native handle
        self.last = None

    def reset(self):
        self.last = None

    def _solve(self, problem, warm_start):
        with self._lock:
            sol = exact_solution(problem)
            sol.iterations = 0 if self.last is None else self.last + 1
            self.last = int(round(float(problem.q[-1])))
            return sol


# ---------------------------------------------------------------- order, violation, lazy answers

#: ``(backend name, q[-1] of the problem)`` of every solve of the ``faulty:order-*`` backends, in call order.
CALLS: list = []


class _Recorder(Backend):
    """Records its solves in :data:`CALLS`; answers ``x = 0`` with status ``max_iter`` (not found).

    On :func:`tick_records` problems ``x = 0`` satisfies ``G x <= h`` and the
    box, and violates ``A x = b`` by exactly ``|b|``.
    """

    family = "test order"

    def _solve(self, problem, warm_start):
        CALLS.append((self.name, float(problem.q[-1])))
        sol = BackendSolution(problem=problem)
        sol.x = np.zeros(problem.q.shape[0])
        sol.status = "max_iter"
        return sol


@register
class OrderA(_Recorder):
    name = "faulty:order-a"


@register
class OrderB(_Recorder):
    name = "faulty:order-b"


@register
class OrderC(_Recorder):
    name = "faulty:order-c"


@register
class OutsideBox(Backend):
    """Answers ``x = 3`` everywhere (status ``optimal``): outside the box ``[-2, 2]`` of :func:`tick_records`."""

    name = "faulty:outside-box"
    family = "test violation"

    def _solve(self, problem, warm_start):
        sol = exact_solution(problem)
        sol.x = 3.0 * np.ones(problem.q.shape[0])
        return sol


class LazySolution(BackendSolution):
    """A solution whose ``y`` is built on first read, slowly (``LAZY_SECONDS``)."""

    @property
    def y(self):
        d = self.__dict__
        if "_y" not in d:
            time.sleep(LAZY_SECONDS)
            d["_y"] = np.zeros(0)
        return d["_y"]

    @y.setter
    def y(self, value):
        if value is not None:
            self.__dict__["_y"] = value


#: How long building :class:`LazySolution`'s ``y`` takes, in [s].
LAZY_SECONDS = 0.05


@register
class LazyDuals(Backend):
    """Returns at once a :class:`LazySolution` whose duals cost :data:`LAZY_SECONDS` on first read."""

    name = "faulty:lazy-duals"
    family = "test timing"

    def _solve(self, problem, warm_start):
        sol = LazySolution(problem=problem)
        sol.x = np.zeros(problem.q.shape[0])
        sol.status = "max_iter"
        return sol


@register
class KernelProbe(Backend):
    """Solves exactly; ``iterations`` = specialisations of the network's general integrator
    this process holds in memory (a worker forked with the kernels loaded has them all)."""

    name = "stateful:kernels"
    family = "test state"

    def _solve(self, problem, warm_start):
        from qpbench.rnn import network as nw

        sol = exact_solution(problem)
        sol.iterations = len(nw.kernel(True).overloads)
        return sol


# ---------------------------------------------------------------- problem sets for the harness tests


def tick_records(
    n_ticks: int,
    scenario: str | None = "wall",
    seed: int = 7,
    n: int = 4,
    prefix: str | None = None,
):
    """``n_ticks`` small strictly convex QPs with ``q[-1] = tick`` (the stateful backends read it).

    Each has 3 inequality rows, 1 equality row and box bounds; ``x = 0``
    satisfies ``G x <= h`` and the box, and the equality right-hand side is
    small, so every problem is feasible.
    """
    from qpbench.formats import ProblemRecord

    rng = np.random.default_rng(seed)
    records = []
    prefix = prefix if prefix is not None else (scenario or "p")
    for k in range(n_ticks):
        M = rng.standard_normal((n, n))
        P = M @ M.T + 0.5 * np.eye(n)
        q = rng.standard_normal(n)
        q[-1] = float(k)
        G = rng.standard_normal((3, n))
        h = rng.random(3) + 0.5
        A = rng.standard_normal((1, n))
        b = 0.05 * rng.standard_normal(1)
        lb, ub = -2.0 * np.ones(n), 2.0 * np.ones(n)
        problem = qpsolvers.Problem(P, q, G, h, A, b, lb, ub)
        records.append(
            ProblemRecord(problem, f"{prefix}/tick-{k:04d}", scenario, k, 0.001 * k, "paper")
        )
    return records


def write_tick_set(folder, n_ticks: int, **kw):
    """Write :func:`tick_records` as a problem-set folder; return the folder."""
    from qpbench.formats import write_problem_set

    return write_problem_set(
        folder,
        tick_records(n_ticks, **kw),
        generator={"name": "tests.tick_records", "n_ticks": n_ticks},
    )


# ---------------------------------------------------------------- closed-loop faults on some ticks only
#
# For the closed loop's per-tick guards (tests/test_loop.py): these solve with
# ``daqp`` but misbehave on the paper formulation's call k (the tick k: one
# such call per tick; the soft fallback, which has no equality, is never
# touched) when ``k % FAULT_EVERY == FAULT_PHASE``. Names ``faulty-ticks:<kind>``:
#
# - ``raise``: raises ``RuntimeError("tick fault k")``;
# - ``nan``: returns ``x`` full of NaN with status ``optimal``;
# - ``slow``: sleeps ``SLOW_S`` before answering (past a small per-tick deadline);
# - ``slow-first``: sleeps ``SLOW_S`` on the first paper call only (tick 0), like
#   a compile on a fresh machine, then answers.

#: Every FAULT_EVERY-th paper-formulation call, from call FAULT_PHASE, misbehaves.
FAULT_EVERY = 10
FAULT_PHASE = 7
#: Sleep of ``faulty-ticks:slow`` on its faulty ticks [s]: the tests' per-tick deadline is half of
#: it, so that no ordinary tick (tens of microseconds) reaches it even on a loaded machine.
SLOW_S = 0.4


def fault_ticks(n_ticks: int) -> list[int]:
    """The ticks on which a ``faulty-ticks:*`` backend misbehaves in a run of ``n_ticks``."""
    return [k for k in range(n_ticks) if k % FAULT_EVERY == FAULT_PHASE]


class DaqpInside(Backend):
    """Not registered: a base whose solves go to ``daqp`` (``self.inner``) unless it says otherwise."""

    def __init__(self, profile="default", **settings):
        super().__init__(profile, **settings)
        from qpbench.backends import get_backend

        self.inner = get_backend("daqp", profile)

    def reset(self):
        self.inner.reset()


class _SomeTicks(DaqpInside):
    family = "test fault"

    def __init__(self, profile="default", **settings):
        super().__init__(profile, **settings)
        self.calls = 0  # paper-formulation calls; not reset (the loop resets after a fault)

    def _fault(self, problem, warm_start):
        raise NotImplementedError

    def _solve(self, problem, warm_start):
        if problem.A is not None:  # the paper formulation
            k = self.calls
            self.calls += 1
            if k % FAULT_EVERY == FAULT_PHASE:
                return self._fault(problem, warm_start)
        return self.inner.solve(problem, warm_start)


@register
class RaiseSomeTicks(_SomeTicks):
    name = "faulty-ticks:raise"

    def _fault(self, problem, warm_start):
        raise RuntimeError(f"tick fault {self.calls - 1}")


@register
class NanSomeTicks(_SomeTicks):
    name = "faulty-ticks:nan"

    def _fault(self, problem, warm_start):
        out = BackendSolution(problem=problem)
        out.x = np.full(problem.q.shape[0], np.nan)
        out.status = "optimal"
        return out


@register
class SlowSomeTicks(_SomeTicks):
    name = "faulty-ticks:slow"

    def _fault(self, problem, warm_start):
        time.sleep(SLOW_S)
        return self.inner.solve(problem, warm_start)


@register
class SlowFirstTick(_SomeTicks):
    name = "faulty-ticks:slow-first"

    def _solve(self, problem, warm_start):
        if problem.A is not None:
            self.calls += 1
            if self.calls == 1:
                time.sleep(SLOW_S)
        return self.inner.solve(problem, warm_start)


def qpbench_file(_=None) -> str:
    """The file the calling process imported qpbench from."""
    import qpbench

    return qpbench.__file__
