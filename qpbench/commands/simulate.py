"""``qpbench simulate``: run a scenario in closed loop with one backend; log, summary, dump, plot.

The output ends with the real-time line, then the verdict (:mod:`qpbench.sim.verdict`), which
is the exit code."""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path

from .options import add, check_tables, log, pick

HELP = "simulate a scenario in closed loop with one backend solving every tick's QP"
EXAMPLE = (
    "qpbench simulate --scenario wall --backend daqp --summary wall.json "
    "--log wall.parquet --dump wall-set --every 10 --plot wall.png; "
    "qpbench simulate --scenario wall --backend rnn --set rnn.eps=0.001 --set rnn.substeps=5; "
    "qpbench simulate --scenario narrow --backend daqp --snapshot narrow.png --animate narrow.gif"
)


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument(
        "--scenario",
        required=True,
        metavar="NAME|PATH",
        help="a shipped scenario's name (`qpbench scenarios` lists them: wall, narrow, panda_table, "
        "...) or a .toml file",
    )
    parser.add_argument(
        "--backend",
        required=True,
        metavar="NAME",
        help="backend name (see `qpbench backends`), e.g. qpsolvers:daqp, clarabel, rnn",
    )
    add(parser, "--formulation", "--duration", "--set", "--profile", "--deadline", "--engine")
    parser.add_argument(
        "--dt", type=float, metavar="S", help="control period in [s] (default: the scenario's)"
    )
    for flag, metavar, text in (
        ("--log", "FILE", "per-tick log, .csv or .parquet"),
        ("--summary", "FILE", "summary as JSON ('-': to stdout)"),
        ("--dump", "DIR", "the ticks' QPs as a problem set (problems.parquet + manifest.json)"),
        ("--plot", "FILE", "figure of the run (.png)"),
        ("--snapshot", "FILE", "picture of the arm at several instants (.png, .svg or .pdf)"),
        ("--animate", "FILE", "animation of the run (.gif; .mp4 when ffmpeg is installed)"),
    ):
        parser.add_argument(flag, metavar=metavar, help=text)
    parser.add_argument("--every", type=int, metavar="K", help="dump every K-th tick (default 1)")
    parser.add_argument(
        "--speed",
        type=float,
        default=2.0,
        metavar="X",
        help="simulated seconds per second of animation (default 2)",
    )
    parser.add_argument(
        "--fps", type=int, default=15, help="frames per second of the animation (default 15)"
    )
    add(parser, "--force", help="overwrite existing outputs")


def run(args: argparse.Namespace) -> int:
    from ..jit import warmup_logged
    from ..selection import parse_overrides, select_backend
    from ..sim.loop import simulate
    from ..sim.scenario import load_scenario

    _check_arguments(args)
    backend = select_backend(args.backend)
    overrides = parse_overrides(args.overrides)
    scenario = load_scenario(args.scenario, overrides, dt=args.dt, duration=args.duration)
    progress = sys.stderr.isatty() and not args.quiet
    warmup_logged(log, [backend])
    settings = pick(args, "formulation every dump profile deadline engine")
    result = simulate(scenario, backend, progress=progress, **settings)
    _write_outputs(args, scenario, result, progress)
    _log_summary(result.summary)
    return log_verdict(result.summary)


def _check_arguments(args: argparse.Namespace) -> None:
    """The options only the command has checked, and no output in the way, before anything runs
    (:func:`qpbench.sim.loop.simulate` checks its own arguments)."""
    from ..atomic import check_output
    from ..exceptions import ParamError, positive_seconds
    from ..report.arm import check_animation

    # the outputs whose format the suffix picks (--animate: check_animation)
    for key, suffixes in (("log", (".csv", ".parquet")), ("snapshot", (".png", ".svg", ".pdf"))):
        value = getattr(args, key)
        if value is not None and Path(value).suffix.lower() not in suffixes:
            raise ParamError(f"must end in {' or '.join(suffixes)}, got {value}", key=f"--{key}")
    if args.every is not None and args.dump is None:
        raise ParamError("--every needs --dump", key="--every")
    if args.deadline is not None:
        positive_seconds(args.deadline, "--deadline")
    if args.animate is not None:
        check_animation(Path(args.animate), args.fps, args.speed)
    summary = None if args.summary == "-" else args.summary
    for out in (args.log, summary, args.plot, args.snapshot, args.animate):
        if out is not None:
            check_output(out, force=args.force)
    if args.dump is not None:
        check_tables(args.dump, ["problems.parquet", "manifest.json"], args, key="--dump")


