"""The scenario file as one typed model (pydantic): every table and key with its type and unit
(paper section 4).

:func:`validate` turns the parsed TOML tables into a :class:`ScenarioSpec`; a missing, unknown
or mistyped key, or a value out of its bounds, raises one
:class:`~qpbench.exceptions.ScenarioError` naming the file and the key. Rules across keys (one
value per joint, ``theta_min < theta0 < theta_max``, ``alpha dt < 1``, the verdict's margin
below ``d_safe``) are checked here too; the objects built from the model (the arm, the contact
surface, the obstacles, :class:`~qpbench.sim.verdict.VerdictSettings`) check the rest.
``[adaptive]``, ``[rnn]`` and ``[verdict]`` may be left out (docs/verdicts.md for the latter).
"""

from __future__ import annotations

import math
from dataclasses import asdict, fields
from pathlib import Path
from typing import Annotated, Literal, Union

import numpy as np
from pydantic import (
    BaseModel,
    BeforeValidator,
    ConfigDict,
    Discriminator,
    Field,
    PlainSerializer,
    Strict,
    StrictBool,
    StrictStr,
    Tag,
    ValidationError,
    create_model,
)

from ..exceptions import InputError, ScenarioError
from ..robot.chain import ChainModel
from ..robot.obstacles import kinds as obstacle_kinds
from ..robot.presets import OWN_KEYS, make_chain
from .verdict import DEFAULT_SAFETY_MARGIN, VerdictSettings


def finite_number(v) -> bool:
    """True for an int or float (not a bool) that is finite."""
    return isinstance(v, (int, float)) and not isinstance(v, bool) and math.isfinite(v)


def _vector(size: int | None = None, lower: float | None = None):
    def check(v):
        ok = isinstance(v, list) and v and all(finite_number(x) for x in v)
        if not ok or (size is not None and len(v) != size):
            what = "a list of finite numbers" if size is None else f"a list of {size} numbers"
            raise ValueError(f"expected {what}, got {v!r}")
        if lower is not None and min(v) < lower:
            raise ValueError(f"every entry must be >= {lower:g}, got {v}")
        return np.array(v, dtype=float)

    return check


def _points(v):
    ok = isinstance(v, list) and v and isinstance(v[0], list) and len(v[0]) in (2, 3)
    ok = ok and all(
        isinstance(p, list) and len(p) == len(v[0]) and all(map(finite_number, p)) for p in v
    )
    if not ok:
        raise ValueError(f"expected a list of [x, y] or [x, y, z] points, got {v!r}")
    return np.array(v, dtype=float)


_AS_LIST = PlainSerializer(lambda a: a.tolist())
Num = Annotated[float, Strict(), Field(allow_inf_nan=False)]  # an int too, never a bool
Int = Annotated[int, Strict()]
Vec = Annotated[np.ndarray, BeforeValidator(_vector()), _AS_LIST]
Points = Annotated[np.ndarray, BeforeValidator(_points), _AS_LIST]


class Table(BaseModel):
    """A table of the file: unknown keys refused, values frozen once validated."""

    model_config = ConfigDict(extra="forbid", frozen=True, arbitrary_types_allowed=True)


def _tag(model: type[BaseModel]) -> str:
    """The ``kind`` a table model stands for (its ``Literal`` field)."""
    return model.model_fields["kind"].annotation.__args__[0]


def _by_kind(*models: type[BaseModel], default: str | None = None):
    """A union of tables picked by their ``kind`` (``[robot]``, ``[path]``, an obstacle); a
    table without one is of kind ``default``."""

    def kind_of(v):
        kind = v.get("kind", default) if isinstance(v, dict) else getattr(v, "kind", None)
        return kind if isinstance(kind, str) else None

    members = [Annotated[m, Tag(_tag(m))] for m in models]
    return Annotated[Union[tuple(members)], Discriminator(kind_of)]  # noqa: UP007


class ScenarioTable(Table):
    """``[scenario]``. ``in_paper``: one of the paper's scenarios, whose ticks ``qpbench run``
    also benchmarks; ``in_run``: ``qpbench run`` runs it when no ``--scenarios`` are given."""

    name: StrictStr
    description: StrictStr
    paper_section: StrictStr
    in_paper: StrictBool = False
    in_run: StrictBool = True


