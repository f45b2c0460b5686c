"""From validated responses to the numbers the analysis fits: the paper's exclusion
of participants who gave one response throughout, z-scores within participant,
per-trial means and their participant bootstrap (Experiments and Results)."""
from __future__ import annotations

from typing import Mapping

import numpy as np
import pandas as pd

from analysis.data.datasets import HumanDataError, ordered_datasets
from lgp.errors import InputError
from analysis.data.trialset import trial_ids

#: Memory (bytes) one block of bootstrap resamples may take in `resample_trial_means`.
BOOTSTRAP_BLOCK_BYTES = 32 * 2**20


def exclude_constant_participants(responses: pd.DataFrame) -> tuple[pd.DataFrame, pd.DataFrame]:
    """Drop participants who gave the identical response on every trial.

    The paper excluded two participants for this (Participants section); their
    z-scores are undefined anyway (zero SD). Returns ``(kept, excluded)`` where
    `excluded` has one row per dropped participant: dataset, participant,
    n_trials, response (the repeated value), reason.
    """
    spread = responses.groupby(["dataset", "participant"], sort=False)["response"].agg(
        n_trials="size", response="first", spread=lambda r: r.max() - r.min())
    constant = spread[spread["spread"] == 0].reset_index()
    excluded = constant[["dataset", "participant", "n_trials", "response"]].assign(
        reason="identical response on all trials")
    keys = set(zip(constant["dataset"], constant["participant"]))
    mask = [(d, p) not in keys for d, p in zip(responses["dataset"], responses["participant"])]
    return responses[mask].reset_index(drop=True), excluded.reset_index(drop=True)


def zscore_responses(responses: pd.DataFrame, ddof: int = 0) -> pd.DataFrame:
    """Z-score each participant's responses within their dataset.

    z = (response - participant mean) / participant SD over that participant's
    24 trials. The default ``ddof=0`` is the population SD (as
    ``scipy.stats.zscore``), so each participant's z-scores have mean 0 and root
    mean square 1; ``ddof=1`` (sample SD, as R's ``scale``) multiplies every z by
    sqrt(23/24), which changes no correlation, ordering or sigma choice, only
    the scale of betas and RMSE. The paper does not say which it used.

    Returns a copy of `responses` with a column ``z``. Raises ValueError naming
    the participant if their SD is zero (drop them first with
    `exclude_constant_participants`), and HumanDataError naming the participant if
    a z-score is not finite (responses so large that the mean or SD overflows).
    """
    grouped = responses.groupby(["dataset", "participant"], sort=False)["response"]
    mean = grouped.transform("mean")
    sd = grouped.transform("std", ddof=ddof)
    # max == min rather than sd == 0: the SD of identical floats can round to 1e-17.
    constant = grouped.transform("max") == grouped.transform("min")
    flat = responses.loc[constant, ["dataset", "participant"]].drop_duplicates()
    if len(flat):
        d, p = flat.iloc[0]
        raise InputError(f"participant {p!r} in dataset {d!r} gave the same response on every "
                         "trial, so their z-scores are undefined; use exclude_constant_participants")
    with np.errstate(over="ignore", invalid="ignore"):
        z = (responses["response"] - mean) / sd
    broken = ~(np.isfinite(z) & np.isfinite(sd))
    if broken.any():
        d, p = responses.loc[broken, ["dataset", "participant"]].iloc[0]
        raise HumanDataError(f"participant {p!r} in dataset {d!r}: z-scores are not finite (responses too "
                             "large to z-score: the mean or SD overflows)")
    return responses.assign(z=z)


def participant_matrices(zscored: pd.DataFrame) -> dict[str, tuple[list[str], np.ndarray]]:
    """Per dataset (in `ordered_datasets` order): participant ids and their z-scores as an
    (n_participants, 24) array, columns in trial_ids() order."""
    out = {}
    for dataset in ordered_datasets(zscored["dataset"].unique()):
        wide = zscored[zscored["dataset"] == dataset].pivot(
            index="participant", columns="trial", values="z")
        wide = wide.reindex(columns=list(trial_ids()))
        if wide.isna().any().any():
            raise InputError(f"dataset {dataset!r}: some participants lack z-scores for some "
                             "trials; validate the data with validate_human_data first")
        out[dataset] = (list(wide.index), wide.to_numpy(dtype=float))
    return out


def trial_means(zscored: pd.DataFrame) -> pd.DataFrame:
    """Mean z-scored response per dataset and trial: columns dataset, trial,
    mean_z, n_participants (trials in trial_ids() order)."""
    rows = []
    for dataset, (participants, Z) in participant_matrices(zscored).items():
        for trial, m in zip(trial_ids(), Z.mean(axis=0)):
            rows.append((dataset, trial, m, len(participants)))
    return pd.DataFrame(rows, columns=["dataset", "trial", "mean_z", "n_participants"])


def resample_trial_means(zscored: pd.DataFrame, n_boot: int, rng: np.random.Generator
                         ) -> dict[str, np.ndarray]:
    """Bootstrap trial means by resampling participants with replacement.

    For each dataset in `ordered_datasets` order, draws ``rng.integers(0, n, size=(n_boot, n))``
    (n = participants in that dataset, indexed in sorted participant-id order)
    and averages the resampled participants' z-scores. Returns {dataset: array (n_boot, 24)}, columns in trial_ids() order.
    """
    out = {}
    for dataset, (_, Z) in participant_matrices(zscored).items():
        n = Z.shape[0]
        idx = rng.integers(0, n, size=(n_boot, n))
        # Averaged a block of resamples at a time: Z[idx] whole would hold
        # n_boot x n x 24 floats (0.9 GB for 5,000 participants); the same sums, in bounded memory.
        means = np.empty((n_boot, Z.shape[1]))
        rows = max(1, BOOTSTRAP_BLOCK_BYTES // max(1, n * Z.shape[1] * 8))
        for a in range(0, n_boot, rows):
            means[a:a + rows] = Z[idx[a:a + rows]].mean(axis=1)
        out[dataset] = means
    return out


def trial_mean_intervals(zscored: pd.DataFrame, boot_means: Mapping[str, np.ndarray],
                         level: float = 0.95) -> pd.DataFrame:
    """Trial means with percentile bootstrap intervals.

    Columns dataset, trial, mean_z (full-sample mean), ci_low, ci_high (the
    (1-level)/2 and (1+level)/2 percentiles of the bootstrap means, numpy's linear
    interpolation), n_participants, n_boot.
    """
    means = trial_means(zscored)
    tail = 100 * (1 - level) / 2
    lows, highs, nboot = [], [], []
    for dataset in means["dataset"].unique():
        boot = boot_means[dataset]
        lows.append(np.percentile(boot, tail, axis=0))
        highs.append(np.percentile(boot, 100 - tail, axis=0))
        nboot.append(np.full(len(trial_ids()), boot.shape[0]))
    return means.assign(ci_low=np.concatenate(lows), ci_high=np.concatenate(highs),
                        n_boot=np.concatenate(nboot))


def bootstrap_trial_means(zscored: pd.DataFrame, n_boot: int, rng: np.random.Generator,
                          level: float = 0.95) -> pd.DataFrame:
    """Trial means with 95% participant-bootstrap intervals in one call
    (`resample_trial_means` then `trial_mean_intervals`)."""
    return trial_mean_intervals(zscored, resample_trial_means(zscored, n_boot, rng), level)
