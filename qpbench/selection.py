"""What a command works on, parsed and checked before any work starts.

Problem subsets (``--problems PATTERN``: comma-separated shell-style patterns on the name;
``--every K`` of those; ``--limit N`` of what is left; file order), backend and scenario lists
(``all`` or comma-separated names, none twice) and ``--set`` overrides, checked against the
backend's own settings where it can tell.
"""

from __future__ import annotations

import fnmatch
from typing import TYPE_CHECKING

from .exceptions import ParamError, did_you_mean, positive_count

if TYPE_CHECKING:
    from .formats import ProblemSet


def select_records(
    records: list, pattern: str | None = None, every: int | None = None, limit: int | None = None
) -> list:
    """The records (anything with a ``name``) kept by ``pattern`` (case-sensitive), then every
    ``every``-th, then the first ``limit``.

    Raises:
        ParamError: ``every`` or ``limit`` below 1, or a pattern that matches nothing.
    """
    for key, value in (("every", every), ("limit", limit)):
        if value is not None:
            positive_count(value, key)
    kept = list(records)
    if pattern:
        pats = [p.strip() for p in pattern.split(",") if p.strip()]
        kept = [r for r in kept if any(fnmatch.fnmatchcase(r.name, p) for p in pats)]
        if not kept:
            sample = ", ".join(r.name for r in list(records)[:3])
            raise ParamError(
                f"'{pattern}' matches no problem (names look like: {sample})", key="problems"
            )
    if every is not None:
        kept = kept[::every]
    if limit is not None:
        kept = kept[:limit]
    return kept


def select_set(
    problem_set: ProblemSet,
    pattern: str | None = None,
    every: int | None = None,
    limit: int | None = None,
) -> ProblemSet:
    """A copy of ``problem_set`` holding the records :func:`select_records` keeps.

    The manifest's generator stride (ticks per record) is multiplied by ``every``, so that an
    online backend integrates the time between two kept records; the set's SHA-256 is kept.
    """
    from dataclasses import replace

    if pattern is None and every is None and limit is None:
        return problem_set
    records = select_records(problem_set.records, pattern, every, limit)
    manifest = problem_set.manifest
    generator = (manifest or {}).get("generator") or {}
    if every is not None and generator.get("every") is not None:
        generator = dict(generator, every=int(generator["every"]) * every)
        manifest = dict(manifest, generator=generator)
    return replace(problem_set, records=records, manifest=manifest)


def parse_list(value: str | list[str] | None, option: str) -> list[str]:
    """Split a comma-separated option value (empty items dropped, order kept); refuse an empty
    list or an item given twice."""
    if value is None:
        return []
    items = value if isinstance(value, list) else value.split(",")
    out: list[str] = []
    for item in items:
        item = item.strip()
        if not item:
            continue
        if item in out:
            raise ParamError(
                f"'{item}' listed twice in {','.join(i.strip() for i in items)}", key=option
            )
        out.append(item)
    if not out:
        raise ParamError("empty list", key=option)
    return out


def select_scenarios(value: str | list[str] | None, option: str = "--scenarios") -> list[str]:
    """``all`` (or nothing): every shipped scenario (the paper's four first); else the names or
    paths given, each loaded here so that a typo or a broken file is one line naming it."""
    from .sim.scenario import load_scenario, scenario_names

    names = parse_list(value or "all", option)
    if names == ["all"]:
        return scenario_names()  # the paper's (``in_paper = true``) first, in its order
    for name in names:
        load_scenario(name)
    return names


def select_backends(value: str | list[str] | None, option: str = "--backends") -> list[str]:
    """``all`` (or nothing): every available backend; else the names given, in their registered
    spelling, each available here (:class:`BackendNotFound` with close names otherwise)."""
    from .backends import backend_names, get_backend, resolve_name

    names = parse_list(value or "all", option)
    if names == ["all"]:
        return list(backend_names())
    resolved = [resolve_name(name) for name in names]  # a typo gets a suggestion
    for i, name in enumerate(resolved):
        if name in resolved[:i]:
            raise ParamError(
                f"'{names[i]}' listed twice in {','.join(names)} (both are '{name}')", key=option
            )
    for name in resolved:
        get_backend(name)  # raises BackendNotFound with the reason
    return resolved


def select_backend(name: str, option: str = "--backend") -> str:
    """One backend name (not a list, not ``all``), as :func:`select_backends` checks it."""
    names = parse_list(name, option)
    if len(names) != 1 or names == ["all"]:
        raise ParamError(f"expected one backend name, got '{name}'", key=option)
    return select_backends(names, option)[0]


def parse_overrides(items: list[str] | None, option: str = "--set") -> dict:
    """``["rnn.eps=0.001", ...]`` -> ``{"rnn.eps": 0.001, ...}``: each value read as TOML, else
    as a string (``euler``); a later setting of a key wins. The keys are checked by their users
    (:func:`qpbench.sim.scenario.apply_overrides`, :func:`backend_settings`)."""
    import tomllib

    out = {}
    for item in items or ():
        key, sep, text = item.partition("=")
        key = key.strip()
        if not sep or not key:
            raise ParamError(f"expected KEY=VALUE, got {item!r}", key=option)
        text = text.strip()
        try:
            value = tomllib.loads(f"value = {text}")["value"]
        except tomllib.TOMLDecodeError:
            value = text
        out[key] = value
    return out


def backend_settings(
    items: list[str] | None, backends: list[str], option: str = "--set"
) -> dict[str, dict]:
    """``--set BACKEND.KEY=VALUE`` items -> ``{backend: {key: value}}``, each key checked against
    :meth:`~qpbench.backends.base.Backend.setting_names` where the backend can tell (``osqp.rhoo``:
    "did you mean 'rho'")."""
    from .backends import backend_class

    out: dict[str, dict] = {}
    for key, value in parse_overrides(items, option).items():
        backend, _, setting = key.rpartition(".")
        folded = {b.casefold(): b for b in backends}  # backend names match without regard to case
        backend = folded.get(backend.casefold(), backend)
        if backend not in backends or not setting:
            raise ParamError(
                f"'{key}' names no backend of this run (expected BACKEND.KEY with BACKEND in "
                "--backends)",
                key=option,
            )
        allowed = backend_class(backend).setting_names()
        if allowed is not None and setting not in allowed:
            listed = f"its settings: {', '.join(sorted(allowed))}" if allowed else "it has none"
            raise ParamError(
                f"'{setting}' is not a setting of backend '{backend}'; "
                f"{did_you_mean(setting, sorted(allowed))}{listed}",
                key=f"{option} {key}",
            )
        out.setdefault(backend, {})[setting] = value
    return out
