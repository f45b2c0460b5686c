"""The comparison as tables: every model's scores under every scheme on the full
sample (`model_comparison`) and in every bootstrap resample (`bootstrap_comparison`),
their bootstrap intervals centred on the point (`summarize_comparison`) and each model's gain over
effort-only (`gain_over_effort`)."""
from __future__ import annotations

from typing import Mapping, Sequence

import numpy as np
import pandas as pd

from analysis.crossval.fits import cross_validate, scores
from analysis.crossval.folds import SCHEMES, pairs_of
from analysis.crossval.grids import RiskGrid
from analysis.data import ordered_datasets
from analysis.data.trialset import trial_ids
from analysis.models import MODELS, effort_per_trial, model_spec


def _sources(models: Sequence[str]) -> list[str]:
    return list(dict.fromkeys(model_spec(m).source for m in models if model_spec(m).source is not None))


def model_comparison(means: Mapping[str, np.ndarray], effort, grids: Mapping[str, RiskGrid],
                     models: Sequence[str] = MODELS, schemes: Sequence[str] = SCHEMES,
                     in_sample_sigma: Mapping[str, float] | None = None,
                     features: Mapping[str, np.ndarray] | None = None,
                     groups: Sequence[Sequence[int]] | None = None
                     ) -> tuple[pd.DataFrame, pd.DataFrame]:
    """Scores of every model under every scheme, on the full-sample trial means.

    `means` {dataset: (24,) trial means in trial_ids() order}; `grids` {source:
    RiskGrid} ("R", and a measure m for full[m]/risk[m]). In-sample, sigma is
    `in_sample_sigma[source]` (the analysis's chosen sigma; default: chosen by the
    rule on all 24 trials); cross-validated, it is chosen in each fold.

    Returns (scores, predictions): scores one row per (dataset, scheme, model):
    dataset, scheme, model, rmse, r, pairs_E_lt_H, n_pairs, sigma_min, sigma_max
    (over folds); predictions one row per (dataset, scheme, model, trial): fold
    (the fold that held the trial out), sigma, observed, predicted. `features`
    {name: (24,)} the heuristic predictors of heuristic models (analysis.spec);
    `groups` the structure groups of crossval.STRUCTURE_SCHEME when it is among
    `schemes`.
    """
    E = effort_per_trial(effort).to_numpy()
    datasets = ordered_datasets(means)
    Y = np.stack([np.asarray(means[d], float) for d in datasets])[None]   # (1, D, 24)
    risks = {s: grids[s].risk for s in _sources(models)}
    rows, pred_rows = [], []
    for scheme in schemes:
        fixed = _fixed_index(grids, risks, in_sample_sigma) if scheme == "in-sample" else None
        preds, chosen, test = cross_validate(Y, E, risks, models, scheme, fixed, features=features, groups=groups)
        fold_of = np.empty(len(trial_ids()), dtype=int)
        for f, held in enumerate(test):
            fold_of[held] = f
        for model in models:
            sc = scores(Y, preds[model])
            source = model_spec(model).source
            for k, dataset in enumerate(datasets):
                if source is None:
                    sig = np.full(len(trial_ids()), np.nan)
                else:
                    sig = grids[source].sigmas[chosen[source][0, :, k]][fold_of]
                rows.append((dataset, scheme, model, sc["rmse"][0, k], sc["r"][0, k], int(sc["pairs"][0, k]),
                             len(pairs_of(trial_ids())), np.nanmin(sig) if source is not None else np.nan,
                             np.nanmax(sig) if source is not None else np.nan))
                for i, trial in enumerate(trial_ids()):
                    pred_rows.append((dataset, scheme, model, trial, int(fold_of[i]), sig[i], Y[0, k, i],
                                      preds[model][0, k, i]))
    table = pd.DataFrame(rows, columns=["dataset", "scheme", "model", "rmse", "r", "pairs_E_lt_H", "n_pairs",
                                        "sigma_min", "sigma_max"])
    predictions = pd.DataFrame(pred_rows, columns=["dataset", "scheme", "model", "trial", "fold", "sigma",
                                                   "observed", "predicted"])
    return table, predictions


def _fixed_index(grids, risks, in_sample_sigma) -> dict[str, int] | None:
    if in_sample_sigma is None:
        return None
    out = {}
    for s in risks:
        sig = in_sample_sigma.get(s, in_sample_sigma.get("R"))
        out[s] = int(np.argmin(np.abs(grids[s].sigmas - sig)))  # nearest, as run_analysis reads build risk
    return out


