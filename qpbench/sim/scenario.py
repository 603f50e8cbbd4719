"""Scenarios: one TOML file holds every parameter of a simulation (paper section 4).

:func:`load_scenario` reads a shipped scenario (``qpbench/data/scenarios/<name>.toml``; one with
``[scenario] in_paper = true`` is one of the paper's, whose per-tick QPs ``qpbench run``
benchmarks too) by name or a file by path and checks it against the schema
(:mod:`.scenario_schema`). Values can be set over a file's without copying it
(``overrides={"rnn.eps": 1e-3}``, ``qpbench simulate --set rnn.eps=0.001``;
:func:`apply_overrides`), checked like the file's own.
"""

from __future__ import annotations

import copy
import logging
import re
import tomllib
from dataclasses import dataclass, field, replace
from importlib import resources
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np

from ..exceptions import InputError, ScenarioError, did_you_mean
from ..robot.body import contact_obstacles
from ..robot.environment import ContactSurface
from ..robot.kinematics import Arm, KeyPoints, closest_key_points, default_key_points
from ..robot.obstacles import Obstacle
from ..robot.obstacles import make as make_obstacle
from .scenario_schema import (
    OPTIONAL_TABLES,
    ScenarioSpec,
    check_simulation,
    robot_chain,
    validate,
)
from .verdict import VerdictSettings

if TYPE_CHECKING:
    from importlib.resources.abc import Traversable

    from ..control.adaptive import AdaptiveImpedance
    from ..control.controller import Controller
    from ..control.terms import CosinePath, PolylinePath

log = logging.getLogger(__name__)


@dataclass
class Scenario:
    """Everything a simulation needs, read from one TOML file.

    ``path`` is None when parsed from text; ``source`` is the file's text (stored in dumped
    problem sets' manifests); ``spec`` the validated file (:class:`ScenarioSpec`: tables as
    attributes, vectors as arrays); ``rnn`` the ``rnn`` backends' settings; ``overrides`` the
    values set over the file's, by dotted key.
    """

    name: str
    path: Path | None
    source: str
    spec: ScenarioSpec
    rnn: dict = field(default_factory=dict)
    overrides: dict = field(default_factory=dict)

    @property
    def description(self) -> str:
        return self.spec.scenario.description

    @property
    def in_paper(self) -> bool:
        """One of the paper's scenarios (``[scenario] in_paper``)."""
        return self.spec.scenario.in_paper

    @property
    def dt(self) -> float:
        """Control period [s]."""
        return self.spec.simulation.dt

    @property
    def duration(self) -> float:
        """Simulated time [s]."""
        return self.spec.simulation.duration

    @property
    def theta0(self) -> np.ndarray:
        return self.spec.robot.theta0.copy()

    @property
    def verdict(self) -> VerdictSettings:
        """Thresholds of a run's verdict (``[verdict]``; :mod:`qpbench.sim.verdict`)."""
        return VerdictSettings(**self.spec.verdict.model_dump())

    @property
    def verdict_overrides(self) -> dict:
        """The ``[verdict]`` thresholds set over the file's, by key (``settle_time``)."""
        prefix = "verdict."
        return {k[len(prefix) :]: v for k, v in self.overrides.items() if k.startswith(prefix)}

    @property
    def normal(self) -> np.ndarray:
        """The contact surface's unit normal."""
        normal = self.spec.contact.normal
        return normal / np.linalg.norm(normal)

    def with_overrides(self, dt: float | None = None, duration: float | None = None) -> Scenario:
        """A copy with another control period or duration (validated like the file's values,
        with the values set over the file's)."""
        times = {k: float(v) for k, v in (("dt", dt), ("duration", duration)) if v is not None}
        spec = self.spec.model_copy(
            update={"simulation": self.spec.simulation.model_copy(update=times)}
        )
        check_simulation(spec, self.path or "<override>", tuple(self.overrides))
        return replace(self, spec=spec)

    def make_arm(self) -> Arm:
        """The robot (``[robot]``: its kind's chain, with the limits the file gives)."""
        return Arm(robot_chain(self.spec.robot))

    def make_key_points(self) -> KeyPoints:
        kp, arm = self.spec.key_points, self.make_arm()
        if kp.kind == "closest":
            return closest_key_points(arm.n, kp.link_radius)
        return default_key_points(
            arm.n, kp.points_per_link, kp.include_joints, kp.link_radius, lengths=arm.lengths
        )

    def make_path(self) -> CosinePath | PolylinePath:
        from ..control.terms import CosinePath, PolylinePath

        p = self.spec.path
        if p.kind == "cosine":
            return CosinePath(p.centre, p.amplitude, p.omega, p.phase)
        return PolylinePath(p.times, p.points)

    def make_surface(self) -> ContactSurface:
        c = self.spec.contact
        return ContactSurface(
            c.point, c.normal, c.stiffness, c.damping, c.force_noise_std, c.noise_seed
        )

    def make_obstacles(self) -> list[Obstacle]:
        return [make_obstacle(o.model_dump()) for o in self.spec.obstacles]

    def make_controller(self) -> Controller:
        """The scenario's :class:`~qpbench.control.controller.Controller`."""
        from ..control.controller import Controller
        from ..control.terms import EscapeVelocityLimits, ImpedanceTask

        r, c, arm = self.spec.robot, self.spec.controller, self.make_arm()
        task = ImpedanceTask(self.make_path(), self.normal, c.desired_force)
        chain = arm.model
        v_min = -chain.v_max if r.velocity_min is None else r.velocity_min
        limits = EscapeVelocityLimits(chain.q_min, chain.q_max, v_min, chain.v_max, c.alpha)
        obstacles = self.make_obstacles()
        gains = {key: getattr(c, key) for key in ("k", "d_safe", "rho", "kp", "kd")}
        exempt = contact_obstacles(obstacles, self.make_surface())
        return Controller(
            arm, self.make_key_points(), task, limits, obstacles, **gains, exempt=exempt
        )

    def make_adaptive(self) -> AdaptiveImpedance | None:
        """The adaptive estimator (section 4.4), or None when ``[adaptive] enabled = false``."""
        from ..control.adaptive import AdaptiveImpedance

        a = self.spec.adaptive
        if not a.enabled:
            return None
        c = self.spec.controller
        return AdaptiveImpedance(
            c.kp, c.kd, a.gain, self.normal, c.desired_force, a.kp_min, a.kd_min
        )


