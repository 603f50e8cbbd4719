"""What a command works on, parsed and checked before any work starts: problem subsets,
backend and scenario lists (``all`` or comma-separated names, none twice) and ``--set``
overrides."""

from __future__ import annotations

import fnmatch
from typing import TYPE_CHECKING

from .exceptions import ParamError, did_you_mean, positive_count

if TYPE_CHECKING:
    from .formats import ProblemSet


def select_set(
    problem_set: ProblemSet,
    pattern: str | None = None,
    every: int | None = None,
    limit: int | None = None,
) -> ProblemSet:
    """A copy of ``problem_set`` holding the records kept by ``pattern`` (comma-separated
    shell-style patterns; none matching is an error), then every ``every``-th, then the first
    ``limit``; its generator stride (ticks per record) times ``every``."""
    from dataclasses import replace

    for key, value in (("every", every), ("limit", limit)):
        if value is not None:
            positive_count(value, key)
    records = problem_set.records
    if pattern:
        pats = [p.strip() for p in pattern.split(",") if p.strip()]
        records = [r for r in records if any(fnmatch.fnmatchcase(r.name, p) for p in pats)]
        if not records:
            sample = ", ".join(r.name for r in problem_set.records[:3])
            raise ParamError(
                f"'{pattern}' matches no problem (names look like: {sample})", key="problems"
            )
    manifest = problem_set.manifest
    generator = (manifest or {}).get("generator") or {}
    if every is not None and generator.get("every") is not None:
        manifest = dict(manifest, generator=dict(generator, every=int(generator["every"]) * every))
    # a None stride or limit keeps them all
    return replace(problem_set, records=list(records)[::every][:limit], manifest=manifest)


def parse_list(value: str | list[str], option: str) -> list[str]:
    """Split a comma-separated option value (empty items dropped, order kept); refuse an empty
    list or an item given twice."""
    items = [i.strip() for i in (value if isinstance(value, list) else value.split(","))]
    out: list[str] = []
    for item in filter(None, items):
        if item in out:
            raise ParamError(f"'{item}' listed twice in {','.join(items)}", key=option)
        out.append(item)
    if not out:
        raise ParamError("empty list", key=option)
    return out


def select_scenarios(value: str | None) -> list[str]:
    """``all`` (or nothing): every shipped scenario; else the names or paths given, each loaded
    here (a typo or a broken file is one line naming it)."""
    from .sim.scenario import load_scenario, scenario_names

    names = parse_list(value or "all", "--scenarios")
    if names == ["all"]:
        return scenario_names()  # the paper's (``in_paper = true``) first, in its order
    for name in names:
        load_scenario(name)
    return names


def select_backends(
    value: str | list[str] | None, option: str = "--backends", floor: bool = True
) -> list[str]:
    """``all`` (or nothing): every available backend but the noise floor; else the names given,
    registered spelling, each available; ``floor=False`` refuses the noise floor by name."""
    from .backends import backend_class, backend_names, get_backend, resolve_name

    names = parse_list(value or "all", option)
    if names == ["all"]:
        return [name for name in backend_names() if not backend_class(name).noise_floor]
    resolved = [resolve_name(name) for name in names]  # a typo gets a suggestion
    for i, name in enumerate(resolved):
        if name in resolved[:i]:
            raise ParamError(
                f"'{names[i]}' listed twice in {','.join(names)} (both are '{name}')", key=option
            )
        if not floor and backend_class(name).noise_floor:
            raise ParamError(
                f"'{name}' is the closed loop's noise floor (x = 0, no solve), not a solver: "
                "it has no answer to score, and every closed-loop run set runs it already",
                key=option,
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


def parse_overrides(items: list[str] | None) -> dict:
    """``["rnn.eps=0.001", ...]`` -> ``{"rnn.eps": 0.001, ...}``: each value read as TOML, else
    as a string; a later setting of a key wins (the keys are checked by their users)."""
    import tomllib

    out = {}
    for item in items or ():
        key, sep, text = (part.strip() for part in item.partition("="))
        if not sep or not key:
            raise ParamError(f"expected KEY=VALUE, got {item!r}", key="--set")
        try:
            out[key] = tomllib.loads(f"value = {text}")["value"]
        except tomllib.TOMLDecodeError:
            out[key] = text
    return out


def backend_settings(items: list[str] | None, backends: list[str]) -> dict[str, dict]:
    """``--set BACKEND.KEY=VALUE`` items -> ``{backend: {key: value}}``, each key checked against
    :meth:`~qpbench.backends.base.Backend.setting_names` where the backend can tell."""
    from .backends import backend_class

    out: dict[str, dict] = {}
    folded = {b.casefold(): b for b in backends}  # backend names match without regard to case
    for key, value in parse_overrides(items).items():
        backend, _, setting = key.rpartition(".")
        backend = folded.get(backend.casefold(), backend)
        if backend not in backends or not setting:
            raise ParamError(
                f"'{key}' names no backend of this run (expected BACKEND.KEY with BACKEND in "
                "--backends)",
                key="--set",
            )
        allowed = backend_class(backend).setting_names()
        if allowed is not None and setting not in allowed:
            listed = f"its settings: {', '.join(sorted(allowed))}" if allowed else "it has none"
            raise ParamError(
                f"'{setting}' is not a setting of backend '{backend}'; "
                f"{did_you_mean(setting, sorted(allowed))}{listed}",
                key=f"--set {key}",
            )
        out.setdefault(backend, {})[setting] = value
    return out
