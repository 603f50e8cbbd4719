"""The scenario file's schema: every table and key, typed and checked (paper section 4).

Layout (every key required unless it has a default; a missing, unknown,
mistyped or impossible key raises :class:`~qpbench.exceptions.ScenarioError`
naming the file and the key)::

    obstacles = [ ... ]            # or [[obstacles]] tables, see below
    [scenario]    name, description, paper_section, in_paper (default false:
                  one of the paper's scenarios, whose ticks ``qpbench run``
                  also benchmarks), in_run (default true: ``qpbench run``
                  runs it when no ``--scenarios`` are given)
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
    [simulation]  dt [s], duration [s]

Tables that describe how a run is judged or how a backend is tuned, not the
task, may be left out; every key of them has a default (:data:`DEFAULTS`;
``qpbench scenarios show NAME --filled`` prints a scenario with every default
filled in)::

    [adaptive]    enabled (default false), gain [kp part, kd part] (default
                  [500, 20], the paper's), kp_min [N/m] (default 100), kd_min
                  [N s/m] (default 1)
    [rnn]         eps [s] (default 0.02, the paper's) and any further settings
                  of the ``rnn`` backends (passed through:
                  ``get_backend("rnn", **scenario.rnn)``)
    [verdict]     the thresholds of a run's verdict and of its real time
                  (:class:`qpbench.sim.verdict.VerdictSettings`; ``docs/verdicts.md``
                  says why each default):
                  settle_time [s] (default 2.0: twice the paper's transient of
                  about 1 s, or half the duration when that is shorter; set on
                  the command line, it must be < simulation.duration),
                  max_tracking_error [m] (default 0.001), max_force_error [N]
                  (default 2.0), safety_margin [m] (default 0.0005, or half of
                  d_safe when that is smaller; 0 <= safety_margin < d_safe,
                  0 when d_safe = 0),
                  max_p99_fraction_of_dt (default 0.5: the p99 of a run's
                  per-tick times may take at most half the control period, the
                  rest of a tick is sensing, the model, the QP's construction,
                  the drives' bus and the operating system's jitter; in (0, 1]),
                  max_over_dt_share (default 0.001: at most one tick in a
                  thousand may take longer than dt, where a drive holds the last
                  command once; in [0, 1))

Obstacles (``[[obstacles]]``, each with ``kind``, ``name`` and ``velocity``
[m/s]): ``line`` (point, normal to the free side), ``segment`` (a, b),
``disk`` (center, radius), ``points`` (points).
"""

from __future__ import annotations

import math
from typing import TYPE_CHECKING

import numpy as np

from ..exceptions import InputError, ScenarioError, check_known_keys
from ..robot.kinematics import KEY_POINT_KINDS
from .verdict import DEFAULT_SAFETY_MARGIN, VerdictSettings

if TYPE_CHECKING:
    from pathlib import Path

__all__ = ["DEFAULTS", "check_simulation", "filled", "validate"]

_NUM = "number"
_INT = "int"
_BOOL = "bool"
_STR = "str"
_VEC = "vector"  # list of numbers
_VEC2 = "vector2"
_PTS = "points"  # list of [x, y]

