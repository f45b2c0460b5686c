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


def summarize_bootstrap(boot: pd.DataFrame, fits: pd.DataFrame | None = None,
                        level: float = 0.95) -> pd.DataFrame:
    """Median and percentile interval of each model's bootstrap correlations.

    Returns one row per (dataset, model): dataset, model, r (full-sample fit, if
    `fits` from `fit_models` is given), r_median, r_low, r_high (the paper's
    method: the 2.5 and 97.5 percentiles for level 0.95, numpy's linear
    interpolation; it need not contain r), n_boot; with `fits` also
    r_low_centred, r_high_centred (`centred_interval`: the same resamples
    shifted to r, always containing it).
    """
    tail = 100 * (1 - level) / 2
    summary = (boot.groupby(["dataset", "model"], sort=False)["r"]
               .agg(r_median="median",
                    r_low=lambda r: np.percentile(r, tail),
                    r_high=lambda r: np.percentile(r, 100 - tail),
                    n_boot="size")
               .reset_index())
    if fits is not None:
        summary = summary.merge(fits[["dataset", "model", "r"]], on=["dataset", "model"], how="left")
        groups = {k: g["r"].to_numpy() for k, g in boot.groupby(["dataset", "model"], sort=False)}
        centred = [centred_interval(r, groups[(d, m)], level, (-1.0, 1.0)) for d, m, r in
                   zip(summary["dataset"], summary["model"], summary["r"])]
        summary["r_low_centred"] = [c[0] for c in centred]
        summary["r_high_centred"] = [c[1] for c in centred]
        summary = summary[["dataset", "model", "r", "r_median", "r_low", "r_high", "r_low_centred", "r_high_centred",
                           "n_boot"]]
    return summary


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
    return pd.DataFrame(rows, columns=["dataset", "model_a", "model_b", "r_a", "r_b", "better",
                                       "p_value", "n_boot"])


def _correlations_one_dataset(task) -> np.ndarray:
    """(n_models, n_boot) correlations for one dataset's resampled trial means."""
    _, designs, Y = task
    return np.stack([rowwise_pearson(batch_predictions(X, Y), Y) for X in designs])