class PlanarRobotTable(Table):
    """``[robot]`` of kind ``planar`` (the default): a planar chain of ``link_lengths`` [m];
    start ``theta0``, limits ``theta_min``, ``theta_max`` [rad], ``velocity_min``,
    ``velocity_max`` [rad/s], one per joint."""

    kind: Literal["planar"] = "planar"
    link_lengths: Vec
    theta0: Vec
    theta_min: Vec
    theta_max: Vec
    velocity_min: Vec
    velocity_max: Vec


class PandaRobotTable(Table):
    """``[robot]`` of kind ``panda`` (``iiwa14``: the same keys): the preset's chain
    (:mod:`qpbench.robot.presets`) from ``theta0`` [rad]; its limits unless given here
    (``velocity_min`` defaults to ``-velocity_max``)."""

    kind: Literal["panda"]
    theta0: Vec
    theta_min: Vec | None = None
    theta_max: Vec | None = None
    velocity_min: Vec | None = None
    velocity_max: Vec | None = None


class Iiwa14RobotTable(PandaRobotTable):
    kind: Literal["iiwa14"]


class UrdfRobotTable(PandaRobotTable):
    """``[robot]`` of kind ``urdf``: the chain from the root of URDF ``file`` to ``ee_frame``
    (read by pinocchio), keys as :class:`PandaRobotTable`'s."""

    kind: Literal["urdf"]
    file: StrictStr
    ee_frame: StrictStr


class DhRobotTable(PandaRobotTable):
    """``[robot]`` of kind ``dh``: a chain of n revolute joints from Craig's modified
    Denavit-Hartenberg rows ``a`` [m], ``d`` [m], ``alpha`` [rad], n + 1 each (the joints, then
    the flange), from ``theta0`` [rad]; its limits ``theta_min``, ``theta_max``,
    ``velocity_max`` are required."""

    kind: Literal["dh"]
    a: Vec
    d: Vec
    alpha: Vec
    theta_min: Vec
    theta_max: Vec
    velocity_max: Vec


_ROBOTS = (PlanarRobotTable, PandaRobotTable, Iiwa14RobotTable, DhRobotTable, UrdfRobotTable)
RobotTable = _by_kind(*_ROBOTS, default="planar")


class KeyPointsTable(Table):
    """``[key_points]``: kind ``paper``, the paper's fixed key points; ``closest``, a row at each
    link's point closest to each obstacle (:class:`qpbench.robot.kinematics.KeyPoints`);
    ``link_radius`` [m]."""

    points_per_link: Int
    include_joints: StrictBool
    link_radius: Annotated[Num, Field(ge=0)]
    kind: Literal["paper", "closest"] = "paper"


class CosinePathTable(Table):
    """``x_d(t) = centre + amplitude cos(omega t + phase)`` per axis (the robot's dim):
    [m], [m], [rad/s], [rad]."""

    kind: Literal["cosine"] = "cosine"
    centre: Vec
    amplitude: Vec
    omega: Vec
    phase: Vec


class PolylinePathTable(Table):
    """``x_d(t)`` through ``points`` [m] (of the robot's dim) at ``times`` [s]."""

    kind: Literal["polyline"] = "polyline"
    times: Vec
    points: Points


class ContactTable(Table):
    """``[contact]``: a surface ``point`` [m] and pressing ``normal`` (the robot's dim), ``stiffness`` [N/m],
    ``damping`` [N s/m], force-sensor noise ``force_noise_std`` [N] drawn from ``noise_seed``."""

    point: Vec
    normal: Vec
    stiffness: Num
    damping: Num
    force_noise_std: Num
    noise_seed: Int


class ControllerTable(Table):
    """``[controller]``: ``desired_force`` [N], ``kp`` [N/m], ``kd`` [N s/m], ``alpha`` [1/s],
    ``k`` [1/s], ``d_safe`` [m], ``rho`` [s^2/m^2]."""

    desired_force: Annotated[Num, Field(ge=0)]
    kp: Annotated[Num, Field(gt=0)]
    kd: Annotated[Num, Field(gt=0)]
    alpha: Annotated[Num, Field(gt=0)]
    k: Annotated[Num, Field(gt=0)]
    d_safe: Annotated[Num, Field(ge=0)]
    rho: Annotated[Num, Field(gt=0)]


