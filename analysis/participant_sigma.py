"""Each participant's own sigma (beyond the paper; its Discussion: "it would be
interesting to try and infer the level of noise directly from people").

For participant p with z-scored responses z_p (24 trials), Eq. 1 at noise level
sigma predicts  y_i = b0 + b1 E_i (1 - R_i(sigma)) + b2 E_i R_i(sigma).  R_i(sigma)
between the risk table's grid points is linear interpolation (trial by trial);
sigma is searched on a fine grid (step 0.001 d by default, plus every grid point)
inside the table's range -- never extrapolated.

Betas, option `betas`:

* ``"shared"`` (default): the ratio b2/b1 is shared by a dataset's participants,
  while each has their own sigma, intercept and scale:
  y_pi = a_p + c_p E_i [(1 - R_i(sigma_p)) cos t + R_i(sigma_p) sin t].
  z-scoring leaves only a response's shape up to a positive affine map, so a
  participant's intercept and scale are theirs anyway (analysis.simulate); what
  Eq. 1 shares across a dataset is the direction t of (b1, b2). t is fit by a
  grid over [0, pi) refined by golden-section search, each participant's sigma,
  a_p and c_p by least squares given t. Default because it is the paper's model
  (one b2/b1 per dataset) with sigma freed, and because with all three betas
  free sigma enters a participant's fit only through the direction of E*R(sigma)
  (E(1-R) b1 + E R b2 = E b1 + E R (b2 - b1)), so 24 responses must pin down four
  numbers and sigma trades off with b2 - b1. (Sharing b0, b1, b2 themselves in z
  units is misspecified: a participant's z-scale depends on their own sigma.)
* ``"participant"``: (b0, b1, b2) of each participant fit at each sigma.

Interval: profile likelihood under Gaussian residuals of unknown variance,
  {sigma : n log(RSS_p(sigma) / RSS_p(sigma_hat)) <= chi2_1(level)},  n = 24,
with t at its estimate and a_p, c_p re-fit at each sigma (shared), or all three
betas re-fit at each sigma (participant).
When the risk curves are flat over sigma, RSS is flat and the interval is the
whole searched range: the table says so (`identified` False) rather than report
a point. An interval that touches an end of the range is censored there
(`low_censored`, `high_censored`).
"""
from __future__ import annotations

import numpy as np
import pandas as pd
from scipy.stats import chi2

from analysis.data import (exclude_constant_participants, participant_matrices, validate_human_data,
                           zscore_responses)
from analysis.models import ModelInputError, effort_per_trial, risk_at_sigma, risk_sigmas
from analysis.data import TRIAL_IDS
from analysis.sigma import least_sigma_index
from lgp.errors import InputError

#: Columns of the per-participant table.
COLUMNS = ["dataset", "participant", "sigma", "sigma_grid", "rmse", "sigma_low", "sigma_high",
           "low_censored", "high_censored", "identified", "level", "betas", "b0", "b1", "b2", "n_trials"]
BETAS = ("shared", "participant")


def interpolated_risk(risk_grid: pd.DataFrame, sigmas) -> np.ndarray:
    """Risk (len(sigmas), 24) by linear interpolation between the table's sigmas,
    trials in TRIAL_IDS order. Raises ModelInputError for a sigma outside the table."""
    grid = risk_sigmas(risk_grid)
    sigmas = np.asarray(sigmas, dtype=float)
    outside = sigmas[(sigmas < grid[0] - 1e-12) | (sigmas > grid[-1] + 1e-12)]
    if len(outside):
        raise ModelInputError(f"sigma {outside[0]:g} is outside the risk table's range "
                              f"{grid[0]:g}..{grid[-1]:g} (no extrapolation)")
    R = np.stack([risk_at_sigma(risk_grid, s).to_numpy() for s in grid])  # (G, 24)
    return np.stack([np.interp(sigmas, grid, R[:, i]) for i in range(R.shape[1])], axis=1)


def search_grid(risk_grid: pd.DataFrame, step: float = 0.001) -> np.ndarray:
    """The sigmas searched: the table's grid plus a fine grid of `step` inside it."""
    grid = risk_sigmas(risk_grid)
    if len(grid) < 2:
        return grid
    fine = np.arange(grid[0], grid[-1] + step / 2, step)
    return np.unique(np.round(np.concatenate([grid, fine[fine <= grid[-1] + 1e-12]]), 9))


def _designs(E: np.ndarray, R: np.ndarray) -> np.ndarray:
    """(S, 24, 3) Eq. 1 design matrices, one per searched sigma."""
    ones = np.ones_like(R)
    return np.stack([ones, E[None, :] * (1 - R), E[None, :] * R], axis=2)


