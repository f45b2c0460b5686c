"""The noise ceiling of the trial means: how well any model could correlate with
them, given how much the participants disagree (split-half reliability with the
Spearman-Brown correction).

Per dataset: the participants are split at random into two halves (sizes
floor(n/2) and ceil(n/2)), each half's 24 trial means computed, and their
Pearson r taken; the split-half r is the mean over `n_splits` random splits.
The Spearman-Brown correction 2 r / (1 + r) is the reliability of the mean over
all n participants (two halves of the whole). A model whose predictions were the
true trial means would correlate with the observed means at about
sqrt(reliability): the noise ceiling of r (``r_ceiling``), the number a model's r
is read against.

Interval: participants resampled with replacement (one split per resample, the
participant bootstrap of analysis.data.resample_trial_means' kind), the
resampled reliabilities centred on the point estimate
(analysis.bootstrap.centred_interval), so the interval always contains it.
Everything is drawn from `rng`: the splits first, then per resample the
participant draw and its split.
"""
from __future__ import annotations

import numpy as np
import pandas as pd

from analysis.bootstrap import INTERVAL, centred_interval
from analysis.data import participant_matrices
from analysis.models import rowwise_pearson

#: Random splits of the point estimate and participant resamples of its interval.
N_SPLITS = 200
N_BOOT = 200
#: Seed stream of the noise ceiling in a run: ``default_rng([seed, CEILING_STREAM])``.
CEILING_STREAM = 2304
#: How the table is labelled.
METHOD = ("split-half reliability of the trial means (participants split at random, halves' trial means "
          "correlated, Spearman-Brown corrected); r_ceiling = sqrt(reliability), the r a perfect model would reach")


def spearman_brown(r: np.ndarray) -> np.ndarray:
    """Reliability of the whole from the correlation r of its two halves: 2r / (1 + r)."""
    r = np.asarray(r, float)
    with np.errstate(invalid="ignore", divide="ignore"):
        return 2 * r / (1 + r)


def split_half_r(Z: np.ndarray, rows: np.ndarray, rng: np.random.Generator) -> np.ndarray:
    """Correlation of the two halves' trial means for each row of participant
    indices `rows` (K, n) into Z (participants, T): one random split per row."""
    K, n = rows.shape
    half = n // 2
    order = rng.permuted(np.tile(np.arange(n), (K, 1)), axis=1)
    take = np.take_along_axis(rows, order, axis=1)
    a = Z[take[:, :half]].mean(axis=1)
    b = Z[take[:, half:]].mean(axis=1)
    with np.errstate(invalid="ignore", divide="ignore"):
        return rowwise_pearson(a, b)


def noise_ceiling(zscored: pd.DataFrame, rng: np.random.Generator, n_splits: int = N_SPLITS,
                  n_boot: int = N_BOOT, level: float = 0.95) -> pd.DataFrame:
    """One row per dataset: dataset, participants, split_half_r, reliability (Spearman-
    Brown), reliability_low/high, r_ceiling, r_ceiling_low/high, n_splits, n_boot,
    interval, method (module docstring). A dataset of fewer than 4 participants
    gets NaN (two halves of at least 2)."""
    rows = []
    for dataset, (participants, Z) in participant_matrices(zscored).items():
        n = len(participants)
        if n < 4:
            rows.append((dataset, n) + (np.nan,) * 8 + (n_splits, n_boot, INTERVAL, METHOD))
            continue
        r = split_half_r(Z, np.tile(np.arange(n), (n_splits, 1)), rng)
        split_r = float(np.nanmean(r))
        rel = float(spearman_brown(split_r))
        boot_rows = rng.integers(0, n, size=(n_boot, n))
        boot_rel = spearman_brown(split_half_r(Z, boot_rows, rng))
        lo, hi = centred_interval(rel, boot_rel, level, (-np.inf, 1.0))
        ceil = float(np.sqrt(rel)) if rel >= 0 else np.nan
        c_lo, c_hi = (float(np.sqrt(max(lo, 0.0))), float(np.sqrt(max(hi, 0.0)))) if rel >= 0 else (np.nan, np.nan)
        rows.append((dataset, n, split_r, rel, lo, hi, ceil, c_lo, c_hi, float(np.nanstd(r)), n_splits, n_boot,
                     INTERVAL, METHOD))
    return pd.DataFrame(rows, columns=["dataset", "participants", "split_half_r", "reliability", "reliability_low",
                                       "reliability_high", "r_ceiling", "r_ceiling_low", "r_ceiling_high",
                                       "split_half_r_sd", "n_splits", "n_boot", "interval", "method"])
