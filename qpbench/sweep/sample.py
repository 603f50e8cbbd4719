"""Instances of a sweep: the base scenario with every swept key drawn, as a full scenario file.

Saved as ``DIR/instances/<name>.toml``, so ``qpbench simulate --scenario`` re-runs one alone. An
instance the loader refuses keeps its one-line reason (:attr:`Instance.invalid`), as does one
starting with a key point inside ``d_safe`` (unless ``[sweep] safe_start = false``): every backend
would be ``unsafe`` at ``t = 0``, which says nothing about the backends.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import TYPE_CHECKING

from ..exceptions import ScenarioError
from .spec import SweepSpec
from .toml_text import dumps, value_text

if TYPE_CHECKING:
    from ..sim.scenario import Scenario


@dataclass(frozen=True)
class Instance:
    """One sampled scenario: ``values`` swept key -> drawn value, ``text`` its scenario file,
    ``invalid`` why the loader (or ``safe_start``) refused it, else ``None``."""

    index: int
    name: str
    values: dict
    text: str
    invalid: str | None = None


def instance_name(index: int, samples: int) -> str:
    """``i00003``: zero-padded to at least 5 digits (to the widest index of ``samples``)."""
    return f"i{index:0{max(5, len(str(samples - 1)))}d}"


def instance_text(spec: SweepSpec, name: str, index: int, values: dict) -> str:
    """The scenario file of instance ``name``: a header saying where it comes from, then every table."""
    from ..sim.scenario import apply_overrides

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
    """Smallest distance [m] of a key point to an obstacle at t = 0, and which key point and obstacle.

    ``(inf, "", "")`` without obstacles. Distances from the link's surface
    (the key points' ``link_radius`` subtracted), as the controller measures them.
    """
    import numpy as np

    arm, kp = scenario.make_arm(), scenario.make_key_points()
    points = arm.points(scenario.theta0, kp.links, kp.fracs)
    best = (np.inf, "", "")
    for obstacle in scenario.make_obstacles():
        dist = obstacle.closest(points, 0.0)[1].min(axis=1) - kp.radius
        i = int(np.argmin(dist))
        if dist[i] < best[0]:
            best = (float(dist[i]), kp.names[i], obstacle.name)
    return best


def _why_invalid(text: str, name: str, safe_start: bool) -> str | None:
    from ..sim.scenario import parse_scenario

    try:
        scenario = parse_scenario(text, path=f"{name}.toml")
    except ScenarioError as exc:
        return str(exc)
    if safe_start:
        d, point, obstacle = start_clearance(scenario)
        d_safe = scenario.data["controller"]["d_safe"]
        if d < d_safe:
            return (
                f"{name}.toml: starts with key point {point} {d * 1e3:.2f} mm from obstacle {obstacle}, "
                f"inside d_safe = {d_safe * 1e3:g} mm (every backend would be unsafe at t = 0)"
            )
    return None


def sample_instances(spec: SweepSpec) -> list[Instance]:
    """Every instance of ``spec`` (deterministic in ``spec.seed``), each checked by the scenario loader
    and, with ``[sweep] safe_start`` (default), for a start outside ``d_safe`` of every obstacle."""
    out = []
    for index in range(spec.samples):
        name = instance_name(index, spec.samples)
        values = {d.key: d.draw(spec.rng(index, d.key)) for d in spec.parameters}
        text = instance_text(spec, name, index, values)
        out.append(Instance(index, name, values, text, _why_invalid(text, name, spec.safe_start)))
    return out
