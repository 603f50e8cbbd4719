"""Reports of benchmark and closed-loop results: ``report.md`` and PNG plots.

:func:`write_report` reads bench and closed-loop CSVs (and the tick logs they
name) and writes ``report.md`` and ``plots/*.png``; every number is recomputed
from those files. Statistics live in :mod:`.tables`, the Markdown in
:mod:`.markdown`, the figures in :mod:`.plots`, the machine description in
:mod:`.machine`.
"""

from __future__ import annotations

from .markdown import render, write_report
from .tables import Results, read_results

__all__ = ["Results", "read_results", "render", "write_report"]
