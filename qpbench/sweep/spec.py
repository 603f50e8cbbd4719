"""Sweep files: a base scenario and distributions over its parameters.

A sweep file (TOML) names a base scenario and, per scenario key, a
distribution to draw that key's value from for every instance::

    [sweep]
    name = "wall"                 # names the instances (wall-i00003)
    base = "wall"                 # shipped scenario name, or a path (relative to this file)
    seed = 1                      # every draw follows from it
    samples = 500                 # instances
    duration = 6.0                # s, optional: simulated time of every instance (default: the base's)
    safe_start = true             # optional (default true): an instance starting inside d_safe is invalid

    [convergence]                 # optional: bands of the time-to-converge figures
    force_band = 0.5              # N   (default: a tenth of the base's [verdict] max_force_error)
    tracking_band = 1e-4          # m   (default: a tenth of its max_tracking_error)

    [[obstacles]]                 # optional: obstacles added to the base's (scenario schema)
    kind = "disk"
    name = "post"
    center = [0.1, 0.3]
    radius = 0.03
    velocity = [0.0, 0.0]

    [parameters]                  # scenario key = distribution
    "robot.theta0" = { dist = "normal", std = 0.05 }
    "controller.desired_force" = { dist = "uniform", low = 10.0, high = 30.0 }
    "obstacles[1].radius" = { dist = "loguniform", low = 0.01, high = 0.05 }
    "simulation.dt" = { dist = "choice", values = [0.001, 0.0005] }

Keys are the scenario's own dotted keys (those of ``simulate --set``), quoted, or nested tables.
Distributions (bounds: a number, or a list of the key's shape, each component drawn on its own):
``uniform`` (``low``, ``high``; or ``spread`` around the base value), ``normal`` (``std``,
``mean`` default the base value, optional truncation ``low``, ``high``), ``loguniform`` (``low``,
``high`` > 0), ``choice`` (``values``, optional ``weights``), ``integers`` (inclusive, integer
keys). ``same = true`` draws once for every component: an offset added to each with ``spread``
(or a normal around the base), else the value itself. Instance ``i`` draws key ``k`` from
``default_rng([seed, i, crc32(k)])``: the same whatever the sample count and the other keys.
"""

from __future__ import annotations

import copy
import difflib
import hashlib
import re
import tomllib
import zlib
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from ..exceptions import InputError, ScenarioError, check_known_keys, positive_seconds
from .distributions import Distribution, checked_distribution, finite_number

#: Names a reader may try for a key, and the scenario key meant.
ALIASES = {
    "theta0": "robot.theta0",
    "fd": "controller.desired_force",
    "desired_force": "controller.desired_force",
    "dt": "simulation.dt",
    "stiffness": "contact.stiffness",
    "noise": "contact.force_noise_std",
    "force_noise_std": "contact.force_noise_std",
    "link_lengths": "robot.link_lengths",
    "centre": "path.centre",
    "center": "path.centre",
    "amplitude": "path.amplitude",
    "speed": "path.omega",
    "omega": "path.omega",
    "duration": "[sweep] duration",
}

_SWEEP_KEYS = {
    "name": str,
    "base": str,
    "seed": int,
    "samples": int,
    "duration": float,
    "safe_start": bool,
}
_TOP = ("sweep", "parameters", "convergence", "obstacles")
SCENARIO_KEY = re.compile(r"([A-Za-z_][A-Za-z0-9_]*)(?:\[(\d+)\])?\.([A-Za-z_][A-Za-z0-9_]*)")


@dataclass
class SweepSpec:
    """A parsed sweep file: ``duration`` [s] (``None``: the base's), ``base_raw`` the base
    scenario's tables with the sweep's ``[[obstacles]]`` and duration, bands [N] and [m]."""

    path: Path
    text: str
    name: str
    seed: int
    samples: int
    duration: float | None
    base: str
    base_path: Path
    base_raw: dict
    parameters: list[Distribution] = field(default_factory=list)
    force_band: float = 0.2
    tracking_band: float = 1e-4
    safe_start: bool = True

    @property
    def sha256(self) -> str:
        return hashlib.sha256(self.text.encode("utf-8")).hexdigest()

    def rng(self, index: int, key: str) -> np.random.Generator:
        """The random stream of instance ``index``'s draw of ``key``."""
        return np.random.default_rng([self.seed, index, zlib.crc32(key.encode("utf-8"))])


