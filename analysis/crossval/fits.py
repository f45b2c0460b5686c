"""The held-out predictions of every model, vectorised over resamples, sigmas and
folds, sigma chosen inside each fold (`cv_arrays`, `cross_validate`), and their
scores (`scores`): "The fits" and "Scores" in analysis.crossval's docstring."""
from __future__ import annotations

import warnings
from typing import Mapping, Sequence

import numpy as np

from analysis.crossval.folds import STRUCTURE_SCHEME, CrossValidationError, make_folds, pairs_of, structure_folds
from analysis.data.trialset import trial_ids
from analysis.models import ModelInputError, model_spec, rowwise_pearson
from analysis.pairs import pair_order_codes
from analysis.sigma import least_sigma_index

#: A column of E*R (or R) whose part beyond the intercept and E has a norm below
#: this fraction of its own is "nothing beyond them" (the fold predicts as effort-only).
COLLINEAR_REL = 1e-9
#: Resamples (or permutations) per array operation: a fixed number, so the numbers
#: never depend on how many processes share the work.
CHUNK = 64


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
              pool: bool = True, features: Mapping[str, np.ndarray] | None = None
              ) -> tuple[dict[str, np.ndarray], dict[str, np.ndarray]]:
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
    `features` {name: (T,)} the heuristic predictors of the heuristic models
    (analysis.spec: ``h`` is y = b0 + b1 h, ``effort+h`` y = b0 + b1 E + b2 h),
    fitted on the training trials like effort-only and risk-only (no sigma).
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

    specs = {m: model_spec(m) for m in models}
    preds = {m: np.full((B, D, T), np.nan) for m in models}
    if "effort" in models:
        _scatter(preds["effort"], gy, test)
    _heuristic_predictions(preds, specs, features, M, G, ey, gy, ymean, yc, train, test)
    chosen = {}
    for source in dict.fromkeys(spec.source for spec in specs.values() if spec.source is not None):
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
                pick = np.repeat(least_sigma_index(crit.mean(axis=-1), axis=1)[..., None], D, axis=-1)
            else:
                pick = least_sigma_index(crit, axis=1)  # (B, F, D); ties: the smaller sigma
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


