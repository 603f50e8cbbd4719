"""A sweep's run into ``DIR``: ``sweep.json`` (the manifest: the sweep file's text and SHA-256,
seed, samples, duration, base, backends, qpbench's version), ``instances/<name>.toml`` and
``sweep.csv`` (:mod:`.rows`). Resuming keeps the ``ok`` and ``invalid_scenario`` rows and runs the
rest again; it refuses a folder of another sweep file or duration (instance ``i`` is the same
whatever the sample count).
"""

from __future__ import annotations

import json
import logging
import shutil
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING

from ..atomic import atomic_path, check_folder, check_output, write_text
from ..exceptions import InputError
from ..harness.closed_loop import LoopTask, failure_fields, run_row
from ..harness.results import ResultsWriter, format_rows, header_bytes, read_results
from .rows import COLUMNS, CSV_NAME, INSTANCE_DIR, KEY_COLUMNS, head_row, sweep_row
from .sample import sample_instances
from .spec import SweepSpec

if TYPE_CHECKING:
    from ..runner import DaskExecutor, ProcessExecutor, SerialExecutor

log = logging.getLogger("qpbench.sweep")

MANIFEST_NAME = "sweep.json"
#: Statuses a resumed sweep keeps.
KEPT_STATUSES = ("ok", "invalid_scenario")


@dataclass
class SweepOutcome:
    """What :func:`run_sweep` did: the table's rows (one per key), how many ran now, how many failed to run."""

    rows: list[dict]
    csv_path: Path
    ran: int
    kept: int
    failed: int


def _manifest(spec: SweepSpec, backends: list[str]) -> dict:
    from .. import __version__

    return {
        # samples, backends: of every run into the folder (a resumed run merges them)
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


def _resumable(out: Path, spec: SweepSpec) -> dict:
    """The manifest of the sweep in ``out``, if made from the same sweep file and duration."""
    path = out / MANIFEST_NAME
    try:
        old = json.loads(path.read_text())
    except (OSError, ValueError) as exc:
        raise InputError(
            f"cannot resume: unreadable manifest ({exc}); use --force to start again", path=path
        ) from None
    for key, value, what in (
        ("sweep_sha256", spec.sha256, f"made from another sweep file ({old.get('sweep_file')})"),
        (
            "duration",
            spec.duration,
            f"made with duration {old.get('duration')}, not {spec.duration}",
        ),
    ):
        if old.get(key) != value:
            raise InputError(f"cannot resume: {what}; use --force", path=path, key=key)
    return old


def read_sweep_rows(csv_path: str | Path, repair: bool = False) -> list[dict]:
    """The rows of ``sweep.csv`` as strings, the last row of each key kept (a half-written line dropped)."""
    rows = read_results(csv_path, repair=repair, columns=COLUMNS, kind="sweep").rows
    last = {tuple(r[c] for c in KEY_COLUMNS): r for r in rows}
    return list(last.values())


def _prepare(out: Path, spec: SweepSpec, backends: list[str], force: bool, resume: bool):
    """Check ``out``, write the instances and the manifest; the instances and the kept rows."""
    csv_path = out / CSV_NAME
    check_folder(out)
    check_output(csv_path, force=force, resume=resume, make_parent=True)  # out is made below
    manifest, kept = _manifest(spec, backends), {}
    if resume and csv_path.exists():  # the table holds the earlier runs' rows too
        old = _resumable(out, spec)
        manifest["backends"] = list(dict.fromkeys(old.get("backends", []) + backends))
        manifest["samples"] = max(int(old.get("samples", 0)), spec.samples)
        rows = read_sweep_rows(csv_path, repair=True)
        kept = {(r["instance"], r["backend"]): r for r in rows if r["status"] in KEPT_STATUSES}
    elif force:
        csv_path.unlink(missing_ok=True)
        shutil.rmtree(out / INSTANCE_DIR, ignore_errors=True)
    instances = sample_instances(spec)
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
) -> SweepOutcome:
    """Run every (instance, backend) of ``spec`` on ``executor`` (:mod:`qpbench.runner`) into ``out``.

    Each run is :func:`qpbench.harness.closed_loop.run_row`; its row is appended to ``sweep.csv``
    as it ends (then ``on_row``). At the end the table is rewritten atomically in instance and
    backend order, one row per key.

    Raises:
        OutputExistsError: ``out/sweep.csv`` exists without ``force`` or ``resume``.
        InputError: resuming a folder of another sweep file or duration.
    """
    out = Path(out)
    instances, kept = _prepare(out, spec, backends, force, resume)
    csv_path = out / CSV_NAME
    rows = dict(kept)
    new = not csv_path.exists() or csv_path.stat().st_size == 0
    ran = failed = 0
    items, heads = [], {}
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
                task = LoopTask(
                    head["instance_file"],
                    backend,
                    plugins=tuple(plugins or ()),
                    scenario_text=inst.text,  # the instance travels with its task
                    bands=(spec.force_band, spec.tracking_band),
                )
                items.append(((inst.name, backend), task))
        for done in executor.run(run_row, items):
            head = heads[done.key]
            fields = done.value if done.lost is None else failure_fields("crashed", done.lost)
            row = sweep_row(head, fields)
            row.update(
                executor=executor.name,
                host=done.host,
                worker=done.worker,
                concurrent_solves=done.concurrent,
                attempts=done.attempts,
            )
            ran += 1
            failed += row["status"] in ("error", "crashed")
            emit(row)
    order = [(inst.name, b) for inst in instances for b in backends]
    final = [rows[k] for k in order if k in rows] + [
        r for k, r in rows.items() if k not in set(order)
    ]
    with atomic_path(csv_path) as tmp:
        tmp.write_bytes(header_bytes(COLUMNS) + format_rows(final, COLUMNS))
    return SweepOutcome(final, csv_path, ran, len(kept), failed)
