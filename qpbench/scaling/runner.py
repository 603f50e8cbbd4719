"""The scaling study: per size, dump ticks of the closed loop, bench them, summarise.

For each size (:mod:`qpbench.scaling.sizes`), in ``DIR``: ``scenarios/<size>.toml`` (the size as a
scenario file); ``sets/<size>/``, every ``every``-th tick's QP of the closed loop run for
``duration`` [s] with the exact ``driver`` (the QPs the controller meets: the arm in contact, the
approaching cloud's rows becoming active; removed once the size is done unless ``keep_sets``); the
time to build a tick's QP (the minimum of ``build_repeat`` calls); ``bench/<size>.csv``
(:func:`qpbench.harness.bench.run_bench`, as ``qpbench bench``, resumable); and one row per
(size, backend) appended to ``scaling.csv`` (:data:`COLUMNS`) once the size is done (a resumed
run skips the sizes it holds).

Skipped (a ``skipped`` row with the reason, never a run of minutes): a dense-only backend
(:func:`matrix_format`) on a size with more than ``dense_limit`` entries ``n x rows``; a backend
whose median solve on a smaller size of the same axis took longer than ``slow_limit`` [s].
"""

from __future__ import annotations

import logging
import math
import shutil
import time
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np

from ..harness.results import ResultsWriter
from .sizes import Size, generate, qp_shape, scenario_toml

if TYPE_CHECKING:
    from ..control.controller import Controller

log = logging.getLogger("qpbench.scaling")

#: Columns of ``scaling.csv``, in order.
COLUMNS = (
    "size",
    "axis",
    "links",
    "points_per_link",
    "key_points",
    "cloud_points",
    "n",
    "m_eq",
    "m_ineq",
    "rows",
    "backend",
    "matrix_format",
    "status",
    "skip_reason",
    "problems",
    "success_rate",
    "failures",
    "time_median_s",
    "time_p99_s",
    "gap_median",
    "gap_max",
    "violation_max",
    "build_median_s",
    "build_p99_s",
    "reference_optimal",
    "driver",
    "repeat",
    "seed",
)
#: The columns of :data:`COLUMNS` that hold text; every other one holds a number.
TEXT_COLUMNS = ("size", "axis", "backend", "matrix_format", "status", "skip_reason", "driver")
SUMMARY_NAME = "scaling.csv"

#: How each built-in route takes its matrices: ``dense`` (a dense factorisation or
#: dense active set: cost grows with n x rows whatever the zeros) or ``sparse``.
#: A backend class may say so itself with a ``matrix_format`` attribute.
_MATRIX_FORMATS = {
    "daqp": "dense",
    "daqp-stateless": "dense",
    "qpoases": "dense",
    "piqp": "dense",
    "proxqp": "dense",
    "pinv": "dense",
    "rnn": "dense",
    "rnn-tuned": "dense",
    "rnn-converged": "dense",
    "qpsolvers:daqp": "dense",
    "qpsolvers:quadprog": "dense",
    "qpsolvers:proxqp": "dense",
    "qpsolvers:piqp": "dense",
    "qpsolvers:cvxopt": "dense",
    "qpsolvers:qpalm": "sparse",
    "osqp": "sparse",
    "clarabel": "sparse",
    "cvxpy": "sparse",
    "qpsolvers:osqp": "sparse",
    "qpsolvers:clarabel": "sparse",
    "qpsolvers:scs": "sparse",
    "qpsolvers:highs": "sparse",
    "qpsolvers:ecos": "sparse",
    "qpsolvers:gurobi": "sparse",
}


def matrix_format(name: str) -> str:
    """``dense``, ``sparse`` or ``unknown`` (a plugin's backend that does not say)."""
    from ..backends import backend_class
    from ..exceptions import QpbenchError

    try:
        declared = getattr(backend_class(name), "matrix_format", None)
    except QpbenchError:
        declared = None
    return declared or _MATRIX_FORMATS.get(name, "unknown")


@dataclass
class ScalingConfig:
    """What to run (module docstring): ``sizes`` smallest first within an axis, ``duration`` [s],
    ``repeat`` timed solves per (tick, backend) (the row keeps the minimum), ``slow_limit`` [s]."""

    backends: list[str]
    sizes: list[Size]
    driver: str = "daqp"
    duration: float = 0.3
    every: int = 5
    repeat: int = 3
    build_repeat: int = 20
    seed: int = 0
    profile: str = "default"
    dense_limit: int = 1_000_000
    slow_limit: float = 0.02
    keep_sets: bool = False

    def __post_init__(self) -> None:
        """Every value checked when made (one-line errors naming the option)."""
        from ..exceptions import ParamError, positive_seconds
        from ..profiles import get_profile

        get_profile(self.profile)
        positive_seconds(self.duration, "--duration")
        positive_seconds(self.slow_limit, "--slow-limit")
        for key, value, low in (
            ("--every", self.every, 1),
            ("--repeat", self.repeat, 1),
            ("--seed", self.seed, 0),
            ("--dense-limit", self.dense_limit, 1),
        ):
            if value < low:
                raise ParamError(f"out of range: {value}", key=key)
        if self.duration / 0.001 < self.every:
            raise ParamError(
                f"{self.duration} s at 1 kHz keeps no tick with --every {self.every}", key="--every"
            )