def _heuristic_predictions(preds, specs, features, M, G, ey, gy, ymean, yc, train, test) -> None:
    """The heuristic models' held-out predictions into `preds` (cv_arrays' operators:
    M, G per fold; ey, gy effort residuals and predictions; ymean, yc training means
    and centred values): ``effort+h`` through the part of h beyond 1 and E, ``h``
    alone as y = b0 + b1 h."""
    for m, spec in specs.items():
        if spec.feature is None:
            continue
        if features is None or spec.feature not in features:
            raise ModelInputError(f"model {m} needs the heuristic predictor {spec.feature!r} per trial")
        h = np.asarray(features[spec.feature], dtype=float)
        htr = h[train]                                                   # (F, n_tr)
        if spec.reads_effort:   # effort + h: the part of h that 1 and E do not explain in training
            z = np.einsum("fij,fj->fi", M, htr)
            zz = np.einsum("fi,fi->f", z, z)
            absent = zz <= COLLINEAR_REL ** 2 * np.einsum("fi,fi->f", htr, htr)
            zy = np.einsum("fi,bfdi->bfd", z, ey)
            c = np.where(absent[None, :, None], 0.0, zy / np.where(absent, 1.0, zz)[None, :, None])
            dh = h[test] - np.einsum("fij,fj->fi", G, htr)               # (F, n_te)
            _scatter(preds[m], gy + c[..., None] * dh[None, :, None, :], test)
        else:                   # h alone: y = b0 + b1 h
            hmean = htr.mean(axis=-1)
            hc = htr - hmean[:, None]
            hh = np.einsum("fi,fi->f", hc, hc)
            flat = hh <= COLLINEAR_REL ** 2 * np.einsum("fi,fi->f", htr, htr)
            hy = np.einsum("fi,bfdi->bfd", hc, yc)
            slope = np.where(flat[None, :, None], 0.0, hy / np.where(flat, 1.0, hh)[None, :, None])
            dh = h[test] - hmean[:, None]
            _scatter(preds[m], ymean[..., None] + slope[..., None] * dh[None, :, None, :], test)


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
                   trials: Sequence[str] | None = None, chunk: int = CHUNK,
                   features: Mapping[str, np.ndarray] | None = None,
                   groups: Sequence[Sequence[int]] | None = None
                   ) -> tuple[dict[str, np.ndarray], dict[str, np.ndarray], np.ndarray | list[np.ndarray]]:
    """`cv_arrays` for one scheme, in chunks of `chunk` resamples (a fixed size, so the
    result never depends on the split of the work). Risks of shape (B, S, T) are
    chunked with Y. Returns (predictions, chosen, test) with test from make_folds
    (for STRUCTURE_SCHEME, which needs `groups` from crossval.structure_groups, a
    list of the held-out index arrays, one per group, of unequal lengths; folds of
    equal size are computed together and chosen keeps the groups' order)."""
    trials = trial_ids() if trials is None else trials
    if scheme == STRUCTURE_SCHEME:
        if groups is None:
            raise CrossValidationError(f"{STRUCTURE_SCHEME} needs the structure groups (crossval.structure_groups)")
        folds = structure_folds(groups, np.asarray(Y).shape[-1])
        sizes = sorted({len(te) for _, te in folds})
        sets = [[k for k, (_, te) in enumerate(folds) if len(te) == n] for n in sizes]
        fold_sets = [(np.stack([folds[k][0] for k in ks]), np.stack([folds[k][1] for k in ks]), ks) for ks in sets]
        test_out: np.ndarray | list[np.ndarray] = [te for _, te in folds]
    else:
        train, test = make_folds(scheme, trials)
        fold_sets = [(train, test, list(range(len(test))))]
        test_out = test
    Y = np.asarray(Y, dtype=float)
    B = Y.shape[0]
    batched = {s: np.asarray(r, float).ndim == 3 for s, r in risks.items()}
    for s, r in risks.items():
        if batched[s] and np.asarray(r).shape[0] not in (B,):
            raise ModelInputError(f"risk source {s}: {np.asarray(r).shape[0]} risk draws for {B} resamples")
    preds: dict[str, list] = {m: [] for m in models}
    chosen: dict[str, list] = {}
    n_folds = sum(len(ks) for _, _, ks in fold_sets)
    for lo in range(0, B, chunk):
        hi = min(B, lo + chunk)
        part = {s: (np.asarray(r)[lo:hi] if batched[s] else r) for s, r in risks.items()}
        p_all: dict[str, np.ndarray] = {}
        c_all: dict[str, np.ndarray] = {}
        for train, test, ks in fold_sets:
            p, c = cv_arrays(Y[lo:hi], E, part, models, train, test, sigma_index, pool, features)
            for m in models:
                p_all[m] = p[m] if m not in p_all else np.where(np.isnan(p[m]), p_all[m], p[m])
            for s, v in c.items():
                if s not in c_all:
                    c_all[s] = np.zeros((v.shape[0], n_folds, v.shape[2]), dtype=v.dtype)
                c_all[s][:, ks] = v
        for m in models:
            preds[m].append(p_all[m])
        for s, v in c_all.items():
            chosen.setdefault(s, []).append(v)
    return ({m: np.concatenate(v) for m, v in preds.items()},
            {s: np.concatenate(v) for s, v in chosen.items()}, test_out)


def scores(Y: np.ndarray, predictions: np.ndarray, trials: Sequence[str] | None = None) -> dict[str, np.ndarray]:
    """Scores of (B, D, T) predictions against (B, D, T) trial means, over the
    trials that have predictions: rmse, r (NaN if either side is constant) and
    pairs (number of pairs with the easy trial predicted lower, the tie rule of
    analysis.pairs). Each (B, D)."""
    trials = trial_ids() if trials is None else trials
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
