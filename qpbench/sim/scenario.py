"""Scenarios: one TOML file holds every parameter of a simulation (paper section 4).

A scenario is named by a file path, or by the name of a shipped file
(``free``, ``wall``, ``adaptive``, ``adaptive_fast``, ``narrow``; see
:func:`scenario_names`). The shipped files are ``problems/scenarios/*.toml`` in
the repository; byte-identical copies live in the package
(``qpbench/data/scenarios``) so that names resolve in an installed qpbench too
(a test keeps the two copies identical).

Layout (every key required; a missing, unknown, mistyped or impossible key
raises :class:`~qpbench.exceptions.ScenarioError` naming the file and the key)::

    obstacles = [ ... ]            # or [[obstacles]] tables, see below
    [scenario]    name, description, paper_section
    [robot]       link_lengths [m], theta0 [rad], theta_min, theta_max [rad],
                  velocity_min, velocity_max [rad/s]
    [key_points]  points_per_link, include_joints, link_radius [m]
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

Values can be set over a file's without copying it (``load_scenario(name,
overrides={"rnn.eps": 1e-3})``, ``qpbench simulate --set rnn.eps=0.001``):
see :func:`apply_overrides`; the validation is the same.

Obstacles (``[[obstacles]]``, each with ``kind``, ``name`` and ``velocity``
[m/s]): ``line`` (point, normal to the free side), ``segment`` (a, b),
``disk`` (center, radius), ``points`` (points).
"""

from __future__ import annotations

import copy
import math
import re
import tomllib
from dataclasses import dataclass, field, replace
from importlib import resources
from pathlib import Path

import numpy as np

from ..exceptions import InputError, ScenarioError
from ..robot.environment import OBSTACLE_KINDS, ContactSurface, Obstacle
from ..robot.kinematics import KeyPoints, PlanarArm, default_key_points
from .verdict import DEFAULT_SAFETY_MARGIN, VerdictSettings

__all__ = ["Scenario", "apply_overrides", "load_scenario", "parse_scenario", "scenario_names", "scenario_path"]

# -- schema -----------------------------------------------------------------------
_NUM = "number"
_INT = "int"
_BOOL = "bool"
_STR = "str"
_VEC = "vector"  # list of numbers
_VEC2 = "vector2"
_PTS = "points"  # list of [x, y]

_SCHEMA: dict[str, dict[str, str]] = {
    "scenario": {"name": _STR, "description": _STR, "paper_section": _STR},
    "robot": {
        "link_lengths": _VEC,
        "theta0": _VEC,
        "theta_min": _VEC,
        "theta_max": _VEC,
        "velocity_min": _VEC,
        "velocity_max": _VEC,
    },
    "key_points": {"points_per_link": _INT, "include_joints": _BOOL, "link_radius": _NUM},
    "contact": {
        "point": _VEC2,
        "normal": _VEC2,
        "stiffness": _NUM,
        "damping": _NUM,
        "force_noise_std": _NUM,
        "noise_seed": _INT,
    },
    "controller": {"desired_force": _NUM, "kp": _NUM, "kd": _NUM, "alpha": _NUM, "k": _NUM, "d_safe": _NUM, "rho": _NUM},
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
_VERDICT_SCHEMA = {"settle_time": _NUM, "max_tracking_error": _NUM, "max_force_error": _NUM, "safety_margin": _NUM}
_VERDICT_OPTIONAL = {"safety_margin": DEFAULT_SAFETY_MARGIN}


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
            or not all(isinstance(p, list) and len(p) == 2 and all(number(v) for v in p) for p in value)
        ):
            bad("a list of [x, y] pairs")
        return np.array(value, dtype=float)
    raise AssertionError(kind)  # pragma: no cover


def _table(raw: dict, schema: dict[str, str], file, prefix: str) -> dict:
    if not isinstance(raw, dict):
        raise ScenarioError("expected a table", path=file, key=prefix)
    for key in raw:
        if key not in schema:
            raise ScenarioError(f"unknown key (expected one of: {', '.join(schema)})", path=file, key=f"{prefix}.{key}")
    out = {}
    for key, kind in schema.items():
        if key not in raw:
            raise ScenarioError("missing key", path=file, key=f"{prefix}.{key}")
        out[key] = _typed(raw[key], kind, file, f"{prefix}.{key}")
    return out