_SCHEMA: dict[str, dict[str, str]] = {
    "scenario": {
        "name": _STR,
        "description": _STR,
        "paper_section": _STR,
        "in_paper": _BOOL,
        "in_run": _BOOL,
    },
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
#: ``[verdict]`` keys (:class:`qpbench.sim.verdict.VerdictSettings`).
_VERDICT_SCHEMA = {
    "settle_time": _NUM,
    "max_tracking_error": _NUM,
    "max_force_error": _NUM,
    "safety_margin": _NUM,
    "max_p99_fraction_of_dt": _NUM,
    "max_over_dt_share": _NUM,
}
_VERDICT_DEFAULTS = VerdictSettings()
#: Defaults of the keys that may be left out, per table (module docstring). ``settle_time``
#: defaults to at most half the duration, ``safety_margin`` to at most half of ``d_safe``
#: (:func:`_verdict_table`).
DEFAULTS: dict[str, dict] = {
    "scenario": {"in_paper": False, "in_run": True},
    "key_points": {"kind": "paper"},
    "adaptive": {"enabled": False, "gain": [500.0, 20.0], "kp_min": 100.0, "kd_min": 1.0},
    "rnn": {"eps": 0.02},
    "verdict": {key: getattr(_VERDICT_DEFAULTS, key) for key in _VERDICT_SCHEMA},
}
#: Tables a file may leave out (all their keys have defaults).
_OPTIONAL_TABLES = ("adaptive", "rnn", "verdict")


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
    raw = {**DEFAULTS.get(prefix, {}), **raw}
    check_known_keys(raw, schema, file, prefix, ScenarioError)
    out = {}
    for key, kind in schema.items():
        if key not in raw:
            raise ScenarioError("missing key", path=file, key=f"{prefix}.{key}")
        out[key] = _typed(raw[key], kind, file, f"{prefix}.{key}")
    return out


def validate(raw: dict, file: str | Path, set_keys=()) -> tuple[dict, dict]:
    """The parsed TOML tables ``raw`` checked against the schema (``set_keys``: the dotted
    keys set over the file's on the command line, checked by the rules for them).

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
    raw = {**{t: {} for t in _OPTIONAL_TABLES}, **raw}
    for key in sorted(_TOP):
        if key not in raw:
            raise ScenarioError("missing table", path=file, key=key)
    data = {name: _table(raw[name], schema, file, name) for name, schema in _SCHEMA.items()}
    data["path"] = _path_table(raw["path"], file)
    data["obstacles"] = _obstacles(raw["obstacles"], file)
    rnn = _rnn_table(raw["rnn"], file)
    _check_values(data, file)
    check_simulation(data, file)
    data["verdict"] = _verdict_table(raw["verdict"], data, file, set_keys)
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
    rnn = {**DEFAULTS["rnn"], **rnn}
    eps = _typed(rnn["eps"], _NUM, file, "rnn.eps")
    if not eps > 0:
        raise ScenarioError(f"must be > 0 [s], got {eps}", path=file, key="rnn.eps")
    return dict(rnn)


def _verdict_table(raw, data: dict, file, set_keys=()) -> dict:
    """The ``[verdict]`` table, validated by :class:`~qpbench.sim.verdict.VerdictSettings`
    and against the task: ``0 <= safety_margin < d_safe`` (``safety_margin = 0`` when
    ``d_safe = 0``; its default is at most half of ``d_safe``) and, for a ``settle_time``
    set on the command line (``set_keys``), ``settle_time < duration``. A file whose own
    ``duration`` is not above its ``settle_time`` (a short check, a sweep's short
    instances) is a short run: its verdict says tracking and force were not judged."""
    d_safe, duration = data["controller"]["d_safe"], data["simulation"]["duration"]
    if isinstance(raw, dict):  # defaults that fit the task (module docstring)
        raw = {
            "settle_time": min(_VERDICT_DEFAULTS.settle_time, duration / 2),
            "safety_margin": min(DEFAULT_SAFETY_MARGIN, d_safe / 2),
            **raw,
        }
    out = _table(raw, _VERDICT_SCHEMA, file, "verdict")
    try:
        VerdictSettings(**out)
    except InputError as exc:
        raise ScenarioError(exc.message, path=file, key=exc.key) from None
    if "verdict.settle_time" in set_keys and not out["settle_time"] < duration:
        raise ScenarioError(
            f"must be < simulation.duration = {duration:g} s (tracking and force are judged "
            f"after it), got {out['settle_time']:g} s",
            path=file,
            key="verdict.settle_time",
        )
    margin = out["safety_margin"]
    if not (margin < d_safe or margin == d_safe == 0):
        raise ScenarioError(
            f"must be < controller.d_safe = {d_safe:g} m (0 when d_safe is 0), got {margin:g} m",
            path=file,
            key="verdict.safety_margin",
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


#: Order of the tables in a filled-in scenario file (:func:`filled`).
_ORDER = (
    "scenario",
    "robot",
    "key_points",
    "path",
    "contact",
    "controller",
    "adaptive",
    "simulation",
    "verdict",
    "rnn",
)


def filled(data: dict, rnn: dict) -> dict:
    """The validated tables (:func:`validate`) as TOML-ready tables, every default filled in:
    what a scenario file with every key written out holds (vectors as lists)."""

    def plain(value):
        return value.tolist() if isinstance(value, np.ndarray) else value

    out = {"obstacles": [{k: plain(v) for k, v in o.items()} for o in data["obstacles"]]}
    for table in _ORDER:
        source = rnn if table == "rnn" else data[table]
        out[table] = {k: plain(v) for k, v in source.items()}
    return out
