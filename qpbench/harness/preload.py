"""Imported by the worker processes' forkserver only: loads the kernels the parent prepared
(:data:`qpbench.runner.process.PRELOAD_KERNELS_ENV`) once for every worker forked from it; a
failure only costs speed (a worker then loads them itself), so it does not stop the forkserver.
"""

from __future__ import annotations

try:
    import os

    from ..jit import prepare
    from ..runner.process import PRELOAD_KERNELS_ENV

    prepare([k for k in os.environ.get(PRELOAD_KERNELS_ENV, "").split(",") if k])
except Exception:  # noqa: BLE001 - see the module docstring
    pass