# -- the scenario -------------------------------------------------------------------
@dataclass
class Scenario:
    """Everything a simulation needs, read from one TOML file.

    Attributes:
        name: Scenario name (``[scenario] name``).
        path: The file it came from (None when parsed from text).
        source: The file's full text (stored in dumped problem sets' manifests).
        data: The parsed, validated tables (numbers as floats, vectors as arrays).
        rnn: Settings of the ``rnn`` backend (``eps`` and more), as a plain dict.
        overrides: Values set over the file's (:func:`apply_overrides`), by
            dotted key; empty when the file is used as it is.
        dt: Control period in [s].
        duration: Simulated time in [s].
    """

    name: str
    path: Path | None
    source: str
    data: dict
    rnn: dict = field(default_factory=dict)
    overrides: dict = field(default_factory=dict)

    # -- convenience views -------------------------------------------------------
    @property
    def dt(self) -> float:
        return self.data["simulation"]["dt"]

    @property
    def duration(self) -> float:
        return self.data["simulation"]["duration"]

    @property
    def theta0(self) -> np.ndarray:
        return self.data["robot"]["theta0"].copy()

    @property
    def verdict(self) -> VerdictSettings:
        """Thresholds of a run's verdict (``[verdict]``; :mod:`qpbench.sim.verdict`)."""
        return VerdictSettings(**self.data["verdict"])

    @property
    def adaptive_enabled(self) -> bool:
        return self.data["adaptive"]["enabled"]

    def with_overrides(self, dt: float | None = None, duration: float | None = None) -> Scenario:
        """A copy with another control period or duration (validated like the file's values)."""
        data = copy.deepcopy(self.data)
        if dt is not None:
            data["simulation"]["dt"] = float(dt)
        if duration is not None:
            data["simulation"]["duration"] = float(duration)
        _check_simulation(data, self.path or "<override>")
        return replace(self, data=data)

    # -- builders ----------------------------------------------------------------
    def make_arm(self) -> PlanarArm:
        return PlanarArm(self.data["robot"]["link_lengths"])

    def make_key_points(self) -> KeyPoints:
        kp = self.data["key_points"]
        return default_key_points(
            len(self.data["robot"]["link_lengths"]), kp["points_per_link"], kp["include_joints"], kp["link_radius"]
        )

    def make_path(self):
        from ..control.terms import CosinePath, PolylinePath

        p = self.data["path"]
        if p["kind"] == "cosine":
            return CosinePath(p["centre"], p["amplitude"], p["omega"], p["phase"])
        return PolylinePath(p["times"], p["points"])

    def make_surface(self) -> ContactSurface:
        c = self.data["contact"]
        return ContactSurface(c["point"], c["normal"], c["stiffness"], c["damping"], c["force_noise_std"], c["noise_seed"])

    def make_obstacles(self) -> list[Obstacle]:
        out = []
        for o in self.data["obstacles"]:
            kind = o["kind"]
            args = {k: v for k, v in o.items() if k != "kind"}
            out.append(OBSTACLE_KINDS[kind](**args))
        return out

    def make_controller(self):
        """The scenario's :class:`~qpbench.control.controller.Controller`."""
        from ..control.controller import Controller
        from ..control.terms import EscapeVelocityLimits, ImpedanceTask

        r, c = self.data["robot"], self.data["controller"]
        normal = self.data["contact"]["normal"]
        normal = normal / np.linalg.norm(normal)
        task = ImpedanceTask(self.make_path(), normal, c["desired_force"])
        limits = EscapeVelocityLimits(r["theta_min"], r["theta_max"], r["velocity_min"], r["velocity_max"], c["alpha"])
        return Controller(
            self.make_arm(), self.make_key_points(), task, limits, self.make_obstacles(),
            k=c["k"], d_safe=c["d_safe"], rho=c["rho"], kp=c["kp"], kd=c["kd"],
        )

    def make_adaptive(self):
        """The adaptive estimator (section 4.4), or None when ``[adaptive] enabled = false``."""
        from ..control.adaptive import AdaptiveImpedance

        a = self.data["adaptive"]
        if not a["enabled"]:
            return None
        c = self.data["controller"]
        normal = self.data["contact"]["normal"]
        normal = normal / np.linalg.norm(normal)
        return AdaptiveImpedance(c["kp"], c["kd"], a["gain"], normal, c["desired_force"], a["kp_min"], a["kd_min"])


