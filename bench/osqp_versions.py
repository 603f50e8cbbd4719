"""OSQP's own answer on Maros-Meszaros problems, under whichever OSQP version is installed.

qpbenchmark's published results for the large Maros-Meszaros problems were made with an
older OSQP than the one qpbench installs; this script shows what the version alone
changes, on exactly the matrices qpbench reads and stacked as ``qpsolvers``' OSQP route
stacks them (``G``, then ``A``, then the bounds as an identity block; written out here
because qpsolvers 4.x's OSQP route does not drive OSQP 0.6), with OSQP's default settings
and a time limit.

Two steps, so that the second can run in a virtual environment of its own (numpy,
scipy and the OSQP version under test, e.g. ``pip install 'osqp<0.7'``)::

    python bench/osqp_versions.py dump FILE.mat [FILE.mat ...] --out DIR     # with qpbench
    python bench/osqp_versions.py solve DIR [--time-limit 30] [--no-check-dualgap]

``solve`` prints, per problem, OSQP's version, status, iterations and solve time [s].
``--no-check-dualgap`` turns off OSQP 1.x's duality-gap stopping test (OSQP 0.6 has none).
"""

from __future__ import annotations

import argparse
import time
from pathlib import Path

import numpy as np
import scipy.sparse as spa

KEYS = ("P", "q", "G", "h", "A", "b", "lb", "ub")


def dump(files: list[str], out: Path) -> None:
    from qpbench.formats.maros_meszaros import load_maros_meszaros

    out.mkdir(parents=True, exist_ok=True)
    for name in files:
        problem = load_maros_meszaros(name)
        problem = getattr(problem, "problem", problem)
        arrays = {}
        for key, value in zip(KEYS, problem.unpack()):
            if value is None:
                continue
            if spa.issparse(value):
                value = spa.csc_matrix(value)
                arrays.update(
                    {
                        f"{key}_data": value.data,
                        f"{key}_indices": value.indices,
                        f"{key}_indptr": value.indptr,
                        f"{key}_shape": np.array(value.shape),
                    }
                )
            else:
                arrays[key] = np.asarray(value, dtype=float)
        np.savez(out / f"{Path(name).stem}.npz", **arrays)
        print(f"{Path(name).stem}: written")


def _read(path: Path) -> dict:
    z = np.load(path)
    got = {}
    for key in KEYS:
        if f"{key}_data" in z:
            got[key] = spa.csc_matrix(
                (z[f"{key}_data"], z[f"{key}_indices"], z[f"{key}_indptr"]),
                shape=tuple(z[f"{key}_shape"]),
            )
        elif key in z:
            got[key] = z[key]
    return got


def solve(folder: Path, time_limit: float, check_dualgap: bool) -> None:
    import osqp

    for path in sorted(folder.glob("*.npz")):
        p = _read(path)
        n = p["q"].shape[0]
        blocks, lower, upper = [], [], []
        if "G" in p:
            (
                blocks.append(p["G"]),
                lower.append(np.full(p["h"].shape, -np.inf)),
                upper.append(p["h"]),
            )
        if "A" in p:
            blocks.append(p["A"]), lower.append(p["b"]), upper.append(p["b"])
        if "lb" in p or "ub" in p:
            blocks.append(spa.eye(n, format="csc"))
            lower.append(p.get("lb", np.full(n, -np.inf)))
            upper.append(p.get("ub", np.full(n, np.inf)))
        settings = {"verbose": False, "time_limit": time_limit}
        if not check_dualgap:
            settings["check_dualgap"] = False
        solver = osqp.OSQP()
        solver.setup(
            P=spa.csc_matrix(p["P"]),
            q=p["q"],
            A=spa.vstack(blocks, format="csc"),
            l=np.hstack(lower),
            u=np.hstack(upper),
            **settings,
        )
        start = time.perf_counter()
        result = solver.solve()
        seconds = time.perf_counter() - start
        print(
            f"{path.stem:10s} osqp {osqp.__version__:12s} {result.info.status:32s} "
            f"{result.info.iter:6d} iterations {seconds:8.2f} s"
        )


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    sub = parser.add_subparsers(dest="step", required=True)
    d = sub.add_parser("dump", help="write the problems as qpbench reads them (needs qpbench)")
    d.add_argument("files", nargs="+")
    d.add_argument("--out", type=Path, required=True)
    s = sub.add_parser("solve", help="solve every dumped problem with the installed OSQP")
    s.add_argument("folder", type=Path)
    s.add_argument("--time-limit", type=float, default=30.0)
    s.add_argument("--no-check-dualgap", action="store_true")
    args = parser.parse_args()
    if args.step == "dump":
        dump(args.files, args.out)
    else:
        solve(args.folder, args.time_limit, check_dualgap=not args.no_check_dualgap)


if __name__ == "__main__":
    main()
