"""The analysis recovers what simulated participants were built from, and the
pipeline labels everything made from them as simulated (analysis.simulate,
analysis.run, analysis.figures). Simulated participants exist for these tests
only; they are not, and never stand in for, the paper's human data."""
from pathlib import Path

import numpy as np
import pandas as pd
import pytest
from PIL import Image

from analysis import (SIGMA_GRID, TRIAL_IDS, HumanDataError, bootstrap_trial_means, choose_sigma,
                      fit_model, full_model_cost, load_human_data, risk_at_sigma, run_analysis,
                      sigma_profile, simulate_participants, trial_means, zscore_responses)
from analysis.figures import SIMULATED_TITLE, plot_effort_risk

BETAS = (0.0, 1.0, 4.0)  # risky effort costs four times safe effort


@pytest.fixture(scope="module")
def E(make_effort):
    return make_effort()


@pytest.fixture(scope="module")
def RISK(make_risk):
    return make_risk()


@pytest.fixture
def simulate(E, RISK):
    def simulate(sigma, n, noise_sd, seed, datasets=("difficulty", "time", "build")):
        return simulate_participants(E, RISK, BETAS, sigma, n, noise_sd, np.random.default_rng(seed),
                                     datasets=datasets)

    return simulate


def test_simulated_participants_are_labelled_and_refused_as_human_data(tmp_path, simulate):
    sim = simulate(0.075, 3, 1.0, seed=0)
    assert sorted(sim["dataset"].unique()) == ["simulated-build", "simulated-difficulty",
                                               "simulated-time"]
    assert list(sim.columns) == ["dataset", "participant", "trial", "response"]
    assert len(sim) == 3 * 3 * 24
    path = tmp_path / "sim.csv"
    sim.to_csv(path, index=False)
    with pytest.raises(HumanDataError, match="line 2: unknown dataset 'simulated-difficulty'"):
        load_human_data(path)


def test_noise_free_simulation_recovers_betas_up_to_the_zscore_map(E, RISK, simulate):
    # Z-scoring maps the latent cost y to (y - mean y)/sd y whatever each participant's
    # scale and offset, so Eq. 1 fit to z-scored means has b1/sd, b2/sd, (b0 - mean)/sd.
    means = trial_means(zscore_responses(simulate(0.075, 5, 0.0, seed=1, datasets=("time",))))
    R = risk_at_sigma(RISK, 0.075)
    y = full_model_cost(E, R, BETAS).to_numpy()
    fit = fit_model("full", means.set_index("trial")["mean_z"], E, R)
    np.testing.assert_allclose(fit.coefficients, [(BETAS[0] - y.mean()) / y.std(),
                                                  BETAS[1] / y.std(), BETAS[2] / y.std()],
                               rtol=1e-8, atol=1e-10)
    assert fit.rmse < 1e-10


def test_noisy_simulation_recovers_the_ratio_of_risky_to_safe_effort_cost(E, RISK, simulate):
    # With noise only the shape of y is identifiable: b2/b1 and the predictions up
    # to a positive affine map (z-scoring divides by a noise-inflated SD).
    R = risk_at_sigma(RISK, 0.075)
    y = full_model_cost(E, R, BETAS).to_numpy()
    for seed in range(3):
        means = trial_means(zscore_responses(simulate(0.075, 40, 2.0, seed, datasets=("time",))))
        fit = fit_model("full", means.set_index("trial")["mean_z"], E, R)
        b0, b1, b2 = fit.coefficients
        assert b2 / b1 == pytest.approx(BETAS[2] / BETAS[1], rel=0.10)
        assert np.corrcoef(fit.predictions, y)[0, 1] > 0.995


@pytest.mark.parametrize("true_sigma", [0.06, 0.075, 0.09])
def test_sigma_fit_recovers_true_sigma(true_sigma, E, RISK, simulate):
    for seed in range(2):
        sim = simulate(true_sigma, 40, 2.0, seed)
        profile = sigma_profile(trial_means(zscore_responses(sim)), E, RISK)
        choice = choose_sigma(profile).set_index("dataset")["sigma"]
        assert len(choice) == 4  # three datasets and the pooled choice
        step = 0.005 + 1e-9
        assert (abs(choice - true_sigma) <= step).all(), choice.to_dict()


def test_bootstrap_intervals_cover_truth(simulate):
    # The estimand is the expected mean z-score of a trial over the population of
    # simulated participants. With response noise this is not exactly z(y): each
    # participant divides by the SD of their own noisy responses. So the truth is
    # computed, with numpy only, from 20000 participants (Monte Carlo error
    # ~0.01 of the interval half-width).
    noise_sd, n = 6.0, 30
    big = simulate(0.075, 20000, noise_sd, seed=999, datasets=("time",))
    X = big["response"].to_numpy().reshape(-1, 24)
    Z = (X - X.mean(axis=1, keepdims=True)) / X.std(axis=1, keepdims=True)
    truth, sd_z = Z.mean(axis=0), Z.std(axis=0)
    covered, width_ratio = [], []
    for rep in range(10):
        sim = simulate(0.075, n, noise_sd, seed=rep, datasets=("time",))
        ci = bootstrap_trial_means(zscore_responses(sim), 1000, np.random.default_rng(100 + rep))
        covered += list((ci["ci_low"] <= truth) & (truth <= ci["ci_high"]))
        width_ratio += list((ci["ci_high"] - ci["ci_low"]) / 2 / (1.96 * sd_z / np.sqrt(n)))
    assert len(covered) == 240
    assert 0.85 <= np.mean(covered) <= 1.0
    # ... and not by being wide: half-widths match the normal-theory 1.96 SE.
    assert 0.8 <= np.mean(width_ratio) <= 1.2


