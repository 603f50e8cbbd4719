"""``line``: a wall, a half-plane of the plane (a ``plane`` whose normal lies in the xy-plane)."""

from __future__ import annotations

from typing import Literal

from . import register
from ._base import PlanarSchema, Vec2
from ._table import LINE
from .plane import PlaneObstacle


class LineSchema(PlanarSchema):
    """``point`` [m] on the line at t = 0, ``normal`` towards the free side."""

    kind: Literal["line"]
    point: Vec2
    normal: Vec2


@register
class LineObstacle(PlaneObstacle):
    """An infinite line (a wall) through ``point`` [m] at t = 0; ``normal`` points to the free
    side (normalised here), the half-plane ``normal . (x - point) < 0`` is forbidden."""

    KIND = "line"
    KERNEL_KIND = LINE
    Schema = LineSchema
    DIM = 2
