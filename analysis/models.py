"""The full effort-risk model (Eq. 1 of the paper) and the two lesioned models,
fit by least squares to per-trial mean z-scored responses.

    full:    y_i = b0 + b1 E_i (1 - R_i) + b2 E_i R_i      (Eq. 1)
    effort:  y_i = b0 + b1 E_i
    risk:    y_i = b0 + b1 R_i

E_i is the physical effort of trial i (kinetic energy, J, averaged over the
planner's samples) and R_i its physical risk at noise level sigma (fraction of
perturbed simulations in which state B fell). Model inputs are tidy tables:

* effort: a Series indexed by trial id, or a DataFrame with columns ``trial`` and
  ``effort`` (more columns allowed, e.g. ``sample``; rows of a trial are averaged,
  as the paper averages its 30 samples of state A).
* risk: a DataFrame with columns ``trial``, ``sigma`` (in units of the block
  length d) and ``risk`` in [0, 1], one row per (trial, sigma).
"""
from __future__ import annotations

import warnings
from dataclasses import dataclass
from typing import Mapping, Sequence

import numpy as np
import pandas as pd

from analysis.data.trialset import trial_ids
from analysis.spec import RISK_BASES, ModelSpec, ModelSpecError

#: Model names used in every table: Eq. 1, effort-only, risk-only.
MODELS: tuple[str, ...] = ("full", "effort", "risk")
#: Human-readable labels for figures.
MODEL_LABELS = {"full": "Full (effort + risk)", "effort": "Effort only", "risk": "Risk only",
                "height": "Height of B (levels)", "blocks": "Blocks in B", "stacked": "Stacked blocks in B",
                "distance": "Transport distance", "actions": "Actions of the plan", "depth": "Support-graph depth",
                "effort+height": "Effort + height (no risk)", "effort+stacked": "Effort + stacked (no risk)"}
#: What b1, b2 multiply in each model (b0 is the intercept).
MODEL_TERMS = {"full": ("E(1-R)", "E*R"), "effort": ("E",), "risk": ("R",)}
#: Aggregates of risk through the build (models/risk/build.py, docs/results.md) that
#: may stand in for R: final-stage risk, max over stages, expected number of
#: collapses, probability of at least one, and the care-weighted sum. Only
#: final, max and any are probabilities; expected and care may exceed 1.
from analysis.spec import RISK_MEASURES  # noqa: E402  (one home: analysis.spec)
PROBABILITY_MEASURES = ("final", "max", "any", "sequential")
#: Models whose R is a build-risk aggregate are named like ``full[max]``.
MEASURE_BASES: tuple[str, ...] = RISK_BASES
#: Two sigmas closer than this are the same grid value (0.065 vs 0.0650000001).
SIGMA_ATOL = 1e-9


class ModelInputError(ValueError):
    """An effort or risk table is unusable: names the trial, sigma and rule broken."""


@dataclass(frozen=True)
class ModelFit:
    """One least-squares fit of a model to 24 trial means.

    coefficients: (b0, b1) or (b0, b1, b2) as in MODEL_TERMS; predictions: Series
    indexed by trial id; rmse: sqrt(mean squared residual) over the 24 trials
    (divided by 24, not by the residual degrees of freedom); r: Pearson r between
    predictions and observations.
    """

    model: str
    coefficients: tuple[float, ...]
    predictions: pd.Series
    rmse: float
    r: float


def effort_per_trial(effort: pd.Series | pd.DataFrame) -> pd.Series:
    """Effort per trial as a Series named ``effort`` indexed by trial_ids().

    A DataFrame with columns trial, effort (and e.g. sample) is averaged over the
    rows of each trial. Raises ModelInputError naming the trial for a missing or
    unknown trial, or a non-finite or negative effort (effort is kinetic energy).
    """
    if isinstance(effort, pd.DataFrame):
        for column in ("trial", "effort"):
            if column not in effort.columns:
                raise ModelInputError(f"effort table lacks column {column!r}; "
                                      f"found {', '.join(map(str, effort.columns))}")
        table = effort.assign(trial=effort["trial"].astype(str).str.strip().str.upper())
        bad = table[~np.isfinite(pd.to_numeric(table["effort"], errors="coerce"))]
        if len(bad):
            row = bad.iloc[0]
            where = f", sample {row['sample']}" if "sample" in table.columns else ""
            raise ModelInputError(f"effort of trial {row['trial']}{where} is {row['effort']!r}, "
                                  "not a finite number")
        series = table.assign(effort=table["effort"].astype(float)).groupby("trial")["effort"].mean()
    else:
        series = pd.Series(effort, dtype=float)
        series.index = [str(t).strip().upper() for t in series.index]
    return _check_per_trial(series.rename("effort"), "effort", nonnegative=True)


