"""Every compiled kernel of qpbench, compiled (or loaded) before anything is timed.

qpbench's hot paths are numba kernels with ``cache=True``: compiled on their
first call with a given argument type (seconds to a minute each, in total
about a minute on a fresh machine), the machine code kept on disk
(:mod:`qpbench.cache` says where) and loaded by every later process (well
under a second). A compile inside a timed or time-limited call would be
measured as the solver's time, so every entry point that times something
(``qpbench run``, ``bench``, ``simulate``, ``closed-loop``, and
:func:`qpbench.sim.loop.simulate` itself) calls :func:`warmup` first;
``qpbench warmup`` does only that. Worker processes find the kernels on disk
and load them when they start (:mod:`qpbench.harness.isolation`), outside any
time limit.

:func:`warmup` calls each kernel's builder on tiny inputs of every argument
type qpbench passes it:

==============  ===============================================================
kernel          argument types warmed
==============  ===============================================================
controller      the controller's packed tick build
                (:mod:`qpbench.control.build_kernel`; one type)
post            the closed loop's sense, log and plant step
                (:func:`qpbench.sim.tick_kernel.warm_post_kernel`; one type)
network         the network's integrator (:func:`qpbench.rnn.network.kernel`)
                for the controller's four QP shapes: with and without the
                task's equality rows (``paper``, ``soft``), with and without
                obstacle rows (absent parts are read-only empty arrays, another
                numba type); the online backend's per-tick kernels
                (:func:`~qpbench.rnn.network.online_kernel` strict,
                :func:`~qpbench.rnn.network.packed_kernel`)
==============  ===============================================================

A problem of yet another shape (a foreign problem set without bounds, say)
compiles its own integrator on its first solve: the bench's discarded
warm-up solve, whose time has no consequence.
"""

from __future__ import annotations

import logging
import os
import time
from dataclasses import dataclass

log = logging.getLogger("qpbench")

__all__ = ["KERNELS", "WarmupReport", "warmup"]

#: Kernel groups :func:`warmup` prepares, in order.
KERNELS = ("controller", "post", "network")

#: Shipped scenarios whose controllers give the QP shapes warmed: obstacle rows, none.
_SCENARIOS = ("wall", "free")


@dataclass(frozen=True)
class WarmupReport:
    """What :func:`warmup` did.

    Attributes:
        compiled: Kernel specialisations compiled by this call (0: all were
            loaded from numba's cache, or were already in memory).
        seconds: Wall time of the call [s].
        cache: Where numba keeps the compiled kernels.
        kernels: The groups prepared (:data:`KERNELS`); empty without numba.
        in_memory: The kernels were already prepared in this process (nothing loaded).
        shims_compiled: Native shims (the qpoases backend's) compiled by this call.
    """

    compiled: int
    seconds: float
    cache: str
    kernels: tuple[str, ...]
    in_memory: bool = False
    shims_compiled: int = 0

    @property
    def loaded(self) -> bool:
        """Nothing was compiled: every kernel came from the cache (or memory)."""
        return self.compiled == 0

    def line(self) -> str:
        """One line for the log."""
        if not self.kernels:
            return "numba is not installed: the numpy paths run, nothing to compile"
        if self.in_memory:
            return "kernels already loaded in this process"
        shims = f" and {self.shims_compiled} native shim" if self.shims_compiled else ""
        if self.compiled or self.shims_compiled:
            return (
                f"kernels: compiled {self.compiled}{shims} (first run with this cache) and cached in "
                f"{self.cache} in {self.seconds:.1f} s; later runs load them"
            )
        return (
            f"kernels: loaded from the cache in {self.cache} in {self.seconds:.2f} s (0 compiled)"
        )


_READY: WarmupReport | None = None


def cache_location() -> str:
    """Where numba keeps qpbench's compiled kernels (``NUMBA_CACHE_DIR`` or beside the sources)."""
    env = os.environ.get("NUMBA_CACHE_DIR")
    if env:
        return env
    from .cache import PACKAGE_DIR

    return f"{PACKAGE_DIR}/**/__pycache__"


def _problems():
    """The controllers' tick QPs of :data:`_SCENARIOS`, both formulations; also warms the build kernel."""
    from .sim.scenario import load_scenario

    out = []
    for name in _SCENARIOS:
        sc = load_scenario(name)
        ctrl = sc.make_controller()
        theta = sc.theta0.astype(float)
        for soft in (False, True):
            arrays = ctrl.build_arrays(theta, 0.0, ctrl.kp, ctrl.kd, soft)
            out.append((sc, ctrl, theta, arrays, ctrl.make_problem(arrays, soft)))
    return out


def _warm_post(problems) -> None:
    from .sim.tick_kernel import warm_post_kernel

    for sc, ctrl, theta, arrays, _ in problems[
        ::2
    ]:  # one per scenario (the formulation does not change types)
        warm_post_kernel(ctrl, sc.make_surface(), sc.dt, theta, arrays)


def _warm_network(problems) -> None:
    import qpsolvers

    from .backends import get_backend

    # the general integrator, through the path the backends call it by
    converged = get_backend("rnn-converged", max_iter=2)
    for *_, problem in problems:
        converged.reset()
        converged.solve(problem)
    # the online backend: first call (general path), then the packed and the strict per-tick kernels
    sc, _, _, _, problem = problems[0]
    online = get_backend("rnn", dt=sc.dt)
    online.solve(problem)
    online.solve(problem)
    plain = qpsolvers.Problem(*(None if a is None else a.copy() for a in problem.unpack()))
    online.solve(plain)


def _warm_shims() -> int:
    """Compile (first time) and load the native shims of backends that have one; how many were compiled."""
    from .backends import backend_class

    compiled = 0
    try:
        qpoases = backend_class("qpoases")
    except Exception:  # noqa: BLE001 - a backend that is not registered has nothing to prepare
        return 0
    if qpoases.unavailable_reason() is None:
        from .backends import _qpoases_shim as shim

        before = shim.LOADED[:]
        existed = shim.shim_path(shim.qpoases_prefix()).is_file()
        qpoases.prepare()
        compiled += int(not existed and not before)
    return compiled


def warmup() -> WarmupReport:
    """Compile, or load from numba's on-disk cache, every compiled kernel of qpbench.

    Idempotent: a second call in the same process returns at once. Returns
    how many kernel specialisations had to be compiled (0 once the cache
    holds them) and how long it took. Without numba nothing needs compiling.
    """
    global _READY
    if _READY is not None:
        return WarmupReport(0, 0.0, _READY.cache, _READY.kernels, in_memory=True)
    from .rnn.network import numba_available

    if not numba_available():
        start = time.perf_counter()
        shims = _warm_shims()
        _READY = WarmupReport(0, time.perf_counter() - start, "", (), shims_compiled=shims)
        return _READY
    from numba.core import event

    start = time.perf_counter()
    with event.install_recorder("numba:compile") as recorder:
        problems = _problems()
        _warm_post(problems)
        _warm_network(problems)
    compiled = sum(1 for _, ev in recorder.buffer if ev.is_start)
    shims = _warm_shims()
    _READY = WarmupReport(
        compiled, time.perf_counter() - start, cache_location(), KERNELS, shims_compiled=shims
    )
    return _READY


def warmup_logged(logger: logging.Logger | None = None) -> WarmupReport:
    """:func:`warmup`, then one INFO line saying what it did and how long it took."""
    report = warmup()
    if not report.in_memory:
        (logger or log).info("%s", report.line())
    return report
