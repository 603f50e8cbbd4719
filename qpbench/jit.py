"""Every compiled kernel of qpbench, compiled (or loaded from numba's cache) before any clock,
only for the backends a command runs: the groups :data:`KERNELS`, ``engine:<backend>``
(:mod:`qpbench.engine.compiled`) and :data:`SHIM`, warmed on :data:`_SCENARIOS`' QPs.
"""

from __future__ import annotations

import logging
import os
import time
from collections.abc import Iterable
from dataclasses import dataclass

from .cache import PACKAGE_DIR

#: Kernel groups :func:`warmup` prepares, in order.
KERNELS = ("controller", "post", "network", "pinv")
#: The groups every closed loop runs (the controller's tick build, the plant step).
LOOP_KERNELS = ("controller", "post")

#: The name :func:`kernels_for` gives the qpoases backend's native shim.
SHIM = "qpoases-shim"
#: Prefix of the group of a backend's compiled engine (``engine:daqp``).
ENGINE = "engine:"
#: Everything :func:`warmup` can prepare, in order.
_ALL = (*KERNELS, SHIM)
#: Shipped scenarios whose controllers give the QP shapes warmed: obstacle rows, none.
_SCENARIOS = ("wall", "free")


@dataclass(frozen=True)
class WarmupReport:
    """What :func:`warmup` did: ``compiled`` specialisations in ``seconds`` [s], numba's
    ``cache`` folder, the ``kernels`` prepared (``in_memory``: ready before the call)."""

    compiled: int
    seconds: float
    cache: str
    kernels: tuple[str, ...]
    in_memory: bool = False
    shims_compiled: int = 0

    def line(self) -> str:
        """One line for the log."""
        shims = self.shims_compiled
        if self.in_memory:
            return "kernels already loaded in this process"
        if not self.kernels:
            if shims:
                return f"native shim: compiled {shims} in {self.seconds:.1f} s"
            return "kernels: none needed by these backends"
        if self.compiled or shims:
            return (
                f"kernels: compiled {self.compiled}{f' and {shims} native shim' if shims else ''}"
                f" (first run with this cache) and cached in {self.cache} in {self.seconds:.1f} s;"
                " later runs load them"
            )
        return (
            f"kernels: loaded from the cache in {self.cache} in {self.seconds:.2f} s (0 compiled)"
        )


#: Kernel groups and shims prepared in this process so far.
_DONE: set[str] = set()


def _problems():
    """The tick QPs of :data:`_SCENARIOS`, both formulations; also warms the build kernel."""
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


def _warm_loop(engines: Iterable[str]) -> None:
    """A few ticks of a closed loop on the Python engine, then on each compiled one of ``engines``."""
    from .sim.loop import simulate

    for name in ("adaptive", "free"):
        simulate(name, "pinv", duration=0.003, engine="python", warmup_ticks=0)
        for backend in engines:
            simulate(name, backend, duration=0.003, engine="compiled", warmup_ticks=0)


def kernels_for(backends: Iterable[str] | None, loop: bool = True) -> tuple[str, ...]:
    """What :func:`warmup` prepares for ``backends`` (``None``: everything), in order:
    :data:`LOOP_KERNELS` when ``loop``, the backends' ``kernels``, :data:`SHIM`, engines."""
    from .backends import backend_class
    from .engine.compiled import SOLVERS
    from .exceptions import BackendNotFound

    if backends is None:
        return _ALL
    wanted = set(LOOP_KERNELS) if loop else set()
    for name in backends:
        try:
            cls = backend_class(name)
        except BackendNotFound:
            continue
        wanted.update(cls.kernels)
        if cls.name == "qpoases":
            wanted.add(SHIM)
        if loop and cls.name in SOLVERS:
            wanted.add(ENGINE + cls.name)
    return _in_order(wanted)


def prepared() -> tuple[str, ...]:
    """The kernel groups (and shims) prepared in this process so far, in :data:`KERNELS` order."""
    return _in_order(_DONE)


def _in_order(names: set[str]) -> tuple[str, ...]:
    """``names`` in :data:`_ALL`'s order, then the engines by name."""
    engines = sorted(k for k in names if k.startswith(ENGINE))
    return tuple(k for k in _ALL if k in names) + tuple(engines)


def warmup(backends: Iterable[str] | None = None, loop: bool = True) -> WarmupReport:
    """Compile or load what ``backends`` use (:func:`kernels_for`) unless already prepared."""
    return prepare(kernels_for(backends, loop))


def prepare(wanted: Iterable[str]) -> WarmupReport:
    """:func:`warmup` of named kernel groups and shims (names of :func:`kernels_for`)."""
    from .backends import backend_class
    from .runner.process import preload_kernels

    wanted = tuple(wanted)
    cache = os.environ.get("NUMBA_CACHE_DIR") or f"{PACKAGE_DIR}/**/__pycache__"
    todo = [k for k in wanted if k not in _DONE]
    if not todo:  # nothing these backends need (said once in the log), or all prepared before
        ready = tuple(k for k in wanted if k in KERNELS)
        return WarmupReport(0, 0.0, cache, ready, in_memory=bool(wanted))
    start = time.perf_counter()
    kernels = tuple(k for k in todo if k in KERNELS)
    compiled = 0
    if kernels or any(k.startswith(ENGINE) for k in todo):
        from numba.core import event

        with event.install_recorder("numba:compile") as recorder:
            problems = _problems()  # also warms the controller's build kernel
            engines = [k[len(ENGINE) :] for k in todo if k.startswith(ENGINE)]
            if "post" in kernels or engines:  # the loop's step and law, each engine asked for
                _warm_loop(engines)
            if "network" in kernels:
                _warm_network(problems)
            if "pinv" in kernels:  # the pseudo-inverse's kernel, with and without equalities
                from .backends import get_backend

                for *_, problem in problems[:2]:
                    get_backend("pinv").solve(problem)
        compiled = sum(1 for _, ev in recorder.buffer if ev.is_start)
        kernels = tuple(k for k in KERNELS if k in kernels or k == "controller")
        todo.append("controller")
    shims = 0
    qpoases = backend_class("qpoases")
    if SHIM in todo and qpoases.unavailable_reason() is None:
        shims = int(qpoases.needs_compile())  # the native shim: compiled the first time, loaded
        qpoases.prepare()
    _DONE.update(todo)
    preload_kernels(prepared())  # what the worker processes' forkserver loads
    return WarmupReport(compiled, time.perf_counter() - start, cache, kernels, shims_compiled=shims)


def warmup_logged(logger: logging.Logger, backends: Iterable[str], loop: bool = True) -> None:
    """:func:`warmup`, then one INFO line on ``logger`` saying what it did and how long it took."""
    report = warmup(backends, loop)
    if not report.in_memory:
        logger.info("%s", report.line())
