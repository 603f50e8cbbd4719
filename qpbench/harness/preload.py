"""Imported by the worker processes' forkserver only: the kernels loaded once, for every fork.

:func:`qpbench.runner.process.context` names this module in the
forkserver's preload list, after the parent has compiled the kernels it runs
into the on-disk cache (:func:`qpbench.jit.warmup`). Importing it loads those
the parent prepared (named in :data:`qpbench.runner.process.PRELOAD_KERNELS_ENV`)
into the forkserver, so each worker forked from it starts with them in
memory (its own :func:`~qpbench.jit.warmup` returns at once) instead of
loading them again. This is the one qpbench module that does work when
imported, and nothing but the forkserver imports it. A failure here only
costs speed (a worker then loads the kernels itself), so it is swallowed:
an exception would stop the forkserver.
"""

from __future__ import annotations

try:
    import os

    from ..jit import prepare
    from ..runner.process import PRELOAD_KERNELS_ENV

    prepare([k for k in os.environ.get(PRELOAD_KERNELS_ENV, "").split(",") if k])
except Exception:  # noqa: BLE001 - see the module docstring
    pass
