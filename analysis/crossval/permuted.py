"""The calibrated held-out comparison test: Freedman-Lane permutation of the
held-out statistic (`freedman_lane`, `held_out_permutation_tests`).

Question: does model a predict held-out trials better than model b? Statistic:
held-out RMSE(b) - RMSE(a) on folds by structure (crossval.STRUCTURE_SCHEME),
every model refit in every fold, sigma chosen inside every fold. Null (b is
true): the residuals of b's in-sample fit (sigma by the paper's rule on all
trials) are permuted across the trials and added back to that fit (Freedman &
Lane 1983), y* = fit_b + P e_b, and each permuted data set goes through the
whole held-out procedure again (folds, refits, sigma inside every fold), in one
array operation per chunk. p = (1 + #{null >= observed}) / (1 + n_perm).

The residuals are permuted across all trials (one exchangeable block): under
the null the responses are b's cost plus noise that does not depend on the
trial. Datasets analysed together share each permutation (their sigma is
chosen pooled, as the paper's rule does); each dataset's p is valid on its own.

Why not the sign-flip over folds (`decisions.held_out_tests`)? Under the null
the richer model's held-out error is larger on average (it over-fits, and
Eq. 1 also picks sigma among the grid's values), so the per-fold differences
are not symmetric about 0: measured in SIMULATED null studies
(bench/analysis_power.py, docs/results.md), "Eq. 1 beats effort-only" is
rejected in 0.3-0.5% of studies and "effort + height beats Eq. 1" in 11-13%.
"""
from __future__ import annotations

from typing import Mapping, Sequence

import numpy as np
import pandas as pd

from analysis.crossval.fits import CHUNK, cross_validate
from analysis.crossval.folds import STRUCTURE_SCHEME, grouping_label
from analysis.data.trialset import trial_ids

#: How the test is labelled in every table.
METHOD = "Freedman-Lane permutation of the held-out RMSE difference (calibrated)"
#: Seed stream of the held-out permutation test in a run: ``default_rng([seed, HELD_OUT_STREAM])``.
HELD_OUT_STREAM = 2303
#: A null statistic within this (relative) of the observed counts as at least as large.
TIE_REL = 1e-12


def held_out_rmse(Y: np.ndarray, E: np.ndarray, risks: Mapping[str, np.ndarray], models: Sequence[str],
                  groups, trials, features=None, scheme: str = STRUCTURE_SCHEME,
                  chunk: int = CHUNK) -> dict[str, np.ndarray]:
    """Held-out RMSE {model: (N, D)} of trial means Y (N, D, T) (in sample with
    scheme "in-sample": sigma by the rule on all trials)."""
    preds, _, _ = cross_validate(Y, E, risks, list(models), scheme, trials=trials, chunk=chunk,
                                 features=features, groups=groups)
    return {m: np.sqrt(np.mean((Y - p) ** 2, axis=-1)) for m, p in preds.items()}


def p_at_least(null: np.ndarray, obs: np.ndarray) -> np.ndarray:
    """(1 + #{null >= obs}) / (1 + P): null (..., P), obs (...); ties within TIE_REL count."""
    at_least = np.sum(null >= (obs - TIE_REL * np.abs(obs))[..., None], axis=-1)
    return (1 + at_least) / (1 + null.shape[-1])


def freedman_lane(Y: np.ndarray, E: np.ndarray, risks: Mapping[str, np.ndarray], b: str, against: Sequence[str],
                  perms: np.ndarray, groups, trials, features=None, observed: Mapping[str, np.ndarray] | None = None,
                  chunk: int = CHUNK) -> tuple[dict[str, np.ndarray], dict[str, np.ndarray]]:
    """Observed statistics {a: (N, D)} and their nulls {a: (N, P, D)} of "a predicts
    held-out trials better than b" for every a in `against`: Y (N, D, T) trial means
    of N studies (or one: N = 1), perms (N, P, T) or (P, T) trial permutations of
    b's residuals. `observed` the held-out RMSEs {model: (N, D)} when known."""
    Y = np.asarray(Y, float)
    N, D, T = Y.shape
    perms = np.broadcast_to(perms, (N,) + np.shape(perms)[-2:])
    P = perms.shape[1]
    models = list(dict.fromkeys([b, *against]))
    if observed is None:
        observed = held_out_rmse(Y, E, risks, models, groups, trials, features, chunk=chunk)
    fit = cross_validate(Y, E, risks, [b], "in-sample", trials=trials, chunk=chunk, features=features)[0][b]
    res = Y - fit                                                        # (N, D, T)
    moved = np.take_along_axis(res[:, None], np.broadcast_to(perms[:, :, None, :], (N, P, D, T)), axis=-1)
    star = (fit[:, None] + moved).reshape(N * P, D, T)
    null = held_out_rmse(star, E, risks, models, groups, trials, features, chunk=chunk)
    obs = {a: observed[b] - observed[a] for a in against}
    return obs, {a: (null[b] - null[a]).reshape(N, P, D) for a in against}


def held_out_permutation_tests(means: Mapping[str, np.ndarray], effort: np.ndarray, grids, comparisons,
                               groups, n_perm: int, rng: np.random.Generator, trials: Sequence[str] | None = None,
                               features: Mapping[str, np.ndarray] | None = None,
                               both_ways: bool = True) -> pd.DataFrame:
    """The calibrated held-out comparison test (module docstring) of each comparison
    (a, b) on the full-sample trial means `means` {dataset: (T,)}, and with
    `both_ways` also of (b, a). `grids` {source: crossval.RiskGrid}; `groups` the
    structure groups; `effort` (T,) in trial order. One permutation set per null
    model (drawn from `rng` in order of first appearance: ``rng.permuted`` of
    (n_perm, T)). Returns one row per (dataset, a, b): dataset, scheme, folds,
    model_a, model_b, rmse_a, rmse_b, observed (rmse_b - rmse_a), null_mean,
    null_q95, n_at_least, n_perm, p_value (of "a predicts held-out trials better
    than b"), method."""
    trials = list(trial_ids() if trials is None else trials)
    datasets = list(means)
    Y = np.stack([np.asarray(means[d], float) for d in datasets])[None]          # (1, D, T)
    E = np.asarray(effort, float)
    risks = {s: g.risk for s, g in grids.items()}
    pairs = list(dict.fromkeys([*comparisons, *((b, a) for a, b in comparisons)] if both_ways else comparisons))
    models = list(dict.fromkeys(m for ab in pairs for m in ab))
    rmse = held_out_rmse(Y, E, risks, models, groups, trials, features)
    rows = []
    for b in dict.fromkeys(b for _, b in pairs):
        against = [a for a, bb in pairs if bb == b]
        perms = rng.permuted(np.tile(np.arange(len(trials)), (n_perm, 1)), axis=1)
        obs, null = freedman_lane(Y, E, risks, b, against, perms, groups, trials, features, rmse)
        for a in against:
            for k, dataset in enumerate(datasets):
                g, o = null[a][0, :, k], obs[a][0, k]
                n_at = int(np.sum(g >= o - TIE_REL * abs(o)))
                rows.append((dataset, STRUCTURE_SCHEME, grouping_label(groups, trials), a, b, rmse[a][0, k],
                             rmse[b][0, k], o, float(g.mean()), float(np.quantile(g, 0.95)), n_at, n_perm,
                             (1 + n_at) / (1 + n_perm), METHOD))
    return pd.DataFrame(rows, columns=["dataset", "scheme", "folds", "model_a", "model_b", "rmse_a", "rmse_b",
                                       "observed", "null_mean", "null_q95", "n_at_least", "n_perm", "p_value",
                                       "method"])