def risk_sigmas(risk_table: pd.DataFrame) -> np.ndarray:
    """The sorted distinct sigma values of a risk table (rounded to 1e-9)."""
    _check_risk_columns(risk_table)
    return np.unique(np.round(risk_table["sigma"].to_numpy(dtype=float), 9))


def risk_at_sigma(risk_table: pd.DataFrame, sigma: float) -> pd.Series:
    """Risk per trial at one sigma, as a Series named ``risk`` indexed by trial_ids().

    Raises ModelInputError if no row has this sigma, a trial is missing or
    repeated at this sigma, or a risk is not a probability.
    """
    _check_risk_columns(risk_table)
    rows = risk_table[np.isclose(risk_table["sigma"].astype(float), sigma, rtol=0, atol=SIGMA_ATOL)]
    if rows.empty:
        raise ModelInputError(f"risk table has no rows at sigma {sigma:g}; it has sigma "
                              f"{', '.join(f'{s:g}' for s in risk_sigmas(risk_table))}")
    trials = rows["trial"].astype(str).str.strip().str.upper()
    repeated = trials[trials.duplicated()]
    if len(repeated):
        raise ModelInputError(f"risk table has more than one row for trial {repeated.iloc[0]} at "
                              f"sigma {sigma:g}; aggregate (e.g. pick one engine) first")
    series = pd.Series(pd.to_numeric(rows["risk"], errors="coerce").to_numpy(), index=trials,
                       name="risk")
    series = _check_per_trial(series, f"risk at sigma {sigma:g}", nonnegative=True)
    above = series[series > 1]
    if len(above):
        raise ModelInputError(f"risk of trial {above.index[0]} at sigma {sigma:g} is "
                              f"{above.iloc[0]:g}, above 1 (risk is a probability)")
    return series


def measure_model(base: str, measure: str) -> str:
    """Name of model `base` ('full' or 'risk') with build-risk aggregate `measure` as R."""
    try:
        return ModelSpec(base, measure).name
    except ModelSpecError as e:
        raise ModelInputError(str(e)) from None


def model_spec(model: "str | ModelSpec") -> ModelSpec:
    """The ModelSpec a model name means (analysis.spec), ModelInputError if none."""
    try:
        return ModelSpec.parse(model)
    except ModelSpecError as e:
        raise ModelInputError(str(e)) from None


def split_model(model: "str | ModelSpec") -> tuple[str, str | None]:
    """'full[max]' -> ('full', 'max'); 'full' -> ('full', None) (ModelSpec's two fields)."""
    spec = model_spec(model)
    return spec.base, spec.risk


