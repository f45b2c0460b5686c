"""Human responses: the tidy CSV format, its validation, exclusions, z-scoring and
per-trial means with participant-bootstrap intervals (Experiments and Results
sections of the paper).

The paper's responses are not public. Nothing here makes up data: the functions
read what a user supplies (see docs/human-data.md) or, in tests only, what
`analysis.simulate.simulate_participants` draws, whose dataset names start with
``simulated-`` so they can never pass for human data.

The package, by idea: `datasets` (the format's names and its error), `validation`
(reading and validating a CSV) and `means` (exclusion, z-scores, trial means and
their bootstrap); every name is importable from analysis.data.
"""
from __future__ import annotations

from analysis.data.datasets import (DATASETS, REQUIRED_COLUMNS, SIMULATED_PREFIX, HumanDataError,  # noqa: F401
                                    is_simulated, is_simulated_dataset, ordered_datasets)
from analysis.data.means import (BOOTSTRAP_BLOCK_BYTES, bootstrap_trial_means,  # noqa: F401
                                 exclude_constant_participants, participant_matrices, resample_trial_means,
                                 trial_mean_intervals, trial_means, zscore_responses)
from analysis.data.validation import (BYTES_PER_PARTICIPANT, MAX_PARTICIPANTS,  # noqa: F401
                                      line_ranges, load_human_data, validate_human_data,
                                      MAX_FIELD_CHARS, CsvShapeError, csv_records, parse_response)
# TRIAL_IDS: the 24 trial ids in the paper's order (pair 1 easy, pair 1 hard, ..., 12H);
# PAIRS: the 12 easy/hard pairs.
from lgp.paper import PAIRS, TRIAL_IDS  # noqa: F401  (re-exported)
# The trial set the analysis runs on (default the paper's 24): analysis.data.trialset.
from analysis.data.trialset import is_paper_set, pair_numbers, trial_ids, using_trials  # noqa: F401,E402
