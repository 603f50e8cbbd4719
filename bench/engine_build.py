"""Median build time of a tick's QP on the compiled engine, and the run's real-time factor.

Runs each scenario's full duration with DAQP on the compiled engine ``--repeat`` times and
prints, per scenario, the median over the runs of the run's median ``build_time_s`` and
``tick_time_s`` [us] and of its real-time factor (simulated over wall time); then the build
kernel alone (``kernel [ns]``): the compiled build called in a compiled loop over the joint
angles of the last run's ticks, compiled as the engine is (without numba's runtime), the least
over 30 passes of the thread's CPU time per build (less moved by other work on the machine than
the run's wall-clock medians).

    PYTHONPATH=$PWD python bench/engine_build.py [--repeat 3] [wall narrow panda_table]
"""

from __future__ import annotations

import argparse
import os
import time
from functools import cache

import numpy as np

from qpbench.control.build_kernel import compiled_build_kernel, packed_layout
from qpbench.sim.loop import simulate
from qpbench.sim.scenario import load_scenario


@cache
def build_loop():
    """``loop(model, thetas, kp, kd, soft, buf)``: the compiled build of each row of ``thetas``."""
    import numba

    build = compiled_build_kernel()

    @numba.njit(_nrt=False)  # as the engine: no reference counts
    def loop(model, thetas, kp, kd, soft, buf):
        for k in range(thetas.shape[0]):
            build(model, thetas[k], k * 1e-3, kp, kd, soft, buf)

    return loop


def kernel_ns(name: str, log) -> float:
    """Least CPU time per build [ns] over 30 passes of the build over ``log``'s joint angles."""
    ctrl = load_scenario(name).make_controller()
    thetas = np.ascontiguousarray(log[[f"theta_{i}" for i in range(ctrl.n)]].to_numpy())
    buf = np.zeros(packed_layout(ctrl.n, ctrl.n_rows, ctrl.dim)[0])
    args = (ctrl.model, thetas, ctrl.kp, ctrl.kd, False, buf)
    build_loop()(*args)
    times = []
    for _ in range(30):
        start = time.thread_time_ns()
        build_loop()(*args)
        times.append((time.thread_time_ns() - start) / len(thetas))
    return min(times)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("scenarios", nargs="*", default=["wall", "narrow", "panda_table"])
    parser.add_argument("--repeat", type=int, default=3)
    parser.add_argument("--backend", default="daqp")
    args = parser.parse_args()
    print(f"load average before: {os.getloadavg()}")
    print(
        f"{'scenario':<12} {'rows':>4} {'build [us]':>10} {'tick [us]':>9} {'RTF':>6} "
        f"{'kernel [ns]':>11}  verdict"
    )
    for name in args.scenarios:
        simulate(name, args.backend, duration=0.1)  # compiled, or loaded from the cache
        runs = [simulate(name, args.backend, engine="compiled") for _ in range(args.repeat)]
        build = np.median([r.summary["build_time_median_s"] for r in runs]) * 1e6
        tick = np.median([r.summary["tick_time_median_s"] for r in runs]) * 1e6
        rtf = np.median([r.summary["real_time_factor"] for r in runs])
        rows = load_scenario(name).make_controller().n_rows
        s = runs[0].summary
        ns = kernel_ns(name, runs[-1].log)
        print(
            f"{name:<12} {rows:>4} {build:>10.2f} {tick:>9.2f} {rtf:>6.0f} {ns:>11.0f}  "
            f"{s['verdict']}"
        )
    print(f"load average after: {os.getloadavg()}")


if __name__ == "__main__":
    main()
