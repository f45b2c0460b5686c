"""Permutation tests of the risk term: does risk, attached to the right trials,
let Eq. 1 predict held-out trials better than effort alone?

Statistic: the full model's cross-validated gain over effort-only, gain = RMSE
(effort-only) - RMSE(Eq. 1), both on held-out folds by structure (SCHEME:
analysis.crossval.STRUCTURE_SCHEME, a pair and every trial whose B is identical
held out together; sigma chosen inside every fold). Positive: risk helps
predict unseen structures.

Null distributions, everything refit (sigma included) for each permutation
(CALIBRATION says which are calibrated; docs/results.md has their measured
false-positive rates):

* ``freedman-lane`` (the default): the residuals of the effort-only fit on all
  trials are permuted across trials and added back to that fit (Freedman & Lane
  1983), y* = X b_E + P e_E; E and risk stay with their trials. Under the null
  (responses are effort-only plus exchangeable noise) y* has the data's law.
* ``within-pair``: each pair's easy and hard trial swap their risks with
  probability 1/2, independently per pair. It asks whether risk's contribution
  is the easy/hard contrast within pairs, keeping which pairs are risky.
* ``shuffle`` (NOT CALIBRATED): the trials' risks permuted across all trials
  (one permutation for every sigma, so each trial's risk curve moves whole),
  while E, the responses and the folds stay. Not exchangeable: a moved risk
  curve breaks the link of risk with the trial's structure (and its identical
  twins) that the folds keep; it rejects too often under the null. Kept to
  measure, labelled.

p = (1 + #{null gain >= observed gain}) / (1 + n_perm), per dataset (datasets
share the permutations; each p is valid on its own).
"""
from __future__ import annotations

import numbers
from typing import Mapping

import numpy as np
import pandas as pd

from analysis.crossval import STRUCTURE_SCHEME, RiskGrid, cross_validate, grouping_label, pairs_of, scores, structure_groups
from analysis.data import ordered_datasets
from analysis.data.trialset import trial_ids
from analysis.models import effort_per_trial
from lgp.errors import InputError

KINDS: tuple[str, ...] = ("freedman-lane", "within-pair", "shuffle")
#: Whether each null is calibrated (false-positive rates measured in bench/analysis_power.py --only fpr, docs/results.md).
CALIBRATION = {"freedman-lane": "calibrated (default)", "within-pair": "calibrated",
               "shuffle": "NOT CALIBRATED (risk moved across trials while E and the folds stay)"}
#: Default permutations per test.
N_PERM = 1000
#: Seed stream of the permutations in run_analysis: ``default_rng([seed, PERMUTATION_STREAM])``.
PERMUTATION_STREAM = 2302
#: The cross-validation scheme of the statistic: folds by structure.
SCHEME = STRUCTURE_SCHEME


def check_count(value, what: str) -> int:
    """`value` as an int if it is a whole number >= 1, else InputError naming `what`."""
    if isinstance(value, bool) or not isinstance(value, (numbers.Integral, numbers.Real)) \
            or not np.isfinite(value) or value != int(value) or value < 1:
        raise InputError(f"{what} must be a whole number >= 1, got {value!r}")
    return int(value)


def draw_permutations(kind: str, n_perm: int, rng: np.random.Generator, trials=None) -> np.ndarray:
    """(n_perm, T) trial index permutations: ``shuffle`` and ``freedman-lane`` draw
    ``rng.permuted`` of every row (of risks, of residuals); ``within-pair``
    ``rng.random((n_perm, pairs)) < 0.5`` swaps."""
    trials = trial_ids() if trials is None else trials
    n_perm = check_count(n_perm, "the number of permutations")
    T = len(trials)
    base = np.tile(np.arange(T), (n_perm, 1))
    if kind in ("shuffle", "freedman-lane"):
        return rng.permuted(base, axis=1)
    if kind == "within-pair":
        pairs = np.array(pairs_of(list(trials)), dtype=int).reshape(-1, 2)
        if not len(pairs):
            raise InputError(f"within-pair permutations: {skip_reason(kind, trials)}")
        swap = rng.random((n_perm, len(pairs))) < 0.5
        out = base.copy()
        out[:, pairs[:, 0]] = np.where(swap, pairs[:, 1], pairs[:, 0])
        out[:, pairs[:, 1]] = np.where(swap, pairs[:, 0], pairs[:, 1])
        return out
    raise InputError(f"unknown permutation kind {kind!r}; expected one of {', '.join(KINDS)}")