def read_summary(path: str | Path, repair: bool = False) -> list[dict]:
    """Rows of a ``scaling.csv`` (strings; :func:`qpbench.harness.results.read_results`)."""
    from ..harness.results import read_results

    return read_results(path, repair=repair, columns=COLUMNS, kind="scaling").rows


def build_times(
    controller: Controller, states: list[tuple[np.ndarray, float]], repeat: int
) -> np.ndarray:
    """Per state ``(theta, t)``: the minimum over ``repeat`` calls of ``controller.build`` in [s]."""
    controller.build(*states[0])
    out = np.empty(len(states))
    for i, (theta, t) in enumerate(states):
        best = math.inf
        for _ in range(repeat):
            t0 = time.perf_counter_ns()
            controller.build(theta, t)
            best = min(best, time.perf_counter_ns() - t0)
        out[i] = best * 1e-9
    return out


def _size_columns(size: Size, config: ScalingConfig) -> dict:
    shape = qp_shape(size)
    return {
        "size": size.name,
        "axis": size.axis,
        "links": size.links,
        "points_per_link": size.points_per_link,
        "key_points": size.key_points,
        "cloud_points": size.cloud_points,
        **shape,
        "rows": shape["m_eq"] + shape["m_ineq"],
        "driver": config.driver,
        "repeat": config.repeat,
        "seed": config.seed,
    }


def _backend_row(base: dict, name: str, rows: list[dict]) -> dict:
    """Summary of one backend's bench rows on one size."""
    from ..harness.bench import is_failure

    def col(key):
        return np.array([float(r[key]) if r[key] not in ("", None) else math.nan for r in rows])

    times, gaps, viol = col("wall_time_min_s"), col("optimality_gap"), col("constraint_violation")
    times = times[np.isfinite(times)]
    gaps = gaps[np.isfinite(gaps)]
    viol = viol[np.isfinite(viol)]
    success = [str(r["success"]) == "True" for r in rows]
    failures = sum(1 for r in rows if is_failure(r["status"], r["reference_status"] or None))
    return {
        **base,
        "backend": name,
        "matrix_format": matrix_format(name),
        "status": "measured",
        "problems": len(rows),
        "success_rate": float(np.mean(success)) if rows else math.nan,
        "failures": failures,
        "time_median_s": float(np.median(times)) if times.size else math.nan,
        "time_p99_s": float(np.percentile(times, 99)) if times.size else math.nan,
        "gap_median": float(np.median(gaps)) if gaps.size else math.nan,
        "gap_max": float(gaps.max()) if gaps.size else math.nan,
        "violation_max": float(viol.max()) if viol.size else math.nan,
        "reference_optimal": sum(1 for r in rows if r["reference_status"] == "optimal"),
    }


def _skip_reason(name: str, size: Size, slow: dict, config: ScalingConfig) -> str | None:
    shape = qp_shape(size)
    entries = shape["n"] * shape["m_ineq"]
    if matrix_format(name) == "dense" and entries > config.dense_limit:
        return f"dense-only; n x rows = {entries:,} > --dense-limit {config.dense_limit:,}"
    if (size.axis, name) in slow:
        smaller, median = slow[(size.axis, name)]
        return f"median solve {median * 1e3:.1f} ms on {smaller} > --slow-limit {config.slow_limit * 1e3:g} ms"
    return None


def _dump_ticks(size: Size, config: ScalingConfig, out: Path):
    """Write the size's scenario and problem set; return ``(scenario, states of the kept ticks)``."""
    from ..atomic import write_text
    from ..sim.loop import simulate
    from ..sim.scenario import parse_scenario

    gen, cloud = generate(size, config.seed)
    path = out / "scenarios" / f"{size.name}.toml"
    path.parent.mkdir(parents=True, exist_ok=True)
    text = scenario_toml(size, gen, cloud, config.duration)
    write_text(path, text)
    scenario = parse_scenario(text, path)
    (out / "sets").mkdir(exist_ok=True)
    result = simulate(scenario, config.driver, every=config.every, dump=out / "sets" / size.name)
    frame = result.log
    thetas = frame[[f"theta_{i}" for i in range(size.links)]].to_numpy()
    ticks = [r.tick for r in result.records]
    states = [(np.ascontiguousarray(thetas[k]), float(frame["t"].iloc[k])) for k in ticks]
    return scenario, states