def _check_simulation(data: dict, file) -> None:
    s = data["simulation"]
    if not s["dt"] > 0:
        raise ScenarioError(f"must be > 0 [s], got {s['dt']}", path=file, key="simulation.dt")
    if not s["duration"] > 0:
        raise ScenarioError(f"must be > 0 [s], got {s['duration']}", path=file, key="simulation.duration")
    if s["duration"] < s["dt"]:
        raise ScenarioError(f"shorter than one control period dt = {s['dt']} s", path=file, key="simulation.duration")
    alpha = data["controller"]["alpha"]
    if alpha * s["dt"] >= 1.0:
        raise ScenarioError(
            f"alpha * dt = {alpha * s['dt']:g} must be < 1 for the escape-velocity bounds to keep the joints inside their limits",
            path=file, key="controller.alpha",
        )


def parse_scenario(text: str, path: str | Path | None = None, overrides: dict | None = None) -> Scenario:
    """Parse and validate a scenario from TOML text (``path`` only names it in errors).

    ``overrides`` (dotted key -> value, see :func:`apply_overrides`) replace
    the file's values before the validation, which then names the key of a
    wrong one exactly as for a wrong value in the file.
    """
    file = path if path is not None else "<scenario>"
    try:
        raw = tomllib.loads(text)
    except tomllib.TOMLDecodeError as exc:
        raise ScenarioError(f"not valid TOML: {exc}", path=file) from None
    if overrides:
        raw = apply_overrides(raw, overrides, file)
    for key in raw:
        if key not in _TOP:
            raise ScenarioError(f"unknown table (expected one of: {', '.join(sorted(_TOP))})", path=file, key=key)
    for key in sorted(_TOP):
        if key not in raw:
            raise ScenarioError("missing table", path=file, key=key)
    data = {name: _table(raw[name], schema, file, name) for name, schema in _SCHEMA.items()}

    # path
    p = raw["path"]
    if not isinstance(p, dict):
        raise ScenarioError("expected a table", path=file, key="path")
    kind = p.get("kind")
    if kind not in _PATH_SCHEMA:
        raise ScenarioError(f"expected one of {', '.join(_PATH_SCHEMA)}, got {kind!r}", path=file, key="path.kind")
    data["path"] = _table(p, _PATH_SCHEMA[kind], file, "path")

    # obstacles
    obstacles = raw["obstacles"]
    if not isinstance(obstacles, list):
        raise ScenarioError("expected a list of obstacle tables ([[obstacles]] or obstacles = [])", path=file, key="obstacles")
    data["obstacles"] = []
    names = set()
    for i, o in enumerate(obstacles):
        prefix = f"obstacles[{i}]"
        if not isinstance(o, dict):
            raise ScenarioError("expected a table", path=file, key=prefix)
        kind = o.get("kind")
        if kind not in _OBSTACLE_SCHEMA:
            raise ScenarioError(f"expected one of {', '.join(_OBSTACLE_SCHEMA)}, got {kind!r}", path=file, key=f"{prefix}.kind")
        entry = _table(o, _OBSTACLE_SCHEMA[kind], file, prefix)
        if entry["name"] in names or not entry["name"]:
            raise ScenarioError(f"obstacle names must be non-empty and unique, got {entry['name']!r}", path=file, key=f"{prefix}.name")
        names.add(entry["name"])
        data["obstacles"].append(entry)

    # rnn (settings of another component: eps required, the rest passed through)
    rnn = raw["rnn"]
    if not isinstance(rnn, dict):
        raise ScenarioError("expected a table", path=file, key="rnn")
    if "eps" not in rnn:
        raise ScenarioError("missing key", path=file, key="rnn.eps")
    eps = _typed(rnn["eps"], _NUM, file, "rnn.eps")
    if not eps > 0:
        raise ScenarioError(f"must be > 0 [s], got {eps}", path=file, key="rnn.eps")

    data["verdict"] = _verdict_table(raw["verdict"], file)

    _check_values(data, file)
    _check_simulation(data, file)
    scenario = Scenario(
        name=data["scenario"]["name"], path=None if path is None else Path(path), source=text, data=data,
        rnn=dict(rnn), overrides=dict(overrides or {}),
    )
    # build every object once so constructor checks surface here, naming the file
    try:
        scenario.make_controller()
        scenario.make_surface()
    except ScenarioError:
        raise
    except InputError as exc:
        raise ScenarioError(exc.message, path=file, key=exc.key) from None
    return scenario