def skip_reason(kind: str, trials=None) -> str | None:
    """Why the null of `kind` cannot be drawn on `trials`, or None: the within-pair
    null swaps the risks of each pair's easy and hard trial, so it needs at least
    one pair (nE and nH both among the trials)."""
    trials = trial_ids() if trials is None else trials
    if kind == "within-pair" and not pairs_of(list(trials)):
        return ("skipped: no easy/hard pairs (nE and nH both) among the trials "
                f"{', '.join(map(str, trials))}; the within-pair null swaps risks within pairs")
    return None


def distinct_assignments(kind: str, risk: np.ndarray, trials=None) -> float:
    """Number of distinct risk tables (S, T) a permutation of `kind` can produce:
    shuffle T! / prod(m!) over groups of trials with identical risk curves (a
    float; may be huge); within-pair 2^k, k the pairs whose E and H curves differ."""
    trials = trial_ids() if trials is None else trials
    from math import lgamma

    if kind == "freedman-lane":
        return float("nan")  # permutes residuals, not risk tables
    if kind == "within-pair":
        pairs = pairs_of(list(trials))
        return float(2 ** sum(not np.array_equal(risk[:, e], risk[:, h]) for e, h in pairs))
    _, counts = np.unique(np.round(risk.T, 12), axis=0, return_counts=True)
    n = float(np.exp(lgamma(risk.shape[1] + 1) - sum(lgamma(c + 1) for c in counts)))
    return float(round(n)) if n < 1e15 else n


def cv_gain(Y: np.ndarray, E: np.ndarray, risk: np.ndarray, scheme: str = SCHEME, pool: bool = True,
            groups=None, trials=None) -> np.ndarray:
    """Cross-validated RMSE of effort-only minus Eq. 1's: Y (B, D, T), risk
    (S, T) or (B, S, T); returns (B, D). `groups` the structure groups (default:
    from `risk` when it is one (S, T) table)."""
    trials = trial_ids() if trials is None else trials
    if scheme == STRUCTURE_SCHEME and groups is None:
        groups = structure_groups(trials, np.asarray(risk))
    preds, _, _ = cross_validate(Y, E, {"R": risk}, ["full", "effort"], scheme, pool=pool, groups=groups,
                                 trials=trials)
    return scores(Y, preds["effort"], trials)["rmse"] - scores(Y, preds["full"], trials)["rmse"]


def _effort(effort, trials) -> np.ndarray:
    """Effort in `trials` order: the paper's 24 through models.effort_per_trial (its
    checks); another trial set from a Series indexed by trial id or T values in order."""
    if trials == list(trial_ids()):
        return effort_per_trial(effort).to_numpy()
    if isinstance(effort, pd.Series):
        missing = [t for t in trials if t not in effort.index]
        if missing:
            raise InputError(f"effort lacks trial(s) {', '.join(missing)}")
        return effort.reindex(trials).to_numpy(dtype=float)
    E = np.asarray(effort, dtype=float)
    if E.shape != (len(trials),):
        raise InputError(f"effort: expected {len(trials)} values in trial order, got shape {E.shape}")
    return E


