"""Closed-loop results of the ``rnn`` backend: the runs and the summary table.

    python bench/rnn_closed_loop.py run      # results/rnn/summaries/<scenario>_<setting>.json, one run at a time
    python bench/rnn_closed_loop.py table    # results/rnn/summaries/*.json -> results/rnn/closed_loop.md
    python bench/rnn_closed_loop.py sweep    # eps / l1 clip on wall, 8 s: the table in results/rnn/README.md

``run`` runs ``qpbench simulate`` for each shipped scenario twice: as the
file says (its ``[rnn]`` table carries the paper's ``eps = 0.02``: setting
"paper") and with the working setting set over the file's
(:data:`qpbench.backends.rnn.WORKING_SETTINGS`, as ``--set rnn.KEY=VALUE``:
setting "working"). The commands it runs are printed; results/rnn/README.md
lists them.
"""

from __future__ import annotations

import json
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
#: Where the summaries and the table go.
OUT = ROOT / "results" / "rnn"
SETTINGS = ("paper", "working")


def scenarios() -> list[str]:
    """Every shipped scenario (the paper's first, in its order)."""
    from qpbench.sim.scenario import scenario_names

    return scenario_names()


def working_overrides() -> list[str]:
    """``--set`` items of the working setting."""
    from qpbench.backends.rnn import WORKING_SETTINGS

    return [f"rnn.{k}={v!r}" for k, v in WORKING_SETTINGS.items()]


def commands() -> list[list[str]]:
    """The ``qpbench`` argument lists of every run."""
    out = []
    for name in scenarios():
        for setting in SETTINGS:
            args = [
                "simulate",
                "--scenario",
                name,
                "--backend",
                "rnn",
                "--summary",
                str((OUT / "summaries" / f"{name}_{setting}.json").relative_to(ROOT)),
                "--force",
            ]
            if setting == "working":
                for item in working_overrides():
                    args += ["--set", item]
            out.append(args)
    return out


def run_all() -> None:
    import os

    from qpbench.cli import main

    os.chdir(ROOT)
    for args in commands():
        print("qpbench " + " ".join(args), flush=True)
        code = main(args)
        if code not in (0, 1):
            raise SystemExit(code)


def _fmt(x, spec):
    return "-" if x is None else format(x, spec)


