"""Model comparisons that can fail (analysis.crossval, .permutation, .recovery):
held-out predictions equal least squares refit without the held-out trials, folds
never see them, the in-sample full-vs-effort test cannot fail while the
out-of-sample one can, permutation p-values are uniform under a null and small
for a planted effect, and model recovery on SIMULATED participants (never human
data) finds the true model out of sample."""
import json
import subprocess
import sys
from pathlib import Path

import numpy as np
import pandas as pd
import pytest
from scipy import stats

from analysis import (TRIAL_IDS, bootstrap_model_correlations, resample_trial_means, risk_at_sigma,
                      run_analysis, simulate_participants, trial_means, zscore_responses)
from analysis.crossval import (SCHEMES, STRUCTURE_SCHEME, CrossValidationError, RiskGrid, bootstrap_comparison, cross_validate,
                               make_folds, model_comparison, redraw_risk, risk_grid, scores, verdicts)
from analysis.data import HumanDataError
from lgp.errors import InputError
from analysis.permutation import KINDS, check_count, draw_permutations, permutation_test
from analysis.recovery import model_cost, recovery, simulate_trial_means

MODELS3 = ["full", "effort", "risk"]


@pytest.fixture(scope="module")
def E(make_effort):
    return make_effort()


@pytest.fixture(scope="module")
def RISK(make_risk):
    return make_risk()


def zero_heavy_risk(seed=0, sigmas=(0.05, 0.065, 0.08, 0.1)):
    """Like our table: most trials never fall, three do, more with sigma."""
    rng = np.random.default_rng(seed)
    risky = rng.choice(24, 3, replace=False)
    rows = []
    for s in sigmas:
        for i, t in enumerate(TRIAL_IDS):
            rows.append((t, s, round(float(np.clip((s - 0.045) * rng.uniform(2, 6), 0, 1)), 2) if i in risky else 0.0, 100))
    return pd.DataFrame(rows, columns=["trial", "sigma", "risk", "n"])


def brute_force(Y, E, grid, scheme):
    """Held-out predictions by an explicit loop: numpy.linalg.lstsq on the training
    rows of each fold, sigma by the least mean training RMSE of Eq. 1 (the paper's
    form), ties (relative difference below 1e-9) to the smaller sigma. Where Eq. 1's E*R column has nothing beyond
    1 and E in training, the minimum-norm fit of y = b0 + b1 E + c E R (c = 0)."""
    train, test = make_folds(scheme)
    B, D, T = Y.shape
    out = {m: np.full((B, D, T), np.nan) for m in MODELS3}
    for b in range(B):
        for tr, te in zip(train, test):
            crit = []
            for R in grid.risk:
                X = np.column_stack([np.ones(T), E * (1 - R), E * R])
                crit.append(np.mean([np.sqrt(np.mean((Y[b, d, tr] - X[tr] @ np.linalg.lstsq(X[tr], Y[b, d, tr], rcond=None)[0]) ** 2))
                                     for d in range(D)]))
            # Ties explicit: RMSEs within 1e-9 (relative) of the least are equal; the smallest sigma wins.
            R = grid.risk[min(k for k, c in enumerate(crit) if c <= min(crit) * (1 + 1e-9) + 1e-12)]
            ER = E * R
            resid = ER[tr] - np.column_stack([np.ones(len(tr)), E[tr]]) @ np.linalg.lstsq(
                np.column_stack([np.ones(len(tr)), E[tr]]), ER[tr], rcond=None)[0]
            if np.linalg.norm(resid) <= 1e-9 * np.linalg.norm(ER[tr]) or not ER[tr].any():
                Xf = np.column_stack([np.ones(T), E])       # c = 0: effort-only
            else:
                Xf = np.column_stack([np.ones(T), E * (1 - R), E * R])
            Xr = np.column_stack([np.ones(T), R]) if np.ptp(R[tr]) > 0 else np.ones((T, 1))
            for d in range(D):
                for name, X in (("full", Xf), ("effort", np.column_stack([np.ones(T), E])), ("risk", Xr)):
                    out[name][b, d, te] = X[te] @ np.linalg.lstsq(X[tr], Y[b, d, tr], rcond=None)[0]
    return out