_OVERRIDE_KEY = re.compile(r"([A-Za-z_][A-Za-z0-9_]*)(?:\[(\d+)\])?\.([A-Za-z_][A-Za-z0-9_]*)")


def apply_overrides(raw: dict, overrides: dict, file="<scenario>") -> dict:
    """A copy of the parsed TOML tables ``raw`` with ``overrides`` set over them.

    Keys are dotted: ``table.key`` (``rnn.eps``, ``controller.k``,
    ``simulation.duration``) or ``obstacles[i].key`` (``obstacles[0].velocity``).
    A key must name a table the file has and, in ``[rnn]``, a setting of the
    ``rnn`` backends (an ``[rnn]`` key may be new: the file need not list
    every setting); anything else is checked by the usual validation of
    :func:`parse_scenario` (an unknown key of another table is reported
    there). Errors name the file and the key.
    """
    raw = copy.deepcopy(raw)
    for key, value in overrides.items():
        match = _OVERRIDE_KEY.fullmatch(str(key))
        if match is None:
            raise ScenarioError("expected TABLE.KEY or obstacles[i].KEY", path=file, key=key)
        table, index, name = match.groups()
        if index is not None:
            if table != "obstacles":
                raise ScenarioError("only obstacles take an index (obstacles[i].KEY)", path=file, key=key)
            obstacles = raw.get("obstacles")
            count = len(obstacles) if isinstance(obstacles, list) else 0
            if int(index) >= count:
                raise ScenarioError(f"no such obstacle (the file has {count})", path=file, key=f"obstacles[{index}]")
            target = obstacles[int(index)]
        else:
            target = raw.get(table)
            if table == "obstacles" or not isinstance(target, dict):
                tables = ", ".join(sorted(t for t in raw if isinstance(raw[t], dict)))
                raise ScenarioError(f"no such table in the file (tables: {tables})", path=file, key=key)
            if table == "rnn" and name not in target:
                from ..backends.rnn import SETTING_NAMES

                if name not in SETTING_NAMES:
                    raise ScenarioError(
                        f"unknown setting of the rnn backends (expected one of: {', '.join(SETTING_NAMES)})",
                        path=file, key=key,
                    )
        target[name] = value
    return raw


def _verdict_table(raw, file) -> dict:
    """The ``[verdict]`` table, validated (``safety_margin`` defaults to 0.0005 m)."""
    raw = dict(raw) if isinstance(raw, dict) else raw
    if isinstance(raw, dict):
        for key, value in _VERDICT_OPTIONAL.items():
            raw.setdefault(key, value)
    out = _table(raw, _VERDICT_SCHEMA, file, "verdict")
    if not out["settle_time"] >= 0:
        raise ScenarioError(f"must be >= 0 [s], got {out['settle_time']}", path=file, key="verdict.settle_time")
    for key, unit in (("max_tracking_error", "m"), ("max_force_error", "N")):
        if not out[key] > 0:
            raise ScenarioError(f"must be > 0 [{unit}], got {out[key]}", path=file, key=f"verdict.{key}")
    if not out["safety_margin"] >= 0:
        raise ScenarioError(f"must be >= 0 [m], got {out['safety_margin']}", path=file, key="verdict.safety_margin")
    return out