class AdaptiveTable(Table):
    """``[adaptive]``: ``gain`` = [kp part, kd part], ``kp_min`` [N/m], ``kd_min`` [N s/m]."""

    enabled: StrictBool = False
    gain: Annotated[np.ndarray, BeforeValidator(_vector(2, lower=0.0)), _AS_LIST] = Field(
        default_factory=lambda: np.array([500.0, 20.0])
    )
    kp_min: Annotated[Num, Field(gt=0)] = 100.0
    kd_min: Annotated[Num, Field(gt=0)] = 1.0


class SimulationTable(Table):
    """``[simulation]``: control period ``dt`` and ``duration`` [s] (:func:`check_simulation`)."""

    dt: Num
    duration: Num


class RnnTable(Table):
    """``[rnn]``: ``eps`` > 0; the other keys are the ``rnn`` backends' settings, checked there."""

    model_config = ConfigDict(extra="allow", frozen=True)
    eps: Annotated[Num, Field(gt=0)] = 0.02


#: ``[verdict]``: the keys given, of :class:`~qpbench.sim.verdict.VerdictSettings` (their
#: defaults depend on the task: :func:`validate` fills them).
VerdictTable = create_model(
    "VerdictTable", __base__=Table, **{f.name: (Num | None, None) for f in fields(VerdictSettings)}
)

_PATHS = (CosinePathTable, PolylinePathTable)
PathTable = _by_kind(*_PATHS)
_OBSTACLES = tuple(cls.Schema for cls in obstacle_kinds().values())
#: An obstacle: its kind's schema (:mod:`qpbench.robot.obstacles`), picked by ``kind``.
ObstacleTable = _by_kind(*_OBSTACLES)


class ScenarioSpec(Table):
    """One scenario file, validated (``verdict`` filled in by :func:`validate`)."""

    scenario: ScenarioTable
    robot: RobotTable
    key_points: KeyPointsTable
    path: PathTable
    contact: ContactTable
    controller: ControllerTable
    adaptive: AdaptiveTable = Field(default_factory=AdaptiveTable)
    simulation: SimulationTable
    obstacles: list[ObstacleTable]
    rnn: RnnTable = Field(default_factory=RnnTable)
    verdict: VerdictTable = Field(default_factory=VerdictTable)


def _key(loc: tuple) -> str:
    """``("obstacles", 0, "line", "radius")`` -> ``obstacles[0].radius`` (a union's tag dropped)."""
    out = ""
    for i, part in enumerate(loc):
        if isinstance(part, int):
            out += f"[{part}]"
        elif i > 0 and (loc[i - 1] in _UNIONS or isinstance(loc[i - 1], int)) and i + 1 < len(loc):
            continue  # the tag pydantic puts in the location of a union's member
        else:
            out += f".{part}" if out else str(part)
    return out


def _expected(loc: tuple) -> list[str]:
    """The keys the table at ``loc`` (the location of an unknown key) may hold."""
    model = ScenarioSpec
    for part in loc[:-1]:
        if isinstance(part, str):  # an index keeps the model, a union's tag picks its member
            found = _TAGGED.get(part) or model.model_fields[part].annotation
            model = found if isinstance(found, type) else model
    return list(model.model_fields)


#: The tables picked by ``kind``, by the union that takes them, and by kind.
_KINDS = {"path": _PATHS, "robot": _ROBOTS, "obstacles": _OBSTACLES}
_TAGGED = {_tag(m): m for models in _KINDS.values() for m in models}
_UNIONS = ("path", "robot")


#: What a value of the wrong type should have been, by pydantic's error type.
_EXPECTED = {
    "bool_type": "true or false",
    "string_type": "a string",
    "int_type": "an integer",
    "float_type": "a finite number",
    "finite_number": "a finite number",
}


