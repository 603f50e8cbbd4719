"""The one renderer of report tables: how a value prints (:func:`fmt`), typed columns
(:class:`Column`), a Markdown table (:func:`md_table`)."""

from __future__ import annotations

import math
import re
from dataclasses import dataclass
from typing import TYPE_CHECKING

import numpy as np

if TYPE_CHECKING:
    from collections.abc import Callable, Iterable

#: Significant digits of every float in the report.
DIGITS = 4
#: Seconds to microseconds and metres to millimetres (display units).
US = 1e6
MM = 1e3


def slug(text: str) -> str:
    """File-name-safe form of a label (figure keys and file names of a report)."""
    return re.sub(r"[^A-Za-z0-9_.-]+", "_", text).strip("_") or "x"


def fmt(value: object) -> str:
    """One cell: ``-`` for missing, ``inf``, integers as is, floats to :data:`DIGITS` digits."""
    if value is None:
        return "-"
    if isinstance(value, (bool, np.bool_)):
        return "yes" if value else "no"
    if isinstance(value, (int, np.integer)):
        return str(int(value))
    if isinstance(value, (float, np.floating)):
        v = float(value)
        if math.isnan(v):
            return "-"
        if math.isinf(v):
            return "inf" if v > 0 else "-inf"
        if v == int(v) and abs(v) < 1e6:
            return str(int(v))
        return f"{v:.{DIGITS}g}"
    text = str(value)
    return text.replace("|", "\\|").replace("\n", " ") if text else "-"


def md_table(header: list[str], rows: list[list], pad: bool = False, left=1) -> str:
    """A Markdown table; ``left``: the first ``left`` columns (or the columns of these indices)
    are left-aligned, the others right-aligned; ``pad``: every column padded to its widest cell."""
    lefts = set(range(left)) if isinstance(left, int) else set(left)
    cells = [[fmt(c) for c in r] for r in rows]
    widths = [max(3, len(h)) for h in header]

    def align(i: int, text: str) -> str:
        return text.ljust(widths[i]) if i in lefts else text.rjust(widths[i])

    if pad:
        widths = [max([w] + [len(r[i]) for r in cells]) for i, w in enumerate(widths)]
        header = [align(i, h) for i, h in enumerate(header)]
        cells = [[align(i, c) for i, c in enumerate(r)] for r in cells]
    head = "| " + " | ".join(header) + " |"
    dashes = [w + 1 if pad else w for w in widths]  # padded: as wide as the cells around them
    rule = "|".join(":" + "-" * w if i in lefts else "-" * w + ":" for i, w in enumerate(dashes))
    body = ["| " + " | ".join(r) + " |" for r in cells]
    return "\n".join([head, f"|{rule}|", *body]) + "\n"


@dataclass(frozen=True)
class Column:
    """A typed table column: ``header``, the record ``key`` it shows, as it is or, a number,
    times ``scale`` and printed with the format spec ``form`` (``-`` when not finite; default:
    :func:`fmt`); or ``cell(record)`` when computed. ``text`` columns are left-aligned."""

    header: str
    key: str | None = None
    scale: float | None = None
    form: str | None = None
    cell: Callable[[dict], object] | None = None
    text: bool = False

    def value(self, record) -> object:
        if self.cell is not None:
            return self.cell(record)
        value = record[self.key]
        if self.scale is None and self.form is None:
            return value
        try:
            v = float(value) * (1.0 if self.scale is None else self.scale)
        except (TypeError, ValueError):
            return math.nan
        if self.form is None:
            return v
        return f"{v:{self.form}}" if math.isfinite(v) else "-"


def titled(title: str, header: list[str], rows: list[list], **kw) -> list[str]:
    """``title`` and the table of ``rows``; nothing when there are no rows."""
    return [title, md_table(header, rows, **kw)] if rows else []


def table(columns: Iterable[Column], records: Iterable) -> list[str]:
    """The Markdown table of ``records`` (mappings) under ``columns``."""
    columns = list(columns)
    rows = [[c.value(r) for c in columns] for r in records]
    left = [i for i, c in enumerate(columns) if c.text]
    return [md_table([c.header for c in columns], rows, left=left)]


def aligned(rows: list, align: str = "l", free_last: bool = False) -> str:
    """Rows of text cells as columns, column ``i`` left-aligned if ``align[i]`` is ``l``, else
    (or past ``align``) right-aligned; ``free_last``: the last column (free text) not padded."""
    n = len(rows[0]) - free_last
    widths = [max(len(r[c]) for r in rows) for c in range(n)]
    return "\n".join(
        "  ".join(
            [
                c.ljust(w) if align[i : i + 1] == "l" else c.rjust(w)
                for i, (c, w) in enumerate(zip(r, widths))
            ]
            + list(r[n:])
        ).rstrip()
        for r in rows
    )
