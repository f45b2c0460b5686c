"""Simulated participants, for testing the analysis only.

The paper's human responses are not public and nothing here stands in for them.
Simulated rows carry dataset names prefixed ``simulated-`` (``simulated-time``
...), the only label they need: it survives every groupby into every table, and
`run_analysis` and the figures turn it into "simulated" in file names and
"SIMULATED participants (not human data)" in figure titles. `load_human_data`
refuses such datasets unless told ``allow_simulated=True``.
"""
from __future__ import annotations

from pathlib import Path
from typing import Mapping, Sequence

import numpy as np
import pandas as pd

from analysis.data import DATASETS, SIMULATED_PREFIX, is_simulated_dataset
from analysis.data.trialset import trial_ids
from analysis.models import ModelInputError, full_model_cost, risk_at_sigma
from lgp.errors import InputError


def simulate_participants(effort, risk_by_sigma: pd.DataFrame,
                          betas: Sequence[float] | Mapping[str, Sequence[float]],
                          sigma: float, n_participants: int | Mapping[str, int],
                          noise_sd: float, rng: np.random.Generator,
                          datasets: Sequence[str] = DATASETS,
                          scale_log_sd: float = 0.5, offset_sd: float = 10.0) -> pd.DataFrame:
    """Draw responses of simulated participants from the full model (Eq. 1).

    Participant p of a dataset answers trial i with
        response = offset_p + scale_p * (y_i + noise_sd * eps_pi),
        y_i = b0 + b1 E_i (1 - R_i(sigma)) + b2 E_i R_i(sigma),
    with eps_pi ~ N(0, 1), scale_p = exp(scale_log_sd * N(0, 1)) and offset_p ~
    N(0, offset_sd): each participant uses the response scale differently, which
    z-scoring removes. So `noise_sd` is in units of the latent cost y, and after
    z-scoring only y's shape up to a positive affine map is recoverable (b1 and
    b2 up to a common positive factor, b0 not at all).

    `betas` is one (b0, b1, b2) or {dataset: (b0, b1, b2)}; `n_participants`
    an int or {dataset: int}. Draws, per dataset in the order given: scales
    (n,), offsets (n,), noise (n, 24).

    Returns the human-data schema (dataset, participant, trial, response) with
    datasets named ``simulated-<dataset>`` and participants ``sim-001``, ....
    """
    R = risk_at_sigma(risk_by_sigma, sigma)
    frames = []
    for dataset in datasets:
        if is_simulated_dataset(dataset):
            raise InputError(f"dataset {dataset!r}: give the plain name; the "
                             f"{SIMULATED_PREFIX!r} prefix is added here")
        b = betas[dataset] if isinstance(betas, Mapping) else betas
        n = n_participants[dataset] if isinstance(n_participants, Mapping) else n_participants
        y = full_model_cost(effort, R, b).to_numpy()
        scale = np.exp(scale_log_sd * rng.standard_normal(n))
        offset = offset_sd * rng.standard_normal(n)
        noise = noise_sd * rng.standard_normal((n, len(trial_ids())))
        responses = offset[:, None] + scale[:, None] * (y[None, :] + noise)
        frames.append(pd.DataFrame({
            "dataset": SIMULATED_PREFIX + dataset,
            "participant": np.repeat([f"sim-{k + 1:03d}" for k in range(n)], len(trial_ids())),
            "trial": np.tile(list(trial_ids()), n),
            "response": responses.reshape(-1),
        }))
    return pd.concat(frames, ignore_index=True)


def read_results(results: Path) -> tuple[pd.DataFrame, pd.DataFrame]:
    """effort_samples.csv and risk.csv of a full `lgp.reproduce` run, checked."""
    tables = []
    for name, columns in (("effort_samples.csv", ("trial", "sample", "effort")), ("risk.csv", ("trial", "sigma", "risk"))):
        path = results / name
        if not path.is_file():
            raise ModelInputError(f"{path} does not exist: --results must be the output folder of a full "
                                  "`python -m lgp.reproduce` run")
        try:
            table = pd.read_csv(path, dtype={"trial": str})
        except (ValueError, UnicodeDecodeError) as e:  # pandas' ParserError is a ValueError
            raise ModelInputError(f"{path}: not a readable CSV ({e})") from e
        missing = [c for c in columns if c not in table.columns]
        if missing:
            raise ModelInputError(f"{path}: missing column(s) {', '.join(missing)}")
        tables.append(table)
    return tables[0], tables[1]