def _error(exc: ValidationError, file) -> ScenarioError:
    """The first of pydantic's errors (an unknown key before the rest) as one line."""
    e = min(exc.errors(), key=lambda e: e["type"] != "extra_forbidden")  # the first of them
    loc, kind = e["loc"], e["type"]
    key = _key(loc)
    if kind == "extra_forbidden":
        where = "table" if len(loc) == 1 else "key"
        msg = f"unknown {where} (expected one of: {', '.join(_expected(loc))})"
    elif kind == "missing":
        msg = "missing table" if len(loc) == 1 else "missing key"
    elif kind in ("union_tag_invalid", "union_tag_not_found", "literal_error"):
        choices = map(_tag, _KINDS.get(str(loc[0]), ()))
        if kind == "literal_error":
            choices = e["ctx"]["expected"].replace("'", "").replace(" or ", ", ").split(", ")
        key = key if kind == "literal_error" else f"{key}.kind"
        value = e["input"].get("kind") if isinstance(e["input"], dict) else e["input"]
        msg = f"expected one of: {', '.join(choices)}, got {value!r}"
    elif kind == "model_type" or kind == "model_attributes_type":
        msg = "expected a table"
    elif kind == "list_type":
        msg = "expected a list of tables"
    else:
        msg = e["msg"].removeprefix("Value error, ")
        if kind in ("greater_than", "greater_than_equal"):
            op, bound = (">", e["ctx"]["gt"]) if kind == "greater_than" else (">=", e["ctx"]["ge"])
            msg = f"must be {op} {bound:g}, got {e['input']}"
        elif kind in _EXPECTED:
            msg = f"expected {_EXPECTED[kind]}, got {e['input']!r}"
    return ScenarioError(msg, path=file, key=key)


def validate(raw: dict, file: str | Path, set_keys=()) -> ScenarioSpec:
    """The parsed TOML tables ``raw`` as a :class:`ScenarioSpec`, every rule checked.

    ``set_keys``: the dotted keys set over the file's on the command line.
    """
    try:
        spec = ScenarioSpec.model_validate(raw)
    except ValidationError as exc:
        raise _error(exc, file) from None
    _check_across_keys(spec, file)
    spec = spec.model_copy(update={"verdict": _verdict_table(spec, file)})
    check_simulation(spec, file, set_keys)
    return spec


def _verdict_table(spec: ScenarioSpec, file) -> VerdictTable:
    """The ``[verdict]`` table, with defaults that fit the task, checked against it (the ranges:
    :class:`~qpbench.sim.verdict.VerdictSettings`)."""
    d_safe, duration = spec.controller.d_safe, spec.simulation.duration
    defaults = VerdictSettings()
    out = asdict(defaults)
    out["settle_time"] = min(defaults.settle_time, duration / 2)
    out["safety_margin"] = min(DEFAULT_SAFETY_MARGIN, d_safe / 2)
    out.update(spec.verdict.model_dump(exclude_none=True))
    margin = out["safety_margin"]
    if not (margin < d_safe or margin == d_safe == 0):
        raise ScenarioError(
            f"must be < controller.d_safe = {d_safe:g} m (0 when d_safe is 0), got {margin:g} m",
            path=file,
            key="verdict.safety_margin",
        )
    return spec.verdict.model_copy(update=out)


def robot_chain(robot) -> ChainModel:
    """The chain of a ``[robot]`` table (:func:`~qpbench.robot.presets.make_chain`), with the
    limits the table gives (a preset's own otherwise)."""
    args = {key: getattr(robot, key) for key in OWN_KEYS.get(robot.kind, ())}
    for key, name in (("q_min", "theta_min"), ("q_max", "theta_max"), ("v_max", "velocity_max")):
        if getattr(robot, name) is not None:
            args[key] = getattr(robot, name)
    return make_chain(robot.kind, **args)


def _chain(robot, file) -> ChainModel:
    """:func:`robot_chain`, its error naming ``file`` (unless it names a file of its own)."""
    try:
        return robot_chain(robot)
    except InputError as exc:
        raise ScenarioError(exc.message, path=exc.path or file, key=exc.key) from None


