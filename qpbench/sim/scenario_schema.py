"""The scenario file's schema: every table and key with its type and unit (paper section 4).

A missing, unknown or mistyped key raises :class:`~qpbench.exceptions.ScenarioError` naming the
file and the key; a range is checked here only for a value no object of the scenario holds
(the arm, the key points, the contact surface, the obstacles and
:class:`qpbench.sim.verdict.VerdictSettings` check their own). An obstacle's entry is its kind's
schema (:mod:`qpbench.robot.obstacles`). ``[adaptive]``, ``[rnn]`` and
``[verdict]`` may be left out (:data:`DEFAULTS`; ``[verdict]``: docs/verdicts.md).
"""

from __future__ import annotations

import math
from dataclasses import asdict
from typing import TYPE_CHECKING

import numpy as np

from ..exceptions import ScenarioError, check_known_keys
from ..robot.kinematics import KEY_POINT_KINDS
from ..robot.obstacles import kinds as obstacle_kinds
from ..robot.obstacles import schema_adapter, validated
from .verdict import DEFAULT_SAFETY_MARGIN, VerdictSettings

if TYPE_CHECKING:
    from pathlib import Path

# Types: num, int, bool, str, vec (numbers), vec2 (two numbers), points ([[x, y], ...]), a tuple
# (one of its strings); ">0" or ">=0" after a type bounds a number or every entry of a vector.
_SCHEMA: dict[str, dict] = {
    # in_paper: one of the paper's scenarios, whose ticks ``qpbench run`` also benchmarks;
    # in_run: ``qpbench run`` runs it when no ``--scenarios`` are given
    "scenario": {
        "name": "str",
        "description": "str",
        "paper_section": "str",
        "in_paper": "bool",
        "in_run": "bool",
    },
    "robot": {
        "link_lengths": "vec",  # [m]
        "theta0": "vec",  # [rad]
        "theta_min": "vec",  # [rad]
        "theta_max": "vec",  # [rad]
        "velocity_min": "vec",  # [rad/s]
        "velocity_max": "vec",  # [rad/s]
    },
    # kind "paper": the paper's fixed key points; "closest": a row at each link's point closest
    # to each obstacle, beyond the paper (:class:`qpbench.robot.kinematics.KeyPoints`)
    "key_points": {
        "points_per_link": "int",
        "include_joints": "bool",
        "link_radius": "num>=0",  # [m]
        "kind": KEY_POINT_KINDS,
    },
    "contact": {
        "point": "vec2",  # [m]
        "normal": "vec2",
        "stiffness": "num",  # [N/m]
        "damping": "num",  # [N s/m]
        "force_noise_std": "num",  # [N]
        "noise_seed": "int",
    },
    "controller": {
        "desired_force": "num>=0",  # [N]
        "kp": "num>0",  # [N/m]
        "kd": "num>0",  # [N s/m]
        "alpha": "num>0",  # [1/s]
        "k": "num>0",  # [1/s]
        "d_safe": "num>=0",  # [m]
        "rho": "num>0",
    },
    # gain: [kp part, kd part]; kp_min [N/m], kd_min [N s/m]
    "adaptive": {"enabled": "bool", "gain": "vec2>=0", "kp_min": "num>0", "kd_min": "num>0"},
    "simulation": {"dt": "num", "duration": "num"},  # [s] (check_simulation)
}
#: ``[path]`` by kind: centre, amplitude [m], omega [rad/s], phase [rad]; times [s], points [m].
_PATH_SCHEMA = {
    "cosine": {
        "kind": "str",
        "centre": "vec2",
        "amplitude": "vec2",
        "omega": "vec2",
        "phase": "vec2",
    },
    "polyline": {"kind": "str", "times": "vec", "points": "points"},
}
#: ``[verdict]``: the fields of :class:`qpbench.sim.verdict.VerdictSettings`, which checks them.
_VERDICT_DEFAULTS = VerdictSettings()
_VERDICT_SCHEMA = dict.fromkeys(asdict(_VERDICT_DEFAULTS), "num")
#: Tables a file may leave out (all their keys have defaults).
OPTIONAL_TABLES = ("adaptive", "rnn", "verdict")
_TOP = (*_SCHEMA, "path", "obstacles", "rnn", "verdict")
#: Defaults of the keys that may be left out, per table.
DEFAULTS: dict[str, dict] = {
    "scenario": {"in_paper": False, "in_run": True},
    "key_points": {"kind": "paper"},
    "adaptive": {"enabled": False, "gain": [500.0, 20.0], "kp_min": 100.0, "kd_min": 1.0},
    "rnn": {"eps": 0.02},
    "verdict": asdict(_VERDICT_DEFAULTS),
}


def finite_number(v) -> bool:
    """True for an int or float (not a bool) that is finite."""
    return isinstance(v, (int, float)) and not isinstance(v, bool) and math.isfinite(v)


