"""The results table: rows appended and ``fsync``-ed as they are produced, one line each, so a
kill leaves at most one half-written last line, which :func:`read_results` drops."""

from __future__ import annotations

import csv
import io
import logging
import math
import os
from contextlib import suppress
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


def bench_columns() -> tuple[str, ...]:
    """Columns of a bench CSV: lead, the per-tick metrics, tail."""
    return LEAD_COLUMNS + metric_columns() + TAIL_COLUMNS


#: Columns that identify a bench result: a resumed run skips rows with a known key.
KEY_COLUMNS = ("problem", "backend", "profile")

#: Columns that depend on timing only (ignored when comparing two runs).
TIMING_COLUMNS = ("wall_time_min_s", "wall_time_median_s", "solver_time_s", "isolated")


def row_key(row: dict) -> tuple[str, str, str]:
    """The key of a row (values as strings)."""
    return tuple(str(row[c]) for c in KEY_COLUMNS)


def cell(value) -> str:
    """Text of one CSV cell: empty for None/NaN, repr-exact floats, one line."""
    if value is None:
        return ""
    if isinstance(value, float):
        return "" if math.isnan(value) else repr(value)
    text = str(value)
    if "\n" in text or "\r" in text:
        text = " ".join(text.split())
    return text


def csv_bytes(rows: list[dict], columns: tuple[str, ...], header: bool = False) -> bytes:
    """CSV bytes of ``rows`` in ``columns`` order, after the header line if ``header``."""
    buf = io.StringIO()
    writer = csv.writer(buf, lineterminator="\n")
    if header:
        writer.writerow(columns)
    writer.writerows([cell(row.get(c)) for c in columns] for row in rows)
    return buf.getvalue().encode("utf-8")


@dataclass
class ExistingResults:
    """What a resumed run finds: complete rows (dicts of strings), partial lines dropped."""

    rows: list[dict]
    dropped: int = 0


def read_results(
    path: str | Path,
    repair: bool = False,
    columns: tuple[str, ...] | None = None,
    kind: str = "bench",
) -> ExistingResults:
    """Read a table written by :class:`ResultsWriter` (default: a bench CSV): a last line without
    its newline or trailing lines with the wrong number of fields are dropped (``repair``: cut
    from the file too); :class:`InputError` for another header or a malformed line inside."""
    path = Path(path)
    names = bench_columns() if columns is None else tuple(columns)
    data = path.read_bytes()
    dropped = 0
    if data and not data.endswith(b"\n"):
        cut = data.rfind(b"\n") + 1
        msg = "%s: dropping a half-written last line (%d bytes) left by an interrupted run"
        log.warning(msg, path, len(data) - cut)
        data = data[:cut]
        dropped += 1
        if repair:
            os.truncate(path, cut)
    if not data:
        if repair:  # killed before the header was complete: start the file again
            ResultsWriter(path, new=True, columns=names).close()
        return ExistingResults([], dropped)
    lines = data.split(b"\n")[:-1]
    header, *body = (next(csv.reader([ln.decode("utf-8", errors="replace")])) for ln in lines)
    if tuple(header) != names:
        missing = [c for c in names if c not in header]
        raise InputError(
            f"not a {kind} CSV of this version (missing columns: {', '.join(missing) or 'none'}; "
            "columns differ); use --force to start again",
            path=path,
        )
    n = len(body)  # the rows before the malformed lines at the end
    while n and len(body[n - 1]) != len(names):
        n -= 1
    if any(len(fields) != len(names) for fields in body[:n]):
        raise InputError(
            "malformed line in the middle of the file; use --force to start again", path=path
        )
    for fields in body[n:]:
        msg = "%s: dropping a malformed line (%d fields, expected %d)"
        log.warning(msg, path, len(fields), len(names))
    if repair and n < len(body):
        os.truncate(path, sum(len(ln) + 1 for ln in lines[: n + 1]))
    rows = [dict(zip(names, fields)) for fields in body[:n]]
    return ExistingResults(rows, dropped + len(body) - n)


class ResultsWriter:
    """Append rows to a table, one ``write`` + ``fsync`` per batch; ``new``: create (truncate)
    the file and write the header, else append; ``columns``: the table's (default: the bench's)."""

    def __init__(self, path: str | Path, new: bool, columns: tuple[str, ...] | None = None):
        from ..atomic import record

        self.path = Path(path)
        self.columns = bench_columns() if columns is None else tuple(columns)
        self.path.parent.mkdir(parents=True, exist_ok=True)
        flags = os.O_WRONLY | os.O_APPEND | os.O_CREAT | (os.O_TRUNC if new else 0)
        self._fd = os.open(self.path, flags, 0o644)
        record(self.path)
        if new:
            self._write(csv_bytes([], self.columns, header=True))

    def _write(self, data: bytes) -> None:
        view = memoryview(data)
        while view:
            view = view[os.write(self._fd, view) :]
        os.fsync(self._fd)

    def write_rows(self, rows: list[dict]) -> None:
        """Append ``rows`` and make them durable before returning."""
        if rows:
            self._write(csv_bytes(rows, self.columns))

    def close(self) -> None:
        if self._fd is not None:
            os.close(self._fd)
            self._fd = None

    def __enter__(self):
        return self

    def __exit__(self, *exc):
        self.close()


class InflightMarker:
    """A side file ``.<out>.inflight`` naming the solve in progress and what killed the run: line
    1, the backends to isolate; line 2, the key, tab-separated; then the :mod:`faulthandler`
    traceback, if any."""

    def __init__(self, out: str | Path):
        self.path = Path(out).with_name(f".{Path(out).name}.inflight")
        self._fd = None
        self._fault_fd = None
        self._faulthandler_was = None

    def read(self) -> tuple[list[str], tuple[str, ...] | None, str]:
        """``(backends to isolate, last in-flight key or None, fatal-error text)``."""
        if not self.path.exists():
            return [], None, ""
        lines = self.path.read_text(errors="replace").split("\n")
        isolate = [b for b in lines[0].split(",") if b]
        key = tuple(lines[1].split("\t")) if len(lines) > 1 and lines[1] else None
        return isolate, key, "\n".join(lines[2:]).strip()

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
        data = (",".join(self.isolate) + "\n" + ("\t".join(key) if key else "") + "\n").encode()
        os.pwrite(self._fd, data, 0)
        os.ftruncate(self._fd, len(data))

    def close(self) -> None:
        if self._fault_fd is not None:
            import faulthandler
            import sys

            faulthandler.disable()
            if self._faulthandler_was:
                with suppress(Exception):  # no usable stderr
                    faulthandler.enable(file=sys.__stderr__)
            os.close(self._fault_fd)
            self._fault_fd = None
        if self._fd is not None:
            os.close(self._fd)
            self._fd = None

    def remove(self) -> None:
        self.close()
        self.path.unlink(missing_ok=True)
