"""The analysis on the wide sigma grid: the RMSE profile and the
chosen sigma use whatever grid the risk table has, so SIMULATED participants
drawn at a sigma past the paper's grid are fitted there."""
import numpy as np
import pandas as pd

from analysis import TRIAL_IDS, simulate_participants
from analysis.data import trial_means, zscore_responses
from analysis.sigma import choose_sigma, sigma_profile
from lgp.paper import SIGMA_GRID, WIDE_SIGMA_GRID


def test_wide_grid_is_the_papers_points_plus_every_hundredth_to_0_3():
    assert set(SIGMA_GRID) <= set(WIDE_SIGMA_GRID)
    assert WIDE_SIGMA_GRID[0] == 0.05 and WIDE_SIGMA_GRID[-1] == 0.3 and len(WIDE_SIGMA_GRID) == 26 + 5
    assert list(WIDE_SIGMA_GRID) == sorted(WIDE_SIGMA_GRID)
    assert all(any(np.isclose(s, 0.05 + 0.01 * k) for s in WIDE_SIGMA_GRID) for k in range(26))


def test_sigma_fit_finds_a_sigma_past_the_papers_grid_on_a_wide_table():
    rng = np.random.default_rng(3)
    E = pd.Series(rng.uniform(1, 10, 24), index=list(TRIAL_IDS))
    onset = rng.uniform(0.08, 0.3, 24)  # each trial's risk rises past its own onset
    rows = [(t, s, float(np.clip((s - onset[i]) / 0.08, 0, 1))) for i, t in enumerate(TRIAL_IDS) for s in WIDE_SIGMA_GRID]
    risk = pd.DataFrame(rows, columns=["trial", "sigma", "risk"])
    sim = simulate_participants(E, risk, (0.0, 1.0, 4.0), 0.2, 40, 0.05, np.random.default_rng(5))
    means = trial_means(zscore_responses(sim))
    profile = sigma_profile(means, E, risk)
    assert sorted(profile["sigma"].unique()) == sorted(WIDE_SIGMA_GRID)  # every sigma of the table, none else
    chosen = choose_sigma(profile).set_index("dataset")["sigma"]
    assert abs(chosen["pooled"] - 0.2) <= 0.02, chosen
    assert chosen["pooled"] > max(SIGMA_GRID)