def _write_outputs(args: argparse.Namespace, scenario, result, progress: bool) -> None:
    """The tick log, the summary, the figure, the snapshot and the animation asked for."""
    from ..atomic import atomic_path, write_text
    from ..report.arm import animate, draw_snapshot
    from ..report.loop_figure import run_figure

    s = result.summary
    if args.log is not None:
        with atomic_path(args.log) as tmp:
            if Path(args.log).suffix.lower() == ".csv":
                result.log.to_csv(tmp, index=False, float_format="%.10g")
            else:
                result.log.to_parquet(tmp, index=False)
    if args.summary == "-":
        print(json.dumps(s, indent=2))
    elif args.summary is not None:
        write_text(args.summary, json.dumps(s, indent=2) + "\n")
    if args.plot is not None:
        run_figure(result.log, s, args.plot)
    kw = {"title": f"{scenario.name} / {s['backend']}", "backend": s["backend"]}
    if args.snapshot is not None:
        draw_snapshot(scenario, result.log, args.snapshot, **kw)
    if args.animate is not None:
        speed, fps = args.speed, args.fps
        animate(scenario, result.log, args.animate, fps=fps, speed=speed, progress=progress, **kw)


def _log_summary(s: dict) -> None:
    """INFO lines: ticks and fallbacks, errors after 2 s, limits and Kp_hat, time, real time."""

    def g(key, spec=".3g"):
        return "-" if s[key] is None else format(s[key], spec)

    dropped = s["deadline_dropped"]
    for line in (
        f"{s['scenario']} / {s['backend']} / {s['formulation']}: {s['ticks']} ticks, "
        f"{s['infeasible_ticks']} infeasible ({g('first_infeasible_t')}..{g('last_infeasible_t')}"
        f" s), {s['fallback_ticks']} fallback, {s['zero_velocity_ticks']} zero-velocity",
        f"after 2 s: tracking rms {g('tracking_rms_after_2s')} m, max "
        f"{g('tracking_max_after_2s')} m; force error rms {g('force_error_rms_after_2s')} N, "
        f"max {g('force_error_max_after_2s')} N",
        f"limit violations: angle {s['joint_limit_violations']}, speed "
        f"{s['joint_velocity_limit_violations']}; Kp_hat {g('kp_hat_final', '.6g')}, Kd_hat "
        f"{g('kd_hat_final', '.6g')}",
        f"wall time {s['wall_time_s']:.3f} s, real-time factor {g('real_time_factor')}; "
        f"{s['deadline_misses']} ticks slower than dt = {s['dt']:g} s"
        + ("" if dropped is None else f", {dropped} dropped past the deadline"),
        # beside the verdict: real time does not change the exit code
        f"real time at dt = {s['dt'] * 1e3:g} ms: {s['realtime']} ({s['realtime_reason']}); "
        f"the solver's own time: {s['realtime_solver']} ({s['realtime_solver_reason']})",
    ):
        log.info("%s", line)


def log_verdict(s: dict) -> int:
    """Log the verdict line, with the body's smallest clearance (in the reasons when unsafe)
    and the key-point rule (its smallest distance, or why it broke); return 0 if ok, else 1."""
    distance = ""
    if s.get("min_body_distance") is not None and s["verdict"] != "unsafe":
        distance = (
            f"; min body distance {s['min_body_distance'] * 1e3:.3f} mm "
            f"(link {s.get('min_body_distance_link')}/{s.get('min_body_distance_obstacle')} "
            f"at t = {s['min_body_distance_t']:.3f} s)"
        )
    if s.get("key_point_rule") == "broken":
        distance += f"; key-point rule broken: {s.get('key_point_rule_reason')}"
    elif s.get("min_obstacle_distance") is not None:
        distance += (
            f"; key-point rule held: min obstacle distance {s['min_obstacle_distance'] * 1e3:.3f} mm "
            f"({s.get('min_obstacle_distance_key_point') or '-'}/{s.get('min_obstacle_distance_obstacle') or '-'} "
            f"at t = {s['min_obstacle_distance_t']:.3f} s, d_safe {s['d_safe'] * 1e3:g} mm)"
        )
    reasons = f": {s['verdict_reasons']}" if s.get("verdict_reasons") else ""
    if s["verdict"] == "ok":
        log.info("verdict ok%s%s", reasons, distance)
        return 0
    log.warning("verdict %s%s%s", s["verdict"], reasons, distance)
    return 1
