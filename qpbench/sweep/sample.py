"""Instances of a sweep: the base scenario with every swept key drawn, as a full scenario file.

:func:`sample_instances` draws instance ``i``'s values from the streams of
:meth:`SweepSpec.rng` and writes them over the base scenario's tables; the
result is the text of a complete scenario file (:func:`instance_text`),
saved as ``DIR/instances/<name>.toml`` so that ``qpbench simulate --scenario
DIR/instances/<name>.toml --backend B`` re-runs that one instance alone. An
instance the scenario loader refuses (a theta0 drawn outside the joint
limits, ``alpha * dt >= 1``, ...) keeps the loader's one-line reason in
:attr:`Instance.invalid`: the sweep records it and goes on.
"""

from __future__ import annotations

import copy
from dataclasses import dataclass

from ..exceptions import ScenarioError
from .spec import SweepSpec
from .toml_text import dumps, value_text

__all__ = ["Instance", "instance_name", "sample_instances"]


@dataclass(frozen=True)
class Instance:
    """One sampled scenario of a sweep.

    Attributes:
        index: 0-based sample index.
        name: ``i00003`` (file stem, the rows' ``instance``).
        values: Swept key -> drawn value (JSON-able), in the sweep file's order.
        text: The full scenario file (TOML).
        invalid: Why the scenario loader refused it, or ``None``.
    """

    index: int
    name: str
    values: dict
    text: str
    invalid: str | None = None


def instance_name(index: int, samples: int) -> str:
    """``i00003``: zero-padded to at least 5 digits (to the widest index of ``samples``)."""
    return f"i{index:0{max(5, len(str(samples - 1)))}d}"


def _set(raw: dict, key: str, value) -> None:
    from .spec import _KEY

    table, index, name = _KEY.fullmatch(key).groups()
    target = raw["obstacles"][int(index)] if index is not None else raw[table]
    target[name] = value


def instance_text(spec: SweepSpec, name: str, index: int, values: dict) -> str:
    """The scenario file of instance ``name``: a header saying where it comes from, then every table."""
    raw = copy.deepcopy(spec.base_raw)
    for key, value in values.items():
        _set(raw, key, value)
    raw["scenario"] = dict(raw.get("scenario", {}))
    raw["scenario"]["name"] = f"{spec.name}-{name}"
    base_description = raw["scenario"].get("description", "")
    raw["scenario"]["description"] = f"Instance {index} of sweep {spec.name!r}, around: {base_description}"
    header = [
        f"Instance {name} (sample {index}) of sweep {spec.name!r} ({spec.path.name}, sha256 {spec.sha256[:16]}, "
        f"seed {spec.seed}).",
        f"Base scenario: {spec.base} ({spec.base_path.name}); units as in it. Drawn for this instance:",
    ]
    header += [f"  {key} = {value_text(value)}" for key, value in values.items()]
    if spec.duration is not None:
        header.append(f"  simulation.duration = {value_text(float(spec.duration))} (the sweep's duration)")
    header.append(f"Re-run alone: qpbench simulate --scenario {name}.toml --backend BACKEND (from its folder)")
    return dumps(raw, header="\n".join(header))


def sample_instances(spec: SweepSpec) -> list[Instance]:
    """Every instance of ``spec`` (deterministic in ``spec.seed``), each checked by the scenario loader."""
    from ..sim.scenario import parse_scenario

    out = []
    for index in range(spec.samples):
        name = instance_name(index, spec.samples)
        values = {d.key: d.draw(spec.rng(index, d.key)) for d in spec.parameters}
        text = instance_text(spec, name, index, values)
        invalid = None
        try:
            parse_scenario(text, path=f"{name}.toml")
        except ScenarioError as exc:
            invalid = str(exc)
        out.append(Instance(index, name, values, text, invalid))
    return out