@pytest.mark.parametrize("scheme", SCHEMES)
@pytest.mark.parametrize("table", ["logistic", "mostly zero"])
def test_held_out_predictions_are_least_squares_refit_without_the_held_out_trials(scheme, table, E, RISK):
    risk = RISK if table == "logistic" else zero_heavy_risk(1)
    grid = risk_grid(risk)
    Y = np.random.default_rng(3).normal(size=(3, 2, 24)) + E.to_numpy()
    preds, _, _ = cross_validate(Y, E.to_numpy(), {"R": grid.risk}, MODELS3, scheme)
    expected = brute_force(Y, E.to_numpy(), grid, scheme)
    for m in MODELS3:
        np.testing.assert_allclose(preds[m], expected[m], rtol=0, atol=1e-10)


def _prediction_moves_when_held_out_responses_change(scheme, E, grid) -> bool:
    """Change the responses of each fold's held-out trials: does that fold's
    prediction of them change? (It must not out of sample: no leak.)"""
    rng = np.random.default_rng(0)
    Y = rng.normal(size=(1, 3, 24)) + E.to_numpy()
    base, chosen, test = cross_validate(Y, E.to_numpy(), {"R": grid.risk}, MODELS3, scheme)
    moved = False
    for held in test:
        Y2 = Y.copy()
        Y2[..., held] += 100.0 * rng.normal(size=(1, 3, len(held)))
        new, chosen2, _ = cross_validate(Y2, E.to_numpy(), {"R": grid.risk}, MODELS3, scheme)
        for m in MODELS3:
            moved |= not np.allclose(new[m][..., held], base[m][..., held], rtol=0, atol=1e-12)
    return moved


def test_folds_never_see_the_held_out_trials(E, RISK):
    grid = risk_grid(RISK)
    for scheme in ("leave-one-pair-out", "leave-one-trial-out"):
        assert not _prediction_moves_when_held_out_responses_change(scheme, E, grid)
    # The check can fail: in-sample "folds" see the trials they predict.
    assert _prediction_moves_when_held_out_responses_change("in-sample", E, grid)


def test_a_fold_that_leaks_is_caught(E, RISK, monkeypatch):
    import analysis.crossval.fits as cv  # where cross_validate looks make_folds up

    real = cv.make_folds

    def leaky(scheme, trials=TRIAL_IDS):
        train, test = real(scheme, trials)
        if scheme != "leave-one-pair-out":
            return train, test
        return np.column_stack([train[:, 1:], test[:, :1]]), test   # the easy trial sneaks into training

    monkeypatch.setattr(cv, "make_folds", leaky)
    assert _prediction_moves_when_held_out_responses_change("leave-one-pair-out", E, risk_grid(RISK))


def test_leave_one_pair_out_holds_out_both_trials_of_a_pair():
    train, test = make_folds("leave-one-pair-out")
    assert test.shape == (12, 2) and train.shape == (12, 22)
    assert [tuple(TRIAL_IDS[i] for i in held) for held in test] == [(f"{p}E", f"{p}H") for p in range(1, 13)]
    for tr, te in zip(train, test):
        assert not set(tr) & set(te) and len(set(tr) | set(te)) == 24


def test_fewer_than_three_pairs_cannot_be_cross_validated():
    with pytest.raises(CrossValidationError, match="at least 3 easy/hard pairs.*have 2"):
        make_folds("leave-one-pair-out", ["1E", "1H", "2E", "2H", "3E", "4H", "5E", "6H"])
    with pytest.raises(CrossValidationError, match="unknown scheme"):
        make_folds("leave-one-out")


def test_in_sample_scheme_reproduces_the_papers_bootstrap(E, RISK):
    sim = simulate_participants(E, RISK, (0, 1, 4), 0.075, 15, 2.0, np.random.default_rng(2))
    boot_means = resample_trial_means(zscore_responses(sim), 50, np.random.default_rng(3))
    R = risk_at_sigma(RISK, 0.075)
    paper = bootstrap_model_correlations(boot_means, E, R).set_index(["dataset", "resample", "model"])["r"]
    ours = bootstrap_comparison(boot_means, E, {"R": risk_grid(RISK)}, MODELS3, ["in-sample"],
                                in_sample_sigma={"R": 0.075}).set_index(["dataset", "resample", "model"])["r"]
    np.testing.assert_allclose(ours.loc[paper.index].to_numpy(), paper.to_numpy(), rtol=0, atol=1e-10)


