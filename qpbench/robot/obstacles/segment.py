"""``segment``: a thin bar of the plane (a ``capsule`` of radius 0 in z = 0)."""

from __future__ import annotations

from typing import Literal

import numpy as np

from . import register
from ._base import PlanarObstacle, PlanarSchema, Vec2
from ._planar import passes_through, swept_point_bound
from ._table import SEGMENT
from .capsule import CapsuleObstacle


class SegmentSchema(PlanarSchema):
    """Ends ``a``, ``b`` [m] at t = 0."""

    kind: Literal["segment"]
    a: Vec2
    b: Vec2


@register
class SegmentObstacle(PlanarObstacle, CapsuleObstacle):
    """A segment from ``a`` to ``b`` (a thin bar). Crossing a segment in the plane, its distance
    is minus the least distance of one segment's end to the other (the shortest way out along
    the crossing; 0 when an end touches), and ``u`` points the way the link must move to come
    free."""

    KIND = "segment"
    KERNEL_KIND = SEGMENT
    Schema = SegmentSchema

    def __init__(self, name: str, a, b, velocity=(0.0, 0.0)):
        super().__init__(name, a, b, velocity=velocity)

    def _ends(self, t, s: int):
        a = self._at(self.a, t, s)
        return a, a + (self.b - self.a)

    def _swept_in_plane(self, t, P0a, P1a, P0b, P1b):
        """The closest pair of two segments has an end of one on the other: the link's ends run
        along the chords ``P0a -> P0b`` and ``P1a -> P1b``, the bar's ends are points swept over
        (a chord's signed distance to the bar is <= 0 where an end crosses it). Positive, no
        crossing begins in the sweep (one begins with an end on the other), nor is there one at
        its ends (their signed distances are in the bound)."""
        a, b = self._ends(t, len(P0a))
        segments = ((P0a, P0b), (P1a, P1b), (P0a, P1a), (P0b, P1b))  # the chords, the link
        return np.minimum.reduce(
            [
                swept_point_bound(a, P0a, P1a, P0b, P1b),
                swept_point_bound(b, P0a, P1a, P0b, P1b),
                *(self.closest_on_segments(P, Q, t)[2][:, 0] for P, Q in segments),
            ]
        )

    def _passed_in_plane(self, t, P0a, P1a, P0b, P1b):
        """An end of the bar through the link, or an end of the link through the bar."""
        a, b = self._ends(t, len(P0a))
        return (
            passes_through(a, a, P0a, P1a, P0b, P1b)
            | passes_through(b, b, P0a, P1a, P0b, P1b)
            | passes_through(P0a, P0b, a, b, a, b)
            | passes_through(P1a, P1b, a, b, a, b)
        )