def load_sweep(
    path: str | Path, samples: int | None = None, duration: float | None = None
) -> SweepSpec:
    """Read and check a sweep file (``samples``, ``duration`` override the file's).

    Raises:
        InputError: unreadable file, unknown or missing key, impossible
            distribution, unknown base scenario (one line naming the file and key).
    """
    path = Path(path)
    try:
        text = path.read_text(encoding="utf-8")
    except (OSError, UnicodeDecodeError) as exc:
        raise InputError(f"cannot read the sweep file: {exc}", path=path) from None
    return parse_sweep(text, path, samples=samples, duration=duration)


def parse_sweep(
    text: str, path: str | Path, samples: int | None = None, duration: float | None = None
) -> SweepSpec:
    """Parse sweep-file ``text`` (``path`` names it in errors and anchors a relative ``base``)."""
    path = Path(path)
    try:
        raw = tomllib.loads(text)
    except tomllib.TOMLDecodeError as exc:
        raise InputError(f"not valid TOML: {exc}", path=path) from None
    for key in raw:
        if key not in _TOP:
            raise InputError(f"unknown table (expected: {', '.join(_TOP)})", path=path, key=key)
    head = _sweep_table(raw.get("sweep"), path)
    if samples is not None:
        head["samples"] = _positive_int(samples, path, "--samples")
    if duration is not None:
        head["duration"] = duration
    if head.get("duration") is not None:
        positive_seconds(head["duration"], "sweep.duration", path)
    base_path, base_raw = _base(head["base"], path)
    extra = raw.get("obstacles", [])
    if not isinstance(extra, list) or not all(isinstance(o, dict) for o in extra):
        raise InputError("expected [[obstacles]] tables", path=path, key="obstacles")
    base_raw["obstacles"] = list(base_raw.get("obstacles", [])) + copy.deepcopy(extra)
    if head.get("duration") is not None:
        base_raw.setdefault("simulation", {})["duration"] = float(head["duration"])
    scenario = _check_base(base_raw, path)
    params = raw.get("parameters", {})
    if not isinstance(params, dict) or not params:
        raise InputError(
            "expected a [parameters] table with at least one key", path=path, key="parameters"
        )
    distributions = [
        checked_distribution(key, spec, _base_value(key, base_raw, path), path)
        for key, spec in _flatten(params, path)
    ]
    force_band, tracking_band = _bands(raw.get("convergence", {}), scenario.verdict, path)
    return SweepSpec(
        path=path,
        text=text,
        name=head["name"],
        seed=head["seed"],
        samples=head["samples"],
        duration=head.get("duration"),
        base=head["base"],
        base_path=base_path,
        base_raw=base_raw,
        parameters=distributions,
        force_band=force_band,
        tracking_band=tracking_band,
        safe_start=head.get("safe_start", True),
    )


def _positive_int(value, path, key) -> int:
    if not isinstance(value, int) or isinstance(value, bool) or value < 1:
        raise InputError(f"must be an integer >= 1, got {value!r}", path=path, key=key)
    return value


def _sweep_table(head, path) -> dict:
    if not isinstance(head, dict):
        raise InputError("missing table", path=path, key="sweep")
    check_known_keys(head, _SWEEP_KEYS, path, "sweep")
    for key in ("name", "base", "seed", "samples"):
        if key not in head:
            raise InputError("missing key", path=path, key=f"sweep.{key}")
    for key in ("name", "base"):
        if not isinstance(head[key], str) or not head[key]:
            raise InputError("expected a non-empty string", path=path, key=f"sweep.{key}")
    if not re.fullmatch(r"[A-Za-z0-9_.-]+", head["name"]):
        raise InputError(
            "letters, digits, '_', '.' and '-' only (it names files)", path=path, key="sweep.name"
        )
    if not isinstance(head["seed"], int) or isinstance(head["seed"], bool) or head["seed"] < 0:
        raise InputError(
            f"expected an integer >= 0, got {head['seed']!r}", path=path, key="sweep.seed"
        )
    _positive_int(head["samples"], path, "sweep.samples")
    if not isinstance(head.get("safe_start", True), bool):
        raise InputError("expected true or false", path=path, key="sweep.safe_start")
    return dict(head)


