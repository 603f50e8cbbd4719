"""Sweep files (format and sampling: ``docs/sweeps.md``) and their instances, each the base
scenario with every swept key drawn, as a full scenario file. ``[convergence]`` holds the bands
of the time-to-converge figures, ``force_band`` [N] and ``tracking_band`` [m] (default: a tenth
of the base's ``[verdict]`` maximum errors).
"""

from __future__ import annotations

import copy
import difflib
import hashlib
import re
import tomllib
import zlib
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from ..exceptions import InputError, ScenarioError, check_choice, check_known_keys, positive_seconds
from ..robot.body import body_clearance, contact_obstacles, link_label
from ..sim.scenario import OVERRIDE_KEY, Scenario, apply_overrides, load_scenario, parse_scenario
from ..sim.scenario_schema import filled, finite_number
from .toml_text import dumps, value_text

#: Other names a reader may give a scenario key (the table is found in the base scenario).
ALIASES = {"fd": "desired_force", "noise": "force_noise_std", "speed": "omega", "center": "centre"}

_SWEEP_KEYS = ("name", "base", "seed", "samples", "duration", "safe_start")
_TOP = ("sweep", "parameters", "convergence", "obstacles")


#: Distribution kinds and their allowed fields (``dist`` aside).
DISTRIBUTIONS = {
    "uniform": ("low", "high", "spread", "same"),
    "normal": ("mean", "std", "low", "high", "same"),
    "loguniform": ("low", "high", "same"),
    "choice": ("values", "weights"),
    "integers": ("low", "high"),
}

#: Draws of a truncated normal tried before giving up on a component.
_MAX_REDRAWS = 1000


@dataclass(frozen=True)
class Distribution:
    """One key's distribution: ``params`` its fields (numbers as arrays of the key's shape),
    ``base`` the base scenario's value."""

    key: str
    kind: str
    params: dict
    base: object

    def draw(self, rng: np.random.Generator) -> object:
        """One value of the key (a float, an int, or a list of the base's shape)."""
        p, base = self.params, self.base
        shape = np.shape(base)
        if self.kind == "choice":
            i = int(rng.choice(len(p["values"]), p=p.get("weights")))
            return copy.deepcopy(p["values"][i])
        if self.kind == "integers":
            return int(rng.integers(p["low"], p["high"], endpoint=True))
        if p.get("same"):  # one draw for every component: an offset from the base, or the value
            relative = "spread" in p or (self.kind == "normal" and "mean" not in p)
            first = float(np.ravel(base)[0])
            one = Distribution(
                self.key, self.kind, {k: v for k, v in p.items() if k != "same"}, first
            ).draw(rng)
            value = base + (one - first) if relative else np.full(shape, one)
            return value.tolist() if shape else float(value)
        if self.kind == "uniform":
            low, high = (
                (base - p["spread"], base + p["spread"]) if "spread" in p else (p["low"], p["high"])
            )
            value = rng.uniform(low, high, size=shape)
        elif self.kind == "loguniform":
            value = np.exp(rng.uniform(np.log(p["low"]), np.log(p["high"]), size=shape))
        else:
            value = self._truncated_normal(rng, shape)
        return value.tolist() if shape else float(value)

    def _truncated_normal(self, rng, shape):
        p = self.params
        mean = p.get("mean", np.asarray(self.base, dtype=float))
        mean, std = np.broadcast_to(mean, shape), np.broadcast_to(p["std"], shape)
        low = np.broadcast_to(p.get("low", -np.inf), shape)
        high = np.broadcast_to(p.get("high", np.inf), shape)
        value = np.asarray(rng.normal(mean, std), dtype=float)
        for _ in range(_MAX_REDRAWS):
            bad = (value < low) | (value > high)
            if not bad.any():
                return value
            value = np.where(bad, rng.normal(mean, std), value)
        raise InputError(
            f"a truncated normal draw stayed outside [low, high] {_MAX_REDRAWS} times", key=self.key
        )