def _rss_free(X: np.ndarray, Z: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """RSS (P, S) and betas (P, S, 3) of each participant's own least-squares fit at each sigma."""
    P, S = Z.shape[0], X.shape[0]
    rss, betas = np.empty((P, S)), np.empty((P, S, 3))
    for s in range(S):
        b, *_ = np.linalg.lstsq(X[s], Z.T, rcond=None)  # (3, P)
        resid = Z - (X[s] @ b).T
        rss[:, s] = (resid ** 2).sum(axis=1)
        betas[:, s] = b.T
    return rss, betas


def _rss_affine(x: np.ndarray, Z: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Each participant's least-squares intercept a and slope c on each regressor
    x[s] (S, 24): RSS (P, S), a (P, S), c (P, S)."""
    xc = x - x.mean(axis=1, keepdims=True)  # (S, 24)
    zc = Z - Z.mean(axis=1, keepdims=True)  # (P, 24)
    sxx = (xc ** 2).sum(axis=1)  # (S,)
    sxz = zc @ xc.T  # (P, S)
    with np.errstate(divide="ignore", invalid="ignore"):
        c = np.where(sxx > 0, sxz / np.where(sxx > 0, sxx, 1), 0.0)
    rss = (zc ** 2).sum(axis=1, keepdims=True) - c * sxz
    a = Z.mean(axis=1, keepdims=True) - c * x.mean(axis=1)[None, :]
    return np.maximum(rss, 0.0), a, c


def _fit_shared(E: np.ndarray, R: np.ndarray, Z: np.ndarray, n_angles: int = 360):
    """Shared direction of (b1, b2) = (cos t, sin t), per-participant intercept and
    scale (module docstring): t on a grid of `n_angles` over [0, pi), then refined
    by golden-section search around the best. Returns sigma index per
    participant, t, and RSS, a, c (P, S) at t."""
    def total(t):
        x = E[None, :] * ((1 - R) * np.cos(t) + R * np.sin(t))
        rss, a, c = _rss_affine(x, Z)
        return rss.min(axis=1).sum(), (rss, a, c)

    angles = np.linspace(0, np.pi, n_angles, endpoint=False)
    values = [total(t)[0] for t in angles]
    k = int(np.argmin(values))
    step = angles[1] - angles[0]
    lo, hi = angles[k] - step, angles[k] + step
    g = (np.sqrt(5) - 1) / 2
    for _ in range(40):  # golden-section search on [lo, hi]
        m1, m2 = hi - g * (hi - lo), lo + g * (hi - lo)
        if total(m1)[0] <= total(m2)[0]:
            hi = m2
        else:
            lo = m1
    t = (lo + hi) / 2 if total((lo + hi) / 2)[0] <= values[k] else angles[k]
    _, (rss, a, c) = total(t)
    return least_sigma_index(rss, axis=1), t, rss, a, c


def profile_interval(sigmas: np.ndarray, rss: np.ndarray, n: int, level: float = 0.95):
    """Profile-likelihood interval of each row of `rss` (P, S) over `sigmas` (S,):
    (low, high, low_censored, high_censored). A participant's set can have holes
    (a multi-modal profile); the interval is its hull."""
    best = rss.min(axis=1, keepdims=True)
    with np.errstate(divide="ignore", invalid="ignore"):
        stat = n * np.log(np.where(best > 0, rss / best, 1.0))
    inside = stat <= chi2.ppf(level, 1) + 1e-12
    low = np.array([sigmas[np.flatnonzero(row)[0]] for row in inside])
    high = np.array([sigmas[np.flatnonzero(row)[-1]] for row in inside])
    return low, high, inside[:, 0], inside[:, -1]


def fit_participant_sigma(human_df: pd.DataFrame, effort, risk_grid: pd.DataFrame, betas: str = "shared",
                          level: float = 0.95, step: float = 0.001) -> pd.DataFrame:
    """Each participant's sigma under Eq. 1 (module docstring).

    `human_df`: responses (dataset, participant, trial, response), validated here
    (simulated datasets allowed; they keep their ``simulated-`` names);
    participants with one response on every trial are dropped, the rest z-scored
    (population SD) as in `run_analysis`. `effort`: anything `effort_per_trial`
    accepts; `risk_grid`: columns trial, sigma, risk on a grid of sigmas.

    Returns one row per participant (COLUMNS): sigma (least RMSE on the fine
    grid, ties to the smallest), sigma_grid (the same on the table's grid
    points only), rmse at sigma, the profile-likelihood interval sigma_low ..
    sigma_high at `level`, whether it is censored at either end of the range,
    identified (False when the interval is the whole range), and the betas used.
    """
    if betas not in BETAS:
        raise InputError(f"betas must be one of {', '.join(BETAS)}, got {betas!r}")
    responses = validate_human_data(human_df, allow_simulated=True)
    kept, _ = exclude_constant_participants(responses)
    zscored = zscore_responses(kept, ddof=0)
    E = effort_per_trial(effort).to_numpy()
    sigmas = search_grid(risk_grid, step)
    grid = risk_sigmas(risk_grid)
    on_grid = np.isin(np.round(sigmas, 9), np.round(grid, 9))
    R = interpolated_risk(risk_grid, sigmas)
    X = _designs(E, R)
    n = len(TRIAL_IDS)
    frames = []
    for dataset, (ids, Z) in participant_matrices(zscored).items():
        if betas == "shared":
            idx, t, rss, a, c = _fit_shared(E, R, Z)
            rows = np.arange(len(ids))
            B = np.column_stack([a[rows, idx], c[rows, idx] * np.cos(t), c[rows, idx] * np.sin(t)])
        else:
            rss, all_b = _rss_free(X, Z)
            idx = least_sigma_index(rss, axis=1)
            B = all_b[np.arange(len(ids)), idx]
        grid_idx = np.flatnonzero(on_grid)[least_sigma_index(rss[:, on_grid], axis=1)]
        low, high, lc, hc = profile_interval(sigmas, rss, n, level)
        frames.append(pd.DataFrame({
            "dataset": dataset, "participant": ids, "sigma": sigmas[idx], "sigma_grid": sigmas[grid_idx],
            "rmse": np.sqrt(rss[np.arange(len(ids)), idx] / n), "sigma_low": low, "sigma_high": high,
            "low_censored": lc, "high_censored": hc, "identified": ~(lc & hc), "level": level,
            "betas": betas, "b0": B[:, 0], "b1": B[:, 1], "b2": B[:, 2], "n_trials": n}))
    return pd.concat(frames, ignore_index=True)[COLUMNS]


def identifiability_demo(risk_grid: pd.DataFrame, n_participants: int = 80, seed: int = 0,
                         noise_sd: float = 0.5, betas=(0.0, 1.0, 4.0)) -> pd.DataFrame:
    """SIMULATED participants, each with their own sigma drawn from the grid, on two
    risk tables: a synthetic one whose risks rise with sigma (a logistic around a
    per-trial threshold) and `risk_grid` (e.g. docs/risk_table.csv). Efforts are
    synthetic, uniform in 1..4. Returns per (table, betas option): coverage of the
    95% intervals, correlation of estimate and truth, median interval width, and
    the fraction identified. For docs; never a stand-in for human data."""
    from analysis.simulate import simulate_participants

    rng = np.random.default_rng(seed)
    effort = pd.Series(rng.uniform(1, 4, len(TRIAL_IDS)), index=list(TRIAL_IDS))
    grid = risk_sigmas(risk_grid)
    c = np.linspace(grid[0] - 0.005, grid[-1] + 0.005, len(TRIAL_IDS))
    rng.shuffle(c)
    synthetic = pd.DataFrame([(t, s, 1 / (1 + np.exp(-(s - ci) / 0.01))) for t, ci in zip(TRIAL_IDS, c) for s in grid],
                             columns=["trial", "sigma", "risk"])
    rows = []
    for name, table in (("synthetic, sigma-sensitive", synthetic), ("given table", risk_grid)):
        truth = rng.choice(grid, size=n_participants)
        frames = [simulate_participants(effort, table, betas, s, 1, noise_sd, rng, datasets=["time"])
                  .assign(participant=f"sim-{p:03d}") for p, s in enumerate(truth)]
        responses = pd.concat(frames, ignore_index=True)
        for option in BETAS:
            out = fit_participant_sigma(responses, effort, table, betas=option)
            true = truth[out["participant"].str[4:].astype(int).to_numpy()]
            covered = (out["sigma_low"] <= true + 1e-9) & (true <= out["sigma_high"] + 1e-9)
            rows.append((f"SIMULATED ({name})", option, n_participants, float(covered.mean()),
                         float(np.corrcoef(out["sigma"], true)[0, 1]),
                         float(np.median(out["sigma_high"] - out["sigma_low"])), float(out["identified"].mean())))
    return pd.DataFrame(rows, columns=["table", "betas", "participants", "coverage_95", "r_estimate_truth",
                                       "median_interval_width", "identified"])


def main(argv=None) -> int:
    import argparse

    p = argparse.ArgumentParser(prog="python -m analysis.participant_sigma",
                                description="Identifiability of each participant's sigma, on SIMULATED participants.")
    p.add_argument("--risk-table", default="docs/risk_table.csv", help="risk table (trial, sigma, risk)")
    p.add_argument("--participants", type=int, default=80)
    p.add_argument("--seed", type=int, default=0)
    args = p.parse_args(argv)
    try:
        table = pd.read_csv(args.risk_table, dtype={"trial": str})
        out = identifiability_demo(table, args.participants, args.seed)
    except (OSError, ValueError) as e:
        p.exit(2, f"{p.prog}: error: {e}\n")
    print("SIMULATED participants (not human data)")
    print(out.to_string(index=False, float_format=lambda x: f"{x:.3f}"))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