def _base(name: str, path: Path) -> tuple[Path, dict]:
    from ..sim.scenario import scenario_path

    candidate = (
        (path.parent / name)
        if ("/" in name or name.endswith(".toml")) and not Path(name).is_absolute()
        else name
    )
    try:
        base_path = scenario_path(candidate)
        raw = tomllib.loads(base_path.read_text(encoding="utf-8"))
    except ScenarioError as exc:
        raise InputError(f"base scenario: {exc}", path=path, key="sweep.base") from None
    except (OSError, UnicodeDecodeError, tomllib.TOMLDecodeError) as exc:
        raise InputError(
            f"base scenario {name!r} unreadable: {exc}", path=path, key="sweep.base"
        ) from None
    return base_path, raw


def _check_base(base_raw: dict, path: Path):
    """The base scenario with the sweep's obstacles and duration, validated."""
    from ..sim.scenario import parse_scenario
    from .toml_text import dumps

    try:
        return parse_scenario(dumps(base_raw), path=path)
    except ScenarioError as exc:
        raise InputError(
            f"base scenario with this sweep's obstacles and duration: {exc.message}",
            path=path,
            key=exc.key,
        ) from None


def _flatten(params: dict, path, prefix: str = ""):
    for key, value in params.items():
        full = f"{prefix}.{key}" if prefix else key
        if isinstance(value, dict) and "dist" not in value:
            yield from _flatten(value, path, full)
        elif isinstance(value, dict):
            yield full, value
        else:
            raise InputError(
                'expected a distribution table, e.g. { dist = "uniform", low = 0.0, high = 1.0 }',
                path=path,
                key=f"parameters.{full}",
            )


def _base_value(key: str, base_raw: dict, path):
    where = f"parameters.{key}"
    match = SCENARIO_KEY.fullmatch(key)
    if match is None:
        hint = ALIASES.get(key.casefold())
        raise InputError(
            "unknown parameter key"
            + (
                f"; the key is {hint}"
                if hint
                else " (expected a scenario key TABLE.KEY or obstacles[i].KEY, e.g. controller.desired_force)"
            ),
            path=path,
            key=where,
        )
    table, index, name = match.groups()
    if index is not None:
        obstacles = base_raw.get("obstacles", []) if table == "obstacles" else []
        if table != "obstacles" or int(index) >= len(obstacles):
            raise InputError(
                f"no such obstacle (base and sweep have {len(obstacles)})", path=path, key=where
            )
        target = obstacles[int(index)]
    else:
        target = base_raw.get(table)
        if table == "obstacles" or not isinstance(target, dict):
            raise InputError(
                f"unknown parameter key: the base scenario has no table [{table}]",
                path=path,
                key=where,
            )
    if name not in target:
        close = difflib.get_close_matches(name, list(target), n=1)
        hint = (
            f"; did you mean {table}{'' if index is None else f'[{index}]'}.{close[0]}?"
            if close
            else ""
        )
        raise InputError(
            f"unknown parameter key: [{table}] has no key {name!r}{hint}", path=path, key=where
        )
    return target[name]


def _bands(conv, verdict, path) -> tuple[float, float]:
    if not isinstance(conv, dict):
        raise InputError("expected a table", path=path, key="convergence")
    for key in conv:
        if key not in ("force_band", "tracking_band"):
            raise InputError(
                "unknown key (expected force_band, tracking_band)",
                path=path,
                key=f"convergence.{key}",
            )
    out = []
    for key, default in (
        ("force_band", verdict.max_force_error / 10),
        ("tracking_band", verdict.max_tracking_error / 10),
    ):
        value = conv.get(key, default)
        if not (finite_number(value) and value > 0):
            raise InputError(
                f"must be a positive number, got {value!r}", path=path, key=f"convergence.{key}"
            )
        out.append(float(value))
    return out[0], out[1]
