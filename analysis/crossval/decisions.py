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
