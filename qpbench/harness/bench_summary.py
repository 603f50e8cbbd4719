"""What a bench run did: per-backend counts and the closing line and table it prints."""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

from ..statuses import FAILURE_STATUSES

#: Seed of the per-problem backend order unless ``--seed`` says otherwise.
DEFAULT_SEED = 0


@dataclass
class BackendStats:
    """One backend's rows in a bench run (a line of the closing table).

    ``times_s``: ``wall_time_min_s`` of its rows [s]; ``violations``: ``constraint_violation``
    of the rows with an ``x``; ``failures``: failed solves (:func:`is_failure`) by status;
    ``isolated``: rows solved in a worker process.
    """

    rows: int = 0
    successes: int = 0
    times_s: list = field(default_factory=list)
    violations: list = field(default_factory=list)
    failures: dict = field(default_factory=dict)
    isolated: int = 0

    @property
    def n_failures(self) -> int:
        return sum(self.failures.values())

    @property
    def unsuccessful(self) -> int:
        return self.rows - self.successes

    def add(self, row: dict) -> None:
        """Count one row (a new row's values or a resumed row's strings)."""
        self.rows += 1
        if _truth(row.get("success")):
            self.successes += 1
        if _truth(row.get("isolated")):
            self.isolated += 1
        t = as_float(row.get("wall_time_min_s"))
        if t is not None and math.isfinite(t):
            self.times_s.append(t)
        v = as_float(row.get("constraint_violation"))
        if v is not None and not math.isnan(v):
            self.violations.append(v)
        status = str(row.get("status"))
        if is_failure(status, row.get("reference_status") or None):
            self.failures[status] = self.failures.get(status, 0) + 1


@dataclass
class BenchSummary:
    """What a bench run did (the data of the closing line and table).

    Attributes:
        rows: Rows of this run's keys in the CSV (resumed and new); ``new_rows``: written now.
        failures: Rows counted as failed solves (:func:`is_failure`).
        elapsed_s: Duration of this invocation [s].
        timed_s: Sum of the new rows' ``wall_time_min_s`` [s].
        overhead_median_s: Median over new rows of ``wall_time_min_s - solver_time_s`` [s]
            (NaN if no backend reports a time), over ``overhead_rows`` rows.
        isolated: Backends that ran in a worker process.
    """

    rows: int = 0
    new_rows: int = 0
    failures: int = 0
    backends: dict = field(default_factory=dict)
    elapsed_s: float = 0.0
    timed_s: float = 0.0
    overhead_median_s: float = math.nan
    overhead_rows: int = 0
    isolated: list = field(default_factory=list)
    seed: int = DEFAULT_SEED

    def line(self) -> str:
        """The closing line: rows, failed and unsuccessful solves by backend, times."""

        def by_backend(counts: dict) -> str:
            return " (" + ", ".join(f"{b} {n}" for b, n in counts.items()) + ")" if counts else ""

        failed = {b: s.n_failures for b, s in self.backends.items() if s.n_failures}
        unsuccessful = {b: s.unsuccessful for b, s in self.backends.items() if s.unsuccessful}
        text = (
            f"{self.rows} rows ({self.new_rows} new) in {self.elapsed_s:.1f} s; "
            f"{self.failures} failed solves{by_backend(failed)}; "
            f"{sum(unsuccessful.values())} without success{by_backend(unsuccessful)}; "
            f"timed solves {self.timed_s:.3f} s; backend order seed {self.seed}"
        )
        if self.overhead_rows:
            text += (
                f"; harness overhead (wall - solver-reported time) median "
                f"{self.overhead_median_s * 1e6:.1f} us over {self.overhead_rows} solves"
            )
        if self.isolated:
            text += f"; isolated: {', '.join(self.isolated)}"
        return text

    def table(self) -> str:
        """Per backend: rows, success %, time p50/p99 [us], max constraint violation (problem
        units), failures by status; ``*`` marks a backend solved in a worker process."""
        header = [
            "backend",
            "rows",
            "success %",
            "time p50 (us)",
            "time p99 (us)",
            "max violation",
            "failures",
        ]
        lines = [header]
        for name, st in self.backends.items():
            times = np.asarray(st.times_s, dtype=float)
            viol = np.asarray(st.violations, dtype=float)
            fails = ", ".join(f"{k} {v}" for k, v in sorted(st.failures.items())) or "0"
            lines.append(
                [
                    name + (" *" if st.isolated else ""),
                    str(st.rows),
                    f"{100.0 * st.successes / st.rows:.1f}" if st.rows else "-",
                    f"{np.percentile(times, 50) * 1e6:.1f}" if times.size else "-",
                    f"{np.percentile(times, 99) * 1e6:.1f}" if times.size else "-",
                    f"{viol.max():.3g}" if viol.size else "-",
                    fails if not st.n_failures else f"{st.n_failures} ({fails})",
                ]
            )
        widths = [max(len(r[j]) for r in lines) for j in range(len(header))]
        out = []
        for r in lines:
            cells = (
                [r[0].ljust(widths[0])]
                + [c.rjust(w) for c, w in zip(r[1:-1], widths[1:-1])]
                + [r[-1]]
            )
            out.append("  ".join(cells).rstrip())
        if any(st.isolated for st in self.backends.values()):
            out.append("* some or all rows solved in a worker process (times taken inside it)")
        return "\n".join(out)


def _truth(value) -> bool:
    """A boolean cell: ``True`` / ``"True"`` (a resumed row) is true."""
    if isinstance(value, str):
        return value.strip().lower() in ("true", "1")
    return bool(value)


def is_failure(status: str, reference_status: str | None) -> bool:
    """A failed solve: a harness failure status, or not ``optimal`` where the reference is.

    A ``skipped`` row (a solve not made: nonconvex, beyond a dense-only backend's size or
    the memory budget; the reason in ``error``) is not a failure.
    """
    if status == "skipped":
        return False
    return status in FAILURE_STATUSES or (reference_status == "optimal" and status != "optimal")


def as_float(value) -> float | None:
    """A number cell (a new row's value or a resumed row's string) as a float, else ``None``."""
    if value is None:
        return None
    try:
        return float(value)
    except (TypeError, ValueError):
        return None