def measure_at_sigma(build_table: pd.DataFrame, sigma: float, measure: str) -> pd.Series:
    """One build-risk aggregate per trial at one sigma, a Series indexed by trial_ids().

    `build_table` has columns trial, sigma, measure, risk (models.risk.build's
    `measure_table`). Raises ModelInputError naming the measure, sigma and trial
    for a missing row, a negative or non-finite value, or a probability measure
    above 1.
    """
    for column in ("trial", "sigma", "measure", "risk"):
        if column not in build_table.columns:
            raise ModelInputError(f"build-risk table lacks column {column!r}; "
                                  f"found {', '.join(map(str, build_table.columns))}")
    if measure not in RISK_MEASURES:
        raise ModelInputError(f"unknown risk measure {measure!r}; expected one of {', '.join(RISK_MEASURES)}")
    rows = build_table[(build_table["measure"] == measure)
                       & np.isclose(build_table["sigma"].astype(float), sigma, rtol=0, atol=SIGMA_ATOL)]
    if rows.empty:
        have = np.unique(np.round(build_table["sigma"].astype(float), 9))
        raise ModelInputError(f"build-risk table has no {measure!r} rows at sigma {sigma:g}; it has sigma "
                              f"{', '.join(f'{s:g}' for s in have)}")
    series = pd.Series(pd.to_numeric(rows["risk"], errors="coerce").to_numpy(),
                       index=rows["trial"].astype(str).str.strip().str.upper(), name="risk")
    series = _check_per_trial(series, f"build risk {measure!r} at sigma {sigma:g}", nonnegative=True)
    if measure in PROBABILITY_MEASURES and (series > 1).any():
        t = series.index[(series > 1).to_numpy()][0]
        raise ModelInputError(f"build risk {measure!r} of trial {t} at sigma {sigma:g} is {series[t]:g}, "
                              "above 1 (it is a probability)")
    return series


def risk_inputs(R: pd.Series, build_table: pd.DataFrame | None = None, sigma: float | None = None) -> pd.DataFrame:
    """The risks the models read, one column per source, indexed by trial_ids():
    ``R`` (used by full and risk) and one column per build-risk measure (used by
    ``full[measure]`` and ``risk[measure]``) when `build_table` is given."""
    out = pd.DataFrame({"R": R.reindex(list(trial_ids()))})
    if build_table is not None:
        for m in RISK_MEASURES:
            out[m] = measure_at_sigma(build_table, sigma, m)
    return out


def design_matrix(model: str, effort: pd.Series, risk: pd.Series | pd.DataFrame | None = None,
                  features: pd.DataFrame | None = None) -> np.ndarray:
    """The (24, p) regressor matrix of `model`, rows in trial_ids() order, first
    column the intercept. `risk` is a per-trial Series, or a DataFrame from
    `risk_inputs` (column R for full and risk, column m for full[m] and risk[m]);
    `features` the heuristic predictors (analysis.heuristics.trial_features,
    indexed by trial or with a column trial) for the heuristic models."""
    spec = model_spec(model)
    model, measure = spec.base, spec.risk
    if spec.feature is not None:
        h = feature_vector(features, spec.feature)
        E = effort.reindex(list(trial_ids())).to_numpy(dtype=float)
        ones = np.ones_like(h)
        return np.column_stack([ones, E, h]) if spec.reads_effort else np.column_stack([ones, h])
    if isinstance(risk, pd.DataFrame):
        column = measure or "R"
        if column not in risk.columns:
            raise ModelInputError(f"model {model}[{measure}] needs build risk {measure!r}; "
                                  f"the risk inputs have {', '.join(risk.columns)}")
        risk = risk[column]
    elif measure is not None:
        raise ModelInputError(f"model {model}[{measure}] needs the build-risk aggregates (risk_inputs)")
    E = effort.reindex(list(trial_ids())).to_numpy(dtype=float)
    ones = np.ones_like(E)
    if model == "effort":
        return np.column_stack([ones, E])
    if risk is None:
        raise ModelInputError(f"model {model!r} needs risk per trial")
    R = risk.reindex(list(trial_ids())).to_numpy(dtype=float)
    if model == "full":
        return np.column_stack([ones, E * (1 - R), E * R])  # Eq. 1 of the paper
    if model == "risk":
        return np.column_stack([ones, R])
    raise ModelInputError(f"unknown model {model!r}; expected one of {', '.join(MODELS)}")


def feature_vector(features: pd.DataFrame | None, feature: str, trials: Sequence[str] | None = None) -> np.ndarray:
    """One heuristic predictor in `trials` order from a features table (indexed by
    trial, or with a column trial). ModelInputError names a missing feature or trial."""
    trials = trial_ids() if trials is None else trials
    if features is None:
        raise ModelInputError(f"model needs the heuristic predictor {feature!r} per trial "
                              "(analysis.heuristics.trial_features)")
    table = features.set_index("trial") if "trial" in features.columns else features
    if feature not in table.columns:
        raise ModelInputError(f"the features table lacks {feature!r}; it has {', '.join(map(str, table.columns))}")
    missing = [t for t in trials if t not in table.index]
    if missing:
        raise ModelInputError(f"heuristic predictor {feature!r}: missing trial(s) {', '.join(missing)}")
    v = table[feature].reindex(list(trials)).to_numpy(dtype=float)
    if not np.all(np.isfinite(v)):
        raise ModelInputError(f"heuristic predictor {feature!r} of trial {list(trials)[int(np.argmin(np.isfinite(v)))]} "
                              "is not a finite number")
    return v