def _check_across_keys(spec: ScenarioSpec, file) -> None:
    """One value per joint, ``theta_min < theta0 < theta_max``,
    ``velocity_min <= 0 <= velocity_max``; vectors of the robot's dim; obstacle kinds of its
    dim; obstacle names unique."""
    r = spec.robot

    def fail(msg, key):
        raise ScenarioError(msg, path=file, key=key)

    unlimited = r.model_copy(update={"theta_min": None, "theta_max": None, "velocity_max": None})
    n = r.link_lengths.size if r.kind == "planar" else _chain(unlimited, file).n
    for key in ("theta0", "theta_min", "theta_max", "velocity_min", "velocity_max"):
        value = getattr(r, key)
        if value is not None and value.size != n:
            fail(f"expected {n} values (one per joint), got {value.size}", f"robot.{key}")
    chain = _chain(r, file)
    outside = np.flatnonzero((r.theta0 < chain.q_min) | (r.theta0 > chain.q_max))
    if outside.size:
        i = int(outside[0])
        fail(
            f"theta0[{i}] = {r.theta0[i]} rad is outside [{chain.q_min[i]}, {chain.q_max[i]}]",
            "robot.theta0",
        )
    vmin = -chain.v_max if r.velocity_min is None else r.velocity_min
    if not (np.all(vmin <= 0) and np.all(vmin < chain.v_max)):
        fail(
            "need velocity_min <= 0 <= velocity_max and velocity_min < velocity_max [rad/s]",
            "robot.velocity_min",
        )
    dim = chain.dim
    vectors = [("contact.point", spec.contact.point), ("contact.normal", spec.contact.normal)]
    if spec.path.kind == "cosine":
        vectors += [(f"path.{k}", value) for k, value in spec.path if k != "kind"]
    else:
        vectors.append(("path.points", spec.path.points[0]))
    for key, value in vectors:
        if value.size != dim:
            fail(f"expected {dim} numbers (the robot's dim), got {value.size}", key)
    names: list[str] = []
    kinds = [kind for kind, cls in obstacle_kinds().items() if cls.DIM == dim]
    for i, o in enumerate(spec.obstacles):
        if o.kind not in kinds:
            arm = "planar" if dim == 2 else "spatial"
            fail(
                f"a {arm} arm takes the {arm} kinds only: {', '.join(kinds)}",
                f"obstacles[{i}].kind",
            )
        if not o.name or o.name in names:
            fail(
                f"obstacle names must be non-empty and unique, got {o.name!r}",
                f"obstacles[{i}].name",
            )
        names.append(o.name)


def check_simulation(spec: ScenarioSpec, file: str | Path, set_keys=()) -> None:
    """``dt`` and ``duration`` > 0 [s], at least one tick, ``alpha * dt < 1``, and a settle time
    set on the command line (``verdict.settle_time`` in ``set_keys``) < ``duration`` [s]: called
    on every change of ``dt`` or ``duration``, so it is checked against the duration run."""
    s = spec.simulation
    for key in ("dt", "duration"):
        if not getattr(s, key) > 0:
            raise ScenarioError(
                f"must be > 0 [s], got {getattr(s, key)}", path=file, key=f"simulation.{key}"
            )
    if s.duration < s.dt:
        raise ScenarioError(
            f"shorter than one control period dt = {s.dt} s", path=file, key="simulation.duration"
        )
    alpha = spec.controller.alpha
    if alpha * s.dt >= 1.0:
        raise ScenarioError(
            f"alpha * dt = {alpha * s.dt:g} must be < 1 for the escape-velocity bounds "
            "to keep the joints inside their limits",
            path=file,
            key="controller.alpha",
        )
    settle = spec.verdict.settle_time
    if "verdict.settle_time" in set_keys and not settle < s.duration:
        raise ScenarioError(
            f"must be < simulation.duration = {s.duration:g} s, the duration run (tracking "
            f"and force are judged after it), got {settle:g} s",
            path=file,
            key="verdict.settle_time",
        )


#: Order of the tables in a filled-in scenario file (:func:`filled`).
_ORDER = (
    "obstacles scenario robot key_points path contact controller adaptive simulation verdict rnn"
)

#: Tables a file may leave out (all their keys have defaults).
OPTIONAL_TABLES = ("adaptive", "rnn", "verdict")


def filled(spec: ScenarioSpec) -> dict:
    """The scenario as TOML-ready tables, every default filled in (vectors as lists)."""
    plain = spec.model_dump(mode="json", exclude_none=True)  # a preset's own limits: unset
    return {table: plain[table] for table in _ORDER.split()}
