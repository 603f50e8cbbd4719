"""Results rows: long format, appended and flushed as they are produced, resumable.

One row per (problem, backend, profile), the key of a result (as in
qpbenchmark's ``Results``). The CSV is written with the :mod:`csv` module, one
physical line per row (newlines inside a field are replaced by spaces), so a
kill at any moment leaves at most one half-written line, at the end of the
file. :func:`read_results` finds it, drops it with a warning and truncates the
file to its last complete line before a run resumes.

Every batch of rows (one problem, all backends) goes out in one ``write``
call on an ``O_APPEND`` descriptor and is ``fsync``-ed before the next
problem starts: a process kill loses only the problem being solved, a power
loss at most that one too.
"""

from __future__ import annotations

import csv
import io
import logging
import math
import os
from dataclasses import dataclass
from pathlib import Path

from ..exceptions import InputError
from ..metrics import metric_columns

log = logging.getLogger("qpbench.harness")

#: Columns before the metrics: the record, what ran, and its outcome.
LEAD_COLUMNS = (
    "problem",
    "scenario",
    "tick",
    "t",
    "backend",
    "profile",
    "mode",
    "status",
    "found",
    "success",
)

#: Columns after the metrics: timings, the harness's own record, sizes and provenance.
TAIL_COLUMNS = (
    "wall_time_min_s",
    "wall_time_median_s",
    "solver_time_s",
    "iterations",
    "error",
    "state_reset",
    "isolated",
    "position",
    "order_seed",
    "repeat",
    "repeat_exact",
    "repeat_note",
    "n",
    "m_eq",
    "m_ineq",
    "n_box",
    "problem_set_sha256",
    "backend_version",
)


def columns() -> tuple[str, ...]:
    """Columns of a bench CSV, in order: lead, every per-tick metric (:func:`qpbench.metrics.metric_columns`), tail."""
    return LEAD_COLUMNS + metric_columns() + TAIL_COLUMNS


#: :func:`columns` under a name that a ``columns`` parameter does not hide.
bench_columns = columns


#: Columns that identify a result: a resumed run skips rows with a known key.
KEY_COLUMNS = ("problem", "backend", "profile")

#: Columns that depend on timing only (ignored when comparing two runs).
TIMING_COLUMNS = ("wall_time_min_s", "wall_time_median_s", "solver_time_s", "isolated")


def row_key(row: dict) -> tuple[str, str, str]:
    """``(problem, backend, profile)`` of a row (values as strings)."""
    return tuple(str(row[c]) for c in KEY_COLUMNS)


def cell_text(value) -> str:
    """Text of one CSV cell: empty for None/NaN, repr-exact floats, one line."""
    if value is None:
        return ""
    if isinstance(value, bool):
        return "True" if value else "False"
    if isinstance(value, float):
        if math.isnan(value):
            return ""
        return repr(value)
    if isinstance(value, int):
        return str(value)
    text = str(value)
    if "\n" in text or "\r" in text:
        text = " ".join(text.split())
    return text


def format_rows(rows: list[dict], columns: tuple[str, ...] | None = None) -> bytes:
    """CSV bytes of ``rows`` (no header), one line each, in ``columns`` order (default: the bench's,
    :func:`bench_columns`)."""
    buf = io.StringIO()
    writer = csv.writer(buf, lineterminator="\n")
    names = bench_columns() if columns is None else columns
    for row in rows:
        writer.writerow([cell_text(row.get(c)) for c in names])
    return buf.getvalue().encode("utf-8")


def header_bytes(columns: tuple[str, ...] | None = None) -> bytes:
    """The header line of a bench CSV (or of another table of ``columns``)."""
    return (",".join(bench_columns() if columns is None else columns) + "\n").encode("utf-8")


@dataclass
class ExistingResults:
    """What a resumed run finds in its ``--out``.

    Attributes:
        rows: Complete rows as dicts of strings, in file order.
        dropped: Number of partial lines dropped (0 or 1 in practice).
    """

    rows: list[dict]
    dropped: int = 0

    def by_key(self) -> dict[tuple[str, str, str], dict]:
        return {row_key(r): r for r in self.rows}


def read_results(
    path: str | Path,
    repair: bool = False,
    columns: tuple[str, ...] | None = None,
    kind: str = "bench",
) -> ExistingResults:
    """Read a bench CSV written by :class:`ResultsWriter` (or a ``kind`` table of ``columns``).

    A last line without its newline (the run was killed while writing it) or
    a line with the wrong number of fields is dropped with a warning; with
    ``repair=True`` the file is also truncated to its last complete line so
    that appending continues cleanly.

    Raises:
        InputError: the file is not a bench CSV (missing or different header).
    """
    path = Path(path)
    names = bench_columns() if columns is None else tuple(columns)
    data = path.read_bytes()
    dropped = 0
    if data and not data.endswith(b"\n"):
        cut = data.rfind(b"\n") + 1
        log.warning(
            "%s: dropping a half-written last line (%d bytes) left by an interrupted run",
            path,
            len(data) - cut,
        )
        data = data[:cut]
        dropped += 1
        if repair:
            os.truncate(path, cut)
    if not data:
        if repair:
            # killed before the header was complete: start the file again
            with open(path, "wb") as fh:
                fh.write(header_bytes(names))
                fh.flush()
                os.fsync(fh.fileno())
        return ExistingResults([], dropped)
    text = data.decode("utf-8", errors="replace")
    lines = text.split("\n")[:-1]
    header = next(csv.reader([lines[0]]))
    if tuple(header) != names:
        missing = [c for c in names if c not in header]
        raise InputError(
            f"not a {kind} CSV of this version (missing columns: {', '.join(missing) or 'none'}; "
            "columns differ); use --force to start again",
            path=path,
        )
    rows = []
    good_end = len(lines[0]) + 1
    offset = good_end
    bad_tail = False
    for line in lines[1:]:
        fields = next(csv.reader([line])) if line else []
        if len(fields) != len(names):
            log.warning(
                "%s: dropping a malformed line (%d fields, expected %d)",
                path,
                len(fields),
                len(names),
            )
            dropped += 1
            bad_tail = True
        else:
            if bad_tail:
                raise InputError(
                    "malformed line in the middle of the file; use --force to start again",
                    path=path,
                )
            rows.append(dict(zip(names, fields)))
            good_end = offset + len(line.encode("utf-8")) + 1
        offset += len(line.encode("utf-8")) + 1
    if repair and bad_tail:
        os.truncate(path, good_end)
    return ExistingResults(rows, dropped)


