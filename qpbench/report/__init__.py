"""Reports of benchmark and closed-loop results: ``report.md`` and PNG plots.

:func:`write_report` reads bench and closed-loop CSVs (and the tick logs they
name) and writes ``report.md`` and ``plots/*.png``; every number is recomputed
from those files. Statistics live in :mod:`.tables`, the Markdown in
:mod:`.markdown`, the figures in :mod:`.plots` (a closed-loop run's figure in
:mod:`.loop_figure`), the machine description in :mod:`.machine`;
:mod:`.write` ties them together.
"""

from __future__ import annotations

from .inputs import Results, read_results
from .markdown import render
from .write import write_report

__all__ = ["Results", "read_results", "render", "write_report"]