def run_size(
    size: Size, config: ScalingConfig, out: Path, slow: dict, progress: bool = False
) -> tuple[list[dict], int]:
    """Everything for one size (module docstring); returns its summary rows and its failed solves.

    Each phase says so in a log line (``progress``: the references and the bench also show a bar)."""
    from ..formats import load_problems
    from ..harness.bench import BenchConfig, run_bench
    from ..reference import reference_solutions

    started = time.perf_counter()
    scenario, states = _dump_ticks(size, config, out)
    log.info(
        "%s: closed loop of %g s with %s: %d ticks kept in %.1f s",
        size.name,
        config.duration,
        config.driver,
        len(states),
        time.perf_counter() - started,
    )
    built = build_times(scenario.make_controller(), states, config.build_repeat)
    base = _size_columns(size, config)
    base.update(build_median_s=float(np.median(built)), build_p99_s=float(np.percentile(built, 99)))
    skipped = {name: _skip_reason(name, size, slow, config) for name in config.backends}
    run = [name for name in config.backends if skipped[name] is None]
    rows, failed = [], 0
    if run:
        problem_set = load_problems(out / "sets" / size.name)
        csv_path = out / "bench" / f"{size.name}.csv"
        csv_path.parent.mkdir(parents=True, exist_ok=True)
        bench = BenchConfig(
            backends=run, profile=config.profile, repeat=config.repeat, seed=config.seed
        )

        def references(subset):  # progress of the reference solves: a bar, else log lines
            from tqdm import tqdm

            return reference_solutions(subset, progress=tqdm if progress else "log")

        log.info("%s: bench of %s on %d ticks", size.name, ", ".join(run), len(problem_set))
        summary = run_bench(
            problem_set,
            bench,
            csv_path,
            resume=csv_path.exists(),
            references=references,
            progress=progress or "log",
        )
        failed = summary.failures
        from ..harness.results import read_results

        by_backend: dict[str, list[dict]] = {}
        for r in read_results(csv_path).rows:
            by_backend.setdefault(r["backend"], []).append(r)
        for name in run:
            row = _backend_row(base, name, by_backend.get(name, []))
            rows.append(row)
            if row["time_median_s"] > config.slow_limit:
                slow[(size.axis, name)] = (size.name, row["time_median_s"])
    for name in config.backends:
        if skipped[name] is not None:
            rows.append(
                {
                    **base,
                    "backend": name,
                    "matrix_format": matrix_format(name),
                    "status": "skipped",
                    "skip_reason": skipped[name],
                }
            )
    return rows, failed


def run_scaling(
    config: ScalingConfig, out: str | Path, resume: bool = False, progress: bool = False
) -> int:
    """Run every size of ``config`` into folder ``out``; return the failed solves of every size
    in the summary (those kept by ``resume`` included)."""
    out = Path(out)
    out.mkdir(parents=True, exist_ok=True)
    summary_path = out / SUMMARY_NAME
    done: dict[str, list[dict]] = {}
    slow: dict = {}
    if resume and summary_path.exists():
        for r in read_summary(summary_path, repair=True):
            done.setdefault(r["size"], []).append(r)
            if (
                r["status"] == "measured"
                and r["time_median_s"]
                and float(r["time_median_s"]) > config.slow_limit
            ):
                slow[(r["axis"], r["backend"])] = (r["size"], float(r["time_median_s"]))
    failed = 0
    for size in config.sizes:
        if size.name in done:
            log.info("%s: done in %s, skipped", size.name, summary_path)
            failed += sum(
                int(float(r["failures"] or 0)) for r in done[size.name] if r["status"] == "measured"
            )
            continue
        started = time.perf_counter()
        shape = qp_shape(size)
        log.info(
            "%s: %d variables, %d rows (%d key points x %d cloud points + 2)",
            size.name,
            shape["n"],
            shape["m_eq"] + shape["m_ineq"],
            size.key_points,
            size.cloud_points,
        )
        rows, size_failed = run_size(size, config, out, slow, progress)
        new = not summary_path.exists() or summary_path.stat().st_size == 0
        with ResultsWriter(summary_path, new=new, columns=COLUMNS) as writer:
            writer.write_rows(rows)
        if not config.keep_sets:
            shutil.rmtree(out / "sets" / size.name, ignore_errors=True)
        failed += size_failed
        log.info(
            "%s: done in %.1f s%s",
            size.name,
            time.perf_counter() - started,
            f"; {size_failed} failed solves" if size_failed else "",
        )
    if not config.keep_sets and (out / "sets").is_dir() and not any((out / "sets").iterdir()):
        (out / "sets").rmdir()
    return failed


def failure_line(path: str | Path) -> str | None:
    """The failed solves of a scaling run, in one line from its ``scaling.csv`` (``None``: no failed solve)."""
    counts: dict[str, int] = {}
    sizes: dict[str, list[str]] = {}
    for r in read_summary(path):
        n = int(float(r["failures"])) if r["failures"] else 0
        if n:
            counts[r["backend"]] = counts.get(r["backend"], 0) + n
            sizes.setdefault(r["backend"], []).append(r["size"])
    if not counts:
        return None
    per_backend = "; ".join(f"{b} {n} on {', '.join(sizes[b])}" for b, n in counts.items())
    return (
        f"{sum(counts.values())} failed solves (error, time_limit, invalid, crashed, or not "
        f"optimal where the reference is): {per_backend} (column 'failures' of {path})"
    )
