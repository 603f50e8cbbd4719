"""The paper's recurrent neural network (eq. 15) as a general QP solver.

:mod:`qpbench.rnn.network` holds the projection network, its step bound and
its two integrators (a numba-compiled loop and a pure-numpy path that gives
the same numbers to 1e-12). The backends ``rnn`` and ``rnn-converged`` in
:mod:`qpbench.backends.rnn` wrap it.
"""

from __future__ import annotations

from .network import (
    METHODS,
    NO_STABLE_STEP,
    SHAPE_MISMATCH,
    DenseQP,
    IntegrationResult,
    NetworkState,
    dense_qp,
    duals,
    integrate,
    kernel,
    make_params,
    numba_available,
    stable_ratio,
)

__all__ = [
    "METHODS",
    "DenseQP",
    "IntegrationResult",
    "NO_STABLE_STEP",
    "SHAPE_MISMATCH",
    "NetworkState",
    "dense_qp",
    "duals",
    "kernel",
    "make_params",
    "integrate",
    "numba_available",
    "stable_ratio",
]
