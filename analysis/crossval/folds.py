"""The schemes of analysis.crossval and their folds: which trials each fold trains
on and which it holds out (a pair's easy and hard trial together, or one trial)."""
from __future__ import annotations

import re
from typing import Sequence

import numpy as np

from analysis.data.trialset import trial_ids

#: The three ways a model is scored: fit and scored on the same 24 trials, or
#: scored on held-out pairs or trials.
SCHEMES: tuple[str, ...] = ("in-sample", "leave-one-pair-out", "leave-one-trial-out")
CV_SCHEMES: tuple[str, ...] = SCHEMES[1:]
#: Held-out folds by structure: a fold holds out a group of trials closed under
#: "same pair" and "identical B (identical risk curve over every sigma)", so a held-out
#: trial is never a copy of a training one (`structure_groups`). Not in SCHEMES:
#: its folds need the risk table, so callers ask for it with the groups.
STRUCTURE_SCHEME = "leave-one-structure-out"
#: Two risk curves closer than this at every sigma are the same structure.
SAME_CURVE_ATOL = 1e-12
#: Fewest easy/hard pairs leave-one-pair-out cross-validation accepts.
MIN_PAIRS = 3


class CrossValidationError(ValueError):
    """The trials or tables cannot be cross-validated: names the scheme and the rule."""


def pairs_of(trials: Sequence[str]) -> list[tuple[int, int]]:
    """(index of nE, index of nH) for every pair n whose easy and hard trial are
    both in `trials` (ids like 4E, 4H), in the order of first appearance."""
    where = {t: k for k, t in enumerate(trials)}
    out, seen = [], set()
    for t in trials:
        m = re.fullmatch(r"(\d+)([EH])", str(t))
        if m and m.group(1) not in seen and f"{m.group(1)}E" in where and f"{m.group(1)}H" in where:
            seen.add(m.group(1))
            out.append((where[f"{m.group(1)}E"], where[f"{m.group(1)}H"]))
    return out


def make_folds(scheme: str, trials: Sequence[str] | None = None) -> tuple[np.ndarray, np.ndarray]:
    """(train, test): index arrays (n_folds, n_train) and (n_folds, n_test) into
    `trials`. In-sample is one fold with train = test = all trials; leave-one-pair-
    out holds out both trials of a pair (trials in no complete pair are always
    trained on); leave-one-trial-out one trial. Raises CrossValidationError for an
    unknown scheme, fewer than MIN_PAIRS pairs (leave-one-pair-out), or folds that
    leave fewer than 4 training trials (Eq. 1 has 3 parameters)."""
    trials = trial_ids() if trials is None else trials
    n = len(trials)
    every = np.arange(n)
    if scheme == "in-sample":
        return every[None, :], every[None, :]
    if scheme == "leave-one-pair-out":
        pairs = pairs_of(trials)
        if len(pairs) < MIN_PAIRS:
            raise CrossValidationError(
                f"leave-one-pair-out cross-validation needs at least {MIN_PAIRS} easy/hard pairs (nE and nH both "
                f"among the trials); the {n} trials have {len(pairs)}")
        test = np.array(pairs, dtype=int)
    elif scheme == "leave-one-trial-out":
        test = every[:, None]
    else:
        raise CrossValidationError(f"unknown scheme {scheme!r}; expected one of {', '.join(SCHEMES)}")
    train = np.array([np.setdiff1d(every, held) for held in test], dtype=int)
    if train.shape[1] < 4:
        raise CrossValidationError(f"{scheme}: folds leave {train.shape[1]} training trials; Eq. 1 needs at least 4")
    return train, test


def structure_groups(trials: Sequence[str], risk: np.ndarray | None = None,
                     same: Sequence[Sequence[str]] = ()) -> list[tuple[int, ...]]:
    """Groups of trial indices for STRUCTURE_SCHEME: the connected components of
    "nE and nH are a pair", the explicit `same` sets of trial ids (identical B:
    analysis.heuristics.identical_targets) and "identical risk curves that vary
    with sigma" (columns of `risk` (S, T) within SAME_CURVE_ATOL at every sigma
    and not constant over sigma: the same B simulated with the same random
    numbers; a curve that never or always falls says nothing about which B it
    is). Sorted by first trial; trials in none of these are their own group."""
    T = len(trials)
    parent = list(range(T))

    def find(i: int) -> int:
        while parent[i] != i:
            parent[i] = parent[parent[i]]
            i = parent[i]
        return i

    def join(i: int, j: int) -> None:
        a, b = find(i), find(j)
        if a != b:
            parent[max(a, b)] = min(a, b)

    for e, h in pairs_of(list(trials)):
        join(e, h)
    if risk is not None:
        R = np.asarray(risk, dtype=float)
        if R.ndim != 2 or R.shape[1] != T:
            raise CrossValidationError(f"{STRUCTURE_SCHEME}: risk must be (sigmas, {T} trials), got {R.shape}")
        varies = np.ptp(R, axis=0) > SAME_CURVE_ATOL
        for i in range(T):
            for j in range(i + 1, T):
                if varies[i] and varies[j] and np.all(np.abs(R[:, i] - R[:, j]) <= SAME_CURVE_ATOL):
                    join(i, j)
    where = {t: k for k, t in enumerate(trials)}
    for names in same:
        idx = [where[n] for n in names if n in where]
        for k in idx[1:]:
            join(idx[0], k)
    groups: dict[int, list[int]] = {}
    for i in range(T):
        groups.setdefault(find(i), []).append(i)
    return sorted((tuple(g) for g in groups.values()), key=lambda g: g[0])


def grouping_label(groups: Sequence[Sequence[int]], trials: Sequence[str] | None = None) -> str:
    """The grouping as text: '1E 1H 9E 9H 11E 11H | 2E 2H | ...'."""
    trials = trial_ids() if trials is None else trials
    return " | ".join(" ".join(str(trials[i]) for i in g) for g in groups)


def structure_folds(groups: Sequence[Sequence[int]], n_trials: int) -> list[tuple[np.ndarray, np.ndarray]]:
    """[(train, test)] index arrays, one fold per group. Raises CrossValidationError for
    fewer than 2 groups, a trial in no group or two, or a fold leaving fewer than 4
    training trials (Eq. 1 has 3 parameters)."""
    flat = sorted(i for g in groups for i in g)
    if flat != list(range(n_trials)):
        raise CrossValidationError(f"{STRUCTURE_SCHEME}: the groups must hold each of the {n_trials} trials once")
    if len(groups) < 2:
        raise CrossValidationError(f"{STRUCTURE_SCHEME}: all {n_trials} trials are one structure group; "
                                   "nothing can be held out")
    every = np.arange(n_trials)
    out = []
    for g in groups:
        test = np.array(sorted(g), dtype=int)
        train = np.setdiff1d(every, test)
        if len(train) < 4:
            raise CrossValidationError(f"{STRUCTURE_SCHEME}: holding out {len(test)} trials leaves {len(train)} "
                                       "training trials; Eq. 1 needs at least 4")
        out.append((train, test))
    return out
