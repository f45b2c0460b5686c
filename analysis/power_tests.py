"""analysis.power's analysis of SIMULATED studies: the held-out verdict and the
tests of "a predicts held-out trials better than b" (analysis.power's
docstring), one row per study (`analyse_studies`)."""
from __future__ import annotations

from typing import Mapping, Sequence

import numpy as np
import pandas as pd

from analysis.crossval import STRUCTURE_SCHEME, cross_validate, verdicts
from analysis.crossval.decisions import sign_flip_p as crossval_sign_flip_p
from analysis.crossval.permuted import freedman_lane
from analysis.power_worlds import PowerInputError, TrialTable
from analysis.spec import FEATURES

#: Models of the held-out verdict, in the order ties go (fewest parameters first, then this order).
MODELS: tuple[str, ...] = ("effort", "full", "risk", *FEATURES, "effort+height", "effort+stacked")
#: Pairwise comparisons "a beats b" every test decides.
COMPARISONS: tuple[tuple[str, str], ...] = (("full", "effort"), ("full", "effort+height"), ("effort+height", "full"),
                                            ("full", "effort+stacked"), ("effort+stacked", "full"))
#: The tests; DEFAULT_TESTS run unless asked otherwise.
TESTS: tuple[str, ...] = ("freedman-lane", "sign-flip", "within-pair", "shuffle", "direct-bootstrap")
DEFAULT_TESTS: tuple[str, ...] = ("freedman-lane", "sign-flip")
#: What each test is, for tables and docs.
TEST_LABELS = {"freedman-lane": "Freedman-Lane residual permutation (calibrated, default)",
               "sign-flip": "held-out sign-flip over folds (NOT CALIBRATED)",
               "within-pair": "within-pair risk permutation (full vs effort)",
               "shuffle": "shuffle risk permutation (NOT CALIBRATED)",
               "direct-bootstrap": "direct bootstrap on held-out RMSE (paper's method, NOT CALIBRATED)"}
#: Tests that only exist for Eq. 1 against effort-only (they move risk between trials).
RISK_ONLY_TESTS = ("within-pair", "shuffle")
N_PERM = 199
N_BOOT = 200
ALPHA = 0.05
#: Rows per array operation of the cross-validation (fixed: results never depend on it).
CHUNK = 512
#: A statistic within this (relative) of the observed counts as at least as large.
TIE_REL = 1e-12


def _cv(Y: np.ndarray, table: TrialTable, models: Sequence[str], scheme: str = STRUCTURE_SCHEME,
        risk: np.ndarray | None = None) -> dict[str, np.ndarray]:
    """Predictions {model: (N, T)} of (N, T) trial means (one dataset)."""
    preds, _, _ = cross_validate(np.asarray(Y, float)[:, None, :], table.effort,
                                 {"R": table.risk.risk if risk is None else risk}, list(models), scheme,
                                 trials=table.trials, chunk=CHUNK, features=table.features, groups=table.groups)
    return {m: p[:, 0, :] for m, p in preds.items()}


def _rmse(Y: np.ndarray, P: np.ndarray) -> np.ndarray:
    return np.sqrt(np.mean((Y - P) ** 2, axis=-1))


def _needed(comparisons) -> list[str]:
    return list(dict.fromkeys(m for ab in comparisons for m in ab))


def heldout_scores(Y: np.ndarray, table: TrialTable, models: Sequence[str] = MODELS) -> dict[str, np.ndarray]:
    """Held-out RMSE {model: (N,)} of (N, T) trial means on folds by structure."""
    P = _cv(Y, table, models)
    return {m: _rmse(Y, P[m]) for m in models}


def freedman_lane_p(Y: np.ndarray, table: TrialTable, a: str, b: str, perms: np.ndarray) -> np.ndarray:
    """p (N,) of "a predicts held-out trials better than b" by Freedman-Lane:
    residuals of b's in-sample fit permuted (perms (N, P, T), one set per study),
    added back to the fit, each permuted data set cross-validated whole."""
    return freedman_lane_ps(Y, table, [a], b, perms)[0]


def freedman_lane_ps(Y: np.ndarray, table: TrialTable, against: Sequence[str], b: str, perms: np.ndarray,
                     rmse: Mapping[str, np.ndarray] | None = None) -> list[np.ndarray]:
    """`freedman_lane_p` of every a in `against` versus the same reduced model b,
    on one set of permuted data sets (perms (N, P, T)); `rmse` the observed
    held-out RMSEs when already computed. The test is analysis.crossval.permuted's
    (the run's held-out permutation test), one dataset per study."""
    Y = np.asarray(Y, float)
    observed = None if rmse is None else {m: np.asarray(v, float)[:, None] for m, v in rmse.items()}
    obs, null = freedman_lane(Y[:, None, :], table.effort, {"R": table.risk.risk}, b, against, perms, table.groups,
                              table.trials, table.features, observed, chunk=CHUNK)
    return [_p_at_least(null[a][..., 0], obs[a][:, 0]) for a in against]


def _gain(Y: np.ndarray, table: TrialTable, a: str, b: str) -> np.ndarray:
    P = _cv(Y, table, [a, b])
    return _rmse(Y, P[b]) - _rmse(Y, P[a])


def _p_at_least(null: np.ndarray, obs: np.ndarray) -> np.ndarray:
    """(1 + #{null >= obs}) / (1 + P), per row; ties within TIE_REL count."""
    at_least = np.sum(null >= (obs - TIE_REL * np.abs(obs))[:, None], axis=1)
    return (1 + at_least) / (1 + null.shape[1])