def parse_scenario(
    text: str,
    path: str | Path | None = None,
    overrides: dict | None = None,
    dt: float | None = None,
    duration: float | None = None,
) -> Scenario:
    """Parse and validate a scenario from TOML text (``path`` only names it in errors);
    ``overrides`` (:func:`apply_overrides`), then ``dt`` and ``duration`` [s] (a command's
    ``--dt``, ``--duration``), are set before the validation, which checks the scenario as it
    runs (a settle time set in ``overrides`` against the duration run)."""
    file = path if path is not None else "<scenario>"
    try:
        raw = tomllib.loads(text)
    except tomllib.TOMLDecodeError as exc:
        raise ScenarioError(f"not valid TOML: {exc}", path=file) from None
    times = {"simulation.dt": dt, "simulation.duration": duration}
    times = {key: value for key, value in times.items() if value is not None}
    if overrides or times:
        raw = apply_overrides(raw, {**(overrides or {}), **times}, file)
    spec = validate(raw, file, tuple(overrides or ()))
    scenario = Scenario(
        name=spec.scenario.name,
        path=None if path is None else Path(path),
        source=text,
        spec=spec,
        rnn=spec.rnn.model_dump(),
        overrides=dict(overrides or {}),
    )
    # build every object once so constructor checks surface here, naming the file
    try:
        scenario.verdict  # noqa: B018
        scenario.make_surface()
        scenario.make_controller()
    except InputError as exc:
        if isinstance(exc, ScenarioError):
            raise
        raise ScenarioError(exc.message, path=file, key=exc.key) from None
    if changed := scenario.verdict_overrides:
        log.warning(
            "%s: verdict thresholds changed on the command line: %s (the verdict is not judged "
            "on the scenario's own thresholds)",
            file,
            ", ".join(f"verdict.{k}={v!r}" for k, v in changed.items()),
        )
    return scenario


#: ``table.key`` or ``table[index].key``: a key of ``--set`` and of a sweep's parameters.
OVERRIDE_KEY = re.compile(r"([A-Za-z_][A-Za-z0-9_]*)(?:\[(\d+)\])?\.([A-Za-z_][A-Za-z0-9_]*)")