def fit_model(model: str, y: pd.Series | Sequence[float], effort: pd.Series | pd.DataFrame,
              risk: pd.Series | None = None, features: pd.DataFrame | None = None) -> ModelFit:
    """Least-squares fit of `model` ('full', 'effort' or 'risk') to trial means `y`.

    `y` is a Series indexed by trial id or 24 values in trial_ids() order; `effort`
    anything `effort_per_trial` accepts; `risk` a per-trial Series (see
    `risk_at_sigma`). Solved with numpy.linalg.lstsq, so a rank-deficient design
    (e.g. the same risk on every trial) gives the minimum-norm coefficients and
    still well-defined predictions.
    """
    E = effort_per_trial(effort)
    y_vec = _trial_vector(y)
    X = design_matrix(model, E, risk, features)
    beta, *_ = np.linalg.lstsq(X, y_vec, rcond=None)
    pred = X @ beta
    return ModelFit(
        model=model,
        coefficients=tuple(float(b) for b in beta),
        predictions=pd.Series(pred, index=list(trial_ids()), name="predicted"),
        rmse=float(np.sqrt(np.mean((y_vec - pred) ** 2))),
        r=pearson_r(pred, y_vec, what=f"{model} model"),
    )


def fit_models(means: pd.DataFrame, effort: pd.Series | pd.DataFrame,
               risk: pd.Series | Mapping[str, pd.Series], sigma: float | Mapping[str, float],
               models: Sequence[str] = MODELS, features: pd.DataFrame | None = None) -> tuple[pd.DataFrame, pd.DataFrame]:
    """Fit each model to each dataset's trial means.

    `means` has columns dataset, trial, mean_z (as `analysis.data.trial_means`).
    `risk` is one per-trial Series for all datasets or {dataset: Series}, and
    `sigma` the matching value(s), recorded in the output.

    Returns ``(fits, predictions)``: fits has one row per (dataset, model) with
    columns dataset, model, sigma, b0, b1, b2 (b2 is NaN for the two-parameter
    lesioned models, whose b1 multiplies E or R), rmse, r, n_trials; predictions
    one row per (dataset, model, trial) with observed and predicted.
    """
    E = effort_per_trial(effort)
    fit_rows, pred_rows = [], []
    for dataset, group in means.groupby("dataset", sort=True):
        y = group.set_index("trial")["mean_z"]
        R = risk[dataset] if isinstance(risk, Mapping) else risk
        s = sigma[dataset] if isinstance(sigma, Mapping) else sigma
        y_vec = _trial_vector(y)
        for model in models:
            fit = fit_model(model, y, E, R, features)
            b = list(fit.coefficients) + [np.nan] * (3 - len(fit.coefficients))
            fit_rows.append((dataset, model, s, *b, fit.rmse, fit.r, len(trial_ids())))
            for trial, obs, pred in zip(trial_ids(), y_vec, fit.predictions.to_numpy()):
                pred_rows.append((dataset, model, s, trial, obs, pred))
    fits = pd.DataFrame(fit_rows, columns=["dataset", "model", "sigma", "b0", "b1", "b2",
                                           "rmse", "r", "n_trials"])
    predictions = pd.DataFrame(pred_rows, columns=["dataset", "model", "sigma", "trial",
                                                   "observed", "predicted"])
    return fits, predictions


def full_model_cost(effort: pd.Series | pd.DataFrame, risk: pd.Series,
                    betas: Sequence[float]) -> pd.Series:
    """Eq. 1 evaluated with given (b0, b1, b2): the model's cost per trial."""
    b0, b1, b2 = betas
    E = effort_per_trial(effort)
    R = risk.reindex(list(trial_ids()))
    return (b0 + b1 * E * (1 - R) + b2 * E * R).rename("cost")


