"""A sweep's run into ``DIR`` (docs/sweeps.md): ``sweep.json`` (the manifest),
``instances/<name>.toml`` and the table ``sweep.csv``, one row per (instance, backend) appended
as runs end and rewritten at the end with the last row of each key. A row's figures are its
closed-loop summary's (:mod:`qpbench.sim.summary`) with the time-to-converge figures (empty:
not converged). ``status``: ``ok`` (a result, whatever its verdict), ``error``, ``crashed`` (its
worker was lost twice) or ``invalid_scenario`` (no verdict). Each instance is run with the
noise floor too, against which its other runs are judged real time (docs/verdicts.md).
"""

from __future__ import annotations

import json
import shutil
from collections.abc import Callable
from dataclasses import dataclass, replace
from pathlib import Path
from typing import TYPE_CHECKING

from ..atomic import atomic_path, check_folder, check_output, write_text
from ..backends import NOISE_FLOOR
from ..exceptions import InputError
from ..harness.closed_loop import (
    FLOOR_JUDGED,
    LoopTask,
    failure_fields,
    judge_against_floor,
    run_row,
)
from ..harness.results import ResultsWriter, csv_bytes, read_results
from .spec import Instance, SweepSpec, sample_instances

if TYPE_CHECKING:
    from ..runner import DaskExecutor, ProcessExecutor, SerialExecutor

#: Names of the table, the manifest and the instances' folder inside the sweep's folder.
CSV_NAME = "sweep.csv"
MANIFEST_NAME = "sweep.json"
INSTANCE_DIR = "instances"
#: Statuses a resumed sweep keeps.
KEPT_STATUSES = ("ok", "invalid_scenario")


#: Columns of ``sweep.csv``, in order.
COLUMNS = (
    "instance",  # the run: its instance, backend and outcome (:func:`head_row`)
    "backend",
    "instance_file",
    "sample",
    "sweep",
    "base_scenario",
    "parameters",
    "status",
    "error",
    "noise_floor",  # the noop run of the instance: the machine's noise floor, not a candidate
    "attempts",
    "verdict",
    "verdict_reasons",
    "duration_s",  # the closed-loop summary's figures from here, but the convergence columns
    "simulated_s",
    "dt",
    "ticks",
    "tracking_rms_after_2s",
    "tracking_max_after_2s",
    "force_error_rms_after_2s",
    "force_error_max_after_2s",
    "t_converge_force_s",  # the convergence figures and their bands
    "t_converge_tracking_s",
    "force_band_n",
    "tracking_band_m",
    "min_obstacle_distance",  # the summary's again
    "min_obstacle_distance_key_point",
    "min_obstacle_distance_obstacle",
    "min_obstacle_distance_t",
    "d_safe",
    "joint_limit_violations",
    "joint_velocity_limit_violations",
    "max_abs_v",
    "infeasible_ticks",
    "non_optimal_ticks",
    "fallback_ticks",
    "zero_velocity_ticks",
    "error_ticks",
    "invalid_ticks",
    "first_error",
    "solve_time_median_s",
    "solve_time_p99_s",
    "solve_time_max_s",
    "deadline_misses",
    "ticks_over_1ms",
    "realtime",
    "realtime_reason",
    "realtime_solver",
    "realtime_solver_reason",
    "over_dt_share",
    "over_dt_optimal",
    "over_dt_infeasible",
    "over_dt_fallback",
    "over_dt_other",
    "time_p99_without_infeasible_s",
    "certify_time_median_s",
    "certify_time_max_s",
    "noise_floor_over_dt_share",
    "noise_floor_tick_p99_s",
    "solver_time_p99_s",
    "solver_over_dt_share",
    "wall_time_s",
    "real_time_factor",
    "verdict_overrides",
    "executor",  # where it ran
    "host",
    "worker",
    "concurrent_solves",
)
#: Columns that depend on timing or on where the run was made (ignored when comparing two sweeps).
TIMING_COLUMNS = (
    ("attempts",)
    + COLUMNS[COLUMNS.index("solve_time_median_s") : COLUMNS.index("verdict_overrides")]
    + COLUMNS[COLUMNS.index("executor") :]
)


