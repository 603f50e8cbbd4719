"""The write of every report folder (:func:`publish`), and ``report.md`` with its figures."""

from __future__ import annotations

import contextlib
import logging
import sys
import threading
import time
from pathlib import Path
from typing import TYPE_CHECKING

from .inputs import ResultFile, read_results
from .markdown import render
from .recommend import MIN_OK_BOUND, read_sweeps

if TYPE_CHECKING:
    from collections.abc import Callable


log = logging.getLogger("qpbench.report")


@contextlib.contextmanager
def figure_progress(folder: Path):
    """While the figures are drawn: a bar of the figures written into ``folder`` on a terminal,
    else a log line every 5 s (and one at the end)."""
    from tqdm import tqdm

    started = time.time()
    stop = threading.Event()
    off = not (sys.stderr.isatty() and log.isEnabledFor(logging.INFO))
    bar = tqdm(unit="figure", desc="report figures", leave=False, disable=off)

    def count() -> int:
        return sum(1 for p in folder.glob("*.png") if p.stat().st_mtime >= started - 1)

    def beat() -> None:
        while not stop.wait(5.0 if off else 0.5):
            done = count()
            if off:
                log.info("report: %d figures in %.0f s", done, time.time() - started)
            else:
                bar.update(done - bar.n)

    thread = threading.Thread(target=beat, name="report-progress", daemon=True)
    thread.start()
    try:
        yield
    finally:
        stop.set()
        thread.join()
        bar.close()
        log.info("report: %d figures in %.1f s", count(), time.time() - started)


def publish(out: str | Path, name: str, force: bool, render: Callable[[Path], str]) -> Path:
    """The one write of a report folder: check ``out`` (its parent must exist) and ``out/name``
    (refused when it exists, unless ``force``); ``render(out)`` draws the figures into ``out``
    and returns the text, written last and atomically to ``out/name``."""
    from ..atomic import check_folder, check_output, write_text

    out = Path(out)
    check_folder(out)
    if out.exists():
        check_output(out / name, force=force)
    text = render(out)
    out.mkdir(exist_ok=True)
    write_text(out / name, text)
    return out / name


def write_report(
    paths: list[str | Path],
    out: str | Path,
    *,
    force: bool = False,
    plots: bool = True,
    prefer: str | None = None,
    sections: Callable[[Path, bool], list[str]] | None = None,
    files: list[ResultFile] = (),
    min_ok_bound: float = MIN_OK_BOUND,
    jobs: int = 1,
) -> Path:
    """Read the result CSVs (:func:`.inputs.read_results`), write ``out/report.md`` and
    ``out/plots/*.png`` (:func:`publish`). ``sections(out, plots)``: markdown lines appended
    after the tables (the sweep section); with it, ``paths`` may be empty; ``files``: the
    tables of ``sections``, listed with the result files; the sweep tables among them are the
    recommendation's perturbed runs, judged on ``min_ok_bound``
    (:func:`.recommend.recommend`); ``jobs``: figures drawn at a time, each in a worker process
    when more than one."""

    def render_all(out: Path) -> str:
        started = time.perf_counter()
        results = read_results(paths, prefer=prefer)
        results.files += files
        read = (len(results.bench), len(results.closed_loop), time.perf_counter() - started)
        log.info("report: %d bench rows and %d closed-loop runs read in %.1f s", *read)
        plot_files: dict[str, str] = {}
        if plots:
            from .plots import write_plots

            with figure_progress(out / "plots"):
                plot_files = write_plots(results, out / "plots", relative_to=out, jobs=jobs)
        swept = [f.path for f in results.files if f.kind == "sweep"]
        sweeps = read_sweeps(swept, relative_to=out) if swept else None
        text = render(results, plot_files, sweeps, min_ok_bound)
        if sections is not None:
            text += "\n" + "\n".join(sections(out, plots))
        return text

    return publish(out, "report.md", force, render_all)
