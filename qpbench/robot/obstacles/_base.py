"""What every obstacle kind shares: the schema's field types and its one-line errors, and the
class :class:`Obstacle` (closest points by the compiled geometry, a generic between-ticks
bound)."""

from __future__ import annotations

import math
from typing import Annotated, ClassVar

import numpy as np
from pydantic import BaseModel, BeforeValidator, ConfigDict, Field, ValidationError

from ...exceptions import InputError
from ._geometry import compiled_closest


def _number(value):
    number = isinstance(value, (int, float, np.floating, np.integer)) and not isinstance(
        value, bool
    )
    if not (number and math.isfinite(value)):
        raise ValueError(f"expected a finite number, got {value!r}")
    return float(value)


def vector(n: int | None):
    """A validator of ``n`` finite numbers (``None``: a list of ``[x, y]`` points)."""
    what = f"a list of {n} finite numbers" if n else "a list of [x, y] points"

    def check(value):
        flat = np.ravel(np.asarray(value, dtype=object)) if isinstance(value, (list, tuple)) else ()
        try:
            arr = np.asarray(value, dtype=float)
        except (TypeError, ValueError):
            arr = np.empty(0)
        shape_ok = arr.shape == (n,) if n else (arr.ndim == 2 and arr.shape[1] == 2 and len(arr))
        if (
            not isinstance(value, (list, tuple, np.ndarray))
            or not shape_ok
            or any(isinstance(v, bool) for v in flat)
            or not np.all(np.isfinite(arr))
        ):
            raise ValueError(f"expected {what}, got {value!r}")
        return arr.tolist()

    return BeforeValidator(check)


#: Field types of the schemas: a finite number, vectors of 2 or 3, a list of planar points.
Num = Annotated[float, BeforeValidator(_number)]
Vec2 = Annotated[tuple[float, float], vector(2)]
Vec3 = Annotated[tuple[float, float, float], vector(3)]
Quat = Annotated[tuple[float, float, float, float], vector(4)]
Points2 = Annotated[list[tuple[float, float]], vector(None)]
Positive = Annotated[Num, Field(gt=0)]
NotNegative = Annotated[Num, Field(ge=0)]


class Schema(BaseModel):
    """A scenario's ``[[obstacles]]`` entry: ``kind``, a unique ``name`` and the ``velocity``
    [m/s] (2-D for a planar kind, 3-D for a spatial one) the shape translates with."""

    model_config = ConfigDict(extra="forbid", frozen=True)
    kind: str
    name: Annotated[str, Field(min_length=1)]


class PlanarSchema(Schema):
    """A planar kind's entry: 2-D points and ``velocity`` [m/s]."""

    velocity: Vec2 = (0.0, 0.0)


class SpatialSchema(Schema):
    """A spatial kind's entry: 3-D points and ``velocity`` [m/s]."""

    velocity: Vec3 = (0.0, 0.0, 0.0)


def unit(vector, key: str) -> np.ndarray:
    """``vector`` normalised, else an :class:`InputError` naming ``key``."""
    arr = np.asarray(vector, dtype=float)
    norm = float(np.linalg.norm(arr))
    if norm < 1e-12:
        raise InputError(f"a direction must not be zero, got {list(vector)!r}", key=key)
    return arr / norm


def validated(schema: type[Schema], data: dict, prefix: str) -> Schema:
    """``data`` validated by pydantic model ``schema``; its first error raised as one line
    :class:`InputError` naming ``prefix.<key>``."""
    try:
        return schema.model_validate(data)
    except ValidationError as exc:
        err = exc.errors()[0]
        loc = [p for p in err["loc"] if isinstance(p, str)]
        if err["type"] == "missing":
            message = "missing key"
        elif err["type"] == "extra_forbidden":
            message = f"unknown key (expected one of: {', '.join(schema.model_fields)})"
        elif err["type"] == "value_error":
            message = err["msg"].removeprefix("Value error, ")
        else:
            message = f"{err['msg'][0].lower()}{err['msg'][1:]}, got {err['input']!r}"
        raise InputError(message, key=".".join([prefix, *loc[:1]])) from None


