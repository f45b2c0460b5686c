"""The calibrated held-out comparison test (analysis.crossval.permuted): "model a
predicts held-out trials better than model b", its null the residuals of b's fit
permuted across trials and the whole held-out procedure (folds by structure,
refits, sigma inside every fold) redone. Checked against the same procedure run
one permuted data set at a time, on SIMULATED worlds whose truth is known: under
the null its p-values are uniform (the sign-flip over folds is not), and a planted
risk effect gets the smallest p."""
import numpy as np
import pytest

from analysis import TRIAL_IDS
from analysis.crossval import STRUCTURE_SCHEME, RiskGrid, cross_validate, risk_grid, structure_groups
from analysis.crossval.decisions import SIGN_FLIP_METHOD, sign_flip_p
from analysis.crossval.permuted import METHOD, freedman_lane, held_out_permutation_tests

SIGMAS = (0.05, 0.075, 0.1)


@pytest.fixture(scope="module")
def world(make_effort, make_risk):
    E = make_effort().to_numpy()
    grid = risk_grid(make_risk(7, sigmas=SIGMAS))
    groups = structure_groups(list(TRIAL_IDS), grid.risk)
    return E, grid, groups


def _rmse(y, E, grid, models, groups, scheme=STRUCTURE_SCHEME):
    """Held-out RMSE of one data set (24,), through cross_validate with one row."""
    preds, _, _ = cross_validate(y[None, None], E, {"R": grid.risk}, models, scheme, groups=groups)
    return {m: float(np.sqrt(np.mean((y - p[0, 0]) ** 2))) for m, p in preds.items()}


def test_each_null_statistic_is_the_held_out_procedure_redone_on_one_permuted_data_set(world):
    E, grid, groups = world
    rng = np.random.default_rng(5)
    y = 0.2 + 0.5 * E + rng.normal(size=24)                         # SIMULATED: effort-only truth
    perms = rng.permuted(np.tile(np.arange(24), (6, 1)), axis=1)
    obs, null = freedman_lane(y[None, None], E, {"R": grid.risk}, "effort", ["full"], perms, groups,
                              list(TRIAL_IDS))
    X = np.column_stack([np.ones(24), E])
    fit = X @ np.linalg.lstsq(X, y, rcond=None)[0]                 # effort-only by least squares, all trials
    res = y - fit
    for k, perm in enumerate(perms):
        s = _rmse(fit + res[perm], E, grid, ["effort", "full"], groups)
        assert null["full"][0, k, 0] == pytest.approx(s["effort"] - s["full"], abs=1e-10)
    s = _rmse(y, E, grid, ["effort", "full"], groups)
    assert obs["full"][0, 0] == pytest.approx(s["effort"] - s["full"], abs=1e-12)


def test_a_planted_risk_effect_gets_the_smallest_p_and_the_table_names_its_folds(world):
    E, grid, groups = world
    R = grid.risk[1]
    y = E * (1 - R) + 4 * E * R + 0.3 * np.random.default_rng(3).normal(size=24)   # SIMULATED Eq. 1, b2/b1 = 4
    table = held_out_permutation_tests({"time": y}, E, {"R": grid}, [("full", "effort")], groups, 99,
                                       np.random.default_rng(0))
    row = table.set_index(["model_a", "model_b"])
    assert row.loc[("full", "effort"), "p_value"] == pytest.approx(1 / 100)
    assert row.loc[("effort", "full"), "p_value"] > 0.05           # both ways: effort does not beat Eq. 1
    assert (table["method"] == METHOD).all() and "calibrated" in METHOD
    assert (table["scheme"] == STRUCTURE_SCHEME).all() and table["folds"].iloc[0].count("|") == len(groups) - 1


@pytest.mark.slow
def test_under_the_null_its_p_values_are_uniform_and_the_sign_flips_are_not(world):
    """200 SIMULATED effort-only studies (fresh noise), 19 permutations each: P(p <= k/20)
    = k/20 exactly; the sign-flip over folds of the same studies rejects far less."""
    E, grid, groups = world
    rng = np.random.default_rng(11)
    n = 200
    Y = (0.2 + 0.5 * E)[None] + rng.normal(size=(n, 24))
    perms = np.stack([rng.permuted(np.tile(np.arange(24), (19, 1)), axis=1) for _ in range(n)])
    obs, null = freedman_lane(Y[:, None], E, {"R": grid.risk}, "effort", ["full"], perms, groups, list(TRIAL_IDS))
    p = (1 + np.sum(null["full"][..., 0] >= obs["full"][:, 0, None] - 1e-12, axis=1)) / 20
    for level, (lo, hi) in ((0.05, (2, 22)), (0.25, (31, 70)), (0.5, (76, 124))):   # binomial 99.9% bounds
        assert lo <= np.sum(p <= level + 1e-12) <= hi, (level, np.sum(p <= level + 1e-12))
    preds, _, _ = cross_validate(Y[:, None], E, {"R": grid.risk}, ["full", "effort"], STRUCTURE_SCHEME, groups=groups)
    sq = {m: (Y - preds[m][:, 0]) ** 2 for m in ("full", "effort")}
    d = np.stack([sq["effort"][:, list(g)].sum(axis=1) - sq["full"][:, list(g)].sum(axis=1) for g in groups], axis=1)
    flips = sign_flip_p(d)
    assert np.sum(flips <= 0.05) < np.sum(p <= 0.05)               # conservative for the richer model
    assert "NOT CALIBRATED" in SIGN_FLIP_METHOD


def test_a_grid_without_run_counts_is_enough(world):
    E, grid, groups = world
    bare = RiskGrid(grid.sigmas, grid.risk)
    y = 0.5 * E + np.random.default_rng(2).normal(size=24)
    t = held_out_permutation_tests({"a": y, "b": -y}, E, {"R": bare}, [("full", "effort")], groups, 9,
                                   np.random.default_rng(1), both_ways=False)
    assert list(t["dataset"]) == ["a", "b"] and t["n_perm"].eq(9).all()
    assert ((t["p_value"] >= 0.1) & (t["p_value"] <= 1)).all()
