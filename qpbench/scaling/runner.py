"""The scaling study's run, per size (:mod:`.sizes`), in ``DIR``: ``scenarios/<size>.toml``, the
ticks of its closed loop dumped into ``sets/<size>/``, their build times, ``bench/<size>.csv``
(:func:`qpbench.harness.bench.run_bench`, resumable) and one row per (size, backend) appended to
``scaling.csv`` (:data:`COLUMNS`) once the size is done; a resumed run skips the sizes it holds.

Skipped, with the reason in a ``skipped`` row: a dense-only backend (:func:`matrix_format`) on a
size of more than ``dense_limit`` entries ``n x rows``; a backend whose median solve on a smaller
size of the same axis took longer than ``slow_limit`` [s].
"""

from __future__ import annotations

import logging
import math
import shutil
import time
from dataclasses import asdict, dataclass
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np

from ..harness.results import ResultsWriter, read_results
from .sizes import Size, generate, qp_shape, scenario_toml
from .spatial import scenario_file

if TYPE_CHECKING:
    from ..control.controller import Controller

log = logging.getLogger("qpbench.scaling")

#: Columns of ``scaling.csv``, in order.
COLUMNS = (
    "size",
    "axis",
    "robot",
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
SUMMARY_NAME = "scaling.csv"

#: How the built-in solvers take their matrices: ``dense`` (a dense factorisation or dense
#: active set: cost grows with n x rows whatever the zeros) or ``sparse``; a route
#: ``qpsolvers:NAME`` or a variant ``NAME-...`` as ``NAME``.
_DENSE = ("daqp", "qpoases", "piqp", "proxqp", "pinv", "rnn", "quadprog", "cvxopt")
_SPARSE = ("qpalm", "osqp", "clarabel", "cvxpy", "scs", "highs", "ecos", "gurobi")


def matrix_format(name: str) -> str:
    """``dense``, ``sparse`` or ``unknown`` (a backend of neither list)."""
    solver = name.removeprefix("qpsolvers:").split("-")[0]
    return "dense" if solver in _DENSE else "sparse" if solver in _SPARSE else "unknown"


@dataclass
class ScalingConfig:
    """What to run (module docstring): ``sizes`` smallest first within an axis; the closed loop of
    ``duration`` [s] driven by ``driver``, every ``every``-th tick kept (``sets/`` removed once a
    size is done unless ``keep_sets``); ``repeat`` timed solves per (tick, backend) and
    ``build_repeat`` builds per tick (the minimum kept); ``slow_limit`` [s]."""

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
        from ..exceptions import ParamError, positive_count, positive_seconds
        from ..profiles import get_profile

        get_profile(self.profile)
        positive_seconds(self.duration, "--duration")
        positive_seconds(self.slow_limit, "--slow-limit")
        for key in ("every", "repeat", "dense_limit"):
            positive_count(getattr(self, key), "--" + key.replace("_", "-"))
        if self.seed < 0:
            raise ParamError(f"out of range: {self.seed}", key="--seed")
        if self.duration / 0.001 < self.every:
            raise ParamError(
                f"{self.duration} s at 1 kHz keeps no tick with --every {self.every}", key="--every"
            )


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


def _backend_row(base: dict, name: str, rows: list[dict]) -> dict:
    """Summary of one backend's bench rows on one size."""
    from ..harness.bench import BackendStats

    stats = BackendStats()
    for r in rows:
        stats.add(r)
    times = np.asarray(stats.times_s)
    gaps = np.array([float(r["optimality_gap"] or "nan") for r in rows])
    gaps = gaps[np.isfinite(gaps)]
    return {
        **base,
        "backend": name,
        "matrix_format": matrix_format(name),
        "status": "measured",
        "problems": stats.rows,
        "success_rate": stats.successes / stats.rows if rows else math.nan,
        "failures": stats.n_failures,
        "time_median_s": float(np.median(times)) if times.size else math.nan,
        "time_p99_s": float(np.percentile(times, 99)) if times.size else math.nan,
        "gap_median": float(np.median(gaps)) if gaps.size else math.nan,
        "gap_max": float(gaps.max()) if gaps.size else math.nan,
        "violation_max": max(stats.violations, default=math.nan),
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

    path = out / "scenarios" / f"{size.name}.toml"
    path.parent.mkdir(parents=True, exist_ok=True)
    if size.spatial:
        text = scenario_file(size, config.seed, config.duration)
    else:
        text = scenario_toml(size, *generate(size, config.seed), config.duration)
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
    shape = qp_shape(size)
    base = {
        **asdict(size),
        **shape,
        "size": size.name,
        "key_points": size.key_points,
        "rows": shape["m_eq"] + shape["m_ineq"],
        "driver": config.driver,
        "repeat": config.repeat,
        "seed": config.seed,
        "build_median_s": float(np.median(built)),
        "build_p99_s": float(np.percentile(built, 99)),
    }
    reasons = {name: _skip_reason(name, size, slow, config) for name in config.backends}
    run = [name for name, why in reasons.items() if why is None]
    rows, failed = _bench_size(size, config, out, run, base, progress) if run else ([], 0)
    for row in rows:
        _note_slow(slow, row, config.slow_limit)
    for name, why in reasons.items():
        if why is not None:
            skipped = {"status": "skipped", "skip_reason": why}
            rows.append({**base, "backend": name, "matrix_format": matrix_format(name), **skipped})
    return rows, failed


def _note_slow(slow: dict, row: dict, limit: float) -> None:
    """Note a measured row (new, or read back) whose median solve took over ``limit`` [s]: the
    backend is skipped on the larger sizes of that axis."""
    median = float(row["time_median_s"] or "nan")
    if row["status"] == "measured" and median > limit:
        slow[(row["axis"], row["backend"])] = (row["size"], median)


def _bench_size(size: Size, config: ScalingConfig, out: Path, run: list, base: dict, progress):
    """Bench the backends ``run`` on the size's dumped ticks: their rows and the failed solves."""
    from tqdm import tqdm

    from ..formats import load_problems
    from ..harness.bench import BenchConfig, run_bench
    from ..reference import reference_solutions

    problem_set = load_problems(out / "sets" / size.name)
    csv_path = out / "bench" / f"{size.name}.csv"
    csv_path.parent.mkdir(parents=True, exist_ok=True)
    bench = BenchConfig(
        backends=run, profile=config.profile, repeat=config.repeat, seed=config.seed
    )
    log.info("%s: bench of %s on %d ticks", size.name, ", ".join(run), len(problem_set))
    summary = run_bench(
        problem_set,
        bench,
        csv_path,
        resume=csv_path.exists(),
        references=lambda subset: reference_solutions(subset, progress=tqdm if progress else "log"),
        progress=progress or "log",
    )
    done = read_results(csv_path).rows
    rows = [_backend_row(base, b, [r for r in done if r["backend"] == b]) for b in run]
    return rows, summary.failures


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
    kept = resume and summary_path.exists()
    for r in read_results(summary_path, True, COLUMNS, "scaling").rows if kept else []:
        done.setdefault(r["size"], []).append(r)
        _note_slow(slow, r, config.slow_limit)
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
        constraint_rows = shape["m_eq"] + shape["m_ineq"]
        what = f"{size.key_points} key points x {size.cloud_points} cloud points + {shape['m_eq']}"
        log.info("%s: %d variables, %d rows (%s)", size.name, shape["n"], constraint_rows, what)
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
    import pandas as pd

    frame = pd.read_csv(path)
    failed = frame[frame["failures"].fillna(0) > 0]
    if failed.empty:
        return None
    per_backend = "; ".join(
        f"{b} {int(g['failures'].sum())} on {', '.join(g['size'])}"
        for b, g in failed.groupby("backend", sort=False)
    )
    return (
        f"{int(failed['failures'].sum())} failed solves (error, time_limit, invalid, crashed, or "
        f"not optimal where the reference is): {per_backend} (column 'failures' of {path})"
    )
