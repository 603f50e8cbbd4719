"""The distributions of a sweep file's ``[parameters]`` (described in :mod:`qpbench.sweep.spec`):
checked against the base scenario's value of their key, and drawn from."""

from __future__ import annotations

import copy
import math
from dataclasses import dataclass

import numpy as np

from ..exceptions import InputError

#: Distribution kinds and their allowed fields (``dist`` aside).
DISTRIBUTIONS = {
    "uniform": ("low", "high", "spread", "same"),
    "normal": ("mean", "std", "low", "high", "same"),
    "loguniform": ("low", "high", "same"),
    "choice": ("values", "weights"),
    "integers": ("low", "high"),
}

#: Draws of a truncated normal tried before giving up on a component.
_MAX_REDRAWS = 1000


def finite_number(v) -> bool:
    """True for an int or float (not a bool) that is finite."""
    return isinstance(v, (int, float)) and not isinstance(v, bool) and math.isfinite(v)


@dataclass(frozen=True)
class Distribution:
    """One key's distribution: ``params`` its fields (numbers as arrays of the key's shape),
    ``base`` the base scenario's value."""

    key: str
    kind: str
    params: dict
    base: object

    def draw(self, rng: np.random.Generator) -> object:
        """One value of the key (a float, an int, or a list of the base's shape)."""
        p, base = self.params, self.base
        shape = np.shape(base)
        if self.kind == "choice":
            i = int(rng.choice(len(p["values"]), p=p.get("weights")))
            return copy.deepcopy(p["values"][i])
        if self.kind == "integers":
            return int(rng.integers(p["low"], p["high"], endpoint=True))
        if p.get("same"):  # one draw for every component: an offset from the base, or the value
            relative = "spread" in p or (self.kind == "normal" and "mean" not in p)
            first = float(np.ravel(base)[0])
            one = Distribution(
                self.key, self.kind, {k: v for k, v in p.items() if k != "same"}, first
            ).draw(rng)
            value = base + (one - first) if relative else np.full(shape, one)
            return value.tolist() if shape else float(value)
        if self.kind == "uniform":
            low, high = (
                (base - p["spread"], base + p["spread"]) if "spread" in p else (p["low"], p["high"])
            )
            value = rng.uniform(low, high, size=shape)
        elif self.kind == "loguniform":
            value = np.exp(rng.uniform(np.log(p["low"]), np.log(p["high"]), size=shape))
        else:
            value = self._truncated_normal(rng, shape)
        return value.tolist() if shape else float(value)

    def _truncated_normal(self, rng, shape):
        p = self.params
        mean = p.get("mean", np.asarray(self.base, dtype=float))
        mean, std = np.broadcast_to(mean, shape), np.broadcast_to(p["std"], shape)
        low = np.broadcast_to(p.get("low", -np.inf), shape)
        high = np.broadcast_to(p.get("high", np.inf), shape)
        value = np.asarray(rng.normal(mean, std), dtype=float)
        for _ in range(_MAX_REDRAWS):
            bad = (value < low) | (value > high)
            if not bad.any():
                return value
            value = np.where(bad, rng.normal(mean, std), value)
        raise InputError(
            f"a truncated normal draw stayed outside [low, high] {_MAX_REDRAWS} times", key=self.key
        )


