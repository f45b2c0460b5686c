"""Required precision sigma* (models/risk/precision.py): the noise level at which
a trial's risk first reaches a level, interpolated on the grid, with a bootstrap
interval over runs and censoring where the grid never reaches the level."""
import numpy as np
import pandas as pd
import pytest

from models.risk import risk_table
from models.risk.core import wilson_interval
from models.risk.precision import check_levels, first_crossing, precision_text, required_precision
from models.risk.structures import two_block


def runs_table(curve, sigmas, n=200, trial="T"):
    """Runs whose fall pattern gives exactly the risk `curve`: run r falls at sigma s
    when r < curve(s) * n (nested, as common random numbers make a monotone curve)."""
    rows = [(trial, s, r, r < round(p * n)) for s, p in zip(sigmas, curve) for r in range(n)]
    return pd.DataFrame(rows, columns=["trial", "sigma", "run", "fell"])


def test_sigma_star_is_the_linear_interpolation_of_the_first_crossing():
    sigmas = np.array([0.1, 0.2, 0.3, 0.4])
    out = required_precision(runs_table([0.0, 0.2, 0.6, 0.9], sigmas), levels=(0.5, 0.1), n_boot=200)
    half = out[out["level"] == 0.5].iloc[0]
    tenth = out[out["level"] == 0.1].iloc[0]
    assert half["sigma_star"] == pytest.approx(0.2 + (0.5 - 0.2) / (0.6 - 0.2) * 0.1)  # 0.275
    assert tenth["sigma_star"] == pytest.approx(0.1 + 0.1 / 0.2 * 0.1)  # 0.15
    assert half["censored"] == "none" and half["sigma_low"] <= half["sigma_star"] <= half["sigma_high"]


def test_a_curve_that_never_reaches_the_level_is_right_censored_and_one_that_starts_above_it_left():
    sigmas = np.array([0.05, 0.1])
    flat = required_precision(runs_table([0.0, 0.02], sigmas), levels=(0.5,), n_boot=50).iloc[0]
    assert flat["censored"] == "right" and np.isnan(flat["sigma_star"]) and np.isinf(flat["sigma_high"])
    assert precision_text(flat) == "> 0.1 d"
    high = required_precision(runs_table([0.7, 0.9], sigmas), levels=(0.5,), n_boot=50).iloc[0]
    assert high["censored"] == "left" and precision_text(high) == "<= 0.05 d"


def test_first_crossing_takes_the_first_not_the_last_crossing_of_a_noisy_curve():
    sigmas = np.array([1.0, 2.0, 3.0, 4.0])
    assert first_crossing(sigmas, np.array([[0.0, 0.6, 0.4, 0.8]]), 0.5)[0] == pytest.approx(1 + 0.5 / 0.6)


def test_bootstrap_interval_shrinks_with_more_runs_and_covers_the_truth():
    # a trial whose risk is exactly p(sigma) = sigma (runs drawn independently per run):
    # sigma* at level 0.5 is 0.5; the bootstrap interval from 400 runs must cover it
    rng = np.random.default_rng(0)
    sigmas = np.linspace(0.1, 0.9, 9)
    widths = []
    for n in (100, 1600):
        u = rng.random(n)  # run r falls at every sigma > u_r: a monotone curve per run, as with common random numbers
        runs = pd.DataFrame([("T", s, r, s > u[r]) for s in sigmas for r in range(n)], columns=["trial", "sigma", "run", "fell"])
        row = required_precision(runs, levels=(0.5,), n_boot=400, seed=1).iloc[0]
        assert row["sigma_low"] <= 0.5 <= row["sigma_high"], row
        widths.append(row["sigma_high"] - row["sigma_low"])
    assert widths[1] < widths[0] / 2.5  # ~1/sqrt(n): 4x narrower for 16x the runs


def test_on_a_marginal_stack_sigma_star_lies_where_its_risk_curve_crosses():
    sigmas = [0.05, 0.1, 0.15, 0.2, 0.3]
    runs = risk_table([two_block(0.4)], sigmas, n_sims=40, seed=0, jobs=1, runs=True)
    table = risk_table([two_block(0.4)], sigmas, n_sims=40, seed=0, jobs=1)
    row = required_precision(runs, levels=(0.5,), n_boot=200).iloc[0]
    risk = table["risk"].to_numpy()
    if row["censored"] == "none":
        k = int(np.argmax(risk >= 0.5))
        assert sigmas[k - 1] <= row["sigma_star"] <= sigmas[k]
    else:
        assert (risk < 0.5).all() if row["censored"] == "right" else risk[0] >= 0.5


def test_precision_levels_outside_zero_one_are_refused():
    for bad in (0, 1, 1.5, -0.1, "x"):
        with pytest.raises(ValueError, match=r"precision level must be a risk in \(0, 1\)"):
            check_levels([bad])


def test_wilson_interval_matches_its_closed_form():
    low, high = wilson_interval(0, 100)
    assert low == 0 and high == pytest.approx(1.959963984540054 ** 2 / (100 + 1.959963984540054 ** 2))  # 0.0370
    low, high = wilson_interval(50, 100)
    assert (low, high) == pytest.approx((0.4038, 0.5962), abs=1e-4)
    low, high = wilson_interval(np.array([2, 17]), np.array([100, 100]))
    assert low[0] > 0 and high[1] < 0.27 and low[1] > 0.10