def sign_flip_p(Y: np.ndarray, table: TrialTable, a: str, b: str, P: Mapping[str, np.ndarray] | None = None) -> np.ndarray:
    """p (N,) of "a predicts held-out trials better than b", paired over the folds
    by structure: d_f = SSE_b,f - SSE_a,f, sum(d) against every sign flip (exact)."""
    Y = np.asarray(Y, float)
    P = _cv(Y, table, [a, b]) if P is None else P
    sq_a, sq_b = (Y - P[a]) ** 2, (Y - P[b]) ** 2
    d = np.stack([sq_b[:, list(g)].sum(axis=1) - sq_a[:, list(g)].sum(axis=1) for g in table.groups], axis=1)
    return crossval_sign_flip_p(d)


def risk_permutation_p(Y: np.ndarray, table: TrialTable, kind: str, rngs: Sequence[np.random.Generator],
                       n_perm: int) -> np.ndarray:
    """p (N,) of Eq. 1 beating effort-only with risk curves permuted (`kind`
    within-pair or shuffle; analysis.permutation.draw_permutations), per study."""
    from analysis.permutation import draw_permutations

    Y = np.asarray(Y, float)
    obs = _gain(Y, table, "full", "effort")
    out = np.empty(len(Y))
    for n, rng in enumerate(rngs):
        perms = draw_permutations(kind, n_perm, rng, table.trials)
        risks = table.risk.risk[:, perms].transpose(1, 0, 2)                      # (P, S, T)
        Yp = np.broadcast_to(Y[n], (n_perm, Y.shape[1]))
        null = _gain_with_risk(Yp, table, risks)
        out[n] = _p_at_least(null[None], obs[n:n + 1])[0]
    return out


def _gain_with_risk(Y: np.ndarray, table: TrialTable, risks: np.ndarray) -> np.ndarray:
    P = _cv(Y, table, ["full", "effort"], risk=risks)
    return _rmse(Y, P["effort"]) - _rmse(Y, P["full"])


def direct_bootstrap_p(Z: Sequence[np.ndarray], table: TrialTable, a: str, b: str,
                       rngs: Sequence[np.random.Generator], n_boot: int) -> tuple[np.ndarray, np.ndarray]:
    """(a_better (N,), p (N,)): the paper's direct bootstrap test on held-out RMSE,
    participants of each study (Z[n] (participants, T) z-scores) resampled."""
    a_better, p = np.zeros(len(Z), bool), np.ones(len(Z))
    for n, (z, rng) in enumerate(zip(Z, rngs)):
        y = z.mean(axis=0)[None]
        s = heldout_scores(y, table, [a, b])
        if s[a][0] == s[b][0]:
            continue
        better, worse = (a, b) if s[a][0] < s[b][0] else (b, a)
        idx = rng.integers(0, z.shape[0], size=(n_boot, z.shape[0]))
        yb = z[idx].mean(axis=1)
        sb = heldout_scores(yb, table, [a, b])
        a_better[n] = better == a
        p[n] = float(np.mean(~(sb[better] < sb[worse])))
    return a_better, p



def analyse_studies(Z: Sequence[np.ndarray], table: TrialTable, rngs: Sequence[np.random.Generator],
                    tests: Sequence[str] = DEFAULT_TESTS, comparisons=COMPARISONS, n_perm: int = N_PERM,
                    n_boot: int = N_BOOT, models: Sequence[str] = MODELS) -> pd.DataFrame:
    """One row per study: the held-out verdict (column ``held-out``), each model's
    held-out RMSE (``rmse:<model>``), and per comparison a>b and test the p-value
    (``p:<test>:<a>><b>``; a_better for direct-bootstrap). Each study's rng draws,
    after its responses: freedman-lane permutations (one set per reduced model, in
    order), then within-pair, shuffle, direct-bootstrap resamples."""
    Y = np.stack([z.mean(axis=0) for z in Z])
    N, T = Y.shape
    models = list(dict.fromkeys(list(models) + _needed(comparisons)))
    P = _cv(Y, table, models)
    rmse = {m: _rmse(Y, P[m]) for m in models}
    out = {"held-out": verdicts(rmse)}
    for m in models:
        out[f"rmse:{m}"] = rmse[m]
    for test in tests:
        if test not in TESTS:
            raise PowerInputError("--tests", f"unknown test {test!r}; expected one of {', '.join(TESTS)}")
        if test == "freedman-lane":
            # one permutation set per reduced model b, in order of first appearance; every a tested against
            # b on the same permuted data sets
            for b in dict.fromkeys(b for _, b in comparisons):
                against = [a for a, bb in comparisons if bb == b]
                perms = np.stack([rng.permuted(np.tile(np.arange(T), (n_perm, 1)), axis=1) for rng in rngs])
                for a, p in zip(against, freedman_lane_ps(Y, table, against, b, perms, rmse)):
                    out[f"p:{test}:{a}>{b}"] = p
            continue
        for a, b in comparisons:
            if test in RISK_ONLY_TESTS and (a, b) != ("full", "effort"):
                continue
            key = f"p:{test}:{a}>{b}"
            if test == "sign-flip":
                out[key] = sign_flip_p(Y, table, a, b, P)
            elif test in RISK_ONLY_TESTS:
                out[key] = risk_permutation_p(Y, table, test, rngs, n_perm)
            elif test == "direct-bootstrap":
                better, p = direct_bootstrap_p(Z, table, a, b, rngs, n_boot)
                out[key] = np.where(better, p, 1.0)
    return pd.DataFrame(out)

