"""Fitting the risk model's noise level sigma (Results section, first paragraph).

The paper fit Eq. 1 to each dataset at every sigma of a grid from 0.05 d to
0.10 d in steps of 0.005 d (d = block length), looked at the RMSE between model
and mean z-scored responses, and set one sigma, 0.065, for all datasets ("RMSE
was higher for lower noise levels, and didn't change much for a range of
levels"). We make that choice a rule: the pooled sigma minimises the mean over
datasets of the per-dataset RMSE (all datasets are z-scored, so their RMSEs are
in the same units); ties go to the smallest sigma. The per-dataset minimisers
are reported too.
"""
from __future__ import annotations

from typing import Sequence

import numpy as np
import pandas as pd

from lgp.errors import InputError
from lgp.paper import PAPER_SIGMA, SIGMA_GRID  # noqa: F401  (re-exported)
from analysis.models import effort_per_trial, fit_model, risk_at_sigma, risk_sigmas

#: RMSEs closer than this (relative to the least) are a tie: the smaller sigma wins.
RMSE_TIE_REL = 1e-9
#: Below this an RMSE (or RSS) is rounding error of an exact fit: ties at zero too.
RMSE_TIE_ABS = 1e-12


def least_sigma_index(values, axis: int = 0, rel: float = RMSE_TIE_REL, abs_tol: float = RMSE_TIE_ABS) -> np.ndarray:
    """Index along `axis` (sigmas ascending) of the least value, ties explicit:
    every value within ``rel * |least| + abs_tol`` of the least is tied, and the
    first of them (the smallest sigma) wins, whatever rounding the CPU did. NaN
    never wins unless every value is NaN (then index 0). Returns an int array of
    the other axes' shape (a 0-d array for a vector)."""
    v = np.asarray(values, dtype=float)
    v = np.where(np.isnan(v), np.inf, v)
    best = v.min(axis=axis, keepdims=True)
    tied = v <= best + rel * np.abs(np.where(np.isfinite(best), best, 0.0)) + abs_tol
    return np.argmax(tied, axis=axis)



def sigma_profile(means: pd.DataFrame, effort, risk_table: pd.DataFrame,
                  sigmas: Sequence[float] | None = None) -> pd.DataFrame:
    """RMSE of the full model (Eq. 1) fit separately at each sigma and dataset.

    `means` has columns dataset, trial, mean_z; `effort` is anything
    `effort_per_trial` accepts; `risk_table` has columns trial, sigma, risk.
    `sigmas` defaults to every sigma in the risk table (the paper's grid is
    SIGMA_GRID); a requested sigma missing from the table raises ModelInputError.

    Returns one row per (dataset, sigma): dataset, sigma, rmse, r, b0, b1, b2.
    """
    E = effort_per_trial(effort)
    grid = risk_sigmas(risk_table) if sigmas is None else np.asarray(sigmas, dtype=float)
    rows = []
    for sigma in grid:
        R = risk_at_sigma(risk_table, sigma)
        for dataset, group in means.groupby("dataset", sort=True):
            fit = fit_model("full", group.set_index("trial")["mean_z"], E, R)
            rows.append((dataset, float(sigma), fit.rmse, fit.r, *fit.coefficients))
    return (pd.DataFrame(rows, columns=["dataset", "sigma", "rmse", "r", "b0", "b1", "b2"])
            .sort_values(["dataset", "sigma"]).reset_index(drop=True))


def choose_sigma(profile: pd.DataFrame) -> pd.DataFrame:
    """The best sigma per dataset and pooled over datasets.

    Per dataset: the sigma of least RMSE. Pooled (row dataset='pooled'): the
    sigma of least mean RMSE across datasets, the paper's one-sigma-for-all
    choice. Ties (`least_sigma_index`) go to the smallest sigma. Returns columns dataset, sigma, rmse
    (the pooled row's rmse is the mean RMSE), rule.
    """
    rows = []
    for dataset, group in profile.sort_values("sigma").groupby("dataset", sort=True):
        best = group.iloc[int(least_sigma_index(group["rmse"].to_numpy()))]
        rows.append((dataset, best["sigma"], best["rmse"], "least RMSE in this dataset"))
    datasets = profile["dataset"].nunique()
    counts = profile.groupby("sigma")["dataset"].nunique()
    if (counts != datasets).any():
        raise InputError("sigma profile is ragged: every dataset needs every sigma to pool")
    mean_rmse = profile.groupby("sigma")["rmse"].mean().sort_index()
    k = int(least_sigma_index(mean_rmse.to_numpy()))
    rows.append(("pooled", float(mean_rmse.index[k]), float(mean_rmse.iloc[k]),
                 f"least mean RMSE over {datasets} dataset(s)"))
    return pd.DataFrame(rows, columns=["dataset", "sigma", "rmse", "rule"])


def pooled_sigma(profile: pd.DataFrame) -> float:
    """The single sigma used for all datasets (see `choose_sigma`)."""
    choice = choose_sigma(profile)
    return float(choice.loc[choice["dataset"] == "pooled", "sigma"].iloc[0])
