"""Cells and tables of ``report.md``: how a number prints, and a Markdown table.

Floats print with :data:`DIGITS` significant digits; times are shown in [us]
(:data:`US`) and distances in [mm] (:data:`MM`).
"""

from __future__ import annotations

import math

import numpy as np

#: Significant digits of every float in the report.
DIGITS = 4


def fmt(value: object) -> str:
    """One table cell: ``-`` for missing, ``inf``, integers as is, floats to 4 significant digits."""
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


def md_table(header: list[str], rows: list[list], pad: bool = False, left: int = 1) -> str:
    """A Markdown table: the first ``left`` columns left-aligned (text), the others right-aligned.

    ``pad``: every column padded to its widest cell, so the table also reads
    aligned as plain text (on a terminal).
    """
    cells = [[fmt(c) for c in r] for r in rows]
    widths = [max(3, len(h)) for h in header]

    def align(i: int, text: str) -> str:
        return text.ljust(widths[i]) if i < left else text.rjust(widths[i])

    if pad:
        widths = [max([w] + [len(r[i]) for r in cells]) for i, w in enumerate(widths)]
        header = [align(i, h) for i, h in enumerate(header)]
        cells = [[align(i, c) for i, c in enumerate(r)] for r in cells]
    head = "| " + " | ".join(header) + " |"
    dashes = [w + 1 if pad else w for w in widths]  # padded: as wide as the cells around them
    rule = (
        "|"
        + "|".join(":" + "-" * w if i < left else "-" * w + ":" for i, w in enumerate(dashes))
        + "|"
    )
    body = ["| " + " | ".join(r) + " |" for r in cells]
    return "\n".join([head, rule, *body]) + "\n"


#: Seconds to microseconds and metres to millimetres (display units).
US = 1e6  # s -> us
MM = 1e3  # m -> mm
