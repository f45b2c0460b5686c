"""Risk as analysis.crossval reads it: every trial's risk over a sigma grid
(`RiskGrid`, from the risk table or one build-risk aggregate), and its Monte Carlo
error redrawn from the runs behind it (`redraw_risk`; the "Bootstrap" paragraph of
analysis.crossval's docstring)."""
from __future__ import annotations

from dataclasses import dataclass
from typing import Sequence

import numpy as np
import pandas as pd
from scipy import stats

from analysis.data.trialset import trial_ids
from analysis.models import ModelInputError, measure_at_sigma, risk_at_sigma, risk_sigmas

#: How each bootstrap resample treats risk: fixed at the table, or redrawn from its runs.
RISK_DRAWS: tuple[str, ...] = ("none", "binomial")
#: Seed streams of the comparison beside the participant bootstrap's own:
#: ``default_rng([seed, RISK_DRAW_STREAM])`` draws the risk redraws.
RISK_DRAW_STREAM = 2301


@dataclass(frozen=True)
class RiskGrid:
    """Risk of every trial at every sigma of a table: ``risk[s, i]`` is trial
    trial_ids()[i] at ``sigmas[s]`` (ascending); ``runs`` the number of noisy runs
    behind each value (None when the table does not say, e.g. a build-risk
    aggregate)."""

    sigmas: np.ndarray
    risk: np.ndarray
    runs: np.ndarray | None = None
    label: str = "R"


def risk_grid(risk_table: pd.DataFrame, sigmas: Sequence[float] | None = None) -> RiskGrid:
    """The risk table (columns trial, sigma, risk; optional n_sims or n, the runs
    per row) as a RiskGrid over `sigmas` (default: every sigma in the table, any
    grid). Raises ModelInputError naming the trial and sigma of a missing or bad
    value, or a run count that is not a whole number >= 1."""
    grid = risk_sigmas(risk_table) if sigmas is None else np.unique(np.round(np.asarray(sigmas, float), 9))
    risk = np.stack([risk_at_sigma(risk_table, s).to_numpy() for s in grid])
    column = "n_sims" if "n_sims" in risk_table.columns else ("n" if "n" in risk_table.columns else None)
    runs = None
    if column is not None:
        runs = np.empty_like(risk)
        for k, s in enumerate(grid):
            rows = risk_table[np.isclose(risk_table["sigma"].astype(float), s, rtol=0, atol=1e-9)]
            n = pd.Series(pd.to_numeric(rows[column], errors="coerce").to_numpy(),
                          index=rows["trial"].astype(str).str.strip().str.upper()).reindex(list(trial_ids()))
            bad = n[~(np.isfinite(n) & (n >= 1) & (n == np.round(n)))]
            if len(bad):
                raise ModelInputError(f"risk table: {column} of trial {bad.index[0]} at sigma {s:g} is "
                                      f"{float(bad.iloc[0]):g}, not a whole number >= 1 (runs behind the risk)")
            runs[k] = n.to_numpy()
    return RiskGrid(np.asarray(grid, dtype=float), risk, runs, "R")


def measure_grid(build_table: pd.DataFrame, measure: str) -> RiskGrid:
    """One build-risk aggregate (models.risk.build's long table: trial, sigma,
    measure, risk) as a RiskGrid over the table's sigmas; no run counts."""
    grid = np.unique(np.round(build_table["sigma"].astype(float), 9))
    risk = np.stack([measure_at_sigma(build_table, s, measure).to_numpy() for s in grid])
    return RiskGrid(grid, risk, None, measure)


def redraw_risk(grid: RiskGrid, n_draws: int, rng: np.random.Generator) -> np.ndarray:
    """(n_draws, S, T) risks redrawn from their runs: falls ~ Binomial(runs, risk)
    by quantile coupling, one uniform per (draw, trial) for every sigma
    (analysis.crossval's docstring). Draws ``rng.random((n_draws, T))``."""
    if grid.runs is None:
        raise ModelInputError(f"risk source {grid.label!r} has no run counts (column n_sims or n); its Monte Carlo "
                              "error cannot be redrawn")
    S, T = grid.risk.shape
    U = rng.random((n_draws, T))
    out = np.empty((n_draws, S, T))
    for s in range(S):
        for t in range(T):
            n = int(grid.runs[s, t])
            p = float(grid.risk[s, t])
            if p <= 0.0 or p >= 1.0:
                out[:, s, t] = p
                continue
            cdf = stats.binom.cdf(np.arange(n + 1), n, p)
            falls = np.minimum(np.searchsorted(cdf, U[:, t], side="left"), n)
            out[:, s, t] = falls / n
    return out