def permutation_test(means: Mapping[str, np.ndarray], effort, grid: RiskGrid, n_perm: int = N_PERM,
                     rng: np.random.Generator | None = None, kinds=KINDS, scheme: str = SCHEME, groups=None,
                     trials=None) -> tuple[pd.DataFrame, pd.DataFrame]:
    """The permutation tests of `kinds` (module docstring) on the full-sample trial means.

    `means` {dataset: (24,)}; `grid` the risk over sigma (crossval.risk_grid).
    Permutations are drawn from `rng` kind by kind, in the order of `kinds`.
    Returns (summary, null): summary one row per (kind, dataset): kind,
    calibration (CALIBRATION), dataset, scheme, folds (the structure groups used),
    observed_gain, null_mean, null_q95, n_at_least, n_perm, p_value;
    null one row per (kind, dataset, permutation) with its gain.
    distinct_assignments is how many different risk tables the permutations can
    make (trials with identical risk curves swap to the same table): the
    observed table is one of them, so p cannot fall far below its inverse. With
    our table's few risky pairs the within-pair test has only 2^k of them.

    `trials` the trial ids of the columns (default the paper's 24). A kind that
    cannot be drawn on them (`skip_reason`: within-pair without pairs) gets one
    row per dataset with its reason in ``calibration``, NaN numbers and no null.
    """
    trials = trial_ids() if trials is None else trials
    n_perm = check_count(n_perm, "the number of permutations")
    rng = np.random.default_rng(0) if rng is None else rng
    trials = list(trials)
    E = _effort(effort, trials)
    datasets = ordered_datasets(means)
    Y = np.stack([np.asarray(means[d], float) for d in datasets])[None]     # (1, D, T)
    if scheme == STRUCTURE_SCHEME:
        # `groups` from the caller (identical B's of the trial files), else pairs and identical risk curves
        groups = structure_groups(trials, grid.risk) if groups is None else groups
    else:
        groups = None
    observed = cv_gain(Y, E, grid.risk, scheme, groups=groups, trials=trials)[0]            # (D,)
    X = np.column_stack([np.ones(len(E)), E])
    fit = (X @ np.linalg.lstsq(X, Y[0].T, rcond=None)[0]).T                  # (D, T) effort-only fit
    grouping = grouping_label(groups, trials) if groups is not None else scheme
    rows, nulls = [], []
    for kind in kinds:
        reason = skip_reason(kind, trials)
        if reason is not None:
            rows += [(kind, reason, dataset, scheme, grouping, observed[k], np.nan, np.nan, 0, 0, np.nan, np.nan)
                     for k, dataset in enumerate(datasets)]
            continue
        perms = draw_permutations(kind, n_perm, rng, trials)
        if kind == "freedman-lane":
            Ystar = fit[None] + (Y[0] - fit)[:, perms].transpose(1, 0, 2)     # (P, D, T)
            null = cv_gain(Ystar, E, grid.risk, scheme, groups=groups, trials=trials)
        else:
            risks = grid.risk[:, perms].transpose(1, 0, 2)                     # (P, S, T)
            null = cv_gain(np.broadcast_to(Y, (n_perm,) + Y.shape[1:]), E, risks, scheme, groups=groups,
                           trials=trials)   # (P, D)
        distinct = distinct_assignments(kind, grid.risk, trials)
        for k, dataset in enumerate(datasets):
            g = null[:, k]
            at_least = int(np.sum(g >= observed[k] - 1e-12 * abs(observed[k])))
            rows.append((kind, CALIBRATION[kind], dataset, scheme, grouping, observed[k], float(np.mean(g)),
                         float(np.quantile(g, 0.95)), at_least, n_perm, (1 + at_least) / (1 + n_perm), distinct))
            nulls.append(pd.DataFrame({"kind": kind, "dataset": dataset, "permutation": np.arange(n_perm),
                                       "gain": g}))
    summary = pd.DataFrame(rows, columns=["kind", "calibration", "dataset", "scheme", "folds", "observed_gain",
                                          "null_mean", "null_q95", "n_at_least", "n_perm", "p_value",
                                          "distinct_assignments"])
    return summary, pd.concat(nulls, ignore_index=True)
