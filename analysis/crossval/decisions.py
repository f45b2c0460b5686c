"""What the comparison decides: direct bootstrap tests on the cross-validated scores
(`direct_p`, `comparison_tests`; the last paragraph of analysis.crossval's
docstring) and the winning model per entry with the parsimony rule (`verdicts`)."""
from __future__ import annotations

from typing import Mapping, Sequence

import numpy as np
import pandas as pd

from analysis.models import model_spec

#: Scores of held-out predictions, and whether a higher value is better.
SCORES: dict[str, bool] = {"rmse": False, "r": True}
#: Parameters of each model's base form (for the parsimony rule of `verdicts`;
#: every model's count is analysis.spec.ModelSpec.n_parameters).
N_PARAMETERS = {"full": 3, "effort": 2, "risk": 2}


def direct_p(better: np.ndarray, worse: np.ndarray, higher_is_better: bool) -> float:
    """Fraction of resamples in which `better` is not strictly better than `worse`
    (NaN counts as a reversal): the direct bootstrap test of analysis.bootstrap."""
    better, worse = np.asarray(better, float), np.asarray(worse, float)
    wins = better > worse if higher_is_better else better < worse
    return float(np.mean(~wins))


#: How the direct bootstrap test is labelled in every table: resampled trial means carry
#: extra noise, so out of sample it is biased toward the simpler model. Its false-positive
#: rate is measured in SIMULATED null studies (bench/analysis_power.py, docs/results.md).
DIRECT_METHOD = ("direct bootstrap (paper's method, NOT CALIBRATED: false-positive rate 0.0% in 1000 SIMULATED null "
                 "studies for Eq. 1 over effort-only, biased toward the simpler model held out; decide by the held-out "
                 "permutation test)")
#: How the sign-flip over folds is labelled: under the null the richer model's held-out error is
#: larger on average (over-fitting), so its per-fold differences are not symmetric about 0.
SIGN_FLIP_METHOD = ("sign-flip over folds, NOT CALIBRATED: false-positive rate 0.3-0.5% for Eq. 1 over effort-only, "
                    "10.7-13.4% for effort + height or stacked over Eq. 1 (1000 SIMULATED null studies per world); "
                    "decide by the held-out permutation test")


def comparison_tests(point: pd.DataFrame, boot: pd.DataFrame, comparisons: Sequence[tuple[str, str]],
                     boot_fixed_risk: pd.DataFrame | None = None) -> pd.DataFrame:
    """Direct bootstrap tests (analysis.crossval's docstring) of each comparison,
    per dataset, scheme and score (rmse, r). Returns dataset, scheme, score, model_a, model_b,
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
    out["method"] = DIRECT_METHOD
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
    rank = np.array([model_spec(m).n_parameters * len(names) + k for k, m in enumerate(names)])
    cost = np.where(tied, rank.reshape((-1,) + (1,) * (S.ndim - 1)), np.iinfo(int).max)
    return np.array(names, dtype=object)[np.argmin(cost, axis=0)]


#: Folds up to this many: every sign flip enumerated (exact); more: SIGN_FLIP_DRAWS random flips.
SIGN_FLIP_EXACT = 16
SIGN_FLIP_DRAWS = 65536


def sign_flip_p(d: np.ndarray, rng: np.random.Generator | None = None) -> np.ndarray:
    """One-sided paired test over folds: d (N, F) per-fold differences (positive:
    the first model better); p (N,) = fraction of sign flips s with sum(s d) >=
    sum(d) (relative 1e-12 ties count). Exact (all 2^F flips, the identity among
    them) for F <= SIGN_FLIP_EXACT, else SIGN_FLIP_DRAWS random flips plus the
    identity from `rng` (default default_rng(0))."""
    d = np.atleast_2d(np.asarray(d, dtype=float))
    F = d.shape[1]
    if F <= SIGN_FLIP_EXACT:
        signs = 1.0 - 2.0 * ((np.arange(2 ** F)[:, None] >> np.arange(F)[None, :]) & 1)
    else:
        rng = np.random.default_rng(0) if rng is None else rng
        signs = np.vstack([np.ones(F), 1.0 - 2.0 * (rng.random((SIGN_FLIP_DRAWS, F)) < 0.5)])
    obs = d.sum(axis=1)
    null = d @ signs.T
    return np.mean(null >= (obs - 1e-12 * np.abs(obs))[:, None], axis=1)


def held_out_tests(cv_predictions: pd.DataFrame, comparisons: Sequence[tuple[str, str]]) -> pd.DataFrame:
    """The held-out comparison paired over folds (NOT CALIBRATED, SIGN_FLIP_METHOD; the
    calibrated test is crossval.permuted.held_out_permutation_tests), per dataset, cross-validated
    scheme and comparison (a, b): d_f = SSE_b,f - SSE_a,f over the trials fold f
    holds out, p of "a predicts held-out trials better than b" by `sign_flip_p`.
    `cv_predictions` from crossval.model_comparison. Returns dataset, scheme,
    model_a, model_b, sse_a, sse_b, n_folds, p_value, method."""
    rows = []
    cv = cv_predictions[cv_predictions["scheme"] != "in-sample"]
    for (dataset, scheme), g in cv.groupby(["dataset", "scheme"], sort=False):
        wide = g.pivot_table(index=["fold", "trial"], columns="model", values="predicted", sort=False)
        obs = g.drop_duplicates(["fold", "trial"]).set_index(["fold", "trial"])["observed"].reindex(wide.index)
        folds = wide.index.get_level_values("fold").to_numpy()
        order = list(dict.fromkeys(folds))
        for a, b in comparisons:
            if a not in wide or b not in wide:
                continue
            sq_a = (obs.to_numpy() - wide[a].to_numpy()) ** 2
            sq_b = (obs.to_numpy() - wide[b].to_numpy()) ** 2
            d = np.array([sq_b[folds == f].sum() - sq_a[folds == f].sum() for f in order])
            p = float(sign_flip_p(d[None])[0])
            method = "exact" if len(order) <= SIGN_FLIP_EXACT else f"{SIGN_FLIP_DRAWS} random flips"
            rows.append((dataset, scheme, a, b, float(sq_a.sum()), float(sq_b.sum()), len(order), p,
                         f"{SIGN_FLIP_METHOD} ({method})"))
    return pd.DataFrame(rows, columns=["dataset", "scheme", "model_a", "model_b", "sse_a", "sse_b", "n_folds",
                                       "p_value", "method"])
