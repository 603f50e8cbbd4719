"""TOML text of a scenario's tables (what :mod:`tomllib` reads, written back exactly).

Floats are written with :func:`repr`, so ``tomllib.loads(dumps(raw)) == raw`` for the tables a
scenario file holds (numbers, booleans, strings, nested lists, arrays of tables).
"""

from __future__ import annotations

import json
import re

_BARE = re.compile(r"[A-Za-z0-9_-]+")


def _key(key: str) -> str:
    return key if _BARE.fullmatch(key) else json.dumps(key)


def value_text(value: object) -> str:
    """One TOML value."""
    if isinstance(value, bool):
        return "true" if value else "false"
    if isinstance(value, int):
        return str(value)
    if isinstance(value, float):  # repr: inf, -inf and nan as TOML writes them
        text = repr(value)
        return text if any(c in text for c in ".en") else text + ".0"
    if isinstance(value, str):
        return json.dumps(value, ensure_ascii=False)
    if isinstance(value, (list, tuple)):
        return "[" + ", ".join(value_text(v) for v in value) + "]"
    if isinstance(value, dict):
        return "{ " + ", ".join(f"{_key(k)} = {value_text(v)}" for k, v in value.items()) + " }"
    if hasattr(value, "tolist"):  # numpy scalars and arrays
        return value_text(value.tolist())
    raise TypeError(f"cannot write {type(value).__name__} as TOML")


def dumps(raw: dict, header: str = "") -> str:
    """TOML text of ``raw``: plain keys first, then ``[tables]``, then ``[[arrays of tables]]``.

    ``header`` (lines without ``#``) is written first as comments.
    """
    lines = [f"# {line}".rstrip() for line in header.splitlines()]
    tables, arrays = [], []
    for key, value in raw.items():
        if isinstance(value, dict):
            tables.append((f"[{_key(key)}]", value))
        elif isinstance(value, list) and value and all(isinstance(v, dict) for v in value):
            arrays += [(f"[[{_key(key)}]]", table) for table in value]
        else:
            lines.append(f"{_key(key)} = {value_text(value)}")
    for head, table in tables + arrays:
        lines += ["", head] + [f"{_key(k)} = {value_text(v)}" for k, v in table.items()]
    return "\n".join(lines).lstrip("\n") + "\n"
