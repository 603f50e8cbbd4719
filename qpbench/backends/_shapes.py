"""Shape checks of a dense problem before it is written into a solver's workspace.

Solvers that keep a workspace of one shape (DAQP's ``Model``, qpOASES'
``SQProblem``, PIQP's ``DenseSolver``) must not be handed arrays of another
shape: DAQP ignores such an update without a word, numpy would broadcast a
1-row ``b`` into two slots. :func:`check_shapes` refuses them with one line
naming the backend, the array and both shapes.
"""

from __future__ import annotations

from typing import TYPE_CHECKING

from ..exceptions import ProblemFormatError

if TYPE_CHECKING:
    import numpy as np


def _refuse(backend: str, key: str, shape, expected) -> None:
    raise ProblemFormatError(
        f"backend '{backend}': {key} has shape {tuple(shape)}, expected {tuple(expected)} "
        "(from q and the rows of A and G)",
        key=key,
    )


def check_shapes(
    backend: str,
    n: int,
    P: np.ndarray | None,
    A: np.ndarray | None,
    b: np.ndarray | None,
    G: np.ndarray | None,
    h: np.ndarray | None,
    lb: np.ndarray | None,
    ub: np.ndarray | None,
) -> tuple[int, int]:
    """``(me, mi)``, the rows of ``A`` and ``G``, after checking every array's shape.

    Args:
        backend: Backend name (for the message).
        n: Number of variables (length of ``q``).
        P, A, b, G, h, lb, ub: Dense arrays (``None`` for an absent part).

    Raises:
        ProblemFormatError: an array whose shape does not fit ``n`` and the
            row counts of ``A`` and ``G``.
    """
    if P.shape != (n, n):
        _refuse(backend, "P", P.shape, (n, n))
    me = _rows(backend, A, b, n, ("A", "b", "me"))
    mi = _rows(backend, G, h, n, ("G", "h", "mi"))
    if lb is not None and lb.shape != (n,):
        _refuse(backend, "lb", lb.shape, (n,))
    if ub is not None and ub.shape != (n,):
        _refuse(backend, "ub", ub.shape, (n,))
    return me, mi


def _rows(backend: str, M, v, n: int, names: tuple[str, str, str]) -> int:
    """Rows of a constraint block ``M x (=|<=) v`` after checking ``M`` is (m, n) and ``v`` is (m,); 0 if absent."""
    if M is None:
        return 0
    matrix, vector, count = names
    if M.ndim != 2 or M.shape[1] != n:
        _refuse(backend, matrix, M.shape, (count, n))
    m = M.shape[0]
    if v is None or v.shape != (m,):
        _refuse(backend, vector, () if v is None else v.shape, (m,))
    return m
