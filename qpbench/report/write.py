"""``report.md`` and its figures from result CSVs: the one entry point of a report.

:mod:`.tables` reads the CSVs, :mod:`.plots` draws the figures, :mod:`.markdown`
renders the text; this module calls them in that order (neither of the last
two imports the other).
"""

from __future__ import annotations

from pathlib import Path
from typing import TYPE_CHECKING

import pandas as pd

from . import tables
from .markdown import render

if TYPE_CHECKING:
    from collections.abc import Callable

__all__ = ["write_report"]


def write_report(
    paths: list[str | Path],
    out: str | Path,
    *,
    force: bool = False,
    plots: bool = True,
    prefer: str | None = None,
    sections: Callable[[Path, bool], list[str]] | None = None,
) -> Path:
    """Read the result CSVs, write ``out/report.md`` and ``out/plots/*.png``.

    Args:
        sections: ``sections(out, plots) -> list of markdown lines`` appended after the
            tables, called once the output is checked (the sweep section of
            :mod:`qpbench.sweep.report`); with it, ``paths`` may be empty.
        prefer: Which file's row to keep for a key present in several bench
            CSVs (``first``/``last``; ``None``: refuse), see
            :func:`qpbench.report.tables.read_results`.

    Raises:
        InputError: a path is missing or not a result CSV, a duplicate key or
            mixed repeat counts without ``prefer``.
        OutputExistsError: ``out/report.md`` exists and ``force`` is false.
    """
    from ..atomic import check_folder, check_output, write_text

    out = Path(out)
    report_path = out / "report.md"
    check_folder(out)
    if out.exists():
        check_output(report_path, force=force)
    results = (
        tables.read_results(paths, prefer=prefer)
        if paths or sections is None
        else tables.Results(pd.DataFrame(), pd.DataFrame())
    )
    plot_files: dict[str, str] = {}
    if plots:
        from .plots import write_plots

        plot_files = write_plots(results, out / "plots", relative_to=out)
    text = render(results, plot_files)
    if sections is not None:
        text += "\n" + "\n".join(sections(out, plots))
    write_text(report_path, text)
    return report_path