def _check_values(data: dict, file) -> None:
    r = data["robot"]
    n = r["link_lengths"].size
    if n < 2:
        raise ScenarioError(f"a planar arm needs at least 2 links, got {n}", path=file, key="robot.link_lengths")
    if np.any(r["link_lengths"] <= 0):
        raise ScenarioError(f"every link length must be > 0 [m], got {r['link_lengths'].tolist()}", path=file, key="robot.link_lengths")
    for key in ("theta0", "theta_min", "theta_max", "velocity_min", "velocity_max"):
        if r[key].size != n:
            raise ScenarioError(f"expected {n} values (one per link), got {r[key].size}", path=file, key=f"robot.{key}")
    if np.any(r["theta_min"] >= r["theta_max"]):
        raise ScenarioError("every theta_min must be < theta_max", path=file, key="robot.theta_min")
    outside = np.flatnonzero((r["theta0"] < r["theta_min"]) | (r["theta0"] > r["theta_max"]))
    if outside.size:
        i = int(outside[0])
        raise ScenarioError(
            f"theta0[{i}] = {r['theta0'][i]} rad is outside [{r['theta_min'][i]}, {r['theta_max'][i]}]",
            path=file, key="robot.theta0",
        )
    if np.any(r["velocity_min"] > 0) or np.any(r["velocity_max"] < 0) or np.any(r["velocity_min"] >= r["velocity_max"]):
        raise ScenarioError("need velocity_min <= 0 <= velocity_max and velocity_min < velocity_max [rad/s]", path=file, key="robot.velocity_min")
    kp = data["key_points"]
    if kp["points_per_link"] < 0:
        raise ScenarioError(f"must be >= 0, got {kp['points_per_link']}", path=file, key="key_points.points_per_link")
    if kp["points_per_link"] == 0 and not kp["include_joints"]:
        raise ScenarioError("no key points (points_per_link = 0 and include_joints = false)", path=file, key="key_points.points_per_link")
    if kp["link_radius"] < 0:
        raise ScenarioError(f"must be >= 0 [m], got {kp['link_radius']}", path=file, key="key_points.link_radius")
    c = data["contact"]
    if np.hypot(*c["normal"]) < 1e-12:
        raise ScenarioError("must not be zero", path=file, key="contact.normal")
    for key in ("stiffness",):
        if not c[key] > 0:
            raise ScenarioError(f"must be > 0, got {c[key]}", path=file, key=f"contact.{key}")
    for key in ("damping", "force_noise_std"):
        if not c[key] >= 0:
            raise ScenarioError(f"must be >= 0, got {c[key]}", path=file, key=f"contact.{key}")
    ctl = data["controller"]
    for key in ("kp", "kd", "alpha", "k", "rho"):
        if not ctl[key] > 0:
            raise ScenarioError(f"must be > 0, got {ctl[key]}", path=file, key=f"controller.{key}")
    for key in ("d_safe", "desired_force"):
        if not ctl[key] >= 0:
            raise ScenarioError(f"must be >= 0, got {ctl[key]}", path=file, key=f"controller.{key}")
    a = data["adaptive"]
    if np.any(a["gain"] < 0):
        raise ScenarioError("gains must be >= 0", path=file, key="adaptive.gain")
    for key in ("kp_min", "kd_min"):
        if not a[key] > 0:
            raise ScenarioError(f"must be > 0, got {a[key]}", path=file, key=f"adaptive.{key}")
    for i, o in enumerate(data["obstacles"]):
        if o["kind"] == "disk" and not o["radius"] > 0:
            raise ScenarioError(f"must be > 0 [m], got {o['radius']}", path=file, key=f"obstacles[{i}].radius")


# -- name resolution ------------------------------------------------------------------
def _shipped_dir():
    return resources.files("qpbench") / "data" / "scenarios"


def scenario_names() -> list[str]:
    """Names of the shipped scenarios, sorted."""
    return sorted(p.name[:-5] for p in _shipped_dir().iterdir() if p.name.endswith(".toml"))


def scenario_path(name_or_path: str | Path) -> Path:
    """The file a scenario name or path refers to.

    A name without a suffix or slash is looked up among the shipped scenarios
    first; anything else is a path.

    Raises:
        ScenarioError: no such file or shipped scenario.
    """
    text = str(name_or_path)
    if "/" not in text and not text.endswith(".toml"):
        candidate = _shipped_dir() / f"{text}.toml"
        if candidate.is_file():
            return Path(str(candidate))
        if not Path(text).is_file():
            raise ScenarioError(
                f"no shipped scenario of that name and no such file (shipped: {', '.join(scenario_names())})",
                path=text,
            )
    path = Path(text)
    if not path.is_file():
        raise ScenarioError("no such scenario file", path=path)
    return path


def load_scenario(name_or_path: str | Path, overrides: dict | None = None) -> Scenario:
    """Load a scenario by shipped name (``wall``) or by path (``my/scene.toml``).

    ``overrides`` (dotted key -> value) replace values of the file
    (:func:`apply_overrides`); they are validated like the file's own.

    Raises:
        ScenarioError: unknown name, unreadable file, or a missing, unknown or
            impossible key (the message names the file and the key).
    """
    path = scenario_path(name_or_path)
    try:
        text = path.read_text(encoding="utf-8")
    except (OSError, UnicodeDecodeError) as exc:
        raise ScenarioError(f"cannot read: {exc}", path=path) from None
    return parse_scenario(text, path, overrides)
