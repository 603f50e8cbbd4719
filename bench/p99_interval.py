"""How far a rerun moves a run's p99 call time, against the block-bootstrap interval of one run.

``qpbench run`` ranks backends by the p99 of their per-tick call times and gives each p99 an
interval from the tick log of its one run (:func:`qpbench.sim.summary.block_bootstrap_quantile`).
This script runs each (scenario, backend) ``--repeats`` times, one run after the other in this
process (as a ``--jobs 1`` run times them), and prints per block length (ticks) the median
relative half-width of the 95 % intervals and the share of the other runs' p99 that fall inside
each run's interval, beside the spread of the p99 over the reruns (its median absolute deviation
and range, relative to the median). A rerun's p99 has noise of its own, so a well-calibrated
interval holds it somewhat less often than 95 % (about 83 % when both are normal and equally
wide). The load average is printed with the figures.

    python bench/p99_interval.py [--scenarios wall,narrow] [--backends daqp,qpoases,piqp]
        [--repeats 6] [--blocks 1,10,50,200,1000]
"""

from __future__ import annotations

import argparse
import itertools
import os

import numpy as np
import pandas as pd


def runs(scenario: str, backend: str, repeats: int) -> list[np.ndarray]:
    """The per-tick call times [s] of ``repeats`` runs, each after a 3-tick warm-up."""
    from qpbench.jit import warmup
    from qpbench.sim import log
    from qpbench.sim.loop import simulate
    from qpbench.sim.scenario import load_scenario

    warmup([backend])
    sc = load_scenario(scenario)
    out = []
    for _ in range(repeats):
        simulate(sc, backend, duration=3 * sc.dt)
        out.append(simulate(sc, backend).log[log.SOLVE_TIME].to_numpy(dtype=float))
    return out


def main() -> None:
    from qpbench.sim.summary import block_bootstrap_quantile

    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--scenarios", default="wall,narrow")
    parser.add_argument("--backends", default="daqp,qpoases,piqp")
    parser.add_argument("--repeats", type=int, default=6)
    parser.add_argument("--blocks", default="1,10,50,200,1000")
    args = parser.parse_args()
    blocks = [int(b) for b in args.blocks.split(",")]
    rows = []
    for scenario, backend in itertools.product(args.scenarios.split(","), args.backends.split(",")):
        times = runs(scenario, backend, args.repeats)
        p99 = np.array([np.quantile(t, 0.99) for t in times])
        mid = float(np.median(p99))
        row = {"scenario": scenario, "backend": backend, "p99 median [us]": round(mid * 1e6, 1)}
        row["rerun MAD %"] = round(100 * float(np.median(np.abs(p99 - mid))) / mid, 1)
        row["rerun range %"] = round(100 * float(p99.max() - p99.min()) / mid, 1)
        for block in blocks:
            ci = [block_bootstrap_quantile(t, 0.99, block) for t in times]
            half = np.median([(hi - lo) / 2 / p for (lo, hi), p in zip(ci, p99)])
            held = [
                lo <= p99[j] <= hi
                for i, (lo, hi) in enumerate(ci)
                for j in range(len(times))
                if j != i
            ]
            row[f"L={block}: half %"] = round(100 * float(half), 1)
            row[f"L={block}: holds %"] = round(100 * float(np.mean(held)), 0)
        rows.append(row)
        print(pd.DataFrame([row]).to_string(index=False), flush=True)
    print(f"load average {' '.join(f'{x:.2f}' for x in os.getloadavg())}; {args.repeats} runs each")
    print(pd.DataFrame(rows).to_string(index=False))


if __name__ == "__main__":
    main()