class Obstacle:
    """Base class of the obstacle kinds: ``name`` (in log columns, ``d_A2_wall``) and constant
    ``velocity`` [m/s] (:attr:`DIM` entries; :attr:`velocity3` in 3-D); its rows of the table
    (:meth:`primitives`), one per obstacle point ``B_j``."""

    KIND: ClassVar[str] = ""
    #: Code of the shape in the table (:mod:`._table`).
    KERNEL_KIND: ClassVar[int]
    #: The kind's scenario schema.
    Schema: ClassVar[type[Schema]]
    #: Dimension of the kind's inputs: 2 (planar, in z = 0) or 3.
    DIM: ClassVar[int] = 3

    def __init__(self, **fields):
        """The fields of :attr:`Schema` (checked by it; errors name ``obstacles.<name>.<key>``);
        ``velocity`` None: at rest, in the kind's dimension."""
        if fields.get("velocity", 0) is None:
            del fields["velocity"]
        name = str(fields.get("name", ""))
        self.fields = validated(self.Schema, {"kind": self.KIND, **fields}, f"obstacles.{name}")
        self.name = name
        self.velocity = np.array(self.fields.velocity, dtype=float)
        self.velocity3 = np.zeros(3)
        self.velocity3[: self.DIM] = self.velocity
        self._rows = None

    @property
    def n_points(self) -> int:
        """Obstacle points (rows of the table) per key point."""
        return len(self.primitives())

    def primitives(self) -> np.ndarray:
        """Rows of the obstacle table (m, :data:`~._table.OBSTACLE_COLUMNS`) at t = 0."""
        raise NotImplementedError

    def _key(self, field: str) -> str:
        return f"obstacles.{self.name}.{field}"

    def closest(self, A: np.ndarray, t: float) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Obstacle points ``B`` (a, m, d) [m] nearest to key points ``A`` (a, d) at time ``t``
        [s], ``dist`` (a, m) [m] and ``u`` (a, m, d): :meth:`closest_on_segments` of the points
        as segments of length 0."""
        A = np.asarray(A, dtype=float)
        _, B, dist, u = self.closest_on_segments(A, A, t)
        return B, dist, u

    def closest_on_segments(self, P0, P1, t):
        """Exact closest points of segments ``P0 -> P1`` (s, d) [m] (d = 2: in z = 0, or 3) to
        the obstacle at ``t`` [s] (a number or one per segment): per segment and obstacle
        point, ``A`` (s, m, d) on the segment, ``B`` (s, m, d) on the obstacle [m], the signed
        ``dist`` (s, m) [m] (``< 0``: inside, by that depth) and ``u`` (s, m, d), the way moving
        ``A`` increases ``dist`` (the compiled geometry, per row)."""
        P0 = np.ascontiguousarray(P0, dtype=float)
        P1 = np.ascontiguousarray(P1, dtype=float)
        s, dim = P0.shape
        if self._rows is None:
            self._rows = np.ascontiguousarray(self.primitives())
        m = len(self._rows)
        t = np.ascontiguousarray(np.broadcast_to(np.asarray(t, dtype=float), (s,)))
        A, u, dist = np.empty((s, m, dim)), np.empty((s, m, dim)), np.empty((s, m))
        compiled_closest()(self._rows, P0, P1, t, A, dist, u)
        return A, A - dist[..., None] * u, dist, u

    def swept_distance_bound(self, P0a, P1a, P0b, P1b, t) -> np.ndarray:
        """A lower bound [m] of the signed distance (as :meth:`closest_on_segments`, smallest
        over the obstacle's points) to every segment ``P0(l) -> P1(l)``, ``P(l) = (1 - l) Pa +
        l Pb`` for ``l`` in [0, 1] (ends (s, d) [m]), the obstacle held as at ``t`` [s]: the
        sweep of a link in the obstacle's frame; a value ``<= 0`` says it may reach it. Here the
        Lipschitz bound of a convex shape's signed distance (docs/body.md)."""
        d_a = self.closest_on_segments(P0a, P1a, t)[2].min(axis=1)
        d_b = self.closest_on_segments(P0b, P1b, t)[2].min(axis=1)
        M = np.maximum(np.linalg.norm(P0b - P0a, axis=1), np.linalg.norm(P1b - P1a, axis=1))
        with np.errstate(divide="ignore", invalid="ignore"):
            l_meet = np.clip(np.where(M > 0, (d_a - d_b + M) / (2 * M), 0.0), 0.0, 1.0)
        return np.minimum.reduce(
            [np.maximum(d_a - l * M, d_b - (1 - l) * M) for l in (0.0, 1.0, l_meet)]
        )

    def passed_through(self, P0a, P1a, P0b, P1b, t) -> np.ndarray:
        """Per sweep (as :meth:`swept_distance_bound`), ``True`` where the obstacle went from
        one side of the segment to the other within it without being inside at either end
        (the crossings a shape without inside makes). A shape with an inside is inside the
        sweep for a time, which the body rule's cuts find: ``False`` here."""
        return np.zeros(np.shape(P0a)[0], dtype=bool)

    def draw(self, ax, t: float = 0.0, plane=("x", "y"), limits=None, faint: bool = False):
        """Draw the obstacle as at ``t`` [s] on matplotlib axes ``ax``: the orthographic view on
        the ``plane`` of two axes (``("x", "z")``: seen along y), within ``limits`` ((xlim,
        ylim) [m]; what is infinite is drawn across them); ``faint``: an earlier time's, paler
        and without label."""
        raise NotImplementedError

    def view_points(self, plane=("x", "y")) -> np.ndarray:
        """Points (k, 2) [m] of the shape at t = 0 in the view ``plane`` a view should hold."""
        raise NotImplementedError


class PlanarObstacle(Obstacle):
    """Base of the planar kinds (listed before the spatial kind each one is in z = 0): 2-D
    inputs; between ticks, where every end of the sweep lies in z = 0, the tests in the plane
    (:meth:`_swept_in_plane`, :meth:`_passed_in_plane` of ``t`` and the ends as (s, 2) arrays
    [m]), else the spatial kind's."""

    DIM = 2

    def swept_distance_bound(self, P0a, P1a, P0b, P1b, t):
        ends = _in_plane(P0a, P1a, P0b, P1b)
        if ends is None:
            return super().swept_distance_bound(P0a, P1a, P0b, P1b, t)
        return self._swept_in_plane(t, *ends)

    def passed_through(self, P0a, P1a, P0b, P1b, t):
        ends = _in_plane(P0a, P1a, P0b, P1b)
        if ends is None:
            return super().passed_through(P0a, P1a, P0b, P1b, t)
        return self._passed_in_plane(t, *ends)

    def _at(self, points, t, s: int) -> np.ndarray:
        """``points`` (..., 2) [m] moved from t = 0 to ``t`` [s] (a number or one per segment of
        ``s``): (s, ..., 2)."""
        t = np.broadcast_to(np.asarray(t, dtype=float), (s,))
        return points + t.reshape(-1, *[1] * np.ndim(points)) * self.velocity


def _in_plane(*ends) -> list[np.ndarray] | None:
    """The segments' ends (each (s, d) [m]) as (s, 2) arrays when all lie in z = 0, else None."""
    if not all(np.shape(E)[1] == 2 or not np.any(np.asarray(E)[:, 2]) for E in ends):
        return None
    return [np.asarray(E, dtype=float)[:, :2] for E in ends]
