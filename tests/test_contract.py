"""The contract every backend keeps with the harness: ``--repeat`` changes timings, not answers.

Every registered, available backend of the package runs a slice of the
``wall`` robot set through :func:`qpbench.harness.bench.run_bench` with
``repeat=1`` and ``repeat=3``, in sequential and independent mode. The slice
crosses the infeasible start of the run (the first ticks: the key points
start inside the safety distance) into feasible ticks, then jumps to the
ticks where the wall's rows become active; in sequential mode it is one
sequence, state carried across the jump. Repeats 2..R are solved by replicas
of the backend fed the same problems (:mod:`qpbench.harness.guard`); the
statuses, iteration counts and ``x`` (bit for bit) kept with ``repeat=3``
must be those of ``repeat=1``, and every row must say that its timed
repeats did the kept solve's work (``repeat_exact``).
"""

from __future__ import annotations

import warnings
from dataclasses import replace
from pathlib import Path

import pytest

import qpbench.harness.bench as hb
from qpbench.backends import backend_class, backend_names, get_backend
from qpbench.formats import load_problems
from qpbench.harness import results as results_module
from qpbench.harness.guard import LocalRunner
from qpbench.harness.results import read_results

WALL = Path(__file__).resolve().parents[1] / "problems" / "wall"

#: Record ranges of ``problems/wall`` (30 ticks): the infeasible start (ticks 0-12) into
#: feasible ticks, and the wall's rows turning active (from tick 133).
RANGES = ((4, 19), (128, 143))
#: Fewer ticks for the backends whose solves take milliseconds (the modelling layer
#: compiles its model after every reset; the network integrates to convergence).
SLOW = {"cvxpy": ((8, 14), (130, 136)), "rnn-converged": ((8, 14), (130, 136))}


def _slice(ranges):
    pset = load_problems(WALL)
    records = [r for a, b in ranges for r in pset.records[a:b]]
    return replace(pset, records=records, path=None, sha256=None, files=[])


@pytest.fixture(scope="module")
def slices():
    if not WALL.exists():
        pytest.skip("problems/wall is not shipped here")
    from qpbench.reference import reference_solutions

    out = {}
    for ranges in {RANGES, *SLOW.values()}:
        pset = _slice(ranges)
        out[ranges] = (pset, reference_solutions(pset, cache=False))
    return out


def _run(monkeypatch, tmp_path, pset, refs, backend: str, repeat: int, mode: str):
    """Per problem: ``(status, iterations, x bytes, repeat_exact, repeat_note, timed solves)``."""
    seen: dict = {}

    class Recording(LocalRunner):
        def solve(self, problem, repeat=None, reset_before=False):
            out = super().solve(problem, repeat=repeat, reset_before=reset_before)
            sol = out.solution
            x = None if sol is None or sol.x is None else sol.x.tobytes()
            seen[id(problem)] = (out.status, getattr(sol, "iterations", None), x)
            return out

    monkeypatch.setattr(hb, "LocalRunner", Recording)
    # rows made durable per problem is not what this test is about (and most of its time)
    monkeypatch.setattr(results_module.os, "fsync", lambda fd: None)
    config = hb.BenchConfig(
        backends=[backend], repeat=repeat, mode=mode, isolate="never", time_limit=60.0
    )
    out = tmp_path / f"{mode}-{repeat}.csv"
    hb.run_bench(pset, config, out, force=True, references=refs)
    rows = {r["problem"]: r for r in read_results(out).rows}
    return [
        (*seen[id(rec.problem)], rows[rec.name]["repeat_exact"], rows[rec.name]["repeat_note"])
        + (int(rows[rec.name]["repeat"]),)
        for rec in pset.records
    ]


def _shipped_backends() -> list[str]:
    """Registered, available backends of the package (not those the tests register)."""
    return [
        name for name in backend_names() if backend_class(name).__module__.startswith("qpbench.")
    ]


@pytest.mark.parametrize("backend", _shipped_backends())
def test_repeat_gives_the_single_solves_answers(backend, slices, monkeypatch, tmp_path):
    pset, refs = slices[SLOW.get(backend, RANGES)]
    # compile / import outside the timed region (a first numba compile takes longer than a solve)
    warm = get_backend(backend)
    warm.solve(pset.records[0].problem)
    statuses = set()
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        for mode in ("sequential", "independent"):
            one = _run(monkeypatch, tmp_path, pset, refs, backend, 1, mode)
            three = _run(monkeypatch, tmp_path, pset, refs, backend, 3, mode)
            for rec, a, b in zip(pset.records, one, three):
                where = f"{backend} {mode} {rec.name}"
                assert a[:3] == b[:3], (where, a[:2], b[:2])
                assert a[3] == b[3] == "True", (where, b[4])  # every repeat did the same work
                assert a[5] == 1 and b[5] in (1, 3), where
                statuses.add(a[0])
                # a failed solve is not repeated; every other one is timed 3 times
                assert (b[5] == 3) == (a[0] not in ("error", "time_limit", "invalid")), where
    # the slice reaches the states the contract is about (not only for the network,
    # which has no infeasibility verdict, nor the pseudo-inverse, which ignores rows)
    if backend_class(backend).certifies_infeasibility and backend != "pinv":
        assert {"optimal", "primal_infeasible"} <= statuses, statuses


def test_slice_has_infeasible_ticks_and_active_wall_rows(slices):
    """The slice is what the contract needs: infeasible start ticks and active obstacle rows."""
    _, refs = slices[RANGES]
    statuses = [r.status for r in refs]
    assert "primal_infeasible" in statuses and "optimal" in statuses
    active = [r for r in refs if r.status == "optimal" and r.z is not None and (r.z > 1e-6).any()]
    assert len(active) >= 10
