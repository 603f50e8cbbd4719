"""A :class:`qpsolvers.Problem` whose arrays are views of one float64 buffer, so that a
tick's QP goes to a compiled kernel as one array instead of eight. Layout::

    [0 : HEADER]   n, me, mi, then the offsets of P, q, A, b, G, h, lb, ub (-1: absent)
    at the offsets the arrays, row-major; anything may follow

The fields cannot be reassigned; writing into the arrays writes into the buffer.
"""

from __future__ import annotations

import numpy as np
import qpsolvers

from .exceptions import ProblemFormatError

#: Length of the header, and the index of each entry in it.
HEADER = 11
N, ME, MI, OFF_P, OFF_Q, OFF_A, OFF_B, OFF_G, OFF_H, OFF_LB, OFF_UB = range(HEADER)

#: Problem fields in header order (after n, me, mi), with their shapes.
_FIELDS = ("P", "q", "A", "b", "G", "h", "lb", "ub")


def _bad(key: str, msg: str):
    raise ProblemFormatError(msg, key=key)


def _shapes(n: int, me: int, mi: int) -> dict[str, tuple[int, ...]]:
    shapes = ((n, n), (n,), (me, n), (me,), (mi, n), (mi,), (n,), (n,))
    return dict(zip(_FIELDS, shapes))


class PackedProblem(qpsolvers.Problem):
    """A QP in qpsolvers form stored in one buffer (copied unless C-contiguous float64);
    a :class:`ProblemFormatError` when the header does not describe arrays inside it."""

    def __init__(self, buffer):
        buf = np.ascontiguousarray(buffer, dtype=np.float64)
        if buf.ndim != 1 or buf.shape[0] < HEADER:
            _bad("buffer", f"buffer of shape {buf.shape} has no header of {HEADER} values")
        head = buf[:HEADER]
        if not np.all(np.isfinite(head)) or np.any(head != np.round(head)):
            _bad("buffer", "header values must be whole numbers")
        n, me, mi = (int(v) for v in head[:3])
        if n < 1 or me < 0 or mi < 0:
            _bad("buffer", f"header sizes n={n}, me={me}, mi={mi} are not valid")
        fields = {}
        for k, (name, shape) in enumerate(_shapes(n, me, mi).items()):
            off = int(head[OFF_P + k])
            if off == -1:
                if name in ("P", "q") or (name in ("A", "b") and me) or (name in ("G", "h") and mi):
                    _bad(name, f"'{name}' is absent but the header sizes need it")
                fields[name] = None
                continue
            size = int(np.prod(shape))
            if off < HEADER or off + size > buf.shape[0]:
                _bad(name, f"'{name}' at offset {off} does not fit a buffer of {buf.shape[0]}")
            fields[name] = buf[off : off + size].reshape(shape)
        if (fields["A"] is None) != (fields["b"] is None) or (fields["G"] is None) != (
            fields["h"] is None
        ):
            _bad("buffer", "A and b (G and h) must be present together")
        self.__dict__.update(buffer=buf, **fields)

    @classmethod
    def from_views(cls, buf, P, q, G, h, A, b, lb, ub) -> PackedProblem:
        """A problem from views the caller made of ``buf`` after writing its header (no checks)."""
        self = object.__new__(cls)
        self.__dict__.update(buffer=buf, P=P, q=q, G=G, h=h, A=A, b=b, lb=lb, ub=ub)
        return self

    @property
    def shape(self) -> tuple[int, int, int]:
        """``(n, me, mi)``: variables, equalities, inequalities."""
        head = self.buffer
        return int(head[N]), int(head[ME]), int(head[MI])

    def __setattr__(self, name, value):
        raise AttributeError(
            f"PackedProblem.{name} cannot be set: its arrays are views of one buffer; "
            "build a qpsolvers.Problem to change a problem"
        )

    def __reduce__(self):
        return (PackedProblem, (self.buffer,))

    def __repr__(self) -> str:
        n, me, mi = self.shape
        return f"PackedProblem(n={n}, me={me}, mi={mi})"


def pack(problem: qpsolvers.Problem) -> PackedProblem:
    """The :class:`PackedProblem` of any problem in qpsolvers form (dense copies)."""
    import scipy.sparse as spa

    arrays = {}
    for name in _FIELDS:
        value = getattr(problem, name)
        if value is not None:
            value = np.asarray(value.toarray() if spa.issparse(value) else value, dtype=np.float64)
        arrays[name] = value
    if arrays["P"] is None or arrays["q"] is None:
        _bad("P" if arrays["P"] is None else "q", "a problem needs P and q")
    n = arrays["q"].size
    me = 0 if arrays["b"] is None else arrays["b"].size
    mi = 0 if arrays["h"] is None else arrays["h"].size
    parts, head, off = [], [n, me, mi], HEADER
    for name, shape in _shapes(n, me, mi).items():
        value = arrays[name]
        if value is None:
            head.append(-1)
            continue
        if value.size != int(np.prod(shape)) or (value.ndim == 2 and value.shape != shape):
            _bad(name, f"'{name}' has shape {value.shape}, expected {shape}")
        head.append(off)
        parts.append(value.reshape(-1))
        off += value.size
    return PackedProblem(np.concatenate([np.array(head, dtype=np.float64), *parts]))
