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

The package, by idea: `folds` (the schemes and their folds), `grids` (risk over
the sigma grid and its redraws), `fits` (held-out predictions and their scores),
`tables` (the comparison's tables and intervals) and `decisions` (direct
bootstrap tests and verdicts); every name is importable from analysis.crossval.
"""
from __future__ import annotations

from analysis.crossval.decisions import (N_PARAMETERS, SCORES, comparison_tests, direct_p, held_out_tests,  # noqa: F401
                                        sign_flip_p, verdicts)
from analysis.crossval.fits import CHUNK, COLLINEAR_REL, cross_validate, cv_arrays, scores  # noqa: F401
from analysis.crossval.folds import (CV_SCHEMES, MIN_PAIRS, SCHEMES, STRUCTURE_SCHEME, CrossValidationError,  # noqa: F401
                                     grouping_label, make_folds, pairs_of, structure_folds, structure_groups)
from analysis.crossval.grids import RISK_DRAW_STREAM, RISK_DRAWS, RiskGrid, measure_grid, redraw_risk, risk_grid  # noqa: F401
from analysis.crossval.tables import (bootstrap_comparison, gain_over_effort, model_comparison,  # noqa: F401
                                      summarize_comparison)
