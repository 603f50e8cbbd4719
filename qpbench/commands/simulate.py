"""``qpbench simulate``: run a scenario in closed loop with one backend; log, summary, dump, plot."""

from __future__ import annotations

import argparse
import json
import logging
import math
import sys
from pathlib import Path

HELP = "simulate a scenario in closed loop with one backend solving every tick's QP"
EXAMPLE = (
    "qpbench simulate --scenario wall --backend daqp --summary wall.json "
    "--log wall.parquet --dump wall-set --every 10 --plot wall.png; "
    "qpbench simulate --scenario wall --backend rnn --set rnn.eps=0.001 --set rnn.substeps=5"
)

log = logging.getLogger("qpbench")


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("--scenario", required=True, metavar="NAME|PATH", help="shipped scenario name (free, wall, adaptive, adaptive_fast, narrow) or a .toml file")
    parser.add_argument("--backend", required=True, metavar="NAME", help="backend name (see `qpbench backends`), e.g. qpsolvers:daqp, clarabel, rnn")
    parser.add_argument("--formulation", default="paper", choices=("paper", "soft"), help="paper: hard task equality (eq. 11); soft: task as a weighted cost (default: paper)")
    parser.add_argument("--duration", type=float, default=None, metavar="S", help="simulated time in s (default: the scenario's)")
    parser.add_argument("--dt", type=float, default=None, metavar="S", help="control period in s (default: the scenario's)")
    parser.add_argument(
        "--set", action="append", default=[], metavar="KEY=VALUE", dest="overrides",
        help="set a scenario value over the file's (repeatable): TABLE.KEY=VALUE or obstacles[i].KEY=VALUE, "
        "VALUE in TOML syntax (a bare word is a string), e.g. --set rnn.eps=0.001 --set rnn.substeps=5",
    )
    parser.add_argument("--profile", default="default", help="backend settings profile (default: default)")
    parser.add_argument(
        "--deadline", type=float, default=None, metavar="SECONDS",
        help="drop an answer that arrives later than this (status time_limit; soft fallback, else zero velocity), "
        "as a real-time controller would; the run then depends on the machine's speed. Default: none, every "
        "answer is applied and the summary's deadline_misses counts ticks slower than dt",
    )
    parser.add_argument("--log", default=None, metavar="FILE", help="per-tick log, .csv or .parquet")
    parser.add_argument("--summary", default=None, metavar="FILE", help="summary as JSON")
    parser.add_argument("--dump", default=None, metavar="DIR", help="write the ticks' QPs as a problem set (problems.parquet + manifest.json)")
    parser.add_argument("--every", type=int, default=None, metavar="K", help="dump every K-th tick (default 1)")
    parser.add_argument("--plot", default=None, metavar="FILE", help="figure of the run (.png)")
    parser.add_argument("--force", action="store_true", help="overwrite existing outputs")


def run(args: argparse.Namespace) -> int:
    from ..atomic import atomic_path, check_output, write_text
    from ..exceptions import ParamError
    from ..jit import warmup_logged
    from ..sim.loop import simulate
    from ..sim.scenario import load_scenario

    if args.log is not None and Path(args.log).suffix not in (".csv", ".parquet"):
        raise ParamError(f"--log must end in .csv or .parquet, got {args.log}", key="--log")
    if args.every is not None and args.every < 1:
        raise ParamError(f"--every must be >= 1, got {args.every}", key="--every")
    if args.every is not None and args.dump is None:
        raise ParamError("--every needs --dump", key="--every")
    for out in (args.log, args.summary, args.plot):
        if out is not None:
            check_output(out, force=args.force)
    if args.dump is not None:
        for name in ("problems.parquet", "manifest.json"):
            check_output(Path(args.dump) / name, force=args.force)

    if args.deadline is not None and not (math.isfinite(args.deadline) and args.deadline > 0):
        raise ParamError(f"--deadline must be a positive number of seconds, got {args.deadline}", key="--deadline")
    scenario = load_scenario(args.scenario, overrides=parse_overrides(args.overrides))
    progress = sys.stderr.isatty() and not args.quiet
    warmup_logged(log)
    result = simulate(
        scenario, args.backend, formulation=args.formulation, duration=args.duration, dt=args.dt,
        every=args.every, dump=args.dump, progress=progress, profile=args.profile, deadline=args.deadline,
    )
    s = result.summary
    if args.log is not None:
        with atomic_path(args.log) as tmp:
            if args.log.endswith(".csv"):
                result.log.to_csv(tmp, index=False, float_format="%.10g")
            else:
                result.log.to_parquet(tmp, index=False)
    if args.summary is not None:
        write_text(args.summary, json.dumps(s, indent=2) + "\n")
    if args.plot is not None:
        plot_run(result.log, s, args.plot)

    def fmt(x, spec=".3g"):
        return "-" if x is None else format(x, spec)

    log.info(
        "%s / %s / %s: %d ticks, %d infeasible (%s..%s s), %d fallback, %d zero-velocity",
        s["scenario"], s["backend"], s["formulation"], s["ticks"], s["infeasible_ticks"],
        fmt(s["first_infeasible_t"]), fmt(s["last_infeasible_t"]), s["fallback_ticks"], s["zero_velocity_ticks"],
    )
    log.info(
        "after 2 s: tracking rms %s m, max %s m; force error rms %s N, max %s N",
        fmt(s["tracking_rms_after_2s"]), fmt(s["tracking_max_after_2s"]),
        fmt(s["force_error_rms_after_2s"]), fmt(s["force_error_max_after_2s"]),
    )
    log.info(
        "min obstacle distance %s m (%s, t = %s s); limit violations: angle %d, speed %d; Kp_hat %s, Kd_hat %s",
        fmt(s["min_obstacle_distance"], ".6f"), s["min_obstacle_distance_key_point"] or "-", fmt(s["min_obstacle_distance_t"]),
        s["joint_limit_violations"], s["joint_velocity_limit_violations"], fmt(s["kp_hat_final"], ".6g"), fmt(s["kd_hat_final"], ".6g"),
    )
    log.info("wall time %.3f s, real-time factor %s; %d ticks slower than dt = %g s%s", s["wall_time_s"],
             fmt(s["real_time_factor"]), s["deadline_misses"], s["dt"],
             "" if s["deadline_dropped"] is None else f", {s['deadline_dropped']} dropped past the deadline")
    return 1 if s["zero_velocity_ticks"] else 0


