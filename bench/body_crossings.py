"""Time the body rule between ticks adds to a run's summary (:func:`qpbench.robot.body.body_crossings`).

For each scenario and backend: one run (20 s at 1 kHz by default), then ``--repeat`` timings of
its whole summary (:func:`qpbench.sim.summary.summarize`) and of the crossing figures alone;
medians in milliseconds, and the crossings found. The load average is printed with the figures:
the machine may be shared.

    python bench/body_crossings.py [--scenarios wall,narrow,moving_disk] [--backends daqp,pinv]
        [--duration 20] [--repeat 7]
"""

from __future__ import annotations

import argparse
import os
import time

import numpy as np

from qpbench.sim import summary
from qpbench.sim.loop import simulate
from qpbench.sim.scenario import load_scenario


def _median_ms(call, repeat: int) -> float:
    times = []
    for _ in range(repeat):
        start = time.perf_counter()
        call()
        times.append(time.perf_counter() - start)
    return 1e3 * float(np.median(times))


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--scenarios", default="wall,narrow,moving_disk")
    parser.add_argument("--backends", default="daqp,pinv")
    parser.add_argument("--duration", type=float, default=20.0)
    parser.add_argument("--repeat", type=int, default=7)
    args = parser.parse_args()
    print(f"load average {os.getloadavg()[0]:.2f}; medians of {args.repeat}")
    print(f"{'scenario':<12} {'backend':<8} {'ticks':>6} {'summary [ms]':>13} "
          f"{'between ticks [ms]':>19} {'crossings':>9}")  # fmt: skip
    for name in args.scenarios.split(","):
        scenario = load_scenario(name, overrides={"simulation.duration": args.duration})
        controller = scenario.make_controller()
        for backend in args.backends.split(","):
            run = simulate(scenario, backend)
            t = run.log["t"].to_numpy()
            whole = _median_ms(
                lambda: summary.summarize(run.log, scenario, controller, backend, "paper", 1.0),
                args.repeat,
            )
            between = _median_ms(
                lambda: summary._crossing_figures(run.log, t, controller, scenario.dt), args.repeat
            )
            print(
                f"{name:<12} {backend:<8} {len(t):>6} {whole:>13.1f} {between:>19.1f} "
                f"{run.summary['body_crossings']:>9}"
            )


if __name__ == "__main__":
    main()
