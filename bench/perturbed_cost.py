"""The cost of one perturbed instance's run (``qpbench run``'s perturbed runs) in one process,
beside the estimates the funding uses: the wall time of a first "one-tick" run (how the runs
were funded before: a whole instance, the one tick being ignored with an instance's text), the
median CPU time of one-tick runs after an untimed one (how they are funded now), and the wall
and CPU time of whole instances as a sweep runs them (DAQP and the noise floor, compiled
engine). Prints the load average before and after.

    PYTHONPATH=$PWD python bench/perturbed_cost.py [SCENARIO] [DURATION|full] [INSTANCES]
"""

import os
import statistics
import sys
import time
from dataclasses import replace
from pathlib import Path

from qpbench.harness.closed_loop import LoopTask, run_row
from qpbench.jit import warmup
from qpbench.sweep.spec import load_sweep, sample_instances

ROOT = Path(__file__).resolve().parents[1]


def timed(task: LoopTask) -> tuple[float, float]:
    """Wall and CPU time [s] of one run."""
    w, c = time.perf_counter(), time.process_time()
    run_row(task)
    return time.perf_counter() - w, time.process_time() - c


def main() -> None:
    args = sys.argv[1:] + ["wall", "1.0", "10"][len(sys.argv) - 1 :]
    scenario, length, count = args[0], args[1], int(args[2])
    print("load average before", os.getloadavg())
    path = ROOT / "problems" / "sweeps" / f"{scenario}.toml"
    spec = load_sweep(path) if length == "full" else load_sweep(path, duration=float(length))
    drawn = sample_instances(replace(spec, samples=2 * count + 4))
    valid = [i for i in drawn if i.invalid is None][: count + 1]
    warmup(["daqp", "noop"])
    terms = LoopTask("", "", bands=(spec.force_band, spec.tracking_band), p99_interval=False)
    tick = replace(terms, scenario="x.toml", scenario_text=valid[0].text)
    tick = replace(tick, duration=float(spec.base_raw["simulation"]["dt"]))
    # before: a first run's wall time, with the p99 interval and, the one tick ignored with an
    # instance's text, the whole instance
    first = timed(replace(tick, backend="daqp", p99_interval=True, duration=None))
    print(f"before: first 'one-tick' run, wall {first[0]:.3f} s")
    for backend in ("daqp", "noop"):
        cpu = [timed(replace(tick, backend=backend))[1] for _ in range(4)][1:]
        print(f"now: one-tick {backend}, median CPU {statistics.median(cpu):.3f} s")
    for backend in ("daqp", "noop"):
        runs = [
            timed(replace(terms, scenario=f"{i.name}.toml", backend=backend, scenario_text=i.text))
            for i in valid[1:]
        ]
        wall, cpu = statistics.median(r[0] for r in runs), statistics.median(r[1] for r in runs)
        print(
            f"{backend}: {len(runs)} instances of {length} s, median wall {wall:.3f} s, CPU {cpu:.3f} s"
        )
    print("load average after", os.getloadavg())


if __name__ == "__main__":
    main()
