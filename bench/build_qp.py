"""Median time to build one control tick's QP (paper eq. 11), per scenario.

Target: at most 15 us per tick (the numpy prototype took 21-30 us). Times
``Controller.build`` (kinematics, impedance reference, bounds, obstacle rows and
the ``qpsolvers.Problem``) on the states of a closed-loop run, after the
kernel is compiled. Also prints the numpy reference path for comparison.

    python bench/build_qp.py [--ticks 2000] [--repeat 5] [SCENARIO ...]

SCENARIO: shipped names or scenario files (default the paper's four), e.g. the scaling
study's sizes in ``results/scaling/scenarios/``.
"""

from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

import numpy as np

from qpbench.sim.loop import simulate
from qpbench.sim.scenario import load_scenario

sys.path.insert(0, str(Path(__file__).resolve().parent.parent / "tests"))
from controller_numpy import numpy_arrays  # noqa: E402 - the numpy twin, a test oracle


def median_us(fn, states, repeat):
    best = []
    for _ in range(repeat):
        times = np.empty(len(states))
        for i, (theta, t, kp, kd) in enumerate(states):
            t0 = time.perf_counter_ns()
            fn(theta, t, kp, kd)
            times[i] = time.perf_counter_ns() - t0
        best.append(np.median(times))
    return min(best) / 1e3


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument(
        "--ticks", type=int, default=2000, help="states sampled from a closed-loop run"
    )
    parser.add_argument("--repeat", type=int, default=5)
    parser.add_argument(
        "--backend", default="qpsolvers:daqp", help="backend of the run that provides the states"
    )
    parser.add_argument("scenarios", nargs="*", default=["free", "wall", "adaptive", "narrow"])
    args = parser.parse_args()
    print(
        f"{'scenario':<14} {'rows':>4} {'build [us]':>10} {'arrays only [us]':>16} {'numpy terms [us]':>16}"
    )
    for name in args.scenarios:
        sc = load_scenario(name)
        name = Path(name).stem
        res = simulate(sc, args.backend, duration=args.ticks * sc.dt)
        n = sc.make_arm().n
        log = res.log
        states = [
            (
                np.ascontiguousarray(row[[f"theta_{i}" for i in range(n)]].to_numpy(float)),
                float(row["t"]),
                float(row["kp_hat"]),
                float(row["kd_hat"]),
            )
            for _, row in log.iterrows()
        ]
        ctrl = sc.make_controller()
        ctrl.build(*states[0])
        build = median_us(lambda th, t, kp, kd: ctrl.build(th, t, kp, kd), states, args.repeat)
        arrays = median_us(
            lambda th, t, kp, kd: ctrl.make_problem(ctrl.build_arrays(th, t, kp, kd), False),
            states,
            args.repeat,
        )
        ref = median_us(
            lambda th, t, kp, kd: ctrl.make_problem(
                numpy_arrays(ctrl, th, t, kp, kd, False), False
            ),
            states[:500],
            1,
        )
        print(f"{name:<14} {ctrl.n_rows:>4} {build:>10.2f} {arrays:>16.2f} {ref:>16.2f}")
    print("target: build <= 15 us median per tick")


if __name__ == "__main__":
    main()
