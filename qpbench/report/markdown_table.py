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


def md_table(header: list[str], rows: list[list]) -> str:
    """A Markdown table (first column left-aligned, the others right-aligned)."""
    cells = [[fmt(c) for c in r] for r in rows]
    head = "| " + " | ".join(header) + " |"
    align = (
        "|:"
        + "-" * max(3, len(header[0]))
        + "|"
        + "|".join("-" * max(3, len(h)) + ":" for h in header[1:])
        + "|"
    )
    body = ["| " + " | ".join(r) + " |" for r in cells]
    return "\n".join([head, align, *body]) + "\n"


#: Seconds to microseconds and metres to millimetres (display units).
US = 1e6  # s -> us
MM = 1e3  # m -> mm