def checked_distribution(key: str, spec: dict, base, path) -> Distribution:
    """Key ``key``'s distribution ``spec`` (a ``[parameters]`` entry), checked against ``base``,
    the base scenario's value of the key; :class:`InputError` naming ``path`` and the key if wrong."""

    def bad(message: str, field: str | None = None) -> InputError:
        return InputError(
            message, path=path, key=".".join(filter(None, ("parameters", key, field)))
        )

    kind = str(spec.get("dist"))
    check_choice(kind, DISTRIBUTIONS, "distribution", f"parameters.{key}.dist", InputError, path)
    for f in spec:
        if f != "dist" and f not in DISTRIBUTIONS[kind]:
            expected = ", ".join(DISTRIBUTIONS[kind])
            raise bad(f"unknown field of a {kind} distribution (expected: {expected})", f)
    if kind == "choice":
        return Distribution(key, kind, _choice(spec, base, bad), base)
    is_int = isinstance(base, int) and not isinstance(base, bool)
    if (kind == "integers") != is_int:
        why = (
            "an integer key takes integers or choice" if is_int else "integers is for integer keys"
        )
        raise bad(why, "dist")
    if is_int:
        lo, hi = spec.get("low"), spec.get("high")
        if not (isinstance(lo, int) and isinstance(hi, int) and lo <= hi):
            raise bad(f"need integers low <= high, got {lo!r}, {hi!r}")
        return Distribution(key, kind, {"low": lo, "high": hi}, base)
    base_arr = _numeric(base, None, bad, None, "the base value")
    same = spec.get("same", False)
    if not isinstance(same, bool):
        raise bad(f"expected true or false, got {same!r}", "same")
    shape = None if same else np.shape(base_arr)  # same: numbers only, checked below
    params = {
        f: _numeric(v, shape, bad, f, f) for f, v in spec.items() if f not in ("dist", "same")
    }
    if same and any(np.ndim(v) for v in params.values()):
        raise bad("same = true takes numbers, not lists (one draw for every component)", "same")
    if same:
        params["same"] = True
    _check_bounds(kind, params, bad)
    return Distribution(key, kind, params, base_arr if np.ndim(base_arr) else float(base_arr))


def _numeric(value, shape, bad, field, what):
    """``value`` as a float array broadcastable to ``shape`` (or any numeric shape when ``shape``
    is None); ``bad(message, field)`` makes the error."""
    try:
        arr = np.asarray(value, dtype=float)
    except (TypeError, ValueError):
        arr = np.array(np.nan)
    if isinstance(value, bool) or not np.all(np.isfinite(arr)):
        raise bad(f"{what}: expected finite numbers, got {value!r}", field)
    if shape is not None and arr.ndim and arr.shape != tuple(shape):
        raise bad(
            f"expected a number or {list(shape)} numbers (the base value's shape), got {value!r}",
            field,
        )
    return arr


def _check_bounds(kind: str, p: dict, bad) -> None:
    if kind == "uniform" and "spread" in p:
        if "low" in p or "high" in p:
            raise bad("give either spread or low and high", "spread")
        if np.any(p["spread"] < 0):
            raise bad("spread must be >= 0", "spread")
        return
    needs = ("std",) if kind == "normal" else ("low", "high")
    for name in needs:
        if name not in p:
            raise bad(f"a {kind} distribution needs {' and '.join(needs)}", name)
    if kind == "normal" and np.any(p["std"] < 0):
        raise bad("std must be >= 0", "std")
    if kind == "loguniform" and np.any(p["low"] <= 0):
        raise bad("loguniform needs low > 0", "low")
    if "low" in p and "high" in p and np.any(p["low"] > p["high"]):
        raise bad("low must be <= high", "low")


def _choice(spec: dict, base, bad) -> dict:
    values = spec.get("values")
    if not isinstance(values, list) or not values:
        raise bad("a choice needs a non-empty list of values", "values")
    for v in values:
        if type(v) is not type(base) and not (finite_number(v) and finite_number(base)):
            raise bad(f"each value must be like the base value {base!r}, got {v!r}", "values")
        if isinstance(base, list) and np.shape(v) != np.shape(base):
            shape = list(np.shape(base))
            raise bad(f"each value must have the base value's shape {shape}, got {v!r}", "values")
    out = {"values": values}
    if "weights" in spec:
        w = spec["weights"]
        if not (
            isinstance(w, list)
            and len(w) == len(values)
            and all(finite_number(x) and x >= 0 for x in w)
            and sum(w) > 0
        ):
            raise bad("weights: one number >= 0 per value, not all zero", "weights")
        out["weights"] = [x / sum(w) for x in w]
    return out


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
    parameters: list[Distribution]
    force_band: float
    tracking_band: float
    safe_start: bool

    @property
    def sha256(self) -> str:
        return hashlib.sha256(self.text.encode("utf-8")).hexdigest()

    def rng(self, index: int, key: str) -> np.random.Generator:
        """The random stream of instance ``index``'s draw of ``key``."""
        return np.random.default_rng([self.seed, index, zlib.crc32(key.encode("utf-8"))])