def apply_overrides(raw: dict, overrides: dict, file: str | Path = "<scenario>") -> dict:
    """A copy of the parsed TOML tables ``raw`` with ``overrides`` set over them.

    Keys are ``table.key`` (``rnn.eps``, ``simulation.duration``) or ``obstacles[i].key``.
    A key must name a table the file has (or may leave out) and, in ``[rnn]``, a setting of
    the ``rnn`` backends; the values are checked by :func:`parse_scenario`'s validation.
    """
    raw = copy.deepcopy(raw)
    for key, value in overrides.items():
        match = OVERRIDE_KEY.fullmatch(str(key))
        if match is None:
            raise ScenarioError("expected TABLE.KEY or obstacles[i].KEY", path=file, key=key)
        table, index, name = match.groups()
        if index is not None:
            if table != "obstacles":
                raise ScenarioError(
                    "only obstacles take an index (obstacles[i].KEY)", path=file, key=key
                )
            obstacles = raw.get("obstacles")
            count = len(obstacles) if isinstance(obstacles, list) else 0
            if int(index) >= count:
                raise ScenarioError(
                    f"no such obstacle (the file has {count})", path=file, key=f"obstacles[{index}]"
                )
            target = obstacles[int(index)]
        else:
            if table in OPTIONAL_TABLES and table not in raw:
                raw[table] = {}  # a table the file may leave out: defaults, then this key
            target = raw.get(table)
            if table == "obstacles" or not isinstance(target, dict):
                tables = ", ".join(sorted(t for t in raw if isinstance(raw[t], dict)))
                raise ScenarioError(
                    f"no such table in the file (tables: {tables})", path=file, key=key
                )
            if table == "rnn" and name not in target:
                from ..backends.rnn import SETTING_NAMES

                if name not in SETTING_NAMES:
                    raise ScenarioError(
                        f"unknown setting of the rnn backends; {did_you_mean(name, SETTING_NAMES)}"
                        f"expected one of: {', '.join(SETTING_NAMES)}",
                        path=file,
                        key=key,
                    )
        target[name] = value
    return raw


def load_scenario(
    name_or_path: str | Path,
    overrides: dict | None = None,
    dt: float | None = None,
    duration: float | None = None,
) -> Scenario:
    """Load a scenario by shipped name (``wall``) or by path, with ``overrides``
    (:func:`apply_overrides`) and another ``dt`` or ``duration`` [s] (:func:`parse_scenario`);
    a :class:`ScenarioError` names the file and the key."""
    path = scenario_path(name_or_path)
    try:
        text = path.read_text(encoding="utf-8")
    except (OSError, UnicodeDecodeError) as exc:
        raise ScenarioError(f"cannot read: {exc}", path=path) from None
    return parse_scenario(text, path, overrides, dt, duration)


def shipped_dir() -> Traversable:
    """The package folder of the shipped scenario files."""
    return resources.files("qpbench") / "data" / "scenarios"


def _scenario_table(name: str) -> dict:
    """The ``[scenario]`` table of shipped scenario ``name``, as written."""
    return tomllib.loads((shipped_dir() / f"{name}.toml").read_text(encoding="utf-8"))["scenario"]


def _section_key(section) -> tuple[int, ...]:
    """``"4.10"`` -> ``(4, 10)``: paper sections in the paper's order."""
    return tuple(int(n) for n in re.findall(r"\d+", str(section)))


def paper_scenarios() -> list[str]:
    """The shipped scenarios of the paper (``in_paper = true``), in the order of their sections."""
    tables = {name: _scenario_table(name) for name in _shipped_names()}
    paper = [name for name, t in tables.items() if t.get("in_paper") is True]
    return sorted(
        paper, key=lambda name: (_section_key(tables[name].get("paper_section", "")), name)
    )


def _shipped_names() -> list[str]:
    return sorted(p.name[:-5] for p in shipped_dir().iterdir() if p.name.endswith(".toml"))


def scenario_names() -> list[str]:
    """Names of the shipped scenarios: the paper's in its order, then the others sorted."""
    paper = paper_scenarios()
    return paper + [name for name in _shipped_names() if name not in paper]


def run_scenarios() -> list[str]:
    """The shipped scenarios ``qpbench run`` runs by default (``[scenario] in_run``, default
    true), in the order of :func:`scenario_names`."""
    return [name for name in scenario_names() if _scenario_table(name).get("in_run", True)]


def scenario_path(name_or_path: str | Path) -> Path:
    """The file a scenario name or path refers to (a name without a suffix or slash is
    looked up among the shipped scenarios first)."""
    text = str(name_or_path)
    if "/" not in text and not text.endswith(".toml"):
        candidate = shipped_dir() / f"{text}.toml"
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
