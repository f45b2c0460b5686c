"""Eq. 1 and the lesioned models, the sigma fit, the model bootstrap and its tests,
and the easy/hard pair table (analysis.models, .sigma, .bootstrap, .pairs)."""
import numpy as np
import pandas as pd
import pytest
from scipy import stats

from analysis import (SIGMA_GRID, TRIAL_IDS, ModelInputError, bootstrap_model_correlations,
                      bootstrap_tests, choose_sigma, effort_per_trial, fit_model, fit_models,
                      pair_table, risk_at_sigma, sigma_profile, summarize_bootstrap)


def means_table(values_by_dataset):
    return pd.DataFrame([(d, t, v) for d, values in values_by_dataset.items()
                         for t, v in zip(TRIAL_IDS, values)], columns=["dataset", "trial", "mean_z"])


# ---- the three models ---------------------------------------------------------------

def test_full_model_matches_lstsq(make_effort, make_risk):
    rng = np.random.default_rng(0)
    E, R = make_effort(), risk_at_sigma(make_risk(), 0.07)
    y = pd.Series(rng.normal(size=24), index=list(TRIAL_IDS))
    fit = fit_model("full", y, E, R)
    e, r = E.to_numpy(), R.to_numpy()
    X = np.column_stack([np.ones(24), e - e * r, e * r])
    beta = np.linalg.lstsq(X, y.to_numpy(), rcond=None)[0]
    np.testing.assert_allclose(fit.coefficients, beta, rtol=1e-10)
    np.testing.assert_allclose(fit.predictions.to_numpy(), X @ beta, rtol=1e-10)
    assert fit.rmse == pytest.approx(np.sqrt(np.sum((y.to_numpy() - X @ beta) ** 2) / 24), rel=1e-10)
    assert fit.r == pytest.approx(stats.pearsonr(X @ beta, y.to_numpy())[0], rel=1e-10)


def test_full_model_recovers_coefficients_of_noise_free_data(make_effort, make_risk):
    E, R = make_effort(1), risk_at_sigma(make_risk(1), 0.08)
    y = 0.3 + 0.2 * E * (1 - R) + 1.7 * E * R
    fit = fit_model("full", y, E, R)
    np.testing.assert_allclose(fit.coefficients, [0.3, 0.2, 1.7], atol=1e-10)
    assert fit.rmse < 1e-10 and fit.r == pytest.approx(1.0)


def test_effort_only_model_is_the_simple_regression_on_effort(make_effort):
    rng = np.random.default_rng(2)
    E = make_effort(2)
    y = rng.normal(size=24)
    fit = fit_model("effort", y, E)
    e = E.to_numpy()
    slope = np.sum((e - e.mean()) * (y - y.mean())) / np.sum((e - e.mean()) ** 2)
    np.testing.assert_allclose(fit.coefficients, [y.mean() - slope * e.mean(), slope], rtol=1e-10)


def test_risk_only_correlation_is_the_size_of_the_risk_data_correlation(make_effort, make_risk):
    # A slope and intercept do not change |r| (Model section of the paper).
    rng = np.random.default_rng(3)
    R = risk_at_sigma(make_risk(3), 0.06)
    y = -2 * R.to_numpy() + rng.normal(size=24)
    fit = fit_model("risk", y, make_effort(3), R)
    assert fit.r == pytest.approx(abs(stats.pearsonr(R.to_numpy(), y)[0]), rel=1e-10)


def test_fit_models_table_has_each_dataset_and_model(make_effort, make_risk):
    rng = np.random.default_rng(4)
    E, R = make_effort(4), risk_at_sigma(make_risk(4), 0.065)
    means = means_table({"time": rng.normal(size=24), "build": rng.normal(size=24)})
    fits, predictions = fit_models(means, E, R, 0.065)
    assert sorted(zip(fits["dataset"], fits["model"])) == sorted(
        (d, m) for d in ("build", "time") for m in ("full", "effort", "risk"))
    row = fits[(fits["dataset"] == "time") & (fits["model"] == "effort")].iloc[0]
    direct = fit_model("effort", means[means["dataset"] == "time"]["mean_z"].to_numpy(), E)
    assert (row["b0"], row["b1"]) == pytest.approx(direct.coefficients) and np.isnan(row["b2"])
    assert len(predictions) == 2 * 3 * 24 and (fits["sigma"] == 0.065).all()


def test_constant_risk_gives_undefined_risk_only_correlation_with_a_warning(make_effort):
    E = make_effort(5)
    R = pd.Series(0.0, index=list(TRIAL_IDS))
    with pytest.warns(RuntimeWarning, match="risk model"):
        fit = fit_model("risk", np.arange(24.0), E, R)
    assert np.isnan(fit.r)


