"""``capsule``: a segment swollen by a radius (3-D); the planar ``segment`` is one of radius 0."""

from __future__ import annotations

from typing import Literal

import numpy as np

from ...exceptions import InputError
from . import register
from ._base import NotNegative, Obstacle, SpatialSchema, Vec3
from ._draw import draw_outline, look, project
from ._planar import PASS_TOL
from ._table import CAPSULE, table_rows


class CapsuleSchema(SpatialSchema):
    """Axis ends ``a``, ``b`` [m] at t = 0 and ``radius`` [m] (0: a bar)."""

    kind: Literal["capsule"]
    a: Vec3
    b: Vec3
    radius: NotNegative = 0.0


@register
class CapsuleObstacle(Obstacle):
    """The points within ``radius`` [m] of the segment ``a -> b`` [m]."""

    KIND = "capsule"
    KERNEL_KIND = CAPSULE
    Schema = CapsuleSchema

    def __init__(self, name: str, a, b, radius: float = 0.0, velocity=(0.0, 0.0, 0.0)):
        fields = dict(name=name, a=a, b=b, velocity=velocity)
        if "radius" in self.Schema.model_fields:  # a planar segment has none
            fields["radius"] = radius
        super().__init__(**fields)
        self.a = np.array(self.fields.a, dtype=float)
        self.b = np.array(self.fields.b, dtype=float)
        self.radius = float(fields.get("radius", 0.0))
        if np.allclose(self.a, self.b):
            raise InputError("segment end points must differ", key=self._key("b"))

    def primitives(self) -> np.ndarray:
        return table_rows(
            self.KERNEL_KIND, p0=self.a, p1=self.b, radius=self.radius, v=self.velocity
        )

    def passed_through(self, P0a, P1a, P0b, P1b, t):
        """The axis and the segment went through each other: the side of one's line against
        the other's, ``(e x f) . (a - P0)``, changes sign while the lines' closest points lie
        within both (to :data:`PASS_TOL`), at both ends of the sweep."""
        a = project(self.a, "xyz")[None, :] + np.reshape(t, (-1, 1)) * self.velocity3
        f = project(self.b - self.a, "xyz")
        P0a, P1a, P0b, P1b = (project(E, "xyz") for E in (P0a, P1a, P0b, P1b))

        def side_and_within(P0, P1):
            e = P1 - P0
            r = a - P0
            side = np.einsum("si,si->s", np.cross(e, f), r)
            ee, ff, ef = np.einsum("si,si->s", e, e), float(f @ f), e @ f
            re, rf = np.einsum("si,si->s", r, e), r @ f
            den = ee * ff - ef**2
            safe = np.where(den > 0, den, 1.0)
            s = (re * ff - rf * ef) / safe
            w = (ef * re - ee * rf) / safe
            within = (den > 0) & (s >= -PASS_TOL) & (s <= 1 + PASS_TOL)
            return side, within & (w >= -PASS_TOL) & (w <= 1 + PASS_TOL)

        ha, wa = side_and_within(P0a, P1a)
        hb, wb = side_and_within(P0b, P1b)
        return (ha * hb <= 0.0) & ((ha != 0.0) | (hb != 0.0)) & wa & wb

    def draw(self, ax, t=0.0, plane=("x", "y"), limits=None, faint=False, color=None):
        """Its shadow on the view plane (a bar of radius 0: a thick line)."""
        ends = project(project([self.a, self.b], "xyz") + t * self.velocity3, plane)
        style = look(self.name, faint, color)
        if self.radius > 0.0:
            draw_outline(ax, ends, self.radius, **style)
        else:
            ax.plot(ends[:, 0], ends[:, 1], lw=3, solid_capstyle="round", **style)

    def view_points(self, plane=("x", "y")):
        ends = project(np.array([self.a, self.b]), plane)
        ring = self.radius * np.array([[1, 0], [-1, 0], [0, 1], [0, -1]])
        return (ends[:, None, :] + ring[None]).reshape(-1, 2)
