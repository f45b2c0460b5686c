"""Out-of-sample comparison of Eq. 1 and its lesions: cross-validation, the
participant bootstrap with the cross-validation inside every resample, Monte
Carlo error of risk, and direct bootstrap tests on the cross-validated scores.

Why. In sample the comparison of the full model with effort-only cannot fail:
Eq. 1 nests effort-only (E = E(1-R) + E R, so effort-only is Eq. 1 with
b1 = b2), and its sigma is chosen on the same data. Its in-sample r is at least
effort-only's in every bootstrap resample, and the direct bootstrap test of full
against effort (analysis.bootstrap) returns p = 0 whatever the data. Predicting
trials the fit has not seen can come out either way.

Schemes (SCHEMES):

* ``in-sample``: every model fit on all 24 trials (the paper's numbers);
* ``leave-one-pair-out``: 12 folds, the easy and the hard trial of one pair held
  out together, so the easy/hard contrast is predicted, not fitted;
* ``leave-one-trial-out``: 24 folds of one trial.

In every fold each model is refit by least squares on the training trials, and
sigma is chosen **inside the fold** by the paper's rule (analysis.sigma) applied
to the training trials only: the grid sigma (every sigma of the risk table) of
least mean, over the datasets analysed together, training RMSE of Eq. 1; ties go
to the smaller sigma. Models whose R is one risk source (the final-state risk
table, or one build-risk aggregate for ``full[m]`` and ``risk[m]``) share the
sigma Eq. 1 with that source chose, as in the paper the risk-only model uses
Eq. 1's sigma. The held-out trials are predicted from that fit.

The fits. Eq. 1 is written y = b0 + b1 E + c E R (c = b2 - b1), which spans the
same columns as the paper's form, and solved by projecting out the intercept and
E (Frisch-Waugh): the same least-squares predictions as numpy.linalg.lstsq on
the training rows, with every resample, sigma and fold in one array operation.
When E*R carries nothing beyond 1 and E on the training trials (say every
training trial has R = 0), c is not identified; the fold then predicts as
effort-only (c = 0: b2 = b1, no evidence that risky effort costs differently).
Likewise risk-only predicts the training mean when R is constant on the
training trials. (A minimum-norm solution of the paper's form would instead set
b2 = 0 there: the risky part of a held-out trial's effort would cost nothing.)

Scores of the held-out predictions: RMSE (root mean squared error over the held-
out trials, z units), Pearson r with the trial means, and the pairs whose easy
trial is predicted lower than its hard trial under the one tie rule
(analysis.pairs.pair_order_codes).

Bootstrap. Each resample of participants (the same draws as the in-sample
bootstrap, `analysis.data.resample_trial_means`) is cross-validated whole, sigma
choice included. With ``risk_draw="binomial"`` every resample also redraws each
trial's risk from its runs: falls ~ Binomial(n_sims, R), the run count read from
the risk table, which is what resampling the runs of one (trial, sigma) with
replacement does. One uniform per (resample, trial) drives every sigma through
its binomial quantile function, so a trial's redrawn risk keeps its order over
sigma, as the common random numbers of the runs keep it (docs/risk.md). A trial
with no falls in its runs redraws as 0 every time: a bootstrap of runs cannot
see risk it never observed. Effort's own Monte Carlo error (the mean over M
layouts) is not redrawn.

Direct bootstrap tests on the cross-validated scores follow the rule of
analysis.bootstrap: with full-sample scores s_a, s_b and a better (higher r,
lower RMSE), p is the fraction of resamples in which a is not strictly better
(ties and undefined scores count as reversals); equal full-sample scores give
p = 1.
"""
from __future__ import annotations

import re
import warnings
from dataclasses import dataclass
from typing import Mapping, Sequence

import numpy as np
import pandas as pd
from scipy import stats

from analysis.data import TRIAL_IDS, ordered_datasets
from analysis.models import (MODELS, ModelInputError, effort_per_trial, measure_at_sigma,
                             risk_at_sigma, risk_sigmas, rowwise_pearson, split_model)
from analysis.pairs import pair_order_codes

