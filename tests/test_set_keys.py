"""``--set BACKEND.KEY=VALUE`` is checked against the solver's own settings before any work starts.

Each backend lists the keys it accepts (:meth:`~qpbench.backends.base.Backend.setting_names`,
read from the installed solver package where it exposes them); a key that is not one of them
ends the command with exit 2 and one line naming the key, the closest names and the valid
ones, before any kernel is compiled, any problem read or any file written.
"""

from __future__ import annotations

from pathlib import Path

import faulty_backends as fb
import numpy as np
import pandas as pd
import pytest

from qpbench.backends import backend_class, get_backend
from qpbench.cli import main

ROOT = Path(__file__).resolve().parents[1]

#: backend, a mistyped ``KEY=VALUE`` of it, the name it must suggest, a valid ``KEY=VALUE``
#: (each ``--set`` item is the backend's name, a dot, then the key).
TYPOS = [
    ("daqp", "iter_limt=5", "iter_limit", "iter_limit=50"),
    ("daqp-stateless", "primal_tl=1e-8", "primal_tol", "eps_prox=0"),
    ("piqp", "eps_abz=1e-7", "eps_abs", "eps_duality_gap_abs=1e-8"),
    ("proxqp", "eps_abss=1e-7", "eps_abs", "eps_primal_inf=1e-5"),
    ("clarabel", "tol_fea=1e-7", "tol_feas", "tol_feas=1e-7"),
    ("qpoases", "terminationTolerence=1e-10", "terminationTolerance", "terminationTolerance=1e-10"),
    ("osqp", "rhoo=0.1", "rho", "rho=0.1"),
    ("rnn", "epz=0.01", "eps", "eps=0.01"),
    # through qpsolvers, which would drop PIQP's unknown name silently
    ("qpsolvers:piqp", "eps_abz=1e-7", "eps_abs", "backend=dense"),
    ("qpsolvers:clarabel", "tol_fea=1e-7", "tol_feas", "tol_feas=1e-7"),
]


def _available(name: str) -> None:
    reason = backend_class(name).unavailable_reason()
    if reason is not None:
        pytest.skip(f"{name}: {reason}")


def _files(folder: Path) -> dict[str, tuple[int, int]]:
    return {
        str(p.relative_to(folder)): (p.stat().st_size, p.stat().st_mtime_ns)
        for p in folder.rglob("*")
    }


@pytest.mark.parametrize("backend, typo, suggestion, valid", TYPOS)
def test_a_mistyped_key_exits_2_before_any_work(
    backend, typo, suggestion, valid, tmp_path, monkeypatch, capsys
):
    _available(backend)
    # the user's command, as typed in a folder that holds the repository's problems/
    (tmp_path / "problems").symlink_to(ROOT / "problems")
    monkeypatch.chdir(tmp_path)
    before = _files(ROOT / "problems" / "wall")

    def no_solve(*args, **kwargs):  # pragma: no cover - must not be reached
        raise AssertionError("a solve started")

    monkeypatch.setattr(backend_class(backend), "solve", no_solve)
    command = (
        f"bench problems/wall --backends {backend} --set {backend}.{typo} --limit 2 --out x.csv"
    )
    assert main(command.split()) == 2
    err = capsys.readouterr().err.strip()
    key = typo.split("=")[0]
    assert len(err.splitlines()) == 1, err
    assert f"--set {backend}.{key}" in err and f"did you mean '{suggestion}'" in err
    valid_key = valid.split("=")[0]
    assert "its settings: " in err and valid_key in err.split("its settings: ")[1].split(", ")
    assert sorted(p.name for p in tmp_path.iterdir()) == ["problems"]  # no x.csv, nothing else
    assert _files(ROOT / "problems" / "wall") == before  # no reference cache beside the set


@pytest.mark.parametrize("backend, typo, suggestion, valid", TYPOS)
def test_a_valid_key_still_runs(backend, typo, suggestion, valid, tmp_path):
    _available(backend)
    folder = fb.write_tick_set(tmp_path / "set", 2)
    out = tmp_path / "x.csv"
    command = ["-q", "bench", str(folder), "--backends", backend, "--set", f"{backend}.{valid}"]
    assert main(command + ["--out", str(out)]) in (0, 1)
    rows = pd.read_csv(out)
    assert len(rows) == 2 and "error" not in set(rows["status"]), rows[["status", "error"]]


def test_a_backend_without_settings_refuses_every_key(tmp_path, capsys):
    folder = fb.write_tick_set(tmp_path / "set", 1)
    out = tmp_path / "x.csv"
    assert main(["bench", str(folder), "--backends", "pinv", "--set", "pinv.eps_abs=1e-9",
                 "--out", str(out)]) == 2  # fmt: skip
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1 and "--set pinv.eps_abs" in err and "it has none" in err
    assert not out.exists()


def _defaults(name: str) -> dict:
    """Each solver's own settings with the value the installed package gives them by default."""
    if name == "daqp":
        import daqp

        return dict(daqp.Model().settings)
    if name == "piqp":
        import piqp

        s = piqp.DenseSolver().settings
    elif name == "proxqp":
        import proxsuite

        s = proxsuite.proxqp.dense.QP(1, 0, 0).settings
    elif name == "clarabel":
        import clarabel

        s = clarabel.DefaultSettings()
    own = backend_class(name).setting_names() - {"eps_abs", "eps_rel", "max_iter", "time_limit"}
    return {k: getattr(s, k) for k in own if k in dir(s)}


@pytest.mark.parametrize("name", ["daqp", "piqp", "proxqp", "clarabel"])
def test_every_listed_key_is_one_the_solver_takes(name, rng):
    """Each key the backend lists, set to the solver's own default, reaches the solver and the
    solve succeeds: the list holds no name the solver would refuse."""
    _available(name)
    from conftest import random_problem

    problem = random_problem(rng)
    expected = get_backend(name).solve(problem).x
    defaults = _defaults(name)
    own = backend_class(name).setting_names() - {"eps_abs", "eps_rel", "max_iter", "time_limit"}
    assert set(defaults) >= own - {"retry_cold"}  # every listed name is a setting of the package
    for key, value in sorted(defaults.items()):
        if key in ("verbose", "compute_timings", "pardiso_iparm"):
            continue  # prints, times, or a vector Clarabel accepts only with its Pardiso solver
        sol = get_backend(name, **{key: value}).solve(problem)
        assert sol.status == "optimal", (key, value, sol.status, sol.error)
        np.testing.assert_allclose(sol.x, expected, atol=1e-4, err_msg=key)


def test_the_backend_of_a_key_matches_without_regard_to_case():
    from qpbench.selection import backend_settings, select_backends

    backends = select_backends("DAQP")
    assert backend_settings(["DAQP.iter_limit=5"], backends) == {"daqp": {"iter_limit": 5}}
