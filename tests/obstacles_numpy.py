"""Test oracle: the planar obstacle kinds' exact closest points in numpy (the distances the
planar kinds have always given), per segment ``P0 -> P1`` (s, 2) [m] and obstacle point:
``A`` (s, m, 2) on the segment, the signed ``dist`` (s, m) [m] and ``u`` (s, m, 2)."""

from __future__ import annotations

import numpy as np


def _foot(X, P0, P1):
    e = P1 - P0
    ee = np.einsum("si,si->s", e, e)
    f = np.einsum("si,si->s", X - P0, e) / np.where(ee > 0, ee, 1.0)
    return P0 + np.clip(f, 0.0, 1.0)[:, None] * e


def _cross(u, v):
    return u[:, 0] * v[:, 1] - u[:, 1] * v[:, 0]


def _from_diff(diff, radius=0.0):
    dist = np.sqrt(np.einsum("...i,...i->...", diff, diff))
    safe = np.where(dist > 0, dist, 1.0)
    return dist - radius, np.where(dist[..., None] > 0, diff / safe[..., None], 0.0)


def _normal_where_zero(u, P0, P1):
    e = P1 - P0
    norm = np.linalg.norm(e, axis=1)
    n = np.stack([-e[:, 1], e[:, 0]], axis=1) / np.where(norm > 0, norm, 1.0)[:, None]
    return np.where(~np.any(u != 0, axis=1)[:, None], n, u)


def line(point, normal, P0, P1):
    normal = np.asarray(normal, float) / np.linalg.norm(normal)
    d0, d1 = (P0 - point) @ normal, (P1 - point) @ normal
    first = d0 <= d1
    A = np.where(first[:, None], P0, P1)
    u = np.broadcast_to(normal, A.shape)
    return A[:, None], np.where(first, d0, d1)[:, None], u[:, None]


def segment(a, b, P0, P1):
    s = len(P0)
    a, b = np.broadcast_to(a, (s, 2)), np.broadcast_to(b, (s, 2))
    cand_A = np.stack([P0, P1, _foot(a, P0, P1), _foot(b, P0, P1)], axis=1)
    cand_B = np.stack([_foot(P0, a, b), _foot(P1, a, b), a, b], axis=1)
    gap = np.linalg.norm(cand_A - cand_B, axis=2)
    j = np.argmin(gap, axis=1)
    rows = np.arange(s)
    A, B, dist = cand_A[rows, j], cand_B[rows, j], gap[rows, j]
    e, f = P1 - P0, b - a
    crossing = (_cross(e, a - P0) * _cross(e, b - P0) < 0) & (
        _cross(f, P0 - a) * _cross(f, P1 - a) < 0
    )
    norm = np.where(dist > 0, dist, 1.0)
    u = np.where((dist > 0)[:, None], (A - B) / norm[:, None], 0.0)
    u = np.where(crossing[:, None], -u, u)
    return A[:, None], np.where(crossing, -dist, dist)[:, None], u[:, None]


def disk(center, radius, P0, P1):
    c = np.broadcast_to(center, P0.shape)
    A = _foot(c, P0, P1)
    dist, u = _from_diff(A - c, radius)
    return A[:, None], dist[:, None], _normal_where_zero(u, P0, P1)[:, None]


def points(cloud, P0, P1):
    out = [disk(c, 0.0, P0, P1) for c in cloud]
    return tuple(np.concatenate([o[k] for o in out], axis=1) for k in range(3))
