"""Statistics of the paper's Results section: human-data loading and z-scoring,
the full effort-risk model (Eq. 1) and its lesions, the sigma fit, the
participant bootstrap and direct bootstrap tests, easy/hard pair orderings, and
Figures 3 and 4. Simulated participants exist for tests only and are always
labelled ``simulated-``. See docs/human-data.md for the input format."""
from analysis.bootstrap import (COMPARISONS, bootstrap_model_correlations,  # noqa: F401
                                bootstrap_tests, summarize_bootstrap)
from analysis.data import (DATASETS, PAIRS, TRIAL_IDS, HumanDataError,  # noqa: F401
                           bootstrap_trial_means, exclude_constant_participants, is_simulated,
                           load_human_data, resample_trial_means, trial_mean_intervals,
                           trial_means, validate_human_data, zscore_responses)
from analysis.models import (MODELS, ModelFit, ModelInputError, effort_per_trial,  # noqa: F401
                             fit_model, fit_models, full_model_cost, pearson_r, risk_at_sigma)
from analysis.pairs import TIE_REL, pair_order, pair_table  # noqa: F401
from analysis.participant_sigma import fit_participant_sigma  # noqa: F401
from analysis.run import run_analysis  # noqa: F401
from analysis.sigma import (PAPER_SIGMA, SIGMA_GRID, choose_sigma, pooled_sigma,  # noqa: F401
                            sigma_profile)
from analysis.simulate import simulate_participants  # noqa: F401