def test_effort_samples_are_averaged_per_trial():
    rows = [(t, s, 2.0 * k + s) for k, t in enumerate(TRIAL_IDS) for s in range(3)]
    E = effort_per_trial(pd.DataFrame(rows, columns=["trial", "sample", "effort"]))
    np.testing.assert_allclose(E.to_numpy(), 2.0 * np.arange(24) + 1.0)  # mean of s = 0, 1, 2


def test_effort_table_missing_a_trial_is_named(make_effort):
    with pytest.raises(ModelInputError, match="missing trial\\(s\\) 9H"):
        effort_per_trial(make_effort().drop("9H"))


def test_risk_at_absent_sigma_is_named(make_risk):
    with pytest.raises(ModelInputError, match="no rows at sigma 0.2"):
        risk_at_sigma(make_risk(), 0.2)


def test_risk_above_one_is_rejected_naming_the_trial(make_risk):
    risk = make_risk()
    risk.loc[(risk["trial"] == "4E") & np.isclose(risk["sigma"], 0.05), "risk"] = 1.5
    with pytest.raises(ModelInputError, match="risk of trial 4E at sigma 0.05 is 1.5"):
        risk_at_sigma(risk, 0.05)


# ---- sigma fit ----------------------------------------------------------------------

def test_sigma_profile_rmse_is_the_eq1_fit_error_at_each_sigma(make_effort, make_risk):
    rng = np.random.default_rng(6)
    E, risk = make_effort(6), make_risk(6)
    means = means_table({"difficulty": rng.normal(size=24), "time": rng.normal(size=24)})
    profile = sigma_profile(means, E, risk)
    assert len(profile) == 2 * 11 and sorted(profile["sigma"].unique()) == pytest.approx(SIGMA_GRID)
    e = E.to_numpy()
    for _, row in profile.iterrows():
        r = risk_at_sigma(risk, row["sigma"]).to_numpy()
        y = means[means["dataset"] == row["dataset"]]["mean_z"].to_numpy()
        X = np.column_stack([np.ones(24), e * (1 - r), e * r])
        residual = y - X @ np.linalg.lstsq(X, y, rcond=None)[0]
        assert row["rmse"] == pytest.approx(np.sqrt(np.mean(residual ** 2)), rel=1e-10)


def test_pooled_sigma_minimises_mean_rmse_not_each_dataset():
    profile = pd.DataFrame({"dataset": ["a"] * 3 + ["b"] * 3, "sigma": [0.05, 0.06, 0.07] * 2,
                            "rmse": [1.0, 1.1, 3.0, 3.0, 1.1, 1.0]})
    choice = choose_sigma(profile).set_index("dataset")
    assert choice.loc["a", "sigma"] == 0.05 and choice.loc["b", "sigma"] == 0.07
    assert choice.loc["pooled", "sigma"] == 0.06  # mean RMSE 2.0, 1.1, 2.0
    assert choice.loc["pooled", "rmse"] == pytest.approx(1.1)


def test_sigma_ties_go_to_the_smallest_sigma():
    profile = pd.DataFrame({"dataset": ["a"] * 3, "sigma": [0.07, 0.06, 0.05],
                            "rmse": [0.5, 0.5, 0.9]})
    assert choose_sigma(profile).set_index("dataset").loc["pooled", "sigma"] == 0.06


# ---- model bootstrap and direct tests ------------------------------------------------------

@pytest.fixture
def boot_inputs(make_effort, make_risk):
    def boot_inputs(seed=7, n_boot=40):
        rng = np.random.default_rng(seed)
        E, R = make_effort(seed), risk_at_sigma(make_risk(seed), 0.07)
        signal = (E * (1 - R) + 3 * E * R).to_numpy()
        boot_means = {d: signal / signal.std() + rng.normal(scale=s, size=(n_boot, 24))
                      for d, s in (("difficulty", 0.5), ("time", 1.0), ("build", 2.0))}
        return E, R, boot_means

    return boot_inputs


def test_bootstrap_correlations_match_explicit_refits(boot_inputs):
    E, R, boot_means = boot_inputs()
    boot = bootstrap_model_correlations(boot_means, E, R)
    e, r = E.to_numpy(), R.to_numpy()
    designs = {"full": np.column_stack([np.ones(24), e * (1 - r), e * r]),
               "effort": np.column_stack([np.ones(24), e]),
               "risk": np.column_stack([np.ones(24), r])}
    for dataset, Y in boot_means.items():
        for model, X in designs.items():
            expected = [np.corrcoef(X @ np.linalg.lstsq(X, y, rcond=None)[0], y)[0, 1] for y in Y]
            got = boot[(boot["dataset"] == dataset) & (boot["model"] == model)].sort_values("resample")
            np.testing.assert_allclose(got["r"], expected, rtol=1e-10)


