"""The schemes of analysis.crossval and their folds: which trials each fold trains
on and which it holds out (a pair's easy and hard trial together, or one trial)."""
from __future__ import annotations

import re
from typing import Sequence

import numpy as np

from analysis.data import TRIAL_IDS

#: The three ways a model is scored: fit and scored on the same 24 trials, or
#: scored on held-out pairs or trials.
SCHEMES: tuple[str, ...] = ("in-sample", "leave-one-pair-out", "leave-one-trial-out")
CV_SCHEMES: tuple[str, ...] = SCHEMES[1:]
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


def make_folds(scheme: str, trials: Sequence[str] = TRIAL_IDS) -> tuple[np.ndarray, np.ndarray]:
    """(train, test): index arrays (n_folds, n_train) and (n_folds, n_test) into
    `trials`. In-sample is one fold with train = test = all trials; leave-one-pair-
    out holds out both trials of a pair (trials in no complete pair are always
    trained on); leave-one-trial-out one trial. Raises CrossValidationError for an
    unknown scheme, fewer than MIN_PAIRS pairs (leave-one-pair-out), or folds that
    leave fewer than 4 training trials (Eq. 1 has 3 parameters)."""
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