def head_row(spec: SweepSpec, inst: Instance, backend: str) -> dict:
    """The row of ``backend``'s run of instance ``inst`` of sweep ``spec``, without its figures."""
    return dict.fromkeys(COLUMNS) | dict(
        instance=inst.name,
        backend=backend,
        instance_file=f"{INSTANCE_DIR}/{inst.name}.toml",
        sample=inst.index,
        sweep=spec.name,
        base_scenario=spec.base,
        parameters=json.dumps(inst.values, separators=(",", ":")),
        duration_s=spec.duration,
        force_band_n=spec.force_band,
        tracking_band_m=spec.tracking_band,
    )


def sweep_row(head: dict, row: dict) -> dict:
    """The sweep's row (``head``: :func:`head_row`) of a closed-loop row
    (:func:`qpbench.harness.closed_loop.run_row` or
    :func:`~qpbench.harness.closed_loop.failure_fields`)."""
    return head | {key: row[key] for key in COLUMNS if key in row and key not in COLUMNS[:7]}


@dataclass
class SweepOutcome:
    """What :func:`run_sweep` did: the table's rows (one per key), how many ran now, how many failed to run."""

    rows: list[dict]
    csv_path: Path
    ran: int
    kept: int
    failed: int


def _resumable(out: Path, spec: SweepSpec) -> dict:
    """The manifest of the sweep in ``out``, if made from the same sweep file and duration."""
    path = out / MANIFEST_NAME
    try:
        old = json.loads(path.read_text())
    except (OSError, ValueError) as exc:
        raise InputError(
            f"cannot resume: unreadable manifest ({exc}); use --force to start again", path=path
        ) from None
    if old.get("sweep_sha256") != spec.sha256:
        key, what = "sweep_sha256", f"made from another sweep file ({old.get('sweep_file')})"
    elif old.get("duration") != spec.duration:
        key, what = "duration", f"made with duration {old.get('duration')}, not {spec.duration}"
    else:
        return old
    raise InputError(f"cannot resume: {what}; use --force", path=path, key=key)


def read_sweep_rows(csv_path: str | Path, repair: bool = False) -> list[dict]:
    """The rows of ``sweep.csv`` as strings, the last row of each key kept (a half-written line dropped)."""
    rows = read_results(csv_path, repair=repair, columns=COLUMNS, kind="sweep").rows
    last = {(r["instance"], r["backend"]): r for r in rows}
    return list(last.values())


def _prepare(out: Path, spec: SweepSpec, backends: list[str], force: bool, resume: bool, drawn):
    """Check ``out``, write the instances (``drawn``, else all of ``spec``'s) and the manifest
    (``sweep.json``); the instances and the kept rows."""
    csv_path = out / CSV_NAME
    check_folder(out)
    check_output(csv_path, force=force, resume=resume, make_parent=True)  # out is made below
    from .. import __version__

    manifest = {  # samples, backends: of every run into the folder (a resumed run merges them)
        "sweep": spec.name,
        "sweep_file": str(spec.path),
        "sweep_sha256": spec.sha256,
        "sweep_text": spec.text,
        "seed": spec.seed,
        "samples": spec.samples,
        "duration": spec.duration,
        "base": spec.base,
        "base_file": str(spec.base_path),
        "backends": backends,
        "qpbench_version": __version__,
        "force_band_n": spec.force_band,
        "tracking_band_m": spec.tracking_band,
    }
    kept = {}
    if resume and csv_path.exists():  # the table holds the earlier runs' rows too
        old = _resumable(out, spec)
        manifest["backends"] = list(dict.fromkeys(old.get("backends", []) + backends))
        manifest["samples"] = max(int(old.get("samples", 0)), spec.samples)
        rows = read_sweep_rows(csv_path, repair=True)
        kept = {(r["instance"], r["backend"]): r for r in rows if r["status"] in KEPT_STATUSES}
    elif force:
        csv_path.unlink(missing_ok=True)
        shutil.rmtree(out / INSTANCE_DIR, ignore_errors=True)
    instances = sample_instances(spec) if drawn is None else list(drawn)
    for inst in instances:
        path = out / INSTANCE_DIR / f"{inst.name}.toml"
        if not path.exists() or path.read_text(encoding="utf-8") != inst.text:
            write_text(path, inst.text)
    write_text(out / MANIFEST_NAME, json.dumps(manifest, indent=2) + "\n")
    return instances, kept