def test_parallel_bootstrap_equals_serial(boot_inputs):
    E, R, boot_means = boot_inputs(n_boot=300)
    serial = bootstrap_model_correlations(boot_means, E, R, jobs=1)
    parallel = bootstrap_model_correlations(boot_means, E, R, jobs=2)
    pd.testing.assert_frame_equal(serial, parallel, check_exact=True)


def test_bootstrap_summary_reports_the_median_and_an_interval_centred_on_it(boot_inputs):
    E, R, boot_means = boot_inputs()
    boot = bootstrap_model_correlations(boot_means, E, R)
    summary = summarize_bootstrap(boot).set_index(["dataset", "model"])
    r = boot[(boot["dataset"] == "time") & (boot["model"] == "risk")]["r"].to_numpy()
    row = summary.loc[("time", "risk")]
    # without the fit's r the point is the median; the interval is the resamples' own quantiles
    # (a median-centred sample shifted back by its median)
    assert (row["r_median"], row["r_low"], row["r_high"]) == pytest.approx(
        (np.median(r), np.percentile(r, 2.5), np.percentile(r, 97.5)))
    assert row["r_low"] <= row["r_median"] <= row["r_high"]
    assert row["n_boot"] == 40


def test_bootstrap_p_is_fraction_of_resamples_where_ordering_reverses():
    # Full sample: full 0.9 > effort 0.8, and risk 0.7 > effort 0.8 is false: effort wins.
    fits = pd.DataFrame({"dataset": "d", "model": ["full", "effort", "risk"], "r": [0.9, 0.8, 0.7]})
    r_star = {"full": [0.90, 0.70, 0.85, 0.60, 0.95],
              "effort": [0.80, 0.75, 0.85, 0.50, 0.60],
              "risk": [0.70, 0.80, 0.10, 0.55, 0.20]}
    boot = pd.DataFrame([("d", k, m, v) for m, values in r_star.items() for k, v in enumerate(values)],
                        columns=["dataset", "resample", "model", "r"])
    tests = bootstrap_tests(boot, fits).set_index(["model_a", "model_b"])
    # full <= effort in resamples 1 (0.70 <= 0.75) and 2 (tie 0.85): 2 of 5.
    assert tests.loc[("full", "effort"), "p_value"] == pytest.approx(2 / 5)
    assert tests.loc[("full", "effort"), "better"] == "full"
    # full <= risk in resample 1 only.
    assert tests.loc[("full", "risk"), "p_value"] == pytest.approx(1 / 5)
    # effort beats risk in the full sample; reversed (effort <= risk) in 1 and 3.
    assert tests.loc[("effort", "risk"), "p_value"] == pytest.approx(2 / 5)
    assert tests.loc[("effort", "risk"), "better"] == "effort"


def test_bootstrap_p_uses_the_full_sample_winner_whichever_order_is_asked():
    fits = pd.DataFrame({"dataset": "d", "model": ["effort", "risk"], "r": [0.5, 0.6]})
    boot = pd.DataFrame([("d", k, m, v) for m, values in
                         {"effort": [0.5, 0.7, 0.4, 0.9], "risk": [0.6, 0.65, 0.5, 0.3]}.items()
                         for k, v in enumerate(values)], columns=["dataset", "resample", "model", "r"])
    row = bootstrap_tests(boot, fits, comparisons=[("effort", "risk")]).iloc[0]
    assert row["better"] == "risk"
    assert row["p_value"] == pytest.approx(2 / 4)  # risk <= effort in resamples 1 and 3


# ---- pair orderings -------------------------------------------------------------------

def test_pair_table_counts_eleven_of_twelve_when_pair_11_is_reversed():
    cost = {f"{p}{h}": p + (0.5 if h == "H" else 0.0) for p in range(1, 13) for h in "EH"}
    cost["11E"], cost["11H"] = 11.6, 11.2
    table = pair_table(cost)
    assert table["pair"].tolist() == list(range(1, 13))
    assert int(table["E_lt_H"].sum()) == 11
    assert table.loc[~table["E_lt_H"], "pair"].tolist() == [11]
    assert table.loc[table["pair"] == 11, ["cost_E", "cost_H"]].values.tolist() == [[11.6, 11.2]]


def test_pair_with_equal_costs_is_not_correctly_ordered():
    cost = pd.Series(1.0, index=list(TRIAL_IDS))
    assert not pair_table(cost)["E_lt_H"].any()


def test_pair_table_names_a_missing_trial(make_effort):
    with pytest.raises(ModelInputError, match="missing trial\\(s\\) 3H"):
        pair_table(make_effort().drop("3H"))
