"""The online network's safety frontier: settings against the minimum key-point distance.

    python bench/rnn_frontier.py [--duration 20] [--scenarios free,wall,...] [--settings NAME,...]

For each shipped scenario and each setting of :data:`SETTINGS` (``eps`` [s],
sub-steps per 1 ms tick or ``auto``, Euler or semi-implicit, ``l1`` clip),
one closed-loop run of the online network, the same as::

    qpbench simulate --scenario S --backend rnn --set rnn.eps=E --set rnn.substeps=N \\
        --set rnn.method=M --set rnn.l1_clip=C --set simulation.duration=D

and one row: the minimum key-point distance ``d_min`` [mm] against the
scenario's ``d_safe`` (bar: ``d_safe - 0.5 mm``), tracking and force error
maxima after 2 s, the per-tick solve time of the loop (median and p99 [us],
``simulate``'s log) and the steps a tick took (sub-steps clamped to the
stability bound show as more steps than set). Printed as a markdown table;
nothing is written.
"""

from __future__ import annotations

import argparse
from dataclasses import replace

import numpy as np

SCENARIOS = ("free", "wall", "adaptive", "narrow", "adaptive_fast")

#: name -> [rnn] settings (over the scenario file's). "tuned" is rnn-tuned's default.
SETTINGS = {
    "paper (eps 20 ms, auto)": {"eps": 0.02},
    "eps 1 ms, 5, clip 10": {"eps": 1e-3, "substeps": 5, "l1_clip": 10.0},
    "eps 1 ms, 5, no clip": {"eps": 1e-3, "substeps": 5},
    "eps 1 ms, 20, clip 10": {"eps": 1e-3, "substeps": 20, "l1_clip": 10.0},
    "eps 1 ms, 5 semi, clip 10": {
        "eps": 1e-3,
        "substeps": 5,
        "method": "semi-implicit",
        "l1_clip": 10.0,
    },
    "eps 1 ms, 5, clip 1": {"eps": 1e-3, "substeps": 5, "l1_clip": 1.0},
    "eps 0.5 ms, 10, clip 10": {"eps": 5e-4, "substeps": 10, "l1_clip": 10.0},
    "eps 0.2 ms, 25, clip 10": {"eps": 2e-4, "substeps": 25, "l1_clip": 10.0},
    "eps 0.2 ms, 10 semi, clip 10": {
        "eps": 2e-4,
        "substeps": 10,
        "method": "semi-implicit",
        "l1_clip": 10.0,
    },
    "eps 0.1 ms, auto, clip 10": {"eps": 1e-4, "l1_clip": 10.0},
    "eps 0.1 ms, 50, clip 10": {"eps": 1e-4, "substeps": 50, "l1_clip": 10.0},
    "eps 0.1 ms, 20 semi, clip 10": {
        "eps": 1e-4,
        "substeps": 20,
        "method": "semi-implicit",
        "l1_clip": 10.0,
    },
    "eps 0.05 ms, 100, clip 10": {"eps": 5e-5, "substeps": 100, "l1_clip": 10.0},
}


def run(scenario: str, rnn: dict, duration: float) -> dict:
    from qpbench.sim.loop import simulate
    from qpbench.sim.scenario import load_scenario

    sc = load_scenario(scenario)
    sc = replace(sc, rnn={**sc.rnn, **rnn})
    result = simulate(sc, "rnn", duration=duration)
    s, log = result.summary, result.log
    t = log["solve_time_s"].to_numpy()
    # the steps of each tick, from a second (identical, untimed) run through a counting wrapper
    from qpbench.backends import get_backend

    be = get_backend("rnn", dt=sc.dt, **sc.rnn)
    counts = []
    solve = be.solve

    def counting(problem, warm_start=None):
        sol = solve(problem, warm_start)
        counts.append(sol.iterations)
        return sol

    be.solve = counting
    again = simulate(sc, be, duration=duration).summary
    assert again["min_obstacle_distance"] == s["min_obstacle_distance"]
    steps = np.array(counts, dtype=float)
    return {
        "d_min": s["min_obstacle_distance"],
        "d_safe": s["d_safe"],
        "d_min_t": s["min_obstacle_distance_t"],
        "track": s["tracking_max_after_2s"],
        "force": s["force_error_max_after_2s"],
        "median_us": float(np.median(t)) * 1e6,
        "p99_us": float(np.percentile(t, 99)) * 1e6,
        "steps": (int(np.nanmin(steps)), int(np.nanmax(steps)))
        if np.isfinite(steps).any()
        else None,
    }


def _mm(d):
    return "-" if d is None or not np.isfinite(d) else f"{d * 1e3:.2f}"


def main(argv=None) -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument(
        "--duration", type=float, default=20.0, help="simulated seconds per run (default 20)"
    )
    parser.add_argument("--scenarios", default=",".join(SCENARIOS))
    parser.add_argument(
        "--settings", default=None, help="comma-separated names of SETTINGS (default all)"
    )
    args = parser.parse_args(argv)
    names = (
        list(SETTINGS) if args.settings is None else [n.strip() for n in args.settings.split(";")]
    )
    # compile the kernels before the first timed run
    run("free", SETTINGS[names[0]], 0.01)
    print(
        f"{args.duration:g} s per run; d_min bar: d_safe - 0.5 mm; times: the loop's per-tick solve [us]"
    )
    print(
        "| scenario | setting | d_min [mm] (t [s]) | bar held | tracking max after 2 s [m] "
        "| force error max after 2 s [N] | solve median / p99 [us] | steps per tick |"
    )
    print("|---|---|---|---|---|---|---|---|")
    for scenario in args.scenarios.split(","):
        for name in names:
            r = run(scenario, SETTINGS[name], args.duration)
            held = (
                "-"
                if r["d_min"] is None
                else ("yes" if r["d_min"] >= r["d_safe"] - 5e-4 else "**no**")
            )
            dmin = "-" if r["d_min"] is None else f"{_mm(r['d_min'])} ({r['d_min_t']:.3f})"
            steps = (
                "-"
                if r["steps"] is None
                else (
                    f"{r['steps'][0]}"
                    if r["steps"][0] == r["steps"][1]
                    else f"{r['steps'][0]}-{r['steps'][1]}"
                )
            )
            track = "-" if r["track"] is None else f"{r['track']:.2g}"
            force = "-" if r["force"] is None else f"{r['force']:.3g}"
            print(
                f"| {scenario} | {name} | {dmin} | {held} | {track} | {force} "
                f"| {r['median_us']:.1f} / {r['p99_us']:.1f} | {steps} |",
                flush=True,
            )


if __name__ == "__main__":
    main()
