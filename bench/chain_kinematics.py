"""Cost of the compiled chain kinematics per tick: forward kinematics, and forward kinematics
with the positions and Jacobians of every key point (the scenario's default key points and the
end effector), for the planar arm of the paper, the Panda and the iiwa 14; and, for the planar
arm, the planar closed form (cumulative angles, cos and sin) the build kernel had, as the
reference of what generality costs.

Each figure is the median over ``--repeats`` batches of the time per call of a compiled loop of
``--calls`` calls (no Python in between), so it is the cost inside a compiled tick.

    PYTHONPATH=$PWD python bench/chain_kinematics.py
"""

from __future__ import annotations

import argparse
import time

import numba
import numpy as np

from qpbench.robot.chain import chain_data, compiled_chain
from qpbench.robot.kinematics import default_key_points
from qpbench.robot.presets import make_chain


@numba.njit(cache=True)
def _planar_closed_form(lengths, theta, links, fracs, px, py, X, J):
    n = theta.shape[0]
    phi = 0.0
    for i in range(n):
        phi += theta[i]
        px[i + 1] = px[i] + lengths[i] * np.cos(phi)
        py[i + 1] = py[i] + lengths[i] * np.sin(phi)
    for j in range(links.shape[0]):
        L = links[j]
        ax = px[L] + fracs[j] * (px[L + 1] - px[L])
        ay = py[L] + fracs[j] * (py[L + 1] - py[L])
        X[j, 0], X[j, 1] = ax, ay
        for k in range(n):
            J[j, 0, k] = -(ay - py[k]) if k <= L else 0.0
            J[j, 1, k] = ax - px[k] if k <= L else 0.0


def _loop(fn):
    @numba.njit
    def run(calls, *args):
        for _ in range(calls):
            fn(*args)

    return run


def per_call(run, calls: int, repeats: int, *args) -> float:
    run(1, *args)  # compile
    times = []
    for _ in range(repeats):
        t = time.perf_counter()
        run(calls, *args)
        times.append((time.perf_counter() - t) / calls)
    return float(np.median(times))


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--calls", type=int, default=100_000)
    ap.add_argument("--repeats", type=int, default=15)
    args = ap.parse_args()
    cc = compiled_chain()
    fk, both = _loop(cc.forward_kinematics), _loop(cc.points_jacobians)
    robots = {
        "planar (paper, n=4)": make_chain("planar", link_lengths=[0.3, 0.4, 0.15, 0.15]),
        "panda": make_chain("panda"),
        "iiwa14": make_chain("iiwa14"),
    }
    print(f"{'robot':22} {'points':>6} {'FK [ns]':>8} {'FK+points+J [ns]':>17}")
    for name, model in robots.items():
        lengths = None if model.dim == 2 else model.lengths
        kp = default_key_points(model.n, 1, True, lengths=lengths)
        links = np.append(kp.links, model.n - 1)
        fracs = np.append(kp.fracs, 1.0)
        q = np.random.default_rng(0).uniform(-1, 1, model.n)
        data = chain_data(model)
        X, J = np.zeros((links.size, 3)), np.zeros((links.size, model.dim, model.n))
        t_fk = per_call(fk, args.calls, args.repeats, model, q, data)
        t_all = per_call(both, args.calls, args.repeats, model, q, data, links, fracs, X, J)
        print(f"{name:22} {links.size:6d} {t_fk * 1e9:8.0f} {t_all * 1e9:17.0f}")
        if model.dim == 2:
            px, py = np.zeros(model.n + 1), np.zeros(model.n + 1)
            X2, J2 = np.zeros((links.size, 2)), np.zeros_like(J)
            closed = _loop(_planar_closed_form)
            t_cf = per_call(
                closed, args.calls, args.repeats, model.lengths, q, links, fracs, px, py, X2, J2
            )
            assert np.allclose(J2, J, atol=1e-12) and np.allclose(X2, X[:, :2], atol=1e-12)
            print(f"{'  closed form (planar)':22} {links.size:6d} {'':>8} {t_cf * 1e9:17.0f}")


if __name__ == "__main__":
    main()
