"""Obstacles: one module per kind, registered here as backends are (paper sections 2.2, 4).

Each kind module holds its scenario schema (a pydantic model), its class (a subclass of
:class:`Obstacle`: its rows of the obstacle table, its drawing, its between-ticks tests for the
body rule) and registers it with :func:`register`; the kinds share the compiled 3-D geometry
(:func:`compiled_segment_distance`: the signed distance of a table row to a segment with its
gradient direction). Planar kinds (``line``, ``segment``, ``disk``, ``points``) take 2-D inputs
and lie in ``z = 0``; spatial kinds (``plane``, ``sphere``, ``capsule``, ``box``) take 3-D ones.
Modules starting with ``_`` are the package's helpers.
"""

from __future__ import annotations

import functools
import importlib
import pkgutil

from ._base import Obstacle
from ._draw import OBSTACLE_COLOR, draw_trace, outline, project, trace
from ._geometry import compiled_segment_distance
from ._table import (
    BOX,
    DISK,
    HX,
    HY,
    HZ,
    KIND,
    LINE,
    OBSTACLE_COLUMNS,
    POINT,
    QW,
    QZ,
    SEGMENT,
    VX,
    VY,
    VZ,
)

#: Re-exported for the controller, the drawings and the tests of the table's layout.
__all__ = [
    "BOX",
    "DISK",
    "HX",
    "HY",
    "HZ",
    "KIND",
    "LINE",
    "OBSTACLE_COLUMNS",
    "POINT",
    "QW",
    "QZ",
    "SEGMENT",
    "VX",
    "VY",
    "VZ",
    "OBSTACLE_COLOR",
    "Obstacle",
    "compiled_segment_distance",
    "draw_trace",
    "outline",
    "project",
    "trace",
]
_REGISTRY: dict[str, type[Obstacle]] = {}


def register(cls: type[Obstacle]) -> type[Obstacle]:
    """Class decorator: add the obstacle kind ``cls`` under ``cls.KIND``."""
    _REGISTRY[cls.KIND] = cls
    return cls


@functools.cache
def kinds() -> dict[str, type[Obstacle]]:
    """Kind name (as written in scenario files) -> class, every module of the package loaded."""
    for m in sorted(pkgutil.iter_modules(__path__), key=lambda m: m.name):
        if not m.name.startswith("_"):
            importlib.import_module(f"{__name__}.{m.name}")
    return dict(sorted(_REGISTRY.items()))


def make(entry: dict) -> Obstacle:
    """The obstacle of a validated scenario entry (``kind`` and its schema's fields)."""
    cls = kinds()[entry["kind"]]
    return cls(**{k: v for k, v in entry.items() if k != "kind"})
