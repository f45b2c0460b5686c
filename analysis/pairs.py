"""Easy/hard pair orderings (Results: "The model produces the correct rank order
... in 11 of the pairs. The only exception is the pair 11E and 11H").
"""
from __future__ import annotations

from typing import Mapping

import numpy as np
import pandas as pd

from analysis.data import PAIRS, TRIAL_IDS
from analysis.models import ModelInputError


def pair_table(cost: pd.Series | Mapping[str, float]) -> pd.DataFrame:
    """Compare the easy and hard trial of each of the 12 pairs.

    `cost` is any per-trial quantity keyed by trial id: full-model predictions,
    effort E, risk R, or mean human z-scores. Returns 12 rows: pair (1..12),
    cost_E, cost_H, E_lt_H (True when the easy trial has the strictly smaller
    cost, the paper's "correct rank order"). ``table['E_lt_H'].sum()`` is the
    number of correctly ordered pairs. Raises ModelInputError naming a missing
    or non-finite trial.
    """
    series = pd.Series(cost, dtype=float)
    series.index = [str(t).strip().upper() for t in series.index]
    missing = [t for t in TRIAL_IDS if t not in series.index]
    if missing:
        raise ModelInputError(f"pair table: cost is missing trial(s) {', '.join(missing)}")
    bad = [t for t in TRIAL_IDS if not np.isfinite(series[t])]
    if bad:
        raise ModelInputError(f"pair table: cost of trial {bad[0]} is {series[bad[0]]!r}, "
                              "not a finite number")
    easy = np.array([series[f"{p}E"] for p in PAIRS])
    hard = np.array([series[f"{p}H"] for p in PAIRS])
    return pd.DataFrame({"pair": list(PAIRS), "cost_E": easy, "cost_H": hard, "E_lt_H": easy < hard})