def checked_distribution(key: str, spec: dict, base, path) -> Distribution:
    """Key ``key``'s distribution ``spec`` (a ``[parameters]`` entry), checked against ``base``,
    the base scenario's value of the key; :class:`InputError` naming ``path`` and the key if wrong."""
    where = f"parameters.{key}"
    kind = spec.get("dist")
    if kind not in DISTRIBUTIONS:
        raise InputError(
            f"unknown distribution {kind!r} (choose from {', '.join(DISTRIBUTIONS)})",
            path=path,
            key=f"{where}.dist",
        )
    for f in spec:
        if f != "dist" and f not in DISTRIBUTIONS[kind]:
            raise InputError(
                f"unknown field of a {kind} distribution (expected: {', '.join(DISTRIBUTIONS[kind])})",
                path=path,
                key=f"{where}.{f}",
            )
    if kind == "choice":
        return Distribution(key, kind, _choice(spec, base, path, where), base)
    is_int = isinstance(base, int) and not isinstance(base, bool)
    if kind == "integers" or is_int:
        if not (kind == "integers" and is_int):
            raise InputError(
                f"{'an integer key takes integers or choice' if is_int else 'integers is for integer keys'}",
                path=path,
                key=f"{where}.dist",
            )
        lo, hi = spec.get("low"), spec.get("high")
        if not (isinstance(lo, int) and isinstance(hi, int) and lo <= hi):
            raise InputError(f"need integers low <= high, got {lo!r}, {hi!r}", path=path, key=where)
        return Distribution(key, kind, {"low": lo, "high": hi}, base)
    base_arr = _numeric(base, None, path, where, "the base value")
    same = spec.get("same", False)
    if not isinstance(same, bool):
        raise InputError(f"expected true or false, got {same!r}", path=path, key=f"{where}.same")
    shape = None if same else np.shape(base_arr)  # same: numbers only, checked below
    params = {
        f: _numeric(v, shape, path, f"{where}.{f}", f)
        for f, v in spec.items()
        if f not in ("dist", "same")
    }
    if same and any(np.ndim(v) for v in params.values()):
        raise InputError(
            "same = true takes numbers, not lists (one draw for every component)",
            path=path,
            key=f"{where}.same",
        )
    if same:
        params["same"] = True
    _check_bounds(kind, params, path, where)
    return Distribution(key, kind, params, base_arr if np.ndim(base_arr) else float(base_arr))


def _numeric(value, shape, path, where, what):
    """``value`` as a float array broadcastable to ``shape`` (or any numeric shape when ``shape`` is None)."""
    try:
        arr = np.asarray(value, dtype=float)
    except (TypeError, ValueError):
        arr = None
    if (
        arr is None
        or arr.dtype == object
        or not np.all(np.isfinite(arr))
        or isinstance(value, bool)
    ):
        raise InputError(f"{what}: expected finite numbers, got {value!r}", path=path, key=where)
    if shape is not None and arr.ndim and arr.shape != tuple(shape):
        raise InputError(
            f"expected a number or {list(shape)} numbers (the base value's shape), got {value!r}",
            path=path,
            key=where,
        )
    return arr


def _check_bounds(kind: str, p: dict, path, where) -> None:
    def need(*names):
        for n in names:
            if n not in p:
                raise InputError(
                    f"a {kind} distribution needs {' and '.join(names)}",
                    path=path,
                    key=f"{where}.{n}",
                )

    if kind == "uniform":
        if "spread" in p:
            if "low" in p or "high" in p:
                raise InputError(
                    "give either spread or low and high", path=path, key=f"{where}.spread"
                )
            if np.any(p["spread"] < 0):
                raise InputError("spread must be >= 0", path=path, key=f"{where}.spread")
            return
        need("low", "high")
    elif kind == "loguniform":
        need("low", "high")
        if np.any(p["low"] <= 0):
            raise InputError("loguniform needs low > 0", path=path, key=f"{where}.low")
    elif kind == "normal":
        need("std")
        if np.any(p["std"] < 0):
            raise InputError("std must be >= 0", path=path, key=f"{where}.std")
    if "low" in p and "high" in p and np.any(p["low"] > p["high"]):
        raise InputError("low must be <= high", path=path, key=f"{where}.low")


def _choice(spec: dict, base, path, where) -> dict:
    values = spec.get("values")
    if not isinstance(values, list) or not values:
        raise InputError(
            "a choice needs a non-empty list of values", path=path, key=f"{where}.values"
        )
    for v in values:
        if type(v) is not type(base) and not (finite_number(v) and finite_number(base)):
            raise InputError(
                f"each value must be like the base value {base!r}, got {v!r}",
                path=path,
                key=f"{where}.values",
            )
        if isinstance(base, list) and np.shape(v) != np.shape(base):
            raise InputError(
                f"each value must have the base value's shape {list(np.shape(base))}, got {v!r}",
                path=path,
                key=f"{where}.values",
            )
    out = {"values": values}
    if "weights" in spec:
        w = spec["weights"]
        if not (
            isinstance(w, list)
            and len(w) == len(values)
            and all(finite_number(x) and x >= 0 for x in w)
            and sum(w) > 0
        ):
            raise InputError(
                "weights: one number >= 0 per value, not all zero",
                path=path,
                key=f"{where}.weights",
            )
        out["weights"] = [x / sum(w) for x in w]
    return out