def _typed(value, kind, file, key: str):
    """``value`` converted to ``kind`` (a schema type), else a :class:`ScenarioError` naming ``key``."""

    def bad(what):
        raise ScenarioError(f"expected {what}, got {value!r}", path=file, key=key)

    if isinstance(kind, tuple):
        if not isinstance(value, str) or value not in kind:
            bad(f"one of {', '.join(kind)}")
        return value
    kind, _, bound = kind.partition(">")
    if kind == "num":
        if not finite_number(value):
            bad("a finite number")
        out = float(value)
    elif kind == "int":
        if not isinstance(value, int) or isinstance(value, bool):
            bad("an integer")
        out = int(value)
    elif kind in ("bool", "str"):
        if not isinstance(value, bool if kind == "bool" else str):
            bad("true or false" if kind == "bool" else "a string")
        return value
    elif kind in ("vec", "vec2"):
        if not isinstance(value, list) or not value or not all(finite_number(v) for v in value):
            bad("a list of finite numbers")
        if kind == "vec2" and len(value) != 2:
            bad("a list of two numbers")
        out = np.array(value, dtype=float)
    else:  # points
        if not (
            isinstance(value, list)
            and value
            and all(
                isinstance(p, list) and len(p) == 2 and all(map(finite_number, p)) for p in value
            )
        ):
            bad("a list of [x, y] pairs")
        return np.array(value, dtype=float)
    if bound and not np.all(out > 0 if bound == "0" else out >= 0):
        raise ScenarioError(f"must be >{bound[:-1]} 0, got {value}", path=file, key=key)
    return out


def _table(raw, schema: dict, file, prefix: str) -> dict:
    if not isinstance(raw, dict):
        raise ScenarioError("expected a table", path=file, key=prefix)
    raw = {**DEFAULTS.get(prefix, {}), **raw}
    check_known_keys(raw, schema, file, prefix, ScenarioError)
    for key in schema:
        if key not in raw:
            raise ScenarioError("missing key", path=file, key=f"{prefix}.{key}")
    return {key: _typed(raw[key], kind, file, f"{prefix}.{key}") for key, kind in schema.items()}


def _by_kind(raw, schemas: dict, file, prefix: str) -> dict:
    """A table whose ``kind`` (one of ``schemas``) picks its schema (``[path]``, an obstacle)."""
    kind = None
    if isinstance(raw, dict):
        kind = _typed(raw.get("kind"), tuple(schemas), file, f"{prefix}.kind")
    return _table(raw, schemas.get(kind, {}), file, prefix)


def validate(raw: dict, file: str | Path, set_keys=()) -> tuple[dict, dict]:
    """The parsed TOML tables ``raw`` checked against the schema: ``(data, rnn)``, the tables
    (numbers as floats, vectors as arrays) and the ``[rnn]`` settings as a plain dict.

    ``set_keys``: the dotted keys set over the file's on the command line.
    """
    for key in raw:
        if key not in _TOP:
            raise ScenarioError(
                f"unknown table (expected one of: {', '.join(sorted(_TOP))})", path=file, key=key
            )
    raw = {**{t: {} for t in OPTIONAL_TABLES}, **raw}
    for key in sorted(_TOP):
        if key not in raw:
            raise ScenarioError("missing table", path=file, key=key)
    data = {name: _table(raw[name], schema, file, name) for name, schema in _SCHEMA.items()}
    data["path"] = _by_kind(raw["path"], _PATH_SCHEMA, file, "path")
    data["obstacles"] = _obstacles(raw["obstacles"], file)
    if not isinstance(raw["rnn"], dict):
        raise ScenarioError("expected a table", path=file, key="rnn")
    rnn = {**DEFAULTS["rnn"], **raw["rnn"]}  # eps checked, the rest passed to the backend
    _typed(rnn["eps"], "num>0", file, "rnn.eps")
    _check_across_keys(data, file)
    data["verdict"] = _verdict_table(raw["verdict"], data, file)
    check_simulation(data, file, set_keys)
    return data, rnn


def _obstacles(obstacles, file) -> list[dict]:
    if not isinstance(obstacles, list):
        raise ScenarioError(
            "expected a list of obstacle tables ([[obstacles]] or obstacles = [])",
            path=file,
            key="obstacles",
        )
    out = []
    for i, o in enumerate(obstacles):
        prefix = f"obstacles[{i}]"
        if not isinstance(o, dict):
            raise ScenarioError("expected a table", path=file, key=prefix)
        kind = _typed(o.get("kind"), tuple(obstacle_kinds()), file, f"{prefix}.kind")
        fields = list(obstacle_kinds()[kind].Schema.model_fields)
        model = validated(schema_adapter(), o, prefix, file, ScenarioError, fields)
        entry = {
            k: np.array(v, dtype=float) if isinstance(v, (tuple, list)) else v
            for k, v in model.model_dump().items()
        }
        if obstacle_kinds()[kind].DIM != 2:  # the arm and its controller are planar
            planar = [k for k, cls in obstacle_kinds().items() if cls.DIM == 2]
            raise ScenarioError(
                f"a spatial kind; a planar scenario takes one of: {', '.join(planar)}",
                path=file,
                key=f"{prefix}.kind",
            )
        if entry["name"] in [e["name"] for e in out]:
            raise ScenarioError(
                f"obstacle names must be unique, got {entry['name']!r}",
                path=file,
                key=f"{prefix}.name",
            )
        out.append(entry)
    return out


