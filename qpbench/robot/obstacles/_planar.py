"""Planar geometry of the between-ticks tests (numpy): a point against a swept segment, a
point through a moving segment; all arrays (s, 2) [m]."""

from __future__ import annotations

import numpy as np


def foot(X: np.ndarray, P0: np.ndarray, P1: np.ndarray) -> np.ndarray:
    """The point of each segment ``P0 -> P1`` closest to ``X`` (all (s, 2)) [m]."""
    e = P1 - P0
    ee = np.einsum("si,si->s", e, e)
    f = np.einsum("si,si->s", X - P0, e) / np.where(ee > 0, ee, 1.0)
    return P0 + np.clip(f, 0.0, 1.0)[:, None] * e


def cross(u: np.ndarray, v: np.ndarray) -> np.ndarray:
    return u[:, 0] * v[:, 1] - u[:, 1] * v[:, 0]


def swept_point_bound(C, P0a, P1a, P0b, P1b) -> np.ndarray:
    """A lower bound [m] of the distance of points ``C`` to the segments ``P0(l) -> P1(l)``,
    ``P(l) = (1 - l) Pa + l Pb``, ``l`` in [0, 1] (all (s, 2)); 0 where one passes over ``C``.
    The closest point of segment ``l`` is an end (on a chord) or its foot, at ``|g(l)| /
    |e(l)|`` with ``g(l) = e(l) x (C - P0(l))`` quadratic in ``l`` (docs/body.md)."""
    Q, D0 = C - P0a, P0b - P0a
    E = P1a - P0a
    DE = (P1b - P0b) - E
    c0 = cross(E, Q)
    c1 = cross(DE, Q) - cross(E, D0)
    c2 = -cross(DE, D0)
    g1 = c0 + c1 + c2
    with np.errstate(divide="ignore", invalid="ignore"):
        lv = np.where(c2 != 0.0, -c1 / (2.0 * c2), -1.0)
    vertex = (lv > 0.0) & (lv < 1.0)
    gv = c0 + lv * (c1 + lv * c2)
    root = (c0 * g1 <= 0.0) | (vertex & (gv * c0 <= 0.0))
    least = np.minimum(np.abs(c0), np.abs(g1))
    least = np.where(vertex, np.minimum(least, np.abs(gv)), least)
    e_max = np.maximum(np.linalg.norm(E, axis=1), np.linalg.norm(E + DE, axis=1))
    interior = np.where(root, 0.0, least / np.where(e_max > 0, e_max, 1.0))
    return np.minimum.reduce(
        [
            interior,
            np.linalg.norm(C - foot(C, P0a, P0b), axis=1),  # to the chords the ends run along
            np.linalg.norm(C - foot(C, P1a, P1b), axis=1),
        ]
    )


#: Slack [m] of "within the segment" in :func:`passes_through` (rounding at a segment's end).
PASS_TOL = 1e-12


def passes_through(Xa, Xb, P0a, P1a, P0b, P1b) -> np.ndarray:
    """Point ``X`` moving from ``Xa`` to ``Xb`` while its segment moves from ``P0a -> P1a`` to
    ``P0b -> P1b`` (all (s, 2)): ``True`` where the side of ``X`` changes sign (or is 0 at one
    end: on the segment there) and ``X`` projects within the segment at both ends (to
    :data:`PASS_TOL`): over a motion short against the distances involved, it went through the
    segment."""
    ea, eb = P1a - P0a, P1b - P0b
    ha, hb = cross(ea, Xa - P0a), cross(eb, Xb - P0b)

    def within(X, P0, e):
        length = np.linalg.norm(e, axis=1)
        along = np.einsum("si,si->s", X - P0, e) / np.where(length > 0, length, 1.0)
        return (along >= -PASS_TOL) & (along <= length + PASS_TOL)

    sides = (ha * hb <= 0.0) & ((ha != 0.0) | (hb != 0.0))
    return sides & within(Xa, P0a, ea) & within(Xb, P0b, eb)