#: The three ways a model is scored: fit and scored on the same 24 trials, or
#: scored on held-out pairs or trials.
SCHEMES: tuple[str, ...] = ("in-sample", "leave-one-pair-out", "leave-one-trial-out")
CV_SCHEMES: tuple[str, ...] = SCHEMES[1:]
#: Scores of held-out predictions, and whether a higher value is better.
SCORES: dict[str, bool] = {"rmse": False, "r": True}
#: How each bootstrap resample treats risk: fixed at the table, or redrawn from its runs.
RISK_DRAWS: tuple[str, ...] = ("none", "binomial")
#: A column of E*R (or R) whose part beyond the intercept and E has a norm below
#: this fraction of its own is "nothing beyond them" (the fold predicts as effort-only).
COLLINEAR_REL = 1e-9
#: Resamples (or permutations) per array operation: a fixed number, so the numbers
#: never depend on how many processes share the work.
CHUNK = 64
#: Seed streams of the comparison beside the participant bootstrap's own:
#: ``default_rng([seed, RISK_DRAW_STREAM])`` draws the risk redraws.
RISK_DRAW_STREAM = 2301
#: Fewest easy/hard pairs leave-one-pair-out cross-validation accepts.
MIN_PAIRS = 3
#: Parameters of each model's base form (for the parsimony rule of `verdicts`).
N_PARAMETERS = {"full": 3, "effort": 2, "risk": 2}


class CrossValidationError(ValueError):
    """The trials or tables cannot be cross-validated: names the scheme and the rule."""


