"""Reports of benchmark and closed-loop results: ``report.md`` and PNG figures, every number
recomputed from the result CSVs. :mod:`.markdown_table` and :func:`.write.publish` are the one
renderer of every report (this one, the sweep's and the scaling study's)."""

from __future__ import annotations

from .write import write_report as write_report
