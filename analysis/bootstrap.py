"""Bootstrap over participants of the models' correlations with the data, and
direct bootstrap tests between models (Results section, Figure 4).

Each resample draws the participants of a dataset with replacement
(`analysis.data.resample_trial_means`), recomputes the 24 trial means, refits
every model at the fixed sigma, and records the Pearson r between each model's
predictions and the resampled trial means. Sigma is not refit per resample
(the paper fixed it before bootstrapping).

Direct bootstrap test of model a against model b in one dataset: let r_a, r_b
be the correlations of the fits to the full sample. If r_a > r_b, p is the
fraction of resamples with r*_a <= r*_b (the ordering reverses or ties); if
r_a < r_b, p is the fraction with r*_b <= r*_a; if r_a == r_b, p = 1. A resample
where either r* is undefined (NaN) counts as a reversal. This is a one-sided
p-value for "the better model in the full sample is better".
"""
from __future__ import annotations

import warnings
from typing import Mapping, Sequence

import numpy as np
import pandas as pd

from lgp.executor import borrowed

from analysis.data import ordered_datasets
from analysis.models import (MODELS, batch_predictions, design_matrix, effort_per_trial,
                             rowwise_pearson)

#: The paper's three comparisons: full vs each lesion, and effort-only vs risk-only.
COMPARISONS: tuple[tuple[str, str], ...] = (("full", "effort"), ("full", "risk"), ("effort", "risk"))


def bootstrap_model_correlations(boot_means: Mapping[str, np.ndarray], effort,
                                 risk: pd.Series | Mapping[str, pd.Series],
                                 models: Sequence[str] = MODELS, jobs: int = 1,
                                 executor=None, features: pd.DataFrame | None = None) -> pd.DataFrame:
    """Correlation of each refit model with each resample's trial means.

    `boot_means` is {dataset: (n_boot, 24) array} from `resample_trial_means`;
    `risk` one per-trial Series (at the chosen sigma) or {dataset: Series}.
    `jobs` > 1 spreads the datasets over that many processes; each dataset is
    computed by the same code on the same arrays whichever process runs it, so
    the numbers are bitwise identical to ``jobs=1``. The refits are vectorised
    (one lstsq with n_boot right-hand sides per model), so at the paper's size
    (3 datasets x 1000 resamples, ~0.1 s) process start-up makes ``jobs=2``
    no faster than serial.

    Returns one row per (dataset, resample, model): dataset, resample (0-based),
    model, r.
    """
    E = effort_per_trial(effort)
    tasks = []
    for dataset in ordered_datasets(boot_means):
        R = risk[dataset] if isinstance(risk, Mapping) else risk
        designs = [design_matrix(m, E, R, features) for m in models]
        tasks.append((dataset, designs, np.asarray(boot_means[dataset], dtype=float)))
    with borrowed(executor, min(jobs, max(len(tasks), 1))) as ex:
        results = ex.map(_correlations_one_dataset, tasks)
    frames = []
    for (dataset, _, Y), r in zip(tasks, results):
        n_boot = Y.shape[0]
        frames.append(pd.DataFrame({
            "dataset": dataset,
            "resample": np.tile(np.arange(n_boot), len(models)),
            "model": np.repeat(list(models), n_boot),
            "r": r.reshape(-1),
        }))
    return pd.concat(frames, ignore_index=True)


def centred_interval(point, boot, level: float = 0.95, bounds: tuple[float, float] = (-np.inf, np.inf)
                     ) -> tuple[float, float]:
    """The bootstrap interval shifted to its point estimate: point + the
    (1-level)/2 and (1+level)/2 quantiles of (boot - median(boot)) (NaN resamples
    left out). It always contains `point` (the lower quantile of a median-centred
    sample is <= 0 <= its upper one), unlike the paper's percentile interval,
    which resampled trial means (carrying extra sampling noise, biased toward 0
    for r) can leave entirely on one side of the point. Clipped to `bounds`
    (the score's range, e.g. r in [-1, 1])."""
    b = np.asarray(boot, dtype=float)
    b = b[np.isfinite(b)]
    if not np.isfinite(point) or b.size == 0:
        return float("nan"), float("nan")
    d = b - np.median(b)
    tail = (1 - level) / 2
    lo, hi = np.quantile(d, [tail, 1 - tail])
    return (float(max(point + min(lo, 0.0), bounds[0])), float(min(point + max(hi, 0.0), bounds[1])))


