"""The shipped scenario files (``qpbench/data/scenarios/*.toml``), by name.

A new shipped scenario is one file there; one with ``[scenario] in_paper = true`` is one of
the paper's (:func:`paper_scenarios`), whose per-tick QPs ``qpbench run`` benchmarks too.
"""

from __future__ import annotations

import re
import tomllib
from importlib import resources
from pathlib import Path
from typing import TYPE_CHECKING

from ..exceptions import ScenarioError

if TYPE_CHECKING:
    from importlib.resources.abc import Traversable


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
