"""Imported by the worker processes' forkserver only: loads the kernels the parent prepared
(:data:`qpbench.runner.process.PRELOAD_KERNELS_ENV`); a failure only costs speed."""

from __future__ import annotations

import os
from contextlib import suppress

with suppress(Exception):  # see the module docstring
    from ..jit import prepare
    from ..runner.process import PRELOAD_KERNELS_ENV

    prepare([k for k in os.environ.get(PRELOAD_KERNELS_ENV, "").split(",") if k])
