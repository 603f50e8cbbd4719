"""Reports of benchmark and closed-loop results: ``report.md`` and PNG figures, every number
recomputed from the result CSVs. :mod:`.markdown_table` and :func:`.write.publish` are the one
renderer of every report (this one, the sweep's and the scaling study's)."""

from __future__ import annotations

from .inputs import Results, read_results
from .markdown import render
from .write import write_report

__all__ = ["Results", "read_results", "render", "write_report"]