def load_sweep(
    path: str | Path,
    samples: int | None = None,
    duration: float | None = None,
    text: str | None = None,
) -> SweepSpec:
    """Read and check a sweep file (``samples``, ``duration`` override the file's; ``text``: the
    file's text, ``path`` then only names it in errors and anchors a relative ``base``); an
    :class:`InputError` names the file and the key."""
    path = Path(path)
    try:
        text = path.read_text(encoding="utf-8") if text is None else text
    except (OSError, UnicodeDecodeError) as exc:
        raise InputError(f"cannot read the sweep file: {exc}", path=path) from None
    try:
        raw = tomllib.loads(text)
    except tomllib.TOMLDecodeError as exc:
        raise InputError(f"not valid TOML: {exc}", path=path) from None
    for key in raw:
        if key not in _TOP:
            raise InputError(f"unknown table (expected: {', '.join(_TOP)})", path=path, key=key)
    head = _sweep_table(raw.get("sweep"), path)
    if samples is not None:
        head["samples"] = _integer(samples, 1, path, "--samples")
    if duration is not None:
        head["duration"] = duration
    name = head["base"]  # shipped, or a path relative to the sweep file's folder
    relative = ("/" in name or name.endswith(".toml")) and not Path(name).is_absolute()
    try:
        base = load_scenario(path.parent / name if relative else name)
    except ScenarioError as exc:
        raise InputError(f"base scenario: {exc}", path=path, key="sweep.base") from None
    base_path, base_raw = base.path, tomllib.loads(base.source)
    extra = raw.get("obstacles", [])
    if not isinstance(extra, list) or not all(isinstance(o, dict) for o in extra):
        raise InputError("expected [[obstacles]] tables", path=path, key="obstacles")
    base_raw["obstacles"] = list(base_raw.get("obstacles", [])) + copy.deepcopy(extra)
    if head["duration"] is not None:
        positive_seconds(head["duration"], "sweep.duration", path)
        base_raw.setdefault("simulation", {})["duration"] = float(head["duration"])
    try:  # the base scenario with the sweep's obstacles and duration
        scenario = parse_scenario(dumps(base_raw), path=path)
    except ScenarioError as exc:
        raise InputError(
            f"base scenario with this sweep's obstacles and duration: {exc.message}",
            path=path,
            key=exc.key,
        ) from None
    params = raw.get("parameters", {})
    if not isinstance(params, dict) or not params:
        raise InputError(
            "expected a [parameters] table with at least one key", path=path, key="parameters"
        )
    dists = [
        checked_distribution(
            key, spec, _base_value(key, base_raw, filled(scenario.spec), path), path
        )
        for key, spec in _flatten(params, path)
    ]
    bands = _bands(raw.get("convergence", {}), scenario.verdict, path)
    return SweepSpec(
        path, text, base_path=base_path, base_raw=base_raw, parameters=dists, **bands, **head
    )


def _integer(value, least: int, path, key) -> int:
    if not isinstance(value, int) or isinstance(value, bool) or value < least:
        raise InputError(f"expected an integer >= {least}, got {value!r}", path=path, key=key)
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
    _integer(head["seed"], 0, path, "sweep.seed")
    _integer(head["samples"], 1, path, "sweep.samples")
    if not isinstance(head.get("safe_start", True), bool):
        raise InputError("expected true or false", path=path, key="sweep.safe_start")
    return {"duration": None, "safe_start": True} | head


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


def _base_value(key: str, base_raw: dict, defaults: dict, path):
    """The base's value of ``key``: the file's, else its default (``defaults``: the validated
    base, every default filled in; an obstacle's ``velocity``)."""

    def bad(message: str) -> InputError:
        return InputError(message, path=path, key=f"parameters.{key}")

    match = OVERRIDE_KEY.fullmatch(key)
    if match is None:
        name = ALIASES.get(key.casefold(), key.casefold())
        for table, value in base_raw.items():
            if isinstance(value, dict) and name in value:
                raise bad(f"unknown parameter key; the key is {table}.{name}")
        raise bad(
            "unknown parameter key (expected a scenario key TABLE.KEY or obstacles[i].KEY, "
            "e.g. controller.desired_force)"
        )
    table, index, name = match.groups()
    if index is not None:
        obstacles = base_raw.get("obstacles", []) if table == "obstacles" else []
        if table != "obstacles" or int(index) >= len(obstacles):
            raise bad(f"no such obstacle (base and sweep have {len(obstacles)})")
        target, default = obstacles[int(index)], defaults["obstacles"][int(index)]
    else:
        target, default = base_raw.get(table), defaults.get(table, {})
        if table == "obstacles" or not isinstance(target, dict):
            raise bad(f"unknown parameter key: the base scenario has no table [{table}]")
    if name not in target and name in default:
        return default[name]
    if name not in target:
        close = difflib.get_close_matches(name, list(target), n=1)
        where = table if index is None else f"{table}[{index}]"
        hint = f"; did you mean {where}.{close[0]}?" if close else ""
        raise bad(f"unknown parameter key: [{table}] has no key {name!r}{hint}")
    return target[name]