def test_the_in_sample_full_vs_effort_comparison_cannot_fail_but_the_held_out_one_can(E, RISK):
    # Pure noise: no model is true. In sample Eq. 1 fits at least as well as
    # effort-only every time (it nests it); on held-out pairs it often does worse.
    grid = risk_grid(RISK)
    Y = np.random.default_rng(7).normal(size=(200, 1, 24))
    s = {}
    for scheme in ("in-sample", "leave-one-pair-out"):
        preds, _, _ = cross_validate(Y, E.to_numpy(), {"R": grid.risk}, MODELS3, scheme)
        s[scheme] = {m: scores(Y, preds[m])["rmse"][:, 0] for m in MODELS3}
    assert np.all(s["in-sample"]["full"] <= s["in-sample"]["effort"] + 1e-12)
    assert np.mean(s["leave-one-pair-out"]["full"] > s["leave-one-pair-out"]["effort"]) > 0.5


# ---- recovery on simulated studies generated here ---------------------------------------------


def _studies(E, risk, betas, sigma, n_studies, n, noise, seed):
    """Trial means of `n_studies` studies of `n` participants drawn with
    analysis.simulate (one dataset of n_studies x n participants, split in order)."""
    sim = simulate_participants(E, risk, betas, sigma, n_studies * n, noise, np.random.default_rng(seed),
                                datasets=("time",))
    z = zscore_responses(sim)["z"].to_numpy().reshape(n_studies, n, 24)   # rows: participant, then trial
    return z.mean(axis=1)[:, None, :]


def _compare(Y, E, grid, scheme):
    preds, _, _ = cross_validate(Y, E.to_numpy(), {"R": grid.risk}, ["full", "effort"], scheme)
    rmse = {m: scores(Y, preds[m])["rmse"][:, 0] for m in ("full", "effort")}
    return verdicts(rmse)


def test_effort_only_truth_is_preferred_out_of_sample_and_never_in_sample(E, RISK):
    # Effort-only is Eq. 1 with b1 = b2.
    Y = _studies(E, RISK, (0.0, 1.0, 1.0), 0.075, 50, 40, 1.5, seed=11)
    grid = risk_grid(RISK)
    assert np.sum(_compare(Y, E, grid, "in-sample") == "full") == 50
    assert np.sum(_compare(Y, E, grid, "leave-one-pair-out") == "effort") >= 30


def test_full_model_truth_on_a_sigma_sensitive_table_is_found_out_of_sample(E, RISK):
    Y = _studies(E, RISK, (0.0, 1.0, 4.0), 0.075, 50, 40, 1.5, seed=12)
    assert np.sum(_compare(Y, E, risk_grid(RISK), "leave-one-pair-out") == "full") >= 45


def test_vectorised_studies_draw_as_analysis_simulate(E, RISK):
    R = risk_at_sigma(RISK, 0.07).to_numpy()
    y = model_cost("full", (0.0, 1.0, 4.0), E.to_numpy(), R)
    ours = simulate_trial_means(y, 30, 0.7, 1, np.random.default_rng(5))
    sim = simulate_participants(E, RISK, (0.0, 1.0, 4.0), 0.07, 30, 0.7, np.random.default_rng(5), datasets=("time",))
    np.testing.assert_allclose(ours[0], trial_means(zscore_responses(sim))["mean_z"].to_numpy(), rtol=0, atol=1e-12)


def test_recovery_confusion_matrix_and_its_seeds(E, RISK):
    grid = risk_grid(RISK, sigmas=[0.06, 0.08])
    conf, summary = recovery(E, grid, participants=(30,), n_studies=40, seed=1,
                             procedures=("in-sample", "leave-one-pair-out"))
    lo = summary[summary["procedure"] == "leave-one-pair-out"].set_index(["true_model", "sigma"])
    assert (lo.loc["full", "p_right"] >= 0.9).all() and (lo.loc["risk", "p_right"] >= 0.9).all()
    assert (lo.loc["effort", "p_right"] >= 0.6).all()
    ins = summary[summary["procedure"] == "in-sample"].set_index(["true_model", "sigma"])
    assert (ins.loc["effort", "p_right"] == 0).all()        # in sample Eq. 1 always wins
    # each (true model, sigma, procedure) row of the confusion matrix sums to the studies
    assert (conf.groupby(["true_model", "sigma", "procedure"])["count"].sum() == 40).all()
    again = recovery(E, grid, participants=(30,), n_studies=40, seed=1, procedures=("in-sample", "leave-one-pair-out"),
                     jobs=2)
    assert conf.to_csv(index=False) == again[0].to_csv(index=False)
    assert summary.to_csv(index=False) == again[1].to_csv(index=False)