@dataclass(frozen=True)
class RiskGrid:
    """Risk of every trial at every sigma of a table: ``risk[s, i]`` is trial
    TRIAL_IDS[i] at ``sigmas[s]`` (ascending); ``runs`` the number of noisy runs
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
                          index=rows["trial"].astype(str).str.strip().str.upper()).reindex(list(TRIAL_IDS))
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


# ---------------------------------------------------------------------------------------------- folds


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


# ---------------------------------------------------------------------------------------------- the fits


def _effort_operators(E: np.ndarray, train: np.ndarray, test: np.ndarray):
    """Per fold: M (F, n_tr, n_tr), the residual-maker of [1, E] on the training
    trials, and G (F, n_te, n_tr), which maps training values to the effort-only
    least-squares prediction at the held-out trials."""
    M, G = [], []
    for tr, te in zip(train, test):
        X = np.column_stack([np.ones(len(tr)), E[tr]])
        pinv = np.linalg.pinv(X)
        M.append(np.eye(len(tr)) - X @ pinv)
        G.append(np.column_stack([np.ones(len(te)), E[te]]) @ pinv)
    return np.stack(M), np.stack(G)


def _as_batch(risk: np.ndarray) -> np.ndarray:
    """(S, T) -> (1, S, T); (B, S, T) unchanged."""
    risk = np.asarray(risk, dtype=float)
    return risk[None] if risk.ndim == 2 else risk


def cv_arrays(Y: np.ndarray, E: np.ndarray, risks: Mapping[str, np.ndarray], models: Sequence[str],
              train: np.ndarray, test: np.ndarray, sigma_index: Mapping[str, int] | None = None,
              pool: bool = True) -> tuple[dict[str, np.ndarray], dict[str, np.ndarray]]:
    """Held-out predictions of every model, vectorised over resamples, sigmas and folds.

    Y: (B, D, T) trial means (B resamples or studies, D datasets analysed together);
    E: (T,) effort; risks: {source: (S, T) or (B, S, T)} risk over a sigma grid
    (ascending), source "R" for full and risk, a measure m for full[m] and
    risk[m]; train/test from `make_folds`. `sigma_index` fixes the sigma of a
    source (an index into its grid) instead of choosing it per fold; `pool`
    chooses one sigma per fold for all D datasets (the paper's rule), else one
    per dataset.

    Returns (predictions, chosen): predictions {model: (B, D, T)} at the held-out
    trials of each fold (NaN at trials no fold holds out; in-sample: the fit);
    chosen {source: (B, F, D)} the grid index of sigma used in each fold.
    """
    Y = np.asarray(Y, dtype=float)
    B, D, T = Y.shape
    F, n_tr = train.shape
    n_te = test.shape[1]
    M, G = _effort_operators(np.asarray(E, float), train, test)
    ytr = np.moveaxis(Y[:, :, train], 2, 1)            # (B, F, D, n_tr)
    ey = np.einsum("fij,bfdj->bfdi", M, ytr)           # effort residuals of y
    gy = np.einsum("fij,bfdj->bfdi", G, ytr)           # effort-only predictions (B, F, D, n_te)
    rss_eff = np.einsum("bfdi,bfdi->bfd", ey, ey)
    ymean = ytr.mean(axis=-1)                          # (B, F, D)
    yc = ytr - ymean[..., None]

    bases = {m: split_model(m) for m in models}
    preds = {m: np.full((B, D, T), np.nan) for m in models}
    if "effort" in models:
        _scatter(preds["effort"], gy, test)
    chosen = {}
    for source in dict.fromkeys((measure or "R") for base, measure in bases.values() if base != "effort"):
        R = _as_batch(risks[source])                   # (Bx, S, T)
        W = R * np.asarray(E, float)                   # E*R
        # Eq. 1 beyond effort: the part of E*R that 1 and E do not explain in training.
        wtr = W[:, :, train]                           # (Bx, S, F, n_tr)
        z = np.einsum("fij,bsfj->bsfi", M, wtr)
        zz = np.einsum("bsfi,bsfi->bsf", z, z)
        absent = zz <= COLLINEAR_REL ** 2 * np.einsum("bsfi,bsfi->bsf", wtr, wtr)
        zy = np.matmul(z[:, :, :, None, :], np.swapaxes(ey, -1, -2)[:, None])[..., 0, :]  # (B, S, F, D)
        c = np.where(absent[..., None], 0.0, zy / np.where(absent, 1.0, zz)[..., None])
        rss_full = np.maximum(rss_eff[:, None] - c * zy, 0.0)
        if sigma_index is not None and source in sigma_index:
            pick = np.full((B, F, D), int(sigma_index[source]))
        else:
            crit = np.sqrt(rss_full / n_tr)            # training RMSE (B, S, F, D)
            if pool:
                pick = np.repeat(np.argmin(crit.mean(axis=-1), axis=1)[..., None], D, axis=-1)
            else:
                pick = np.argmin(crit, axis=1)         # (B, F, D); ties: the first, the smaller sigma
        chosen[source] = pick
        full_name = "full" if source == "R" else f"full[{source}]"
        risk_name = "risk" if source == "R" else f"risk[{source}]"
        if full_name in models:
            dw = W[:, :, test] - np.einsum("fij,bsfj->bsfi", G, wtr)             # (Bx, S, F, n_te)
            c_at = np.take_along_axis(c, pick[:, None], axis=1)[:, 0]           # (B, F, D)
            dw_at = _at_sigma(dw, pick)                                          # (B, F, D, n_te)
            _scatter(preds[full_name], gy + c_at[..., None] * dw_at, test)
        if risk_name in models:
            rtr = R[:, :, train]
            rmean = rtr.mean(axis=-1)                   # (Bx, S, F)
            rc = rtr - rmean[..., None]
            rr = np.einsum("bsfi,bsfi->bsf", rc, rc)
            flat = rr <= COLLINEAR_REL ** 2 * np.einsum("bsfi,bsfi->bsf", rtr, rtr)
            ry = np.matmul(rc[:, :, :, None, :], np.swapaxes(yc, -1, -2)[:, None])[..., 0, :]
            slope = np.where(flat[..., None], 0.0, ry / np.where(flat, 1.0, rr)[..., None])  # (B, S, F, D)
            dr = R[:, :, test] - rmean[..., None]                               # (Bx, S, F, n_te)
            s_at = np.take_along_axis(slope, pick[:, None], axis=1)[:, 0]
            _scatter(preds[risk_name], ymean[..., None] + s_at[..., None] * _at_sigma(dr, pick), test)
    return preds, chosen


def _at_sigma(a: np.ndarray, pick: np.ndarray) -> np.ndarray:
    """a (Bx, S, F, n) at the chosen sigma of each (resample, fold, dataset):
    pick (B, F, D) -> (B, F, D, n)."""
    Bx, S, F, n = a.shape
    B, _, D = pick.shape
    rows = np.zeros((B, 1, 1), dtype=int) if Bx == 1 else np.arange(B)[:, None, None]
    return a[rows, pick, np.arange(F)[None, :, None]]


def _scatter(out: np.ndarray, fold_values: np.ndarray, test: np.ndarray) -> None:
    """fold_values (B, F, D, n_te) into out (B, D, T) at the held-out trials."""
    for f, held in enumerate(test):
        out[:, :, held] = fold_values[:, f]


def cross_validate(Y: np.ndarray, E: np.ndarray, risks: Mapping[str, np.ndarray], models: Sequence[str],
                   scheme: str, sigma_index: Mapping[str, int] | None = None, pool: bool = True,
                   trials: Sequence[str] = TRIAL_IDS, chunk: int = CHUNK
                   ) -> tuple[dict[str, np.ndarray], dict[str, np.ndarray], np.ndarray]:
    """`cv_arrays` for one scheme, in chunks of `chunk` resamples (a fixed size, so the
    result never depends on the split of the work). Risks of shape (B, S, T) are
    chunked with Y. Returns (predictions, chosen, test) with test from make_folds."""
    train, test = make_folds(scheme, trials)
    Y = np.asarray(Y, dtype=float)
    B = Y.shape[0]
    batched = {s: np.asarray(r, float).ndim == 3 for s, r in risks.items()}
    for s, r in risks.items():
        if batched[s] and np.asarray(r).shape[0] not in (B,):
            raise ModelInputError(f"risk source {s}: {np.asarray(r).shape[0]} risk draws for {B} resamples")
    preds: dict[str, list] = {m: [] for m in models}
    chosen: dict[str, list] = {}
    for lo in range(0, B, chunk):
        hi = min(B, lo + chunk)
        part = {s: (np.asarray(r)[lo:hi] if batched[s] else r) for s, r in risks.items()}
        p, c = cv_arrays(Y[lo:hi], E, part, models, train, test, sigma_index, pool)
        for m in models:
            preds[m].append(p[m])
        for s, v in c.items():
            chosen.setdefault(s, []).append(v)
    return ({m: np.concatenate(v) for m, v in preds.items()},
            {s: np.concatenate(v) for s, v in chosen.items()}, test)


# ---------------------------------------------------------------------------------------------- scores


def scores(Y: np.ndarray, predictions: np.ndarray, trials: Sequence[str] = TRIAL_IDS) -> dict[str, np.ndarray]:
    """Scores of (B, D, T) predictions against (B, D, T) trial means, over the
    trials that have predictions: rmse, r (NaN if either side is constant) and
    pairs (number of pairs with the easy trial predicted lower, the tie rule of
    analysis.pairs). Each (B, D)."""
    Y = np.broadcast_to(np.asarray(Y, float), predictions.shape)
    held = ~np.isnan(predictions[0, 0])
    P, Yh = predictions[..., held], Y[..., held]
    B, D = P.shape[:2]
    rmse = np.sqrt(np.mean((Yh - P) ** 2, axis=-1))
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", RuntimeWarning)
        r = rowwise_pearson(P.reshape(B * D, -1), Yh.reshape(B * D, -1)).reshape(B, D)
    idx = np.array(pairs_of(list(trials)), dtype=int).reshape(-1, 2)
    ok = [k for k, (e, h) in enumerate(idx) if held[e] and held[h]]
    idx = idx[ok]
    pairs = (pair_order_codes(predictions[..., idx[:, 0]], predictions[..., idx[:, 1]]) == 1).sum(axis=-1)
    return {"rmse": rmse, "r": r, "pairs": pairs}


# ---------------------------------------------------------------------------------------------- risk redraws


def redraw_risk(grid: RiskGrid, n_draws: int, rng: np.random.Generator) -> np.ndarray:
    """(n_draws, S, T) risks redrawn from their runs: falls ~ Binomial(runs, risk)
    by quantile coupling, one uniform per (draw, trial) for every sigma (module
    docstring). Draws ``rng.random((n_draws, T))``."""
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


# ---------------------------------------------------------------------------------------------- tables


def _sources(models: Sequence[str]) -> list[str]:
    return list(dict.fromkeys((split_model(m)[1] or "R") for m in models if split_model(m)[0] != "effort"))


def model_comparison(means: Mapping[str, np.ndarray], effort, grids: Mapping[str, RiskGrid],
                     models: Sequence[str] = MODELS, schemes: Sequence[str] = SCHEMES,
                     in_sample_sigma: Mapping[str, float] | None = None
                     ) -> tuple[pd.DataFrame, pd.DataFrame]:
    """Scores of every model under every scheme, on the full-sample trial means.

    `means` {dataset: (24,) trial means in TRIAL_IDS order}; `grids` {source:
    RiskGrid} ("R", and a measure m for full[m]/risk[m]). In-sample, sigma is
    `in_sample_sigma[source]` (the analysis's chosen sigma; default: chosen by the
    rule on all 24 trials); cross-validated, it is chosen in each fold.

    Returns (scores, predictions): scores one row per (dataset, scheme, model):
    dataset, scheme, model, rmse, r, pairs_E_lt_H, n_pairs, sigma_min, sigma_max
    (over folds); predictions one row per (dataset, scheme, model, trial): fold
    (the fold that held the trial out), sigma, observed, predicted.
    """
    E = effort_per_trial(effort).to_numpy()
    datasets = ordered_datasets(means)
    Y = np.stack([np.asarray(means[d], float) for d in datasets])[None]   # (1, D, 24)
    risks = {s: grids[s].risk for s in _sources(models)}
    rows, pred_rows = [], []
    for scheme in schemes:
        fixed = _fixed_index(grids, risks, in_sample_sigma) if scheme == "in-sample" else None
        preds, chosen, test = cross_validate(Y, E, risks, models, scheme, fixed)
        fold_of = np.empty(len(TRIAL_IDS), dtype=int)
        for f, held in enumerate(test):
            fold_of[held] = f
        for model in models:
            sc = scores(Y, preds[model])
            source = split_model(model)[1] or "R"
            for k, dataset in enumerate(datasets):
                if model == "effort":
                    sig = np.full(len(TRIAL_IDS), np.nan)
                else:
                    sig = grids[source].sigmas[chosen[source][0, :, k]][fold_of]
                rows.append((dataset, scheme, model, sc["rmse"][0, k], sc["r"][0, k], int(sc["pairs"][0, k]),
                             len(pairs_of(TRIAL_IDS)), np.nanmin(sig) if model != "effort" else np.nan,
                             np.nanmax(sig) if model != "effort" else np.nan))
                for i, trial in enumerate(TRIAL_IDS):
                    pred_rows.append((dataset, scheme, model, trial, int(fold_of[i]), sig[i], Y[0, k, i],
                                      preds[model][0, k, i]))
    table = pd.DataFrame(rows, columns=["dataset", "scheme", "model", "rmse", "r", "pairs_E_lt_H", "n_pairs",
                                        "sigma_min", "sigma_max"])
    predictions = pd.DataFrame(pred_rows, columns=["dataset", "scheme", "model", "trial", "fold", "sigma",
                                                   "observed", "predicted"])
    return table, predictions


def _fixed_index(grids, risks, in_sample_sigma) -> dict[str, int] | None:
    if in_sample_sigma is None:
        return None
    out = {}
    for s in risks:
        sig = in_sample_sigma.get(s, in_sample_sigma.get("R"))
        out[s] = int(np.argmin(np.abs(grids[s].sigmas - sig)))  # nearest, as run_analysis reads build risk
    return out


def bootstrap_comparison(boot_means: Mapping[str, np.ndarray], effort, grids: Mapping[str, RiskGrid],
                         models: Sequence[str] = MODELS, schemes: Sequence[str] = SCHEMES,
                         in_sample_sigma: Mapping[str, float] | None = None,
                         risk_draws: np.ndarray | None = None) -> pd.DataFrame:
    """Scores of every model under every scheme in every bootstrap resample, the
    cross-validation (sigma choice included) redone inside each resample.

    `boot_means` {dataset: (n_boot, 24)} (`resample_trial_means`); `risk_draws`
    (n_boot, S, 24) redrawn risks of source "R" (`redraw_risk`) or None for the
    table's risks. Returns one row per (dataset, scheme, model, resample):
    dataset, scheme, model, resample, rmse, r, pairs_E_lt_H.
    """
    E = effort_per_trial(effort).to_numpy()
    datasets = ordered_datasets(boot_means)
    Y = np.stack([np.asarray(boot_means[d], float) for d in datasets], axis=1)   # (n_boot, D, 24)
    n_boot = Y.shape[0]
    risks = {s: grids[s].risk for s in _sources(models)}
    if risk_draws is not None and "R" in risks:
        risks["R"] = risk_draws
    frames = []
    for scheme in schemes:
        fixed = _fixed_index(grids, risks, in_sample_sigma) if scheme == "in-sample" else None
        preds, _, _ = cross_validate(Y, E, risks, models, scheme, fixed)
        for model in models:
            sc = scores(Y, preds[model])
            for k, dataset in enumerate(datasets):
                frames.append(pd.DataFrame({"dataset": dataset, "scheme": scheme, "model": model,
                                            "resample": np.arange(n_boot), "rmse": sc["rmse"][:, k],
                                            "r": sc["r"][:, k], "pairs_E_lt_H": sc["pairs"][:, k]}))
    return pd.concat(frames, ignore_index=True)


def summarize_comparison(point: pd.DataFrame, boot: pd.DataFrame, boot_fixed_risk: pd.DataFrame | None = None,
                         level: float = 0.95) -> pd.DataFrame:
    """`point` (model_comparison's scores) with percentile intervals from `boot`
    (bootstrap_comparison): rmse_low/high, r_low/high, pairs_low/high; with
    `boot_fixed_risk` (the same resamples, risk not redrawn) also the widths of
    the fixed-risk intervals and how much redrawing risk widens them
    (r_widening = width with risk redrawn / width without)."""
    tail = 100 * (1 - level) / 2
    keys = ["dataset", "scheme", "model"]

    def bands(b: pd.DataFrame, suffix: str = "") -> pd.DataFrame:
        g = b.groupby(keys, sort=False)
        out = pd.DataFrame({
            f"rmse_low{suffix}": g["rmse"].quantile(tail / 100), f"rmse_high{suffix}": g["rmse"].quantile(1 - tail / 100),
            f"r_low{suffix}": g["r"].quantile(tail / 100), f"r_high{suffix}": g["r"].quantile(1 - tail / 100),
            f"pairs_low{suffix}": g["pairs_E_lt_H"].quantile(tail / 100),
            f"pairs_high{suffix}": g["pairs_E_lt_H"].quantile(1 - tail / 100)})
        if not suffix:
            out["n_boot"] = g.size()
        return out.reset_index()

    table = point.merge(bands(boot), on=keys, how="left")
    if boot_fixed_risk is not None:
        fixed = bands(boot_fixed_risk, "_fixed_risk")
        table = table.merge(fixed[keys + ["rmse_low_fixed_risk", "rmse_high_fixed_risk", "r_low_fixed_risk",
                                          "r_high_fixed_risk"]], on=keys, how="left")
        with np.errstate(invalid="ignore", divide="ignore"):
            table["rmse_widening"] = ((table["rmse_high"] - table["rmse_low"])
                                      / (table["rmse_high_fixed_risk"] - table["rmse_low_fixed_risk"]))
            table["r_widening"] = ((table["r_high"] - table["r_low"])
                                   / (table["r_high_fixed_risk"] - table["r_low_fixed_risk"]))
    return table


def gain_over_effort(point: pd.DataFrame, boot: pd.DataFrame, level: float = 0.95) -> pd.DataFrame:
    """How much lower each model's RMSE is than effort-only's (effort RMSE - model
    RMSE; positive: the model predicts better), per dataset and scheme, with the
    percentile interval of the per-resample difference. In sample Eq. 1's gain is
    >= 0 by construction; out of sample it can be negative."""
    tail = (1 - level) / 2
    keys = ["dataset", "scheme"]
    pt = point.pivot_table(index=keys, columns="model", values="rmse", sort=False)
    bt = boot.pivot_table(index=keys + ["resample"], columns="model", values="rmse", sort=False)
    rows = []
    for model in [m for m in pt.columns if m != "effort"]:
        g = (bt["effort"] - bt[model]).groupby(level=keys, sort=False)
        lo, hi = g.quantile(tail), g.quantile(1 - tail)
        for key in pt.index:
            rows.append((*key, model, float(pt.loc[key, "effort"] - pt.loc[key, model]), float(lo[key]), float(hi[key])))
    return pd.DataFrame(rows, columns=keys + ["model", "gain", "gain_low", "gain_high"])


def direct_p(better: np.ndarray, worse: np.ndarray, higher_is_better: bool) -> float:
    """Fraction of resamples in which `better` is not strictly better than `worse`
    (NaN counts as a reversal): the direct bootstrap test of analysis.bootstrap."""
    better, worse = np.asarray(better, float), np.asarray(worse, float)
    wins = better > worse if higher_is_better else better < worse
    return float(np.mean(~wins))


def comparison_tests(point: pd.DataFrame, boot: pd.DataFrame, comparisons: Sequence[tuple[str, str]],
                     boot_fixed_risk: pd.DataFrame | None = None) -> pd.DataFrame:
    """Direct bootstrap tests (module docstring) of each comparison, per dataset,
    scheme and score (rmse, r). Returns dataset, scheme, score, model_a, model_b,
    value_a, value_b, better, p_value, (p_value_fixed_risk), n_boot."""
    rows = []
    for (dataset, scheme), b in boot.groupby(["dataset", "scheme"], sort=False):
        pt = point[(point["dataset"] == dataset) & (point["scheme"] == scheme)].set_index("model")
        fixed = None
        if boot_fixed_risk is not None:
            fixed = boot_fixed_risk[(boot_fixed_risk["dataset"] == dataset) & (boot_fixed_risk["scheme"] == scheme)]
        for score, higher in SCORES.items():
            wide = b.pivot(index="resample", columns="model", values=score)
            wide_fixed = fixed.pivot(index="resample", columns="model", values=score) if fixed is not None else None
            for a, c in comparisons:
                va, vc = float(pt.loc[a, score]), float(pt.loc[c, score])
                if np.isnan(va) or np.isnan(vc):
                    better, p, pf = "", np.nan, np.nan
                elif va == vc:
                    better, p, pf = "", 1.0, 1.0
                else:
                    better, worse = (a, c) if (va > vc) == higher else (c, a)
                    p = direct_p(wide[better], wide[worse], higher)
                    pf = direct_p(wide_fixed[better], wide_fixed[worse], higher) if wide_fixed is not None else np.nan
                rows.append((dataset, scheme, score, a, c, va, vc, better, p, pf, len(wide)))
    out = pd.DataFrame(rows, columns=["dataset", "scheme", "score", "model_a", "model_b", "value_a", "value_b",
                                      "better", "p_value", "p_value_fixed_risk", "n_boot"])
    if boot_fixed_risk is None:
        out = out.drop(columns=["p_value_fixed_risk"])
    return out


def verdicts(score_by_model: Mapping[str, np.ndarray], higher_is_better: bool = False,
             tie_rel: float = 1e-9) -> np.ndarray:
    """The winning model per entry of equally shaped score arrays: the best score
    (lowest RMSE by default); scores within `tie_rel` (relative) of the best are
    tied, and a tie goes to the model with fewer parameters, then to the earlier
    in the given order. Returns an array of model names."""
    names = list(score_by_model)
    S = np.stack([np.asarray(score_by_model[m], float) for m in names])
    s = S if higher_is_better else -S
    s = np.where(np.isnan(s), -np.inf, s)
    best = s.max(axis=0)
    tied = s >= best - tie_rel * np.abs(best)
    rank = np.array([N_PARAMETERS[split_model(m)[0]] * len(names) + k for k, m in enumerate(names)])
    cost = np.where(tied, rank.reshape((-1,) + (1,) * (S.ndim - 1)), np.iinfo(int).max)
    return np.array(names, dtype=object)[np.argmin(cost, axis=0)]