def run_sweep(
    spec: SweepSpec,
    backends: list[str],
    out: str | Path,
    executor: SerialExecutor | ProcessExecutor | DaskExecutor,
    *,
    force: bool = False,
    resume: bool = False,
    plugins: list[str] | None = None,
    on_row: Callable[[dict], None] | None = None,
    engine: str = "compiled",
    instances: list[Instance] | None = None,
) -> SweepOutcome:
    """Run every (instance, backend) of ``spec`` on ``executor`` (:mod:`qpbench.runner`) into
    ``out``, each row to ``on_row`` once appended; ``instances``: those of
    :func:`~.spec.sample_instances` to run (default: every one of ``spec``). An
    :class:`OutputExistsError` without ``force`` or ``resume`` when ``out/sweep.csv`` exists,
    an :class:`InputError` when resuming a folder of another sweep file or duration."""
    out = Path(out)  # each instance's noise floor, run like the others (docs/verdicts.md)
    backends = [NOISE_FLOOR, *(b for b in backends if b != NOISE_FLOOR)]
    instances, kept = _prepare(out, spec, backends, force, resume, instances)
    csv_path = out / CSV_NAME
    rows = dict(kept)
    new = not csv_path.exists() or csv_path.stat().st_size == 0
    items, heads, figures = [], {}, {}
    # the tasks' common terms (an instance's time ranks nothing); each carries its instance's text
    bands = (spec.force_band, spec.tracking_band)
    plugins = tuple(plugins or ())
    terms = LoopTask("", "", plugins=plugins, bands=bands, engine=engine, p99_interval=False)
    with ResultsWriter(csv_path, new=new, columns=COLUMNS) as writer:

        def emit(row):
            rows[(row["instance"], row["backend"])] = row
            writer.write_rows([row])
            if on_row is not None:
                on_row(row)

        for inst in instances:
            for backend in backends:
                if (inst.name, backend) in kept:
                    continue
                head = head_row(spec, inst, backend)
                if inst.invalid is not None:
                    emit(sweep_row(head, failure_fields("invalid_scenario", inst.invalid)))
                    continue
                heads[(inst.name, backend)] = head
                file = head["instance_file"]
                task = replace(terms, scenario=file, backend=backend, scenario_text=inst.text)
                items.append(((inst.name, backend), task))
        failed = _run_items(executor, items, heads, figures, rows, emit)
    for (name, backend), fields in figures.items():  # real time against the instance's floor
        judge_against_floor(fields, figures.get((name, NOISE_FLOOR)))
        rows[(name, backend)] |= {k: fields[k] for k in FLOOR_JUDGED if k in fields}
    order = [(inst.name, b) for inst in instances for b in backends]
    final = [rows[k] for k in order if k in rows] + [r for k, r in rows.items() if k not in order]
    with atomic_path(csv_path) as tmp:
        tmp.write_bytes(csv_bytes(final, COLUMNS, header=True))
    return SweepOutcome(final, csv_path, len(items), len(kept), failed)


def _run_items(executor, items: list, heads: dict, figures: dict, rows: dict, emit) -> int:
    """Run ``items`` (``(key, task)``) on ``executor``, the noise floors last and only those the
    other runs need (:func:`_floors_needed`, from ``rows``, which ``emit`` fills): each run's
    figures into ``figures``, its row to ``emit``; the count of runs that failed to run."""
    failed = 0
    floors = {key: task for key, task in items if key[1] == NOISE_FLOOR}
    for batch in ([i for i in items if i[0] not in floors], floors):
        if isinstance(batch, dict):  # the floors the runs' real time needs, now they are in
            needed = _floors_needed(rows, {name for name, _ in batch})
            batch = [(k, t) for k, t in batch.items() if k[0] in needed]
        for done in executor.run(run_row, batch):
            fields = done.value if done.lost is None else failure_fields("crashed", done.lost)
            figures[done.key] = fields
            row = sweep_row(heads[done.key], fields) | dict(
                executor=executor.name,
                host=done.host,
                worker=done.worker,
                concurrent_solves=done.concurrent,
                attempts=done.attempts,
            )
            failed += row["status"] in ("error", "crashed")
            emit(row)
    return failed


def _floors_needed(rows: dict, names: set[str]) -> set[str]:
    """The instances among ``names`` whose noise floor must run: one of their runs (run now, or
    kept) in ``rows`` is not real time, or none of them says (the floor only excuses misses:
    docs/verdicts.md)."""
    said: dict[str, set[str]] = {}
    for (name, backend), row in rows.items():
        if backend != NOISE_FLOOR and row.get("realtime") not in (None, ""):
            said.setdefault(name, set()).add(str(row["realtime"]))
    return {name for name in names if said.get(name) != {"yes"}}
