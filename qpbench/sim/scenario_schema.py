"""The scenario file's schema: every table and key, typed and checked (paper section 4).

Layout (every key required unless marked optional; a missing, unknown,
mistyped or impossible key raises :class:`~qpbench.exceptions.ScenarioError`
naming the file and the key)::

    obstacles = [ ... ]            # or [[obstacles]] tables, see below
    [scenario]    name, description, paper_section, in_paper (optional, default
                  false: one of the paper's scenarios, whose ticks ``qpbench run``
                  also benchmarks)
    [robot]       link_lengths [m], theta0 [rad], theta_min, theta_max [rad],
                  velocity_min, velocity_max [rad/s]
    [key_points]  points_per_link, include_joints, link_radius [m], kind (optional,
                  default "paper": the paper's fixed key points; "closest": an
                  obstacle row at each link's point closest to each obstacle, end
                  effector's link included, beyond the paper; see
                  :class:`qpbench.robot.kinematics.KeyPoints`)
    [path]        kind = "cosine": centre, amplitude [m], omega [rad/s], phase [rad]
                  kind = "polyline": times [s], points [[x, y], ...] [m]
    [contact]     point [m], normal, stiffness [N/m], damping [N s/m],
                  force_noise_std [N], noise_seed
    [controller]  desired_force [N], kp [N/m], kd [N s/m], alpha [1/s], k [1/s],
                  d_safe [m], rho
    [adaptive]    enabled, gain [kp part, kd part], kp_min, kd_min
    [simulation]  dt [s], duration [s]
    [rnn]         eps [s] and any further settings of the ``rnn`` backend
                  (passed through: ``get_backend("rnn", **scenario.rnn)``)
    [verdict]     settle_time [s], max_tracking_error [m], max_force_error [N],
                  safety_margin [m] (optional, default 0.0005): the thresholds
                  of a run's verdict (:mod:`qpbench.sim.verdict`)

Obstacles (``[[obstacles]]``, each with ``kind``, ``name`` and ``velocity``
[m/s]): ``line`` (point, normal to the free side), ``segment`` (a, b),
``disk`` (center, radius), ``points`` (points).
"""

from __future__ import annotations

import math
from typing import TYPE_CHECKING

import numpy as np

from ..exceptions import ScenarioError, check_known_keys
from ..robot.kinematics import KEY_POINT_KINDS
from .verdict import DEFAULT_SAFETY_MARGIN

if TYPE_CHECKING:
    from pathlib import Path

__all__ = ["check_simulation", "validate"]

_NUM = "number"
_INT = "int"
_BOOL = "bool"
_STR = "str"
_VEC = "vector"  # list of numbers
_VEC2 = "vector2"
_PTS = "points"  # list of [x, y]

_SCHEMA: dict[str, dict[str, str]] = {
    "scenario": {"name": _STR, "description": _STR, "paper_section": _STR, "in_paper": _BOOL},
    "robot": {
        "link_lengths": _VEC,
        "theta0": _VEC,
        "theta_min": _VEC,
        "theta_max": _VEC,
        "velocity_min": _VEC,
        "velocity_max": _VEC,
    },
    "key_points": {
        "points_per_link": _INT,
        "include_joints": _BOOL,
        "link_radius": _NUM,
        "kind": _STR,
    },
    "contact": {
        "point": _VEC2,
        "normal": _VEC2,
        "stiffness": _NUM,
        "damping": _NUM,
        "force_noise_std": _NUM,
        "noise_seed": _INT,
    },
    "controller": {
        "desired_force": _NUM,
        "kp": _NUM,
        "kd": _NUM,
        "alpha": _NUM,
        "k": _NUM,
        "d_safe": _NUM,
        "rho": _NUM,
    },
    "adaptive": {"enabled": _BOOL, "gain": _VEC2, "kp_min": _NUM, "kd_min": _NUM},
    "simulation": {"dt": _NUM, "duration": _NUM},
}
_PATH_SCHEMA = {
    "cosine": {"kind": _STR, "centre": _VEC2, "amplitude": _VEC2, "omega": _VEC2, "phase": _VEC2},
    "polyline": {"kind": _STR, "times": _VEC, "points": _PTS},
}
_OBSTACLE_SCHEMA = {
    "line": {"kind": _STR, "name": _STR, "point": _VEC2, "normal": _VEC2, "velocity": _VEC2},
    "segment": {"kind": _STR, "name": _STR, "a": _VEC2, "b": _VEC2, "velocity": _VEC2},
    "disk": {"kind": _STR, "name": _STR, "center": _VEC2, "radius": _NUM, "velocity": _VEC2},
    "points": {"kind": _STR, "name": _STR, "points": _PTS, "velocity": _VEC2},
}
_TOP = set(_SCHEMA) | {"path", "obstacles", "rnn", "verdict"}
#: ``[verdict]`` keys: required ones, then the optional ``safety_margin`` (see :mod:`qpbench.sim.verdict`).
_VERDICT_SCHEMA = {
    "settle_time": _NUM,
    "max_tracking_error": _NUM,
    "max_force_error": _NUM,
    "safety_margin": _NUM,
}
#: Optional keys and their defaults, per table.
_OPTIONAL = {
    "scenario": {"in_paper": False},
    "verdict": {"safety_margin": DEFAULT_SAFETY_MARGIN},
    "key_points": {"kind": "paper"},
}


