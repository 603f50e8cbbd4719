"""The p99 call time's interval of a run (qpbench.sim.summary.block_bootstrap_quantile): the
shortcut that counts only the largest values against every resample drawn whole, its coverage of
a known p99 (i.i.d. and serially correlated series), and its place in a run's summary."""

from __future__ import annotations

import math

import numpy as np
import pytest

from qpbench.sim.summary import block_bootstrap_quantile

#: Series per coverage test, and resamples per interval; at a level of 0.95 the share of
#: series whose interval holds the truth has a standard deviation of about 0.022 over 100.
SERIES = 100
RESAMPLES = 300


def whole_resamples(x, q, block, level=0.95, resamples=1000, seed=0):
    """The same interval with every resample drawn and sorted whole (the draws of the function)."""
    n = x.size
    block = min(block, n)
    k = max(1, round(n / block))
    m = k * block
    starts = np.sort(np.random.default_rng(seed).integers(0, n, size=(resamples, k)), axis=1)
    rank = math.ceil(round(q * m, 9))
    stats = [np.sort(x[((s[:, None] + np.arange(block)) % n).ravel()])[rank - 1] for s in starts]
    alpha = (1 - level) / 2
    return tuple(np.quantile(stats, [alpha, 1 - alpha]))


@pytest.mark.parametrize(
    "n, block", [(2000, 50), (1000, 50), (1037, 7), (500, 1), (30, 100), (5, 2), (401, 400)]
)
def test_counting_the_largest_values_gives_the_whole_resamples_interval(n, block):
    x = np.random.default_rng(n).lognormal(size=n)
    assert block_bootstrap_quantile(x, 0.99, block) == pytest.approx(
        whole_resamples(x, 0.99, block), rel=0, abs=0
    )


def test_heavy_ties_and_non_finite_values():
    x = np.r_[np.full(300, 1e-4), np.full(5, 9e-4), [np.nan, np.inf]]
    lo, hi = block_bootstrap_quantile(x, 0.99, 10)
    assert 1e-4 <= lo <= hi <= 9e-4
    assert block_bootstrap_quantile(np.full(50, 3.0), 0.99, 5) == (3.0, 3.0)
    assert all(math.isnan(v) for v in block_bootstrap_quantile(np.array([np.nan]), 0.99, 5))


def test_seeded():
    x = np.random.default_rng(3).exponential(size=3000)
    assert block_bootstrap_quantile(x, 0.99, 30) == block_bootstrap_quantile(x.copy(), 0.99, 30)


def coverage(series, truth, block) -> float:
    """The share of ``series`` whose interval holds ``truth``."""
    intervals = (block_bootstrap_quantile(x, 0.99, block, resamples=RESAMPLES) for x in series)
    return float(np.mean([lo <= truth <= hi for lo, hi in intervals]))


def test_an_iid_sample_holds_the_true_p99_at_about_the_level():
    """Exponential(1) ticks: p99 = ln 100; single ticks and blocks of 40 both near 0.95."""
    rng = np.random.default_rng(11)
    series = [rng.exponential(size=4000) for _ in range(SERIES)]
    truth = math.log(100.0)
    assert 0.88 <= coverage(series, truth, 1) <= 0.99
    assert 0.88 <= coverage(series, truth, 40) <= 0.99


def test_blocks_keep_the_spread_of_a_serially_correlated_series():
    """A stationary AR(1) series (phi = 0.95, as slow phases of solve times): its p99 is
    2.3263 sigma / sqrt(1 - phi^2). Resampling single ticks takes the series for far more
    independent data than it is and misses the truth about half the time; blocks of 200 ticks
    hold it near the level."""
    from scipy.signal import lfilter

    rng = np.random.default_rng(5)
    phi, n = 0.95, 4000
    sigma = 1.0 / math.sqrt(1 - phi**2)
    series = []
    for _ in range(SERIES):
        e = rng.standard_normal(n)
        e[0] *= sigma  # started in the stationary distribution
        series.append(lfilter([1.0], [1.0, -phi], e))
    truth = 2.326347874 * sigma
    assert coverage(series, truth, 1) < 0.65
    assert coverage(series, truth, 200) >= 0.8


def test_a_run_summary_bounds_its_p99():
    from qpbench.sim.loop import simulate
    from qpbench.sim.scenario import load_scenario
    from qpbench.sim.summary import BOOTSTRAP_BLOCK_S

    scenario = load_scenario("wall")
    result = simulate(scenario, "pinv", duration=0.4)
    s = result.summary
    assert s["rank_time_source"] == "compiled"  # pinv runs on the compiled engine
    assert s["rank_time_p99_lo_s"] <= s["rank_time_p99_s"] <= s["rank_time_p99_hi_s"]
    times = (result.log["solve_time_s"] + result.log["fallback_solve_time_s"].fillna(0)).to_numpy()
    block = round(BOOTSTRAP_BLOCK_S / scenario.dt)
    lo, hi = block_bootstrap_quantile(times, 0.99, block)
    assert (s["rank_time_p99_lo_s"], s["rank_time_p99_hi_s"]) == (lo, hi)
