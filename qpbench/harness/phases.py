"""A long job told phase by phase: a line when a phase starts and ends, a bar on a terminal."""

from __future__ import annotations

import logging
import sys
import time
from contextlib import contextmanager
from dataclasses import dataclass, field


@dataclass
class Phase:
    """One phase in progress: :meth:`update` counts work done."""

    name: str
    bar: object | None = None

    def update(self, n: int = 1) -> None:
        if self.bar is not None:
            self.bar.update(n)

    def describe(self, text: str) -> None:
        """Show what is being done now beside the bar."""
        if self.bar is not None:
            self.bar.set_postfix_str(text, refresh=False)


@dataclass
class Phases:
    """The phases of a job, each timed and told; ``bars``: ``None`` when stderr is a terminal,
    ``False`` never; ``times_s``: wall time of each finished phase [s], in the order run."""

    log: logging.Logger
    bars: bool | None = None
    times_s: dict[str, float] = field(default_factory=dict)

    def __post_init__(self) -> None:
        if self.bars is None:
            self.bars = sys.stderr.isatty()

    @contextmanager
    def phase(self, name: str, total: int | None = None, unit: str = "step", bar: bool = True):
        """Run a phase, yielding a :class:`Phase`; ``total``: the work units it counts (the bar's
        length); ``bar=False``: its code draws one."""
        self.log.info("%s: started", name)
        progress = None
        if self.bars and bar:
            from tqdm import tqdm

            progress = tqdm(total=total, unit=unit, desc=name, leave=False, file=sys.stderr)
        start = time.perf_counter()
        try:
            yield Phase(name, progress)
        finally:
            if progress is not None:
                progress.close()
        seconds = time.perf_counter() - start
        self.times_s[name] = round(self.times_s.get(name, 0.0) + seconds, 1)
        self.log.info("%s: done in %.1f s", name, seconds)