def _typed(value, kind: str, file, key: str):
    def bad(what):
        raise ScenarioError(f"expected {what}, got {value!r}", path=file, key=key)

    def number(v):
        return isinstance(v, (int, float)) and not isinstance(v, bool) and math.isfinite(v)

    if kind == _NUM:
        if not number(value):
            bad("a finite number")
        return float(value)
    if kind == _INT:
        if not isinstance(value, int) or isinstance(value, bool):
            bad("an integer")
        return int(value)
    if kind == _BOOL:
        if not isinstance(value, bool):
            bad("true or false")
        return value
    if kind == _STR:
        if not isinstance(value, str):
            bad("a string")
        return value
    if kind in (_VEC, _VEC2):
        if not isinstance(value, list) or not all(number(v) for v in value) or not value:
            bad("a list of finite numbers")
        if kind == _VEC2 and len(value) != 2:
            bad("a list of two numbers")
        return np.array(value, dtype=float)
    if kind == _PTS:
        if (
            not isinstance(value, list)
            or not value
            or not all(
                isinstance(p, list) and len(p) == 2 and all(number(v) for v in p) for p in value
            )
        ):
            bad("a list of [x, y] pairs")
        return np.array(value, dtype=float)
    raise AssertionError(kind)  # pragma: no cover


def _table(raw: dict, schema: dict[str, str], file, prefix: str) -> dict:
    if not isinstance(raw, dict):
        raise ScenarioError("expected a table", path=file, key=prefix)
    raw = {**_OPTIONAL.get(prefix, {}), **raw}
    check_known_keys(raw, schema, file, prefix, ScenarioError)
    out = {}
    for key, kind in schema.items():
        if key not in raw:
            raise ScenarioError("missing key", path=file, key=f"{prefix}.{key}")
        out[key] = _typed(raw[key], kind, file, f"{prefix}.{key}")
    return out


def validate(raw: dict, file: str | Path) -> tuple[dict, dict]:
    """The parsed TOML tables ``raw`` checked against the schema.

    Returns:
        ``(data, rnn)``: the validated tables (numbers as floats, vectors as
        arrays), and the ``[rnn]`` settings as a plain dict.

    Raises:
        ScenarioError: a missing, unknown, mistyped or impossible table or key.
    """
    for key in raw:
        if key not in _TOP:
            raise ScenarioError(
                f"unknown table (expected one of: {', '.join(sorted(_TOP))})", path=file, key=key
            )
    for key in sorted(_TOP):
        if key not in raw:
            raise ScenarioError("missing table", path=file, key=key)
    data = {name: _table(raw[name], schema, file, name) for name, schema in _SCHEMA.items()}
    data["path"] = _path_table(raw["path"], file)
    data["obstacles"] = _obstacles(raw["obstacles"], file)
    rnn = _rnn_table(raw["rnn"], file)
    data["verdict"] = _verdict_table(raw["verdict"], file)
    _check_values(data, file)
    check_simulation(data, file)
    return data, rnn


def _path_table(p, file) -> dict:
    if not isinstance(p, dict):
        raise ScenarioError("expected a table", path=file, key="path")
    kind = p.get("kind")
    if kind not in _PATH_SCHEMA:
        raise ScenarioError(
            f"expected one of {', '.join(_PATH_SCHEMA)}, got {kind!r}", path=file, key="path.kind"
        )
    return _table(p, _PATH_SCHEMA[kind], file, "path")


def _obstacles(obstacles, file) -> list[dict]:
    if not isinstance(obstacles, list):
        raise ScenarioError(
            "expected a list of obstacle tables ([[obstacles]] or obstacles = [])",
            path=file,
            key="obstacles",
        )
    out = []
    names = set()
    for i, o in enumerate(obstacles):
        prefix = f"obstacles[{i}]"
        if not isinstance(o, dict):
            raise ScenarioError("expected a table", path=file, key=prefix)
        kind = o.get("kind")
        if kind not in _OBSTACLE_SCHEMA:
            raise ScenarioError(
                f"expected one of {', '.join(_OBSTACLE_SCHEMA)}, got {kind!r}",
                path=file,
                key=f"{prefix}.kind",
            )
        entry = _table(o, _OBSTACLE_SCHEMA[kind], file, prefix)
        if entry["name"] in names or not entry["name"]:
            raise ScenarioError(
                f"obstacle names must be non-empty and unique, got {entry['name']!r}",
                path=file,
                key=f"{prefix}.name",
            )
        names.add(entry["name"])
        out.append(entry)
    return out


