"""Test-only backend of the sweep tests: DAQP, but its process dies while a flag file exists.

``sweep:die-on-flag`` solves like ``daqp`` unless the file named by
``QPBENCH_TEST_DIE`` exists: then it SIGKILLs the process it runs in (a worker
lost mid-run, as the out-of-memory killer or a segfault in a solver would).
Loaded with ``--plugin tests/sweep_backends.py``.
"""

from __future__ import annotations

import os
import signal

from qpbench.backends import Backend, get_backend, register

#: Environment variable naming the flag file.
FLAG_ENV = "QPBENCH_TEST_DIE"


# Written out rather than built on faulty_backends.DaqpInside: a plugin file is loaded by its
# path in every worker, where tests/ is not importable.
@register
class DieOnFlag(Backend):
    name = "sweep:die-on-flag"
    family = "test fault"

    def __init__(self, profile="default", **settings):
        super().__init__(profile, **settings)
        self.inner = get_backend("daqp", profile)

    def _solve(self, problem, warm_start):
        flag = os.environ.get(FLAG_ENV)
        if flag and os.path.exists(flag):
            os.kill(os.getpid(), signal.SIGKILL)
        return self.inner._solve(problem, warm_start)

    def reset(self):
        self.inner.reset()
