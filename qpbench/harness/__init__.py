"""The benchmark harness: timed, guarded, resumable runs of backends over problem sets.

- :mod:`.bench`: :func:`run_bench` (``qpbench bench``), sequences, rows;
- :mod:`.timing`: the timed region and state restoration between repeats;
- :mod:`.guard`: guarded in-process solves (exceptions, time limit, non-finite answers);
- :mod:`.isolation`: solves in a worker process (hangs and crashes), through
  :mod:`qpbench.runner.process`, the one module that owns worker processes;
- :mod:`.results`: CSV rows appended as produced, read back on resume;
- :mod:`.plugins`: extra backend modules (``--plugin``, ``QPBENCH_PLUGINS``);
- :mod:`.closed_loop`: :func:`run_row` (one closed-loop run, every command's) and
  :func:`run_closed_loop` (``qpbench closed-loop``, ``closed_loop.csv``);
- :mod:`.pipeline`: :func:`run_all` (``qpbench run``): problem sets, bench,
  closed loop, report.
"""

from .bench import BenchConfig, BenchSummary, is_failure, run_bench, sequences
from .results import KEY_COLUMNS, columns, read_results

__all__ = [
    "KEY_COLUMNS",
    "columns",
    "BenchConfig",
    "BenchSummary",
    "is_failure",
    "read_results",
    "run_bench",
    "sequences",
]