def parse_overrides(items: list[str]) -> dict:
    """``["rnn.eps=0.001", ...]`` -> ``{"rnn.eps": 0.001, ...}``.

    A value is read as a TOML value (``0.001``, ``5``, ``true``, ``[0.0, 0.1]``,
    ``"text"``); one that is not valid TOML is taken as a string (``euler``).
    A later setting of the same key wins. Keys are checked by the scenario
    loader (:func:`qpbench.sim.scenario.apply_overrides`).

    Raises:
        ParamError: an item without ``=`` or with an empty key.
    """
    import tomllib

    from ..exceptions import ParamError

    out = {}
    for item in items or ():
        key, sep, text = item.partition("=")
        key = key.strip()
        if not sep or not key:
            raise ParamError(f"expected KEY=VALUE, got {item!r}", key="--set")
        text = text.strip()
        try:
            value = tomllib.loads(f"value = {text}")["value"]
        except tomllib.TOMLDecodeError:
            value = text
        out[key] = value
    return out


def plot_run(frame, summary: dict, path) -> None:
    """Six panels: tangential error, force, key-point distances, ``|v|^2``, joint angles, ``Kp_hat``."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    from ..atomic import atomic_path

    t = frame["t"].to_numpy()
    fig, axes = plt.subplots(3, 2, figsize=(11, 9), sharex=True)
    ax = axes[0, 0]
    ax.plot(t, frame["tracking_error"])
    ax.set_ylabel("tangential error [m]")
    ax = axes[0, 1]
    ax.plot(t, frame["force"])
    ax.set_ylabel("contact force [N]")
    ax = axes[1, 0]
    dcols = [c for c in frame.columns if c.startswith("d_") and c != "d_min"]
    for c in dcols:
        ax.plot(t, frame[c], lw=0.8, label=c[2:])
    if dcols:
        ax.axhline(summary["d_safe"], color="k", ls="--", lw=0.8)
        ax.legend(fontsize=6, ncol=2)
    ax.set_ylabel("key point distance [m]")
    ax = axes[1, 1]
    ax.plot(t, frame["v_sq"])
    ax.set_ylabel("|v|^2 [rad^2/s^2]")
    ax = axes[2, 0]
    for c in [c for c in frame.columns if c.startswith("theta_")]:
        ax.plot(t, frame[c], label=c)
    ax.legend(fontsize=7)
    ax.set_ylabel("joint angle [rad]")
    ax.set_xlabel("t [s]")
    ax = axes[2, 1]
    ax.plot(t, frame["kp_hat"], label="Kp_hat")
    ax.set_ylabel("Kp_hat [N/m]")
    ax.set_xlabel("t [s]")
    fig.suptitle(f"{summary['scenario']} / {summary['backend']} / {summary['formulation']}")
    fig.tight_layout()
    with atomic_path(path) as tmp:
        fig.savefig(tmp, format="png", dpi=110)
    plt.close(fig)