@pytest.mark.slow
def test_run_analysis_on_simulated_participants_writes_labelled_tables_and_figures(tmp_path, E, RISK, simulate):
    sim = simulate(0.075, 25, 2.0, seed=5)
    out = run_analysis(sim, E, RISK, tmp_path, seed=1, n_boot=200, jobs=1)
    settings = out["settings"].iloc[0]
    assert bool(settings["simulated"]) and not bool(settings["human_data"])
    assert settings["sigma"] == pytest.approx(0.075)
    summary = out["bootstrap_summary"].set_index(["dataset", "model"])
    for dataset in ("simulated-difficulty", "simulated-time", "simulated-build"):
        assert summary.loc[(dataset, "full"), "r_low"] > summary.loc[(dataset, "effort"), "r_high"]
        assert len(out["orderings"].query("dataset == @dataset and source == 'full'")) == 12
    assert len(out["bootstrap_correlations"]) == 3 * 3 * 200
    assert len(out["bootstrap_tests"]) == 3 * 3
    # Every file name says simulated, every figure title says simulated participants.
    paths = out["files"]["path"].tolist()
    assert all("simulated" in p.split("/")[-1] for p in paths)
    for key in ("fits", "sigma_profile", "bootstrap_tests", "orderings", "trial_means"):
        assert (tmp_path / f"simulated_{key}.csv").exists()
    pngs = [p for p in paths if p.endswith(".png")]
    assert len(pngs) == 5 and sum(p.endswith(".pdf") for p in paths) == 5  # Fig. 3, 4, its comparison, sigma, pairs
    for png in pngs:
        assert Image.open(png).text["Title"].startswith(SIMULATED_TITLE)


@pytest.mark.slow  # the analysis with its figures
def test_run_analysis_without_human_data_writes_pairs_and_effort_risk_figure(tmp_path, E, RISK):
    out = run_analysis(None, E, RISK, tmp_path, seed=0)
    assert out["settings"].iloc[0]["sigma"] == pytest.approx(0.065)
    assert out["orderings"]["source"].value_counts().to_dict() == {"effort": 12, "risk": 12}
    png = tmp_path / "effort_risk_pairs.png"
    assert png.exists() and (tmp_path / "effort_risk_pairs.pdf").exists()
    assert "SIMULATED" not in Image.open(png).text["Title"]
    assert not any("simulated" in p for p in out["files"]["path"])
    # files.csv names its files relative to its own folder: true after the folder is moved
    moved = tmp_path.parent / (tmp_path.name + "-moved")
    tmp_path.rename(moved)
    listed = pd.read_csv(moved / "files.csv")["path"]
    assert len(listed) == len(out["files"]) and not any(Path(p).is_absolute() for p in listed)
    assert all((moved / p).is_file() for p in listed)


def test_effort_risk_figure_with_fitted_betas_is_written_as_png_and_pdf(tmp_path, E, RISK):
    paths = plot_effort_risk(E, RISK, 0.07, tmp_path, betas=BETAS, stem="er")
    assert [p.name for p in paths] == ["er.png", "er.pdf"]
    with Image.open(paths[0]) as image:
        assert image.size[0] > 600 and image.size[1] > 600


def test_run_analysis_refuses_a_csv_of_simulated_participants_as_human_data(tmp_path, E, RISK, simulate):
    path = tmp_path / "responses.csv"
    simulate(0.075, 3, 1.0, seed=6).to_csv(path, index=False)
    with pytest.raises(HumanDataError, match="simulated participants are not human data"):
        run_analysis(path, E, RISK, tmp_path / "out", seed=0, n_boot=10, jobs=1)


@pytest.mark.slow
def test_demo_labels_every_output_as_simulated(tmp_path, quick_run):
    from analysis import demo

    # a real (small) model run: the session's --quick run of every trial (conftest.QUICK_RUN), read only
    demo.main(["--results", str(quick_run), "--out", str(tmp_path / "sim"), "--n-boot", "20"])
    written = list((tmp_path / "sim").iterdir())
    assert written and all(p.name.startswith("simulated_") for p in written)
    # the heuristic baselines are in its comparison, fitted like effort-only, on folds by structure
    from analysis.spec import HEURISTIC_MODELS

    mc = pd.read_csv(tmp_path / "sim" / "simulated_model_comparison.csv")
    assert set(HEURISTIC_MODELS) <= set(mc["model"])
    assert "1E 1H 9E 9H 11E 11H" in pd.read_csv(tmp_path / "sim" / "simulated_settings.csv")["folds_by_structure"].iloc[0]