def write_table() -> None:
    from qpbench.atomic import write_text
    from qpbench.sim.scenario import load_scenario

    rows = [
        "| scenario | setting | eps [s] | sub-steps | l1 clip | tracking rms / max after 2 s [m] "
        "| force error rms / max after 2 s [N] | final force [N] | min key-point distance [m] (point, t [s]) "
        "| min body distance [m] (link, t [s]) "
        "| joint angle / speed limit violations [ticks] | max abs v [rad/s] | non-optimal ticks | infeasible ticks "
        "| verdict |",
        "|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|",
    ]
    for name in scenarios():
        for setting in SETTINGS:
            path = OUT / "summaries" / f"{name}_{setting}.json"
            if not path.exists():
                continue
            s = json.loads(path.read_text())
            rnn = dict(load_scenario(name).rnn)
            for key, value in s.get("scenario_overrides", {}).items():
                if key.startswith("rnn."):
                    rnn[key[4:]] = value
            non_opt = s.get("non_optimal_ticks")
            if non_opt is None:  # a summary written before the key existed
                non_opt = sum(v for k, v in s.get("status_counts", {}).items() if k != "optimal")
            dmin = "-"
            if s["min_obstacle_distance"] is not None:
                dmin = (
                    f"{s['min_obstacle_distance']:.4f} ({s['min_obstacle_distance_key_point']}, "
                    f"{s['min_obstacle_distance_t']:.3f})"
                )
            body = "-"
            if s["min_body_distance"] is not None:
                body = (
                    f"{s['min_body_distance']:.4f} ({s['min_body_distance_link']}, "
                    f"{s['min_body_distance_t']:.3f})"
                )
            rows.append(
                f"| {name} | {setting} | {rnn.get('eps', '-')} | {rnn.get('substeps', 'auto')} "
                f"| {rnn.get('l1_clip', '-')} "
                f"| {_fmt(s['tracking_rms_after_2s'], '.2e')} / {_fmt(s['tracking_max_after_2s'], '.2e')} "
                f"| {_fmt(s['force_error_rms_after_2s'], '.3g')} / {_fmt(s['force_error_max_after_2s'], '.3g')} "
                f"| {_fmt(s['force_final'], '.4g')} | {dmin} | {body} "
                f"| {s['joint_limit_violations']} / {s['joint_velocity_limit_violations']} "
                f"| {_fmt(s['max_abs_v'], '.3g')} | {non_opt} of {s['ticks']} | {s['infeasible_ticks']} "
                f"| {s['verdict']} |"
            )
    text = (
        "# rnn in closed loop, 20 s per scenario\n\n"
        "Produced by `python bench/rnn_closed_loop.py run` (the `qpbench simulate` commands in README.md beside it);\n"
        "numbers from `summaries/<scenario>_<setting>.json` (the summary `qpbench simulate --summary` writes).\n"
        "The verdict is qpbench's (the scenario file's `[verdict]` thresholds: tracking within 1 mm and force\n"
        "error within 0.5 N after 2 s, no part of the arm's body inside an obstacle; a key point closer than\n"
        "d_safe - 5e-4 m = 0.0095 m breaks the paper's key-point rule, reported, not judged).\n"
        '"non-optimal ticks": the network\'s state at the end of the tick was not within the default\n'
        "profile's tolerance (1e-6) of the tick's KKT conditions (status max_iter); the loop applies it\n"
        'anyway, as the paper does. "infeasible ticks": ticks the backend\n'
        "declared infeasible; the network never does.\n\n" + "\n".join(rows) + "\n"
    )
    write_text(OUT / "closed_loop.md", text)
    print(text)


#: ``(eps [s], l1 clip or None)`` of the sweep on wall (auto sub-steps, Euler).
SWEEP = (
    (0.02, None),
    (0.02, 10.0),
    (0.01, None),
    (0.005, None),
    (0.005, 10.0),
    (0.001, None),
    (0.001, 10.0),
    (0.0001, 10.0),
)


def sweep(duration: float = 8.0) -> None:
    """Print the eps / l1-clip table of results/rnn/README.md: ``wall`` for ``duration`` s, auto sub-steps."""
    from dataclasses import replace

    from qpbench.sim.loop import simulate
    from qpbench.sim.scenario import load_scenario

    base = load_scenario("wall")
    print(f"wall, {duration:g} s, backend rnn, Euler, auto sub-steps")
    print(
        "| eps [s] | l1 clip | tracking max after 2 s [m] | force error max [N] | min distance [m] |"
    )
    print("|---|---|---|---|---|")
    for eps, clip in SWEEP:
        rnn = {"eps": eps} if clip is None else {"eps": eps, "l1_clip": clip}
        s = simulate(replace(base, rnn=rnn), "rnn", duration=duration).summary
        t = s["min_obstacle_distance_t"]
        at = (
            f" (t = {t:.2f} s)"
            if s["min_obstacle_distance"] < s["d_safe"] - 5e-4 and t < 2.0
            else ""
        )
        print(
            f"| {eps:g} | {'-' if clip is None else f'{clip:g}'} | {s['tracking_max_after_2s']:.2g} "
            f"| {s['force_error_max_after_2s']:.3g} | {s['min_obstacle_distance']:.2g}{at} |",
            flush=True,
        )


if __name__ == "__main__":
    if len(sys.argv) != 2 or sys.argv[1] not in ("run", "table", "sweep"):
        raise SystemExit(__doc__)
    {"run": run_all, "table": write_table, "sweep": sweep}[sys.argv[1]]()
