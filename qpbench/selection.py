"""Choosing a subset of a problem set: by name pattern, stride and count.

The same three options on every command that reads a problem set
(``qpbench list``, ``qpbench export``): ``--problems PATTERN`` keeps the
records whose name matches a shell-style pattern (``wall_paper_0001*``;
several patterns separated by commas), ``--every K`` keeps every K-th of
those, ``--limit N`` the first N of what is left. Order is the file's.
"""

from __future__ import annotations

import fnmatch

from .exceptions import ParamError

__all__ = ["select_records", "select_set"]


def select_records(records: list, pattern: str | None = None, every: int | None = None, limit: int | None = None) -> list:
    """The records kept by ``pattern``, then ``every``, then ``limit`` (file order).

    Args:
        records: Problem records (anything with a ``name``).
        pattern: Comma-separated shell-style patterns on the name, case-sensitive;
            ``None`` keeps all.
        every: Keep every K-th record (K >= 1) of those that match.
        limit: Keep at most N records (N >= 1).

    Raises:
        ParamError: ``every`` or ``limit`` below 1, or a pattern that matches nothing.
    """
    if every is not None and every < 1:
        raise ParamError(f"must be an integer >= 1, got {every}", key="every")
    if limit is not None and limit < 1:
        raise ParamError(f"must be an integer >= 1, got {limit}", key="limit")
    kept = list(records)
    if pattern:
        pats = [p.strip() for p in pattern.split(",") if p.strip()]
        kept = [r for r in kept if any(fnmatch.fnmatchcase(r.name, p) for p in pats)]
        if not kept:
            sample = ", ".join(r.name for r in list(records)[:3])
            raise ParamError(f"'{pattern}' matches no problem (names look like: {sample})", key="problems")
    if every is not None:
        kept = kept[::every]
    if limit is not None:
        kept = kept[:limit]
    return kept


def select_set(problem_set, pattern: str | None = None, every: int | None = None, limit: int | None = None):
    """A copy of ``problem_set`` holding the records :func:`select_records` keeps.

    With ``every`` > 1 the manifest's generator stride (``every``, ticks per
    record of a dumped sequence) is multiplied by it, so that an online backend
    integrates the real time between two kept records. The set's SHA-256 (of
    its file) is kept: rows stay tied to the file they came from.
    """
    from dataclasses import replace

    if pattern is None and every is None and limit is None:
        return problem_set
    records = select_records(problem_set.records, pattern, every, limit)
    manifest = problem_set.manifest
    if every is not None and every > 1 and manifest and (manifest.get("generator") or {}).get("every") is not None:
        generator = dict(manifest["generator"], every=int(manifest["generator"]["every"]) * every)
        manifest = dict(manifest, generator=generator)
    return replace(problem_set, records=records, manifest=manifest)