def _bands(conv, verdict, path) -> dict:
    if not isinstance(conv, dict):
        raise InputError("expected a table", path=path, key="convergence")
    check_known_keys(conv, ("force_band", "tracking_band"), path, "convergence")
    force = conv.get("force_band", verdict.max_force_error / 10)
    tracking = conv.get("tracking_band", verdict.max_tracking_error / 10)
    for key, value in (("force_band", force), ("tracking_band", tracking)):
        if not (finite_number(value) and value > 0):
            raise InputError(
                f"must be a positive number, got {value!r}", path=path, key=f"convergence.{key}"
            )
    return {"force_band": float(force), "tracking_band": float(tracking)}


@dataclass(frozen=True)
class Instance:
    """One sampled scenario: ``values`` swept key -> drawn value, ``text`` its scenario file,
    ``invalid`` why the loader (or ``safe_start``) refused it, else ``None``."""

    index: int
    name: str
    values: dict
    text: str
    invalid: str | None = None


def instance_text(spec: SweepSpec, name: str, index: int, values: dict) -> str:
    """The scenario file of instance ``name``: a header saying where it comes from, then every table."""
    raw = apply_overrides(spec.base_raw, values)
    about = raw["scenario"]
    about["name"] = f"{spec.name}-{name}"
    about["description"] = (
        f"Instance {index} of sweep {spec.name!r}, around: {about['description']}"
    )
    header = [
        f"Instance {name} (sample {index}) of sweep {spec.name!r} ({spec.path.name}, sha256 {spec.sha256[:16]}, "
        f"seed {spec.seed}).",
        f"Base scenario: {spec.base} ({spec.base_path.name}); units as in it. Drawn for this instance:",
    ]
    header += [f"  {key} = {value_text(value)}" for key, value in values.items()]
    if spec.duration is not None:
        header.append(
            f"  simulation.duration = {value_text(float(spec.duration))} (the sweep's duration)"
        )
    header.append(
        f"Re-run alone: qpbench simulate --scenario {name}.toml --backend BACKEND (from its folder)"
    )
    return dumps(raw, header="\n".join(header))


def start_clearance(scenario: Scenario) -> tuple[float, str, str]:
    """Smallest clearance [m] of a link's capsule to an obstacle at t = 0, and which link and
    obstacle: :func:`~qpbench.robot.body.body_clearance`, as the verdict measures the body, for
    any chain (planar or spatial). ``(inf, "", "")`` without obstacles."""
    arm, obstacles = scenario.make_arm(), scenario.make_obstacles()
    if not obstacles:
        return np.inf, "", ""
    exempt = contact_obstacles(obstacles, scenario.make_surface())
    radius = scenario.spec.key_points.link_radius
    body = body_clearance(arm, scenario.theta0, 0.0, obstacles, radius, exempt)
    link, obstacle = int(body.link[0]), obstacles[int(body.obstacle[0])].name
    return float(body.d_min[0]), link_label(link, arm.n), obstacle


def _why_invalid(text: str, name: str, safe_start: bool) -> str | None:
    try:
        scenario = parse_scenario(text, path=f"{name}.toml")
    except ScenarioError as exc:
        return str(exc)
    if safe_start:
        d, point, obstacle = start_clearance(scenario)
        d_safe = scenario.spec.controller.d_safe
        if d < d_safe:
            return (
                f"{name}.toml: starts with {point} {d * 1e3:.2f} mm from obstacle {obstacle}, "
                f"inside d_safe = {d_safe * 1e3:g} mm (every backend would start unsafe)"
            )
    return None


def sample_instances(spec: SweepSpec, start: int = 0) -> list[Instance]:
    """The instances ``start`` to ``spec.samples - 1`` of ``spec`` (deterministic in ``spec.seed``),
    each checked by the scenario loader and, with ``[sweep] safe_start`` (default), for a start
    outside ``d_safe`` of every obstacle."""
    out = []
    digits = max(5, len(str(spec.samples - 1)))  # i00003: as wide as the widest index
    for index in range(start, spec.samples):
        name = f"i{index:0{digits}d}"
        values = {d.key: d.draw(spec.rng(index, d.key)) for d in spec.parameters}
        text = instance_text(spec, name, index, values)
        out.append(Instance(index, name, values, text, _why_invalid(text, name, spec.safe_start)))
    return out
