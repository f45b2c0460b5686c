"""The design objective: a set of trials whose risk is not a stand-in for tower
height, block count or effort, and whose risk curves spread over the sigma prior.

For a set of k trials with effort E, height H, blocks N, stacked blocks S and
risk R(0.10 d), R(0.15 d):

    cost = c + 10 max(0, c - TARGET_R) + 5 max(0, RISING - rising)
           - 0.5 (sd R(0.10) + sd R(0.15)) - 0.5 p

    c      = max |r(R_s, f)| over s in {0.10, 0.15}, f in {H, N, E}   (Pearson)
    rising = the share of risk curves rising within the prior (screen.RISE)
    p      = min over s and over the baselines {E, H}, {E, S}, {E, N} of
             1 - R^2 of E R_s regressed on the baseline: the part of the full
             model's risk term (b2 - b1) E R no simpler story can mimic

(a constant column counts as |r| = 1). This is a proxy for the power of the
model comparison; the chosen set's power is measured with analysis.power.
The search is simulated annealing over swaps (one trial out, one in), from a
numpy Generator: the same pool and seed choose the same set.
"""
from __future__ import annotations

import numpy as np
import pandas as pd
from lgp.errors import InputError

#: The goal for |r| between risk and height, block count and effort (issue 34).
TARGET_R = 0.3
#: The goal share of risk curves rising within the prior.
RISING = 0.5
#: Risk columns the objective reads: sigma 0.10 d and 0.15 d.
RISK_SIGMAS = (0.10, 0.15)
STEPS = 6000


def _partial_unexplained(r_y1: float, r_y2: float, r_12: float) -> float:
    """1 - R^2 of y regressed on [1, x1, x2], from the three Pearson correlations."""
    den = 1 - r_12 ** 2
    if den < 1e-12:  # x1 and x2 collinear: y on x1 alone
        return 1 - r_y1 ** 2
    return max(0.0, 1 - (r_y1 ** 2 + r_y2 ** 2 - 2 * r_y1 * r_y2 * r_12) / den)


def terms(E, H, N, S, R10, R15, rises) -> dict:
    """The objective's parts for one set (arrays of equal length). A constant
    column correlates |r| = 1 with everything (the worst case, never chosen)."""
    E = np.asarray(E, float)
    R10, R15 = np.asarray(R10, float), np.asarray(R15, float)
    X = np.vstack([E, np.asarray(H, float), np.asarray(N, float), np.asarray(S, float), R10, R15, E * R10, E * R15])
    sd = X.std(axis=1)
    const = sd < 1e-12
    Z = (X - X.mean(axis=1, keepdims=True)) / np.where(const, 1.0, sd)[:, None]
    C = (Z @ Z.T) / X.shape[1]
    C[const, :] = 1.0
    C[:, const] = 1.0
    e, h, n, s, r10, r15, er10, er15 = range(8)
    c = float(max(abs(C[r, f]) for r in (r10, r15) for f in (h, n, e)))
    p = min(_partial_unexplained(C[er, e], C[er, b], C[e, b]) if not const[er] else 0.0
            for er in (er10, er15) for b in (h, s, n))
    rising = float(np.mean(np.asarray(rises, bool)))
    spread = float(sd[r10] + sd[r15])
    cost = c + 10 * max(0.0, c - TARGET_R) + 5 * max(0.0, RISING - rising) - 0.5 * spread - 0.5 * p
    return {"cost": cost, "max_abs_r": c, "rising": rising, "risk_sd": spread, "unexplained": p}


def columns(df: pd.DataFrame, effort: str, risk: str) -> tuple:
    """The objective's arrays from a table with columns `effort`, height, blocks,
    stacked, `risk`_0.1, `risk`_0.15 and `risk`_rises."""
    return (df[effort].to_numpy(float), df["height"].to_numpy(float), df["blocks"].to_numpy(float),
            df["stacked"].to_numpy(float), df[f"{risk}_0.1"].to_numpy(float), df[f"{risk}_0.15"].to_numpy(float),
            df[f"{risk}_rises"].to_numpy(bool))


def choose(df: pd.DataFrame, k: int, rng: np.random.Generator, effort: str = "effort_proxy", risk: str = "screen_risk",
           steps: int = STEPS) -> tuple[list[int], dict]:
    """Positions (into `df`, sorted) of the k rows minimising the cost, and its terms."""
    n = len(df)
    if not 1 <= k <= n:
        raise InputError(f"cannot choose {k} trials from {n} candidates")
    cols = columns(df, effort, risk)
    cost = lambda idx: terms(*(c[idx] for c in cols))["cost"]  # noqa: E731
    current = np.sort(rng.choice(n, k, replace=False))
    best, best_cost = current.copy(), cost(current)
    now = best_cost
    if n > k:
        inside = np.zeros(n, bool)
        inside[current] = True
        for step in range(steps):
            temp = 0.05 * (1 - step / steps) + 1e-4
            i_out = int(rng.integers(k))
            j_in = int(rng.choice(np.flatnonzero(~inside)))
            trial = current.copy()
            trial[i_out] = j_in
            c_new = cost(trial)
            if c_new < now or rng.random() < np.exp(-(c_new - now) / temp):
                inside[current[i_out]], inside[j_in] = False, True
                current, now = trial, c_new
                if now < best_cost - 1e-12:
                    best, best_cost = np.sort(current), now
    chosen = sorted(int(i) for i in best)
    return chosen, terms(*(c[chosen] for c in cols))