def _rnn_table(rnn, file) -> dict:
    """Settings of another component: ``eps`` required, the rest passed through."""
    if not isinstance(rnn, dict):
        raise ScenarioError("expected a table", path=file, key="rnn")
    if "eps" not in rnn:
        raise ScenarioError("missing key", path=file, key="rnn.eps")
    eps = _typed(rnn["eps"], _NUM, file, "rnn.eps")
    if not eps > 0:
        raise ScenarioError(f"must be > 0 [s], got {eps}", path=file, key="rnn.eps")
    return dict(rnn)


def _verdict_table(raw, file) -> dict:
    """The ``[verdict]`` table, validated (``safety_margin`` defaults to 0.0005 m)."""
    out = _table(raw, _VERDICT_SCHEMA, file, "verdict")
    if not out["settle_time"] >= 0:
        raise ScenarioError(
            f"must be >= 0 [s], got {out['settle_time']}", path=file, key="verdict.settle_time"
        )
    for key, unit in (("max_tracking_error", "m"), ("max_force_error", "N")):
        if not out[key] > 0:
            raise ScenarioError(
                f"must be > 0 [{unit}], got {out[key]}", path=file, key=f"verdict.{key}"
            )
    if not out["safety_margin"] >= 0:
        raise ScenarioError(
            f"must be >= 0 [m], got {out['safety_margin']}", path=file, key="verdict.safety_margin"
        )
    return out


def _check_values(data: dict, file) -> None:
    r = data["robot"]
    n = r["link_lengths"].size
    if n < 2:
        raise ScenarioError(
            f"a planar arm needs at least 2 links, got {n}", path=file, key="robot.link_lengths"
        )
    if np.any(r["link_lengths"] <= 0):
        raise ScenarioError(
            f"every link length must be > 0 [m], got {r['link_lengths'].tolist()}",
            path=file,
            key="robot.link_lengths",
        )
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
    if (
        np.any(r["velocity_min"] > 0)
        or np.any(r["velocity_max"] < 0)
        or np.any(r["velocity_min"] >= r["velocity_max"])
    ):
        raise ScenarioError(
            "need velocity_min <= 0 <= velocity_max and velocity_min < velocity_max [rad/s]",
            path=file,
            key="robot.velocity_min",
        )
    _check_key_points(data["key_points"], file)
    c = data["contact"]
    if np.hypot(*c["normal"]) < 1e-12:
        raise ScenarioError("must not be zero", path=file, key="contact.normal")
    _check_signs(
        c, "contact", file, positive=("stiffness",), non_negative=("damping", "force_noise_std")
    )
    _check_signs(
        data["controller"],
        "controller",
        file,
        positive=("kp", "kd", "alpha", "k", "rho"),
        non_negative=("d_safe", "desired_force"),
    )
    a = data["adaptive"]
    if np.any(a["gain"] < 0):
        raise ScenarioError("gains must be >= 0", path=file, key="adaptive.gain")
    _check_signs(a, "adaptive", file, positive=("kp_min", "kd_min"))
    for i, o in enumerate(data["obstacles"]):
        if o["kind"] == "disk" and not o["radius"] > 0:
            raise ScenarioError(
                f"must be > 0 [m], got {o['radius']}", path=file, key=f"obstacles[{i}].radius"
            )


def _check_key_points(kp: dict, file) -> None:
    """The ``[key_points]`` table: some key points, a known kind, a radius >= 0."""
    if kp["points_per_link"] < 0:
        raise ScenarioError(
            f"must be >= 0, got {kp['points_per_link']}",
            path=file,
            key="key_points.points_per_link",
        )
    if kp["points_per_link"] == 0 and not kp["include_joints"]:
        raise ScenarioError(
            "no key points (points_per_link = 0 and include_joints = false)",
            path=file,
            key="key_points.points_per_link",
        )
    if kp["kind"] not in KEY_POINT_KINDS:
        raise ScenarioError(
            f"expected one of {', '.join(KEY_POINT_KINDS)}, got {kp['kind']!r}",
            path=file,
            key="key_points.kind",
        )
    if kp["link_radius"] < 0:
        raise ScenarioError(
            f"must be >= 0 [m], got {kp['link_radius']}", path=file, key="key_points.link_radius"
        )


def _check_signs(
    table: dict, name: str, file, positive: tuple = (), non_negative: tuple = ()
) -> None:
    """Reject a value of ``table`` (the TOML table ``name``) that is not > 0 / not >= 0 (NaN included)."""
    for key in positive:
        if not table[key] > 0:
            raise ScenarioError(f"must be > 0, got {table[key]}", path=file, key=f"{name}.{key}")
    for key in non_negative:
        if not table[key] >= 0:
            raise ScenarioError(f"must be >= 0, got {table[key]}", path=file, key=f"{name}.{key}")


def check_simulation(data: dict, file: str | Path) -> None:
    s = data["simulation"]
    if not s["dt"] > 0:
        raise ScenarioError(f"must be > 0 [s], got {s['dt']}", path=file, key="simulation.dt")
    if not s["duration"] > 0:
        raise ScenarioError(
            f"must be > 0 [s], got {s['duration']}", path=file, key="simulation.duration"
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