def bootstrap_comparison(boot_means: Mapping[str, np.ndarray], effort, grids: Mapping[str, RiskGrid],
                         models: Sequence[str] = MODELS, schemes: Sequence[str] = SCHEMES,
                         in_sample_sigma: Mapping[str, float] | None = None,
                         risk_draws: np.ndarray | None = None, features: Mapping[str, np.ndarray] | None = None,
                         groups: Sequence[Sequence[int]] | None = None) -> pd.DataFrame:
    """Scores of every model under every scheme in every bootstrap resample, the
    cross-validation (sigma choice included) redone inside each resample.

    `boot_means` {dataset: (n_boot, 24)} (`resample_trial_means`); `risk_draws`
    (n_boot, S, 24) redrawn risks of source "R" (`redraw_risk`) or None for the
    table's risks. Returns one row per (dataset, scheme, model, resample):
    dataset, scheme, model, resample, rmse, r, pairs_E_lt_H.
    """
    E = effort_per_trial(effort).to_numpy()
    datasets = ordered_datasets(boot_means)
    Y = np.stack([np.asarray(boot_means[d], float) for d in datasets], axis=1)   # (n_boot, D, 24)
    n_boot = Y.shape[0]
    risks = {s: grids[s].risk for s in _sources(models)}
    if risk_draws is not None and "R" in risks:
        risks["R"] = risk_draws
    frames = []
    for scheme in schemes:
        fixed = _fixed_index(grids, risks, in_sample_sigma) if scheme == "in-sample" else None
        preds, _, _ = cross_validate(Y, E, risks, models, scheme, fixed, features=features, groups=groups)
        for model in models:
            sc = scores(Y, preds[model])
            for k, dataset in enumerate(datasets):
                frames.append(pd.DataFrame({"dataset": dataset, "scheme": scheme, "model": model,
                                            "resample": np.arange(n_boot), "rmse": sc["rmse"][:, k],
                                            "r": sc["r"][:, k], "pairs_E_lt_H": sc["pairs"][:, k]}))
    return pd.concat(frames, ignore_index=True)


def summarize_comparison(point: pd.DataFrame, boot: pd.DataFrame, boot_fixed_risk: pd.DataFrame | None = None,
                         level: float = 0.95) -> pd.DataFrame:
    """`point` (model_comparison's scores) with bootstrap intervals from `boot`
    (bootstrap_comparison), each centred on its point estimate
    (analysis.bootstrap.centred_interval: it always contains it): rmse_low/high,
    r_low/high, pairs_low/high, n_boot, interval; with `boot_fixed_risk` (the
    same resamples, risk not redrawn) also the fixed-risk intervals and how much
    redrawing risk widens them (r_widening = width with risk redrawn / width
    without). The paper's percentile intervals are not outputs (they can miss
    the point; docs/results.md)."""
    from analysis.bootstrap import INTERVAL

    keys = ["dataset", "scheme", "model"]
    table = _with_centred(point.copy(), boot, keys, ("rmse", "r", "pairs"), level)
    table["n_boot"] = table[keys].apply(tuple, axis=1).map(boot.groupby(keys, sort=False).size()).to_numpy()
    table["interval"] = INTERVAL
    if boot_fixed_risk is not None:
        fixed = _with_centred(point[keys + ["rmse", "r", "pairs_E_lt_H"]].copy(), boot_fixed_risk, keys, ("rmse", "r"),
                              level, "_fixed_risk")
        table = table.merge(fixed.drop(columns=["rmse", "r", "pairs_E_lt_H"]), on=keys, how="left")
        with np.errstate(invalid="ignore", divide="ignore"):
            table["rmse_widening"] = ((table["rmse_high"] - table["rmse_low"])
                                      / (table["rmse_high_fixed_risk"] - table["rmse_low_fixed_risk"]))
            table["r_widening"] = ((table["r_high"] - table["r_low"])
                                   / (table["r_high_fixed_risk"] - table["r_low_fixed_risk"]))
    return table


#: Each score's column in the bootstrap table and its range.
_SCORE_COLUMN = {"rmse": "rmse", "r": "r", "pairs": "pairs_E_lt_H"}


def _with_centred(table: pd.DataFrame, boot: pd.DataFrame, keys, scores, level: float,
                  suffix: str = "") -> pd.DataFrame:
    """Columns <score>_low<suffix>, <score>_high<suffix>: the bootstrap interval
    shifted to the point estimate (analysis.bootstrap.centred_interval), always
    containing it."""
    from analysis.bootstrap import centred_interval

    groups = dict(iter(boot.groupby(keys, sort=False)))
    for score in scores:
        col = _SCORE_COLUMN[score]
        bounds = {"r": (-1.0, 1.0), "rmse": (0.0, np.inf)}.get(score, (0.0, np.inf))
        lo, hi = [], []
        for _, row in table.iterrows():
            g = groups.get(tuple(row[k] for k in keys))
            c = centred_interval(row[col], g[col].to_numpy() if g is not None else [], level, bounds)
            lo.append(c[0])
            hi.append(c[1])
        table[f"{score}_low{suffix}"], table[f"{score}_high{suffix}"] = lo, hi
    return table


def gain_over_effort(point: pd.DataFrame, boot: pd.DataFrame, level: float = 0.95) -> pd.DataFrame:
    """How much lower each model's RMSE is than effort-only's (effort RMSE - model
    RMSE; positive: the model predicts better), per dataset and scheme, with the
    bootstrap interval of the per-resample difference centred on the gain
    (gain_low, gain_high: always containing it). In sample Eq. 1's gain is >= 0 by
    construction; out of sample it can be negative."""
    from analysis.bootstrap import INTERVAL, centred_interval

    keys = ["dataset", "scheme"]
    pt = point.pivot_table(index=keys, columns="model", values="rmse", sort=False)
    bt = boot.pivot_table(index=keys + ["resample"], columns="model", values="rmse", sort=False)
    rows = []
    for model in [m for m in pt.columns if m != "effort"]:
        diffs = dict(iter((bt["effort"] - bt[model]).groupby(level=keys, sort=False)))
        for key in pt.index:
            gain = float(pt.loc[key, "effort"] - pt.loc[key, model])
            rows.append((*key, model, gain, *centred_interval(gain, diffs[key].to_numpy(), level), INTERVAL))
    return pd.DataFrame(rows, columns=keys + ["model", "gain", "gain_low", "gain_high", "interval"])