class ResultsWriter:
    """Append rows to a bench CSV, one ``write`` + ``fsync`` per batch.

    Args:
        path: The CSV file.
        new: Create (truncate) the file and write the header; else append.
        fsync: Call ``os.fsync`` after each batch (off only in tests of speed).
        columns: The table's columns (default: the bench's, :func:`bench_columns`).
    """

    def __init__(
        self,
        path: str | Path,
        new: bool,
        fsync: bool = True,
        columns: tuple[str, ...] | None = None,
    ):
        self.path = Path(path)
        self.fsync = fsync
        self.columns = bench_columns() if columns is None else tuple(columns)
        self.path.parent.mkdir(parents=True, exist_ok=True)
        flags = os.O_WRONLY | os.O_APPEND | os.O_CREAT
        if new:
            flags |= os.O_TRUNC
        self._fd = os.open(self.path, flags, 0o644)
        from ..atomic import record

        record(self.path)
        if new:
            self._write(header_bytes(self.columns))
        self.count = 0

    def _write(self, data: bytes) -> None:
        view = memoryview(data)
        while view:
            done = os.write(self._fd, view)
            view = view[done:]
        if self.fsync:
            os.fsync(self._fd)

    def write_rows(self, rows: list[dict]) -> None:
        """Append ``rows`` and make them durable before returning."""
        if rows:
            self._write(format_rows(rows, self.columns))
            self.count += len(rows)

    def close(self) -> None:
        if self._fd is not None:
            os.close(self._fd)
            self._fd = None

    def __enter__(self):
        return self

    def __exit__(self, *exc):
        self.close()


class InflightMarker:
    """A small side file naming the solve in progress, and what killed the run.

    Written before every solve (two system calls, outside the timed region;
    no fsync: it only has to outlive this process, and the page cache does).
    While the run lasts, :mod:`faulthandler` writes to the end of the same file
    (a second descriptor opened with ``O_APPEND``) when this process gets a
    fatal signal (SIGSEGV, SIGFPE, SIGABRT, SIGBUS, SIGILL). So after a run died:

    - the key names a solve that has no row, and a traceback follows: a
      backend crashed this process; with ``--isolate auto`` the next
      ``--resume`` runs that backend in a worker process from then on;
    - no traceback: the process was killed from outside (SIGKILL, power): the
      solve is simply run again.

    Removed when a run ends normally.

    Format: line 1, the comma-separated backends to isolate; line 2, the key
    ``problem<TAB>backend<TAB>profile`` (``warmup <TAB>...`` or
    ``replay <problem><TAB>...`` outside recorded solves); then the traceback, if any.
    """

    def __init__(self, path: str | Path):
        self.path = Path(path)
        self.isolate: list[str] = []
        self._fd = None
        self._fault_fd = None
        self._faulthandler_was = None

    @staticmethod
    def for_output(out: str | Path) -> Path:
        out = Path(out)
        return out.with_name(f".{out.name}.inflight")

    def read(self) -> tuple[list[str], tuple[str, ...] | None, str]:
        """``(backends to isolate, last in-flight key or None, fatal-error text)`` of a previous run."""
        if not self.path.exists():
            return [], None, ""
        lines = self.path.read_text(errors="replace").split("\n")
        isolate = [b for b in lines[0].split(",") if b] if lines else []
        key = tuple(lines[1].split("\t")) if len(lines) > 1 and lines[1] else None
        crash = "\n".join(lines[2:]).strip()
        return isolate, key, crash

    def open(self, isolate: list[str], catch_faults: bool = True) -> None:
        self.isolate = list(isolate)
        self._fd = os.open(self.path, os.O_WRONLY | os.O_CREAT | os.O_TRUNC, 0o644)
        self.mark(None)
        if catch_faults:
            import faulthandler

            self._fault_fd = os.open(self.path, os.O_WRONLY | os.O_APPEND)
            self._faulthandler_was = faulthandler.is_enabled()
            faulthandler.enable(file=self._fault_fd, all_threads=False)

    def mark(self, key: tuple[str, ...] | None) -> None:
        if self._fd is None:
            return
        data = (",".join(self.isolate) + "\n" + ("\t".join(key) if key else "") + "\n").encode()
        os.pwrite(self._fd, data, 0)
        os.ftruncate(self._fd, len(data))

    def close(self) -> None:
        if self._fault_fd is not None:
            import faulthandler
            import sys

            faulthandler.disable()
            if self._faulthandler_was:
                try:
                    faulthandler.enable(file=sys.__stderr__)
                except Exception:  # noqa: BLE001 - no usable stderr
                    pass
            os.close(self._fault_fd)
            self._fault_fd = None
        if self._fd is not None:
            os.close(self._fd)
            self._fd = None

    def remove(self) -> None:
        self.close()
        if self.path.exists():
            self.path.unlink()
