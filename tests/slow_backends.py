"""A test-only backend slower than the 1 kHz loop: ``daqp``'s answers after a sleep.

Not registered on import (a registered backend would join every ``--backends
all``); :func:`registered` adds it to the registry for one test.
"""

from __future__ import annotations

import time

from faulty_backends import DaqpInside

from qpbench.backends import _registry

#: Sleep per solve [s]: with the solve itself a real-time factor of about 0.3 at 1 kHz.
SLOW_S = 0.003


class SlowExact(DaqpInside):
    """``daqp`` with a sleep per solve: the same answers, a real-time factor below 1."""

    name = "test-slow-exact"
    family = "test"

    def _solve(self, problem, warm_start):
        time.sleep(SLOW_S)
        return self.inner.solve(problem, warm_start)


def registered(monkeypatch) -> str:
    """Register :class:`SlowExact` for the test (``monkeypatch`` removes it after); its name."""
    monkeypatch.setitem(_registry(), SlowExact.name, SlowExact)
    return SlowExact.name