# ---- permutation tests --------------------------------------------------------------------------


def test_permutations_are_permutations_and_within_pair_swaps_stay_in_pairs():
    rng = np.random.default_rng(0)
    shuffle = draw_permutations("shuffle", 50, rng)
    assert (np.sort(shuffle, axis=1) == np.arange(24)).all()
    within = draw_permutations("within-pair", 50, rng)
    assert (np.sort(within, axis=1) == np.arange(24)).all()
    assert (within // 2 == np.arange(24) // 2).all()        # trial 2k and 2k+1 are one pair
    assert 0.3 < np.mean(within[:, 0] == 1) < 0.7


@pytest.mark.slow
def test_permutation_p_values_are_uniform_under_a_null_and_small_for_a_planted_effect(E):
    from conftest import synthetic_risk

    E_ = E.to_numpy()
    sigmas = np.array([0.05, 0.075, 0.1])
    ps = []
    for k in range(200):
        rng = np.random.default_rng(1000 + k)
        # fresh logistic risk curves (as conftest's), unrelated to E and to y
        threshold = rng.uniform(0.04, 0.12, 24)
        grid = RiskGrid(sigmas, 1 / (1 + np.exp(-(sigmas[:, None] - threshold[None, :]) / 0.01)))
        y = {"time": 0.3 + 0.5 * E_ + rng.normal(size=24)}
        summary, _ = permutation_test(y, E, grid, 99, rng, kinds=("shuffle",))
        ps.append(summary["p_value"].iloc[0])
    ps = np.array(ps)
    # Exact under the null: P(p <= k/100) = k/100. Coverage counts at binomial 99.9% bounds ...
    for level, (lo, hi) in ((0.05, (2, 22)), (0.2, (23, 58)), (0.5, (76, 124))):
        assert lo <= np.sum(ps <= level + 1e-12) <= hi, (level, np.sum(ps <= level))
    # ... and Kolmogorov-Smirnov on the p-values smoothed within their 1/100 steps.
    u = np.random.default_rng(9).uniform(size=len(ps))
    assert stats.kstest(ps - u / 100, "uniform").pvalue > 0.001
    # A planted risk effect: Eq. 1 with risky effort 4x safe effort.
    grid = risk_grid(synthetic_risk(7, sigmas=tuple(sigmas)))
    R = grid.risk[1]
    rng = np.random.default_rng(3)
    y = {"time": E_ * (1 - R) + 4 * E_ * R + 0.3 * rng.normal(size=24)}
    summary, null = permutation_test(y, E, grid, 199, rng)
    assert (summary["p_value"] <= 0.02).all()
    assert len(null) == len(KINDS) * 199


def test_distinct_risk_tables_bound_the_smallest_p():
    import math

    from analysis.permutation import distinct_assignments

    risk = np.zeros((2, 24))
    risk[:, 7], risk[:, 9], risk[1, 3] = 0.1, 0.2, 0.05     # 4H, 5H and (at one sigma) 2H fall
    assert distinct_assignments("within-pair", risk) == 8    # three pairs whose E and H differ
    assert distinct_assignments("shuffle", risk) == math.factorial(24) // math.factorial(21)


def test_counts_must_be_whole_numbers_at_least_one():
    assert check_count(3, "n") == 3 and check_count(4.0, "n") == 4
    for bad in (0, -1, 2.5, float("nan"), True, "3"):
        with pytest.raises(ValueError, match="must be a whole number >= 1"):
            check_count(bad, "the number of permutations")


# ---- Monte Carlo error of risk ------------------------------------------------------------------


def test_redrawn_risk_is_binomial_with_the_tables_run_count_and_keeps_its_order_over_sigma():
    # 23 trials never fell; the last fell in 5 of 100 runs at 0.05 d and 17 of 100 at 0.10 d.
    grid = RiskGrid(np.array([0.05, 0.1]), np.vstack([np.r_[np.zeros(23), 0.05], np.r_[np.zeros(23), 0.17]]),
                    np.full((2, 24), 100.0))
    draws = redraw_risk(grid, 20000, np.random.default_rng(0))
    assert (draws[:, :, :23] == 0).all()                       # no falls seen, none redrawn
    falls = np.round(draws[:, 1, 23] * 100).astype(int)
    counts = np.bincount(falls, minlength=101)
    expected = stats.binom.pmf(np.arange(101), 100, 0.17) * 20000
    keep = expected > 5
    chi2 = np.sum((counts[keep] - expected[keep]) ** 2 / expected[keep])
    assert stats.chi2.sf(chi2, keep.sum() - 1) > 0.001
    assert (draws[:, 1, 23] >= draws[:, 0, 23]).all()          # one uniform drives both sigmas


def test_risk_table_without_run_counts_cannot_be_redrawn(RISK):
    with pytest.raises(ValueError, match="no run counts"):
        redraw_risk(risk_grid(RISK), 5, np.random.default_rng(0))
    bad = zero_heavy_risk().assign(n=lambda t: t["n"].where(t["trial"] != "3H", 2.5))
    with pytest.raises(ValueError, match="n of trial 3H at sigma 0.05 is 2.5, not a whole number"):
        risk_grid(bad)


def test_verdict_ties_go_to_the_model_with_fewer_parameters():
    v = verdicts({"full": np.array([1.0, 0.5, 2.0]), "effort": np.array([1.0, 0.7, 1.0 + 1e-12]),
                  "risk": np.array([3.0, 3.0, 1.0 + 1e-12])})
    assert list(v) == ["effort", "full", "effort"]


# ---- the analysis end to end --------------------------------------------------------------------


def _sim(E, risk, n=20, seed=4):
    return simulate_participants(E, risk, (0, 1, 4), 0.065, n, 1.0, np.random.default_rng(seed))


@pytest.mark.slow
def test_run_analysis_writes_in_and_out_of_sample_tables_the_same_whatever_jobs(tmp_path, E):
    risk = zero_heavy_risk(2)
    sim = _sim(E, risk)
    files = {}
    for jobs in (1, 2):
        out = run_analysis(sim, E, risk, tmp_path / f"j{jobs}", seed=3, n_boot=60, n_perm=40, jobs=jobs, figures=False)
        files[jobs] = {p: open(p, "rb").read() for p in out["files"]["path"] if "comparison" in p or "cv_" in p
                       or "permutation" in p}
    assert len(files[1]) == 9   # with model_comparison_held_out_permutation
    assert [v for _, v in sorted(files[1].items())] == [v for _, v in sorted(files[2].items())]
    mc = out["model_comparison"]
    assert set(mc["scheme"]) == set(SCHEMES) | {STRUCTURE_SCHEME} and len(mc) == 3 * 4 * 3
    assert (out["fits"]["scheme"] == "in-sample").all() and (out["bootstrap_tests"]["scheme"] == "in-sample").all()
    # the in-sample row is the paper's fit
    fits = out["fits"].set_index(["dataset", "model"])
    ins = mc[mc["scheme"] == "in-sample"].set_index(["dataset", "model"])
    np.testing.assert_allclose(ins["r"], fits.loc[ins.index, "r"], rtol=1e-10)
    assert (out["settings"]["risk_draw"] == "binomial").all()
    assert out["permutation_test"]["p_value"].between(1 / 41, 1).all()


@pytest.mark.slow
def test_run_analysis_fits_every_heuristic_model_like_effort_and_every_centred_interval_holds_its_point(tmp_path, E):
    from analysis.heuristics import FEATURES
    from analysis.spec import HEURISTIC_MODELS

    risk = zero_heavy_risk(2)
    rng = np.random.default_rng(1)
    feats = pd.DataFrame({"trial": list(TRIAL_IDS), **{f: rng.integers(1, 9, 24).astype(float) for f in FEATURES}})
    out = run_analysis(_sim(E, risk), E, risk, tmp_path / "h", seed=3, n_boot=60, n_perm=20, jobs=1, figures=False,
                       features=feats)
    mc = out["model_comparison"]
    for scheme in (*SCHEMES, STRUCTURE_SCHEME):
        assert set(HEURISTIC_MODELS) <= set(mc.loc[mc["scheme"] == scheme, "model"])
    # in sample a heuristic model's r is its least-squares fit's (fit_models), as effort-only's
    fits = out["fits"].set_index(["dataset", "model"])
    ins = mc[mc["scheme"] == "in-sample"].set_index(["dataset", "model"])
    np.testing.assert_allclose(ins["r"], fits.loc[ins.index, "r"], rtol=1e-10)
    for table, score in ((mc, "r"), (mc, "rmse"), (out["bootstrap_summary"], "r"), (out["model_comparison_gain"], "gain")):
        ok = table[np.isfinite(table[score])]
        assert (ok[f"{score}_low"] <= ok[score]).all() and (ok[score] <= ok[f"{score}_high"]).all()
        assert not any(c.endswith("_centred") for c in table.columns) and table["interval"].str.contains("centred").all()
    held = out["model_comparison_held_out_tests"]
    assert {("full", "effort+height"), ("full", "effort+stacked")} <= set(zip(held["model_a"], held["model_b"]))
    assert held["p_value"].between(0, 1).all() and (held.loc[held.scheme == STRUCTURE_SCHEME, "n_folds"] >= 2).all()
    assert (out["model_comparison_tests"]["method"].str.contains("NOT CALIBRATED")).all()
    assert set(out["permutation_test"]["kind"]) == set(KINDS)
    assert out["permutation_test"].loc[out["permutation_test"]["kind"] == "shuffle", "calibration"].str.startswith(
        "NOT CALIBRATED").all()
    # the decision (the calibrated held-out comparison test) and the noise ceiling reach the run's outputs,
    # each the function's own answer on its seed stream
    from analysis.crossval.permuted import HELD_OUT_STREAM
    from analysis.reliability import CEILING_STREAM, noise_ceiling

    perm, ceiling = out["model_comparison_held_out_permutation"], out["noise_ceiling"]
    datasets = set(out["trial_means"]["dataset"])
    assert set(perm["dataset"]) == datasets == set(ceiling["dataset"])
    for ab in (("full", "effort"), ("full", "effort+height"), ("full", "effort+stacked")):
        assert {ab, ab[::-1]} <= set(zip(perm["model_a"], perm["model_b"]))
    assert (perm["n_perm"] == 20).all() and perm["p_value"].between(1 / 21, 1).all()
    assert perm["method"].str.contains("calibrated").all() and (perm["scheme"] == STRUCTURE_SCHEME).all()
    np.testing.assert_allclose(perm["observed"], perm["rmse_b"] - perm["rmse_a"], rtol=1e-12, atol=1e-15)
    assert ceiling["r_ceiling"].between(0, 1).all() and ceiling["reliability"].between(0, 1).all()
    assert (ceiling["r_ceiling_low"] <= ceiling["r_ceiling"]).all() and (ceiling["r_ceiling"] <= ceiling["r_ceiling_high"]).all()
    np.testing.assert_allclose(ceiling["r_ceiling"], np.sqrt(ceiling["reliability"]), rtol=1e-12)
    pd.testing.assert_frame_equal(ceiling, noise_ceiling(out["zscored"], np.random.default_rng([3, CEILING_STREAM])))
    written = {Path(p).name for p in out["files"]["path"]}
    assert {"simulated_model_comparison_held_out_permutation.csv", "simulated_noise_ceiling.csv"} <= written
    on_disk = pd.read_csv(tmp_path / "h" / "simulated_model_comparison_held_out_permutation.csv")
    np.testing.assert_allclose(on_disk["p_value"], perm["p_value"])


def test_centred_interval_holds_its_point_where_the_percentile_interval_does_not():
    from analysis.bootstrap import centred_interval

    rng = np.random.default_rng(0)
    boot = 0.9 - np.abs(rng.normal(0.05, 0.02, 500))   # every resample below the point, as r of resampled means
    point = 0.99
    assert np.percentile(boot, 97.5) < point           # the paper's interval misses the point
    lo, hi = centred_interval(point, boot)
    assert lo <= point <= hi
    d = boot - np.median(boot)                          # by hand: the median-centred quantiles added to the point
    assert lo == pytest.approx(point + np.quantile(d, 0.025)) and hi == pytest.approx(point + np.quantile(d, 0.975))
    assert centred_interval(0.999, boot + 0.1, bounds=(-1, 1))[1] <= 1.0
    assert all(np.isnan(centred_interval(np.nan, boot)))


def test_run_analysis_refuses_bad_counts_and_partial_data_writing_nothing(tmp_path, E):
    risk = zero_heavy_risk(2)
    sim = _sim(E, risk, n=5)
    for kwargs in ({"n_perm": 0}, {"n_perm": 2.5}, {"n_boot": 0}):
        with pytest.raises(ValueError, match="whole number >= 1"):
            run_analysis(sim, E, risk, tmp_path / "out", seed=0, **kwargs)
    partial = sim[sim["trial"] != "12H"]
    with pytest.raises(HumanDataError, match="missing trial\\(s\\) 12H"):
        run_analysis(partial, E, risk, tmp_path / "out", seed=0)
    assert not (tmp_path / "out").exists()


def test_model_comparison_counts_pairs_ordered_out_of_sample_by_the_tie_rule(E):
    risk = zero_heavy_risk(3)
    grid = risk_grid(risk)
    y = {"time": E.to_numpy() + np.random.default_rng(0).normal(scale=0.01, size=24)}
    table, preds = model_comparison(y, E, {"R": grid}, MODELS3)
    from analysis.pairs import pair_table

    for scheme in SCHEMES:
        p = preds[(preds["scheme"] == scheme) & (preds["model"] == "effort")].set_index("trial")["predicted"]
        row = table[(table["scheme"] == scheme) & (table["model"] == "effort")].iloc[0]
        assert row["pairs_E_lt_H"] == pair_table(p)["E_lt_H"].sum()


@pytest.mark.slow
def test_recovery_cli_writes_only_simulated_files_and_refuses_bad_counts(tmp_path, E, capsys):
    results = tmp_path / "results"
    results.mkdir()
    pd.DataFrame({"trial": list(TRIAL_IDS), "sample": 0, "effort": E.to_numpy()}).to_csv(results / "effort_samples.csv", index=False)
    zero_heavy_risk(4).to_csv(results / "risk.csv", index=False)
    cmd = [sys.executable, "-m", "analysis.recovery", "--results", str(results), "--studies", "5",
           "--participants", "20", "--sigmas", "0.065", "0.1"]
    bad = subprocess.run(cmd[:-5] + ["--studies", "2.5", "--out", str(tmp_path / "bad")], capture_output=True, text=True)
    assert bad.returncode == 2 and len(bad.stderr.strip().splitlines()) == 1 and "--studies" in bad.stderr
    assert not (tmp_path / "bad").exists()
    # the rest through the command's own main and its run_cli wrapper, in this process (imports paid once)
    from analysis import recovery as command
    from lgp.cli import run_cli

    argv = cmd[3:]
    assert run_cli(command.main, argv + ["--out", str(tmp_path / "rec")], prog=command.PROG) == 0
    written = sorted(p.name for p in (tmp_path / "rec").iterdir())
    assert written and all(name.startswith("simulated_") for name in written)
    human = tmp_path / "human"
    human.mkdir()
    pd.DataFrame([{"human_data": True}]).to_csv(human / "settings.csv", index=False)
    capsys.readouterr()
    assert run_cli(command.main, argv + ["--out", str(human)], prog=command.PROG) == 1
    assert "human-data analysis" in capsys.readouterr().err
    assert sorted(p.name for p in human.iterdir()) == ["settings.csv"]


@pytest.mark.slow
def test_reproduce_writes_the_comparison_the_permutations_and_the_recovery(tmp_path, capsys, quick_run):
    # Random responses in the human-data format stand in for a file (no claim is tested on them).
    # The effort and risk are the session's --quick run's (a copy of its cache: nothing recomputed).
    from conftest import QUICK_RUN, copy_of_run
    from lgp import reproduce

    rng = np.random.default_rng(0)
    rows = [(d, f"p{k}", t, float(rng.normal())) for d in ("difficulty", "time") for k in range(8) for t in TRIAL_IDS]
    path = tmp_path / "h.csv"
    pd.DataFrame(rows, columns=["dataset", "participant", "trial", "response"]).to_csv(path, index=False)
    out = copy_of_run(quick_run, tmp_path / "r")
    args = [*(a for a in QUICK_RUN if a != "--quick"), "--jobs", "1", "--n-boot", "20",
            "--no-replays", "--out", str(out), "--human-data", str(path), "--n-perm", "9", "--recovery",
            "--recovery-studies", "4"]
    capsys.readouterr()
    assert reproduce.main(args) == 0
    # the run ends with one line on the fit: the chosen sigma, and Eq. 1 against effort-only on held-out
    # pairs, the numbers of model_comparison.csv
    summary = capsys.readouterr().out.strip().splitlines()[-3]
    comparison = pd.read_csv(out / "analysis" / "model_comparison.csv")
    held = comparison[comparison["scheme"] == "leave-one-pair-out"].set_index(["dataset", "model"])["rmse"]
    sigma = pd.read_csv(out / "analysis" / "settings.csv")["sigma"].iloc[0]
    assert summary.startswith(f"human data: sigma = {sigma:g} d (")
    for d in ("difficulty", "time"):
        assert f"{d} {held[d, 'full']:.3f} vs {held[d, 'effort']:.3f} (" in summary, summary
    listed = {e["path"] for e in json.loads((out / "manifest.json").read_text())["files"]}
    for name in ("model_comparison", "model_comparison_tests", "cv_predictions", "permutation_test",
                 "model_comparison_held_out_permutation", "noise_ceiling"):
        assert (out / "analysis" / f"{name}.csv").exists() and f"analysis/{name}.csv" in listed
    decision = pd.read_csv(out / "analysis" / "model_comparison_held_out_permutation.csv")
    assert (decision["n_perm"] == 9).all() and decision["p_value"].between(0.1, 1).all()   # p >= 1/(1 + 9)
    assert pd.read_csv(out / "analysis" / "noise_ceiling.csv")["r_ceiling"].dropna().between(0, 1).all()
    assert sorted(p.name for p in (out / "recovery").iterdir()) == [
        "simulated_recovery.csv", "simulated_recovery.pdf", "simulated_recovery.png", "simulated_recovery_summary.csv"]
    report = (out / "report.md").read_text()
    assert "## Model comparison: in-sample and out of sample" in report and "cannot fail" in report
    assert "## fits (in-sample)" in report and "## Model recovery on SIMULATED studies" in report
    page = (out / "index.html").read_text()
    assert 'id="comparison"' in page and "SIMULATED participants, not human data" in page
    assert "The decision: held-out comparison test (calibrated)" in page and "Noise ceiling beside the scores" in page
    assert "**The decision: the held-out comparison test (calibrated).**" in report and "Noise ceiling beside" in report
    perm = pd.read_csv(out / "analysis" / "permutation_test.csv")
    assert (perm["n_perm"] == 9).all() and len(perm) == len(KINDS) * 2


def test_within_pair_null_on_a_set_without_pairs_is_skipped_with_its_reason_and_the_others_still_run():
    # Eight trials none of which has its partner (1E..8E): the within-pair null has
    # nothing to swap, so it is skipped with its reason; freedman-lane and shuffle run.
    trials = [f"{k}E" for k in range(1, 9)]
    rng = np.random.default_rng(3)
    sigmas = np.array([0.05, 0.1])
    grid = RiskGrid(sigmas, rng.uniform(0, 1, (2, 8)))
    E = pd.Series(rng.uniform(1, 3, 8), index=trials)
    y = {"simulated-time": E.to_numpy() + rng.normal(0, 0.3, 8)}
    with pytest.raises(InputError, match="no easy/hard pairs"):
        draw_permutations("within-pair", 5, rng, trials)
    summary, null = permutation_test(y, E, grid, 19, rng, trials=trials)
    skipped = summary[summary["kind"] == "within-pair"].iloc[0]
    assert skipped["calibration"].startswith("skipped: no easy/hard pairs")
    assert np.isnan(skipped["p_value"]) and skipped["n_perm"] == 0
    assert set(null["kind"]) == {"freedman-lane", "shuffle"}
    ran = summary[summary["kind"] != "within-pair"]
    assert ran["p_value"].between(1 / 20, 1).all() and (ran["n_perm"] == 19).all()
