"""The benchmark harness: timed, guarded, resumable runs of backends over problem sets.

:mod:`.bench` (``qpbench bench``), :mod:`.closed_loop` (``qpbench closed-loop``) and
:mod:`.pipeline` (``qpbench run``); solves timed by :mod:`.timing`, guarded by :mod:`.guard` or
isolated in a worker process by :mod:`.isolation`; rows written by :mod:`.results`.
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
