"""Median build time of a tick's QP on the compiled engine, and the run's real-time factor.

Runs each scenario's full duration with DAQP on the compiled engine ``--repeat`` times and
prints, per scenario, the median over the runs of the run's median ``build_time_s`` and
``tick_time_s`` [us] and of its real-time factor (simulated over wall time).

    PYTHONPATH=$PWD python bench/engine_build.py [--repeat 3] [wall narrow panda_table]
"""

from __future__ import annotations

import argparse
import os

import numpy as np

from qpbench.sim.loop import simulate
from qpbench.sim.scenario import load_scenario


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("scenarios", nargs="*", default=["wall", "narrow", "panda_table"])
    parser.add_argument("--repeat", type=int, default=3)
    parser.add_argument("--backend", default="daqp")
    args = parser.parse_args()
    print(f"load average before: {os.getloadavg()}")
    print(f"{'scenario':<12} {'rows':>4} {'build [us]':>10} {'tick [us]':>9} {'RTF':>6}  verdict")
    for name in args.scenarios:
        simulate(name, args.backend, duration=0.1)  # compiled, or loaded from the cache
        runs = [simulate(name, args.backend, engine="compiled") for _ in range(args.repeat)]
        build = np.median([r.summary["build_time_median_s"] for r in runs]) * 1e6
        tick = np.median([r.summary["tick_time_median_s"] for r in runs]) * 1e6
        rtf = np.median([r.summary["real_time_factor"] for r in runs])
        rows = load_scenario(name).make_controller().n_rows
        s = runs[0].summary
        print(f"{name:<12} {rows:>4} {build:>10.2f} {tick:>9.2f} {rtf:>6.0f}  {s['verdict']}")
    print(f"load average after: {os.getloadavg()}")


if __name__ == "__main__":
    main()
