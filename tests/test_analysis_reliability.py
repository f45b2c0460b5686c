"""The noise ceiling (analysis.reliability): split-half reliability of the trial
means with the Spearman-Brown correction, on SIMULATED participants whose true
trial means and noise are known, against classical test theory's closed form
var(mu) / (var(mu) + sigma^2 / n); its interval always holds its point."""
import numpy as np
import pandas as pd
import pytest

from analysis import TRIAL_IDS
from analysis.reliability import METHOD, noise_ceiling, spearman_brown


def _participants(mu, n, sigma, rng, dataset="simulated-time"):
    Z = mu[None] + sigma * rng.standard_normal((n, len(mu)))
    return pd.DataFrame({"dataset": dataset, "participant": np.repeat([f"p{k:03d}" for k in range(n)], len(mu)),
                         "trial": np.tile(list(TRIAL_IDS), n), "z": Z.reshape(-1)})


def test_spearman_brown_is_the_reliability_of_two_halves_together():
    assert spearman_brown(0.5) == pytest.approx(2 / 3)
    assert spearman_brown(np.array([0.0, 1.0])).tolist() == [0.0, 1.0]


def test_split_half_reliability_matches_classical_test_theory_on_simulated_participants():
    rng = np.random.default_rng(0)
    mu = rng.standard_normal(24)
    n, sigma = 80, 3.0
    data = pd.concat([_participants(mu, n, sigma, rng), _participants(mu, 3, sigma, rng, "simulated-build")])
    table = noise_ceiling(data, np.random.default_rng(1), n_splits=400, n_boot=200).set_index("dataset")
    row = table.loc["simulated-time"]
    expected = np.var(mu) / (np.var(mu) + sigma ** 2 / n)      # 0.86 here
    assert row["reliability"] == pytest.approx(expected, abs=0.05)
    assert row["r_ceiling"] == pytest.approx(np.sqrt(row["reliability"]))
    assert row["reliability_low"] <= row["reliability"] <= row["reliability_high"]
    assert row["r_ceiling_low"] <= row["r_ceiling"] <= row["r_ceiling_high"] <= 1
    assert row["participants"] == n and row["method"] == METHOD
    assert np.isnan(table.loc["simulated-build", "reliability"])   # 3 participants: no two halves of 2


def test_noise_alone_has_no_reliability_and_the_same_seed_gives_the_same_table():
    rng = np.random.default_rng(4)
    data = _participants(np.zeros(24), 60, 1.0, rng)
    a = noise_ceiling(data, np.random.default_rng(2), n_splits=200, n_boot=100)
    b = noise_ceiling(data, np.random.default_rng(2), n_splits=200, n_boot=100)
    pd.testing.assert_frame_equal(a, b)
    assert abs(a["split_half_r"].iloc[0]) < 0.15