#: How the in-sample direct bootstrap test is labelled: Eq. 1 nests effort-only (b1 = b2), so its
#: refit r is at least effort-only's in every resample and "full beats effort" has p = 0 whatever the data.
IN_SAMPLE_METHOD = ("direct bootstrap in sample (paper's method, NOT CALIBRATED: Eq. 1 nests effort-only, so full "
                    "beats effort with p = 0 whatever the data; decide by the held-out permutation test)")
#: What every bootstrap interval in the outputs is (column ``interval``).
INTERVAL = "95% bootstrap interval centred on the point estimate (resamples minus their median, added to it)"


def summarize_bootstrap(boot: pd.DataFrame, fits: pd.DataFrame | None = None,
                        level: float = 0.95) -> pd.DataFrame:
    """Median and interval of each model's bootstrap correlations.

    Returns one row per (dataset, model): dataset, model, r (full-sample fit, if
    `fits` from `fit_models` is given), r_median, r_low, r_high, n_boot, interval:
    r_low, r_high is `centred_interval` of the resamples around r (around the
    median without `fits`), so it always contains its point. The paper's
    percentile interval (the 2.5 and 97.5 percentiles of the resampled r) is not
    an output: resampled trial means carry extra noise, so it can miss r
    altogether (docs/results.md has how often).
    """
    groups = {k: g["r"].to_numpy() for k, g in boot.groupby(["dataset", "model"], sort=False)}
    summary = (boot.groupby(["dataset", "model"], sort=False)["r"]
               .agg(r_median="median", n_boot="size").reset_index())
    if fits is not None:
        summary = summary.merge(fits[["dataset", "model", "r"]], on=["dataset", "model"], how="left")
    point = summary["r"] if fits is not None else summary["r_median"]
    centred = [centred_interval(r, groups[(d, m)], level, (-1.0, 1.0)) for d, m, r in
               zip(summary["dataset"], summary["model"], point)]
    summary["r_low"] = [c[0] for c in centred]
    summary["r_high"] = [c[1] for c in centred]
    summary["interval"] = INTERVAL
    columns = ["dataset", "model"] + (["r"] if fits is not None else []) + ["r_median", "r_low", "r_high", "n_boot",
                                                                            "interval"]
    return summary[columns]


def bootstrap_tests(boot: pd.DataFrame, fits: pd.DataFrame,
                    comparisons: Sequence[tuple[str, str]] = COMPARISONS) -> pd.DataFrame:
    """Direct bootstrap tests between models (definition in the module docstring).

    `boot` from `bootstrap_model_correlations`, `fits` from `fit_models` (the
    full-sample correlations). Returns one row per (dataset, comparison):
    dataset, model_a, model_b, r_a, r_b, better (the model with the higher
    full-sample r), p_value, n_boot.
    """
    rows = []
    for dataset in ordered_datasets(boot["dataset"].unique()):
        wide = boot[boot["dataset"] == dataset].pivot(index="resample", columns="model", values="r")
        point = fits[fits["dataset"] == dataset].set_index("model")["r"]
        for a, b in comparisons:
            r_a, r_b = float(point[a]), float(point[b])
            if np.isnan(r_a) or np.isnan(r_b):
                warnings.warn(f"{dataset}: {a} vs {b}: a full-sample r is undefined, p is NaN",
                              RuntimeWarning, stacklevel=2)
                better, p = "", float("nan")
            elif r_a == r_b:
                better, p = "", 1.0
            else:
                better, worse = (a, b) if r_a > r_b else (b, a)
                s_better = wide[better].to_numpy()
                s_worse = wide[worse].to_numpy()
                # NaN compares False, so `not (better > worse)` counts it as a reversal.
                p = float(np.mean(~(s_better > s_worse)))
            rows.append((dataset, a, b, r_a, r_b, better, p, len(wide)))
    out = pd.DataFrame(rows, columns=["dataset", "model_a", "model_b", "r_a", "r_b", "better",
                                      "p_value", "n_boot"])
    out["method"] = IN_SAMPLE_METHOD
    return out


def _correlations_one_dataset(task) -> np.ndarray:
    """(n_models, n_boot) correlations for one dataset's resampled trial means."""
    _, designs, Y = task
    return np.stack([rowwise_pearson(batch_predictions(X, Y), Y) for X in designs])
