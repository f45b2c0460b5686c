"""Each participant's sigma (analysis/participant_sigma.py): recovery with near-
nominal coverage where risk depends on sigma, honest (wide) intervals where it
does not. Every participant here is SIMULATED."""
from pathlib import Path

import numpy as np
import pandas as pd
import pytest

from analysis import simulate_participants
from analysis.participant_sigma import fit_participant_sigma, interpolated_risk, profile_interval
from lgp.paper import SIGMA_GRID, TRIAL_IDS

ROOT = Path(__file__).resolve().parent.parent


def sigma_sensitive_table(rng):
    """Synthetic risk: trial i's risk rises as a logistic in sigma around its own
    threshold c_i, thresholds spread over and beyond the grid."""
    c = np.linspace(0.045, 0.105, len(TRIAL_IDS))
    rng.shuffle(c)
    rows = [(t, s, 1 / (1 + np.exp(-(s - ci) / 0.01))) for t, ci in zip(TRIAL_IDS, c) for s in SIGMA_GRID]
    return pd.DataFrame(rows, columns=["trial", "sigma", "risk"])


def simulate_own_sigmas(effort, table, sigmas, rng, noise_sd=0.5, betas=(0.0, 1.0, 4.0)):
    frames = []
    for p, s in enumerate(sigmas):
        d = simulate_participants(effort, table, betas, s, 1, noise_sd, rng, datasets=["time"])
        frames.append(d.assign(participant=f"sim-{p:03d}"))
    return pd.concat(frames, ignore_index=True)


@pytest.fixture(scope="module")
def synthetic():
    rng = np.random.default_rng(11)
    effort = pd.Series(rng.uniform(1, 4, len(TRIAL_IDS)), index=list(TRIAL_IDS))
    table = sigma_sensitive_table(rng)
    truth = rng.choice(SIGMA_GRID, size=80)
    return effort, table, truth, simulate_own_sigmas(effort, table, truth, rng)


@pytest.mark.parametrize("betas", ["shared", "participant"])
def test_known_sigmas_are_recovered_with_near_nominal_coverage(synthetic, betas):
    effort, table, truth, responses = synthetic
    out = fit_participant_sigma(responses, effort, table, betas=betas, level=0.95)
    assert (out["dataset"] == "simulated-time").all() and len(out) == len(truth)
    order = out["participant"].str[4:].astype(int).to_numpy()
    true = truth[order]
    covered = (out["sigma_low"] <= true + 1e-9) & (true <= out["sigma_high"] + 1e-9)
    # 80 participants: a 95% interval covers 76 on average; binomial 2.5% tail ~ 71
    assert covered.mean() >= 0.85, covered.mean()
    assert np.corrcoef(out["sigma"], true)[0, 1] > 0.9
    assert out["identified"].all()
    assert np.median(out["sigma_high"] - out["sigma_low"]) < 0.02  # of a 0.05 d range


def test_intervals_are_wide_on_the_real_flat_risk_table(synthetic):
    effort, _, _, _ = synthetic
    real = pd.read_csv(ROOT / "docs" / "risk_table.csv", dtype={"trial": str})
    rng = np.random.default_rng(3)
    responses = simulate_own_sigmas(effort, real, rng.choice([0.05, 0.075, 0.1], size=30), rng)
    out = fit_participant_sigma(responses, effort, real)
    width = out["sigma_high"] - out["sigma_low"]
    # the real curves barely move over sigma (docs/risk.md): no participant is pinned down
    assert np.median(width) > 0.5 * (max(SIGMA_GRID) - min(SIGMA_GRID))
    assert (out["low_censored"] | out["high_censored"]).all()  # every interval runs to an end of the grid


def test_flat_risk_gives_the_whole_range_not_a_false_point(synthetic):
    effort, table, truth, responses = synthetic
    flat = table.assign(risk=0.3)
    out = fit_participant_sigma(responses, effort, flat)
    assert (out["sigma_low"] == min(SIGMA_GRID)).all() and (out["sigma_high"] == max(SIGMA_GRID)).all()
    assert not out["identified"].any()


def test_interpolation_is_linear_between_grid_points_and_refuses_extrapolation():
    table = pd.DataFrame([(t, s, 2 * s) for t in TRIAL_IDS for s in (0.05, 0.1)], columns=["trial", "sigma", "risk"])
    R = interpolated_risk(table, [0.05, 0.0625, 0.1])
    assert np.allclose(R[:, 0], [0.1, 0.125, 0.2])
    with pytest.raises(ValueError, match="outside"):
        interpolated_risk(table, [0.12])


def test_profile_interval_is_the_chi_square_cut():
    sigmas = np.array([0.05, 0.06, 0.07, 0.08])
    rss = np.array([[20.0, 10.0, 10.0 * np.exp(3.0 / 24), 30.0]])  # 24 log(ratio) = 3.0 < 3.84 at 0.07
    low, high, lc, hc = profile_interval(sigmas, rss, 24, 0.95)
    assert (low[0], high[0], lc[0], hc[0]) == (0.06, 0.07, False, False)


def test_bad_betas_option_is_refused(synthetic):
    effort, table, _, responses = synthetic
    with pytest.raises(ValueError, match="betas"):
        fit_participant_sigma(responses, effort, table, betas="pooled")


def test_histogram_figure_is_labelled_simulated(synthetic, tmp_path):
    from analysis.figures import plot_participant_sigma

    effort, table, _, responses = synthetic
    paths = plot_participant_sigma(fit_participant_sigma(responses, effort, table), tmp_path)
    assert [p.name for p in paths] == ["simulated_participant_sigma.png", "simulated_participant_sigma.pdf"]
    from PIL import Image

    assert "SIMULATED" in Image.open(paths[0]).info.get("Title", "")