def pearson_r(a: np.ndarray, b: np.ndarray, what: str = "model") -> float:
    """Pearson correlation of two vectors. If either is constant r is undefined:
    returns NaN and warns naming `what` (e.g. a risk-only model whose risk is the
    same on every trial)."""
    a, b = np.asarray(a, dtype=float), np.asarray(b, dtype=float)
    if _is_constant(a) or _is_constant(b):
        warnings.warn(f"Pearson r of the {what} is undefined (constant predictions or data); "
                      "reported as NaN", RuntimeWarning, stacklevel=2)
        return float("nan")
    a, b = a - a.mean(), b - b.mean()
    return float(np.dot(a, b) / np.sqrt(np.dot(a, a) * np.dot(b, b)))


def batch_predictions(X: np.ndarray, Y: np.ndarray) -> np.ndarray:
    """Least-squares predictions of design `X` (24, p) for many responses at once:
    `Y` is (n, 24), one row per bootstrap resample; returns (n, 24)."""
    beta, *_ = np.linalg.lstsq(X, Y.T, rcond=None)
    return (X @ beta).T


def rowwise_pearson(P: np.ndarray, Y: np.ndarray) -> np.ndarray:
    """Pearson r of each row of `P` with the same row of `Y` (NaN where a row is
    constant)."""
    Pc = P - P.mean(axis=1, keepdims=True)
    Yc = Y - Y.mean(axis=1, keepdims=True)
    denom = np.sqrt((Pc * Pc).sum(axis=1) * (Yc * Yc).sum(axis=1))
    with np.errstate(invalid="ignore", divide="ignore"):
        r = (Pc * Yc).sum(axis=1) / denom
    return np.where(_is_constant(P, axis=1) | _is_constant(Y, axis=1), np.nan, r)


def _is_constant(x: np.ndarray, axis=None):
    """Spread no larger than rounding error: the mean of 24 equal floats need not
    equal them exactly, so centring alone would leave ~1e-16 noise to correlate."""
    spread = np.ptp(x, axis=axis)
    return spread <= 1e-12 * np.max(np.abs(x), axis=axis)


def _trial_vector(y) -> np.ndarray:
    if isinstance(y, pd.Series):
        y = _check_per_trial(pd.Series(y.to_numpy(dtype=float), index=[str(t) for t in y.index]),
                             "trial means", nonnegative=False)
        return y.to_numpy()
    y = np.asarray(y, dtype=float)
    if y.shape != (len(trial_ids()),):
        raise ModelInputError(f"expected {len(trial_ids())} trial means in order "
                              f"{trial_ids()[0]}..{trial_ids()[-1]}, got shape {y.shape}")
    return y


def _check_risk_columns(risk_table: pd.DataFrame) -> None:
    for column in ("trial", "sigma", "risk"):
        if column not in risk_table.columns:
            raise ModelInputError(f"risk table lacks column {column!r}; "
                                  f"found {', '.join(map(str, risk_table.columns))}")


def _check_per_trial(series: pd.Series, what: str, nonnegative: bool) -> pd.Series:
    unknown = [t for t in series.index if t not in trial_ids()]
    if unknown:
        raise ModelInputError(f"{what}: unknown trial id {unknown[0]!r}; expected 1E, 1H, ..., 12H")
    if series.index.duplicated().any():
        raise ModelInputError(f"{what}: trial {series.index[series.index.duplicated()][0]} "
                              "appears more than once")
    missing = [t for t in trial_ids() if t not in series.index]
    if missing:
        raise ModelInputError(f"{what}: missing trial(s) {', '.join(missing)}")
    series = series.reindex(list(trial_ids())).astype(float)
    bad = series[~np.isfinite(series.to_numpy())]
    if len(bad):
        raise ModelInputError(f"{what} of trial {bad.index[0]} is {bad.iloc[0]!r}, "
                              "not a finite number")
    if nonnegative and (series < 0).any():
        t = series.index[(series < 0).to_numpy()][0]
        raise ModelInputError(f"{what} of trial {t} is {series[t]:g}, negative")
    return series