def _verdict_table(raw, data: dict, file) -> dict:
    """The ``[verdict]`` table, with defaults that fit the task, checked against it (the ranges:
    :class:`~qpbench.sim.verdict.VerdictSettings`)."""
    d_safe, duration = data["controller"]["d_safe"], data["simulation"]["duration"]
    if isinstance(raw, dict):  # defaults that fit the task
        raw = {
            "settle_time": min(_VERDICT_DEFAULTS.settle_time, duration / 2),
            "safety_margin": min(DEFAULT_SAFETY_MARGIN, d_safe / 2),
            **raw,
        }
    out = _table(raw, _VERDICT_SCHEMA, file, "verdict")
    margin = out["safety_margin"]
    if not (margin < d_safe or margin == d_safe == 0):
        raise ScenarioError(
            f"must be < controller.d_safe = {d_safe:g} m (0 when d_safe is 0), got {margin:g} m",
            path=file,
            key="verdict.safety_margin",
        )
    return out


def _check_across_keys(data: dict, file) -> None:
    """One value per link, ``theta_min < theta0 < theta_max``,
    ``velocity_min <= 0 <= velocity_max``."""
    r = data["robot"]
    n = r["link_lengths"].size
    for key in ("theta0", "theta_min", "theta_max", "velocity_min", "velocity_max"):
        if r[key].size != n:
            raise ScenarioError(
                f"expected {n} values (one per link), got {r[key].size}",
                path=file,
                key=f"robot.{key}",
            )
    if np.any(r["theta_min"] >= r["theta_max"]):
        raise ScenarioError("every theta_min must be < theta_max", path=file, key="robot.theta_min")
    outside = np.flatnonzero((r["theta0"] < r["theta_min"]) | (r["theta0"] > r["theta_max"]))
    if outside.size:
        i = int(outside[0])
        raise ScenarioError(
            f"theta0[{i}] = {r['theta0'][i]} rad is outside [{r['theta_min'][i]}, {r['theta_max'][i]}]",
            path=file,
            key="robot.theta0",
        )
    vmin, vmax = r["velocity_min"], r["velocity_max"]
    if not (np.all(vmin <= 0) and np.all(vmax >= 0) and np.all(vmin < vmax)):
        raise ScenarioError(
            "need velocity_min <= 0 <= velocity_max and velocity_min < velocity_max [rad/s]",
            path=file,
            key="robot.velocity_min",
        )


def check_simulation(data: dict, file: str | Path, set_keys=()) -> None:
    """``dt`` and ``duration`` > 0 [s], at least one tick, ``alpha * dt < 1``, and a settle time
    set on the command line (``verdict.settle_time`` in ``set_keys``) < ``duration`` [s].

    Called on every change of ``dt`` or ``duration`` (the file's, ``--set``, ``--duration``, a
    sweep's), so a settle time set on the command line is checked against the duration run: a
    run shorter than it would not judge tracking and force that it was set to judge.
    """
    s = data["simulation"]
    for key in ("dt", "duration"):
        if not s[key] > 0:
            raise ScenarioError(
                f"must be > 0 [s], got {s[key]}", path=file, key=f"simulation.{key}"
            )
    if s["duration"] < s["dt"]:
        raise ScenarioError(
            f"shorter than one control period dt = {s['dt']} s",
            path=file,
            key="simulation.duration",
        )
    alpha = data["controller"]["alpha"]
    if alpha * s["dt"] >= 1.0:
        raise ScenarioError(
            f"alpha * dt = {alpha * s['dt']:g} must be < 1 for the escape-velocity bounds "
            "to keep the joints inside their limits",
            path=file,
            key="controller.alpha",
        )
    settle = data["verdict"]["settle_time"]
    if "verdict.settle_time" in set_keys and not settle < s["duration"]:
        raise ScenarioError(
            f"must be < simulation.duration = {s['duration']:g} s, the duration run (tracking "
            f"and force are judged after it), got {settle:g} s",
            path=file,
            key="verdict.settle_time",
        )


#: Order of the tables in a filled-in scenario file (:func:`filled`): the schema's, ``[path]``
#: after ``[key_points]``, ``[verdict]`` last.
_ORDER = (*list(_SCHEMA)[:3], "path", *list(_SCHEMA)[3:], "verdict")


def filled(data: dict, rnn: dict) -> dict:
    """The validated tables (:func:`validate`) as TOML-ready tables, every default filled in
    (vectors as lists)."""

    def plain(table: dict) -> dict:
        return {k: v.tolist() if isinstance(v, np.ndarray) else v for k, v in table.items()}

    out = {"obstacles": [plain(o) for o in data["obstacles"]]}
    out.update((table, plain(data[table])) for table in _ORDER)
    out["rnn"] = plain(rnn)
    return out
