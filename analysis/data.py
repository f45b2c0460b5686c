"""Human responses: the tidy CSV format, its validation, exclusions, z-scoring and
per-trial means with participant-bootstrap intervals (Experiments and Results
sections of the paper).

The paper's responses are not public. Nothing here makes up data: the functions
read what a user supplies (see docs/human-data.md) or, in tests only, what
`analysis.simulate.simulate_participants` draws, whose dataset names start with
``simulated-`` so they can never pass for human data.
"""
from __future__ import annotations

import csv
import math
from pathlib import Path
from typing import Iterable, Mapping

import numpy as np
import pandas as pd

from lgp.paper import PAIRS, TRIAL_IDS, canonical_trial_id  # noqa: F401  (re-exported)

#: The 24 trial ids in the paper's order: pair 1 easy, pair 1 hard, ..., 12H.
#: The 12 easy/hard pairs.
#: The paper's three datasets: Difficulty Estimation, Time Estimation, Build Task.
DATASETS: tuple[str, ...] = ("difficulty", "time", "build")
#: Dataset names of simulated participants carry this prefix (e.g. ``simulated-time``)
#: in every table, file and figure made from them.
SIMULATED_PREFIX = "simulated-"
#: Columns a human-data CSV must have.
REQUIRED_COLUMNS: tuple[str, ...] = ("dataset", "participant", "trial", "response")
#: Problems listed in one HumanDataError message before "... and N more".
_MAX_LISTED = 20


class HumanDataError(ValueError):
    """A human-data table breaks a rule of the format in docs/human-data.md.

    The message names the CSV line (1-based, the header is line 1) and the rule
    broken. ``line`` is the line of the first problem (None if the problem has no
    single line, e.g. a missing column is reported on the header, line 1) and
    ``problems`` lists every problem found in the failing check.
    """

    def __init__(self, message: str, line: int | None = None, problems: Iterable[str] = ()):
        super().__init__(message)
        self.line = line
        self.problems = tuple(problems) or (message,)


def is_simulated_dataset(name: str) -> bool:
    """True if `name` is a dataset of simulated participants (``simulated-...``)."""
    return str(name).startswith(SIMULATED_PREFIX)


def is_simulated(responses: pd.DataFrame) -> bool:
    """True if any row of `responses` comes from simulated participants."""
    return bool(responses["dataset"].astype(str).map(is_simulated_dataset).any())


def ordered_datasets(names: Iterable[str]) -> list[str]:
    """Distinct dataset names in the paper's order (difficulty, time, build; a
    simulated dataset next to its plain name), unknown names last, alphabetical."""
    def key(name: str):
        base = name[len(SIMULATED_PREFIX):] if is_simulated_dataset(name) else name
        return (DATASETS.index(base) if base in DATASETS else len(DATASETS), base, name)
    return sorted(set(map(str, names)), key=key)


def load_human_data(path: str | Path, *, allow_simulated: bool = False) -> pd.DataFrame:
    """Read and validate a tidy human-response CSV (format: docs/human-data.md).

    Columns ``dataset`` (difficulty, time or build), ``participant``, ``trial``
    (1E ... 12H) and ``response`` (a finite number), one row per response; extra
    columns are kept. Every participant must answer all 24 trials exactly once.
    Ids and names are stripped of surrounding spaces and trial ids upper-cased
    (``1e`` is ``1E``); participant ids are strings scoped by dataset.

    Returns a DataFrame with columns dataset, participant, trial, response, the
    extra columns, and ``line`` (the CSV line each row came from).

    Raises HumanDataError naming the CSV line for a missing column, unknown
    dataset, unknown trial id, non-numeric or non-finite response, duplicate
    (dataset, participant, trial) row, or a participant with missing trials.
    Datasets named ``simulated-...`` are refused unless `allow_simulated`, so
    simulated participants cannot be loaded as human data by accident.
    """
    path = Path(path)
    with path.open(newline="", encoding="utf-8-sig") as handle:
        reader = csv.reader(handle)
        header = next(reader, None)
        if header is None:
            raise HumanDataError(f"{path}: line 1: empty file, expected a header with "
                                 f"columns {', '.join(REQUIRED_COLUMNS)}", line=1)
        header = [name.strip() for name in header]
        rows, lines = [], []
        for record in reader:
            if not record or all(not field.strip() for field in record):
                continue  # blank line
            # Short rows are padded so the missing field fails its own check below.
            record = record + [""] * (len(header) - len(record))
            rows.append(record[: len(header)])
            lines.append(reader.line_num)
    missing = [c for c in REQUIRED_COLUMNS if c not in header]
    if missing:
        raise HumanDataError(f"{path}: line 1 (header): missing column(s) {', '.join(missing)}; "
                             f"found {', '.join(header) or 'none'}", line=1)
    table = pd.DataFrame(rows, columns=header, dtype=str)
    return validate_human_data(table, lines=lines, source=str(path), allow_simulated=allow_simulated)


def validate_human_data(
    responses: pd.DataFrame,
    *,
    lines: Iterable[int] | None = None,
    source: str = "human data",
    allow_simulated: bool = False,
) -> pd.DataFrame:
    """Validate a human-response table and return it cleaned (see `load_human_data`).

    `lines` gives the CSV line of each row for error messages; by default the
    table's own ``line`` column (as `load_human_data` returns), else row k
    (0-based) is reported as line k + 2, the line it occupies in a CSV written
    with a header and no index (``DataFrame.to_csv(index=False)``).
    """
    missing = [c for c in REQUIRED_COLUMNS if c not in responses.columns]
    if missing:
        raise HumanDataError(f"{source}: line 1 (header): missing column(s) {', '.join(missing)}; "
                             f"found {', '.join(map(str, responses.columns)) or 'none'}", line=1)
    table = responses.copy().reset_index(drop=True)
    if lines is not None:
        table["line"] = list(lines)
    elif "line" not in table.columns:  # a table from load_human_data keeps its CSV lines
        table["line"] = np.arange(len(table)) + 2
    for column in ("dataset", "participant", "trial"):
        table[column] = table[column].map(lambda v: "" if _is_missing(v) else str(v).strip())
    table["trial"] = table["trial"].map(canonical_trial_id)  # "1e" is 1E, as on every command line

    allowed = set(DATASETS) | ({SIMULATED_PREFIX + d for d in DATASETS} if allow_simulated else set())
    problems: list[tuple[int, str]] = []
    values = np.full(len(table), np.nan)
    for k, (line, dataset, participant, trial, response) in enumerate(
        zip(table["line"], table["dataset"], table["participant"], table["trial"], table["response"])
    ):
        if dataset not in allowed:
            hint = (" (simulated participants are not human data; pass allow_simulated=True "
                    "only in tests)" if is_simulated_dataset(dataset) else "")
            problems.append((line, f"unknown dataset {dataset!r}; expected one of "
                                   f"{', '.join(sorted(allowed))}{hint}"))
        if participant == "":
            problems.append((line, "empty participant id"))
        if trial not in TRIAL_IDS:
            problems.append((line, f"unknown trial id {trial!r}; expected 1E, 1H, ..., 12H"))
        value = _parse_response(response)
        if isinstance(value, str):
            problems.append((line, value))
        else:
            values[k] = value
    _raise_if(problems, source)
    table["response"] = values

    duplicated = table.duplicated(["dataset", "participant", "trial"], keep=False)
    for _, group in table[duplicated].groupby(["dataset", "participant", "trial"], sort=False):
        first, *others = group["line"].tolist()
        for line in others:
            d, p, t = group.iloc[0][["dataset", "participant", "trial"]]
            problems.append((line, f"duplicate response of participant {p!r} in dataset {d!r} "
                                   f"to trial {t} (first given on line {first})"))
    _raise_if(problems, source)

    for (dataset, participant), group in table.groupby(["dataset", "participant"], sort=False):
        absent = [t for t in TRIAL_IDS if t not in set(group["trial"])]
        if absent:
            line_list = group["line"].tolist()
            problems.append((min(line_list), f"participant {participant!r} in dataset {dataset!r} "
                                             f"(rows on lines {_line_ranges(line_list)}) is missing "
                                             f"trial(s) {', '.join(absent)}"))
    _raise_if(problems, source)
    return table


def exclude_constant_participants(responses: pd.DataFrame) -> tuple[pd.DataFrame, pd.DataFrame]:
    """Drop participants who gave the identical response on every trial.

    The paper excluded two participants for this (Participants section); their
    z-scores are undefined anyway (zero SD). Returns ``(kept, excluded)`` where
    `excluded` has one row per dropped participant: dataset, participant,
    n_trials, response (the repeated value), reason.
    """
    spread = responses.groupby(["dataset", "participant"], sort=False)["response"].agg(
        n_trials="size", response="first", spread=lambda r: r.max() - r.min())
    constant = spread[spread["spread"] == 0].reset_index()
    excluded = constant[["dataset", "participant", "n_trials", "response"]].assign(
        reason="identical response on all trials")
    keys = set(zip(constant["dataset"], constant["participant"]))
    mask = [(d, p) not in keys for d, p in zip(responses["dataset"], responses["participant"])]
    return responses[mask].reset_index(drop=True), excluded.reset_index(drop=True)


def zscore_responses(responses: pd.DataFrame, ddof: int = 0) -> pd.DataFrame:
    """Z-score each participant's responses within their dataset.

    z = (response - participant mean) / participant SD over that participant's
    24 trials. The default ``ddof=0`` is the population SD (as
    ``scipy.stats.zscore``), so each participant's z-scores have mean 0 and root
    mean square 1; ``ddof=1`` (sample SD, as R's ``scale``) multiplies every z by
    sqrt(23/24), which changes no correlation, ordering or sigma choice, only
    the scale of betas and RMSE. The paper does not say which it used.

    Returns a copy of `responses` with a column ``z``. Raises ValueError naming
    the participant if their SD is zero (drop them first with
    `exclude_constant_participants`).
    """
    grouped = responses.groupby(["dataset", "participant"], sort=False)["response"]
    mean = grouped.transform("mean")
    sd = grouped.transform("std", ddof=ddof)
    # max == min rather than sd == 0: the SD of identical floats can round to 1e-17.
    constant = grouped.transform("max") == grouped.transform("min")
    flat = responses.loc[constant, ["dataset", "participant"]].drop_duplicates()
    if len(flat):
        d, p = flat.iloc[0]
        raise ValueError(f"participant {p!r} in dataset {d!r} gave the same response on every "
                         "trial, so their z-scores are undefined; use exclude_constant_participants")
    return responses.assign(z=(responses["response"] - mean) / sd)


def participant_matrices(zscored: pd.DataFrame) -> dict[str, tuple[list[str], np.ndarray]]:
    """Per dataset (in `ordered_datasets` order): participant ids and their z-scores as an
    (n_participants, 24) array, columns in TRIAL_IDS order."""
    out = {}
    for dataset in ordered_datasets(zscored["dataset"].unique()):
        wide = zscored[zscored["dataset"] == dataset].pivot(
            index="participant", columns="trial", values="z")
        wide = wide.reindex(columns=list(TRIAL_IDS))
        if wide.isna().any().any():
            raise ValueError(f"dataset {dataset!r}: some participants lack z-scores for some "
                             "trials; validate the data with validate_human_data first")
        out[dataset] = (list(wide.index), wide.to_numpy(dtype=float))
    return out


def trial_means(zscored: pd.DataFrame) -> pd.DataFrame:
    """Mean z-scored response per dataset and trial: columns dataset, trial,
    mean_z, n_participants (trials in TRIAL_IDS order)."""
    rows = []
    for dataset, (participants, Z) in participant_matrices(zscored).items():
        for trial, m in zip(TRIAL_IDS, Z.mean(axis=0)):
            rows.append((dataset, trial, m, len(participants)))
    return pd.DataFrame(rows, columns=["dataset", "trial", "mean_z", "n_participants"])


def resample_trial_means(zscored: pd.DataFrame, n_boot: int, rng: np.random.Generator
                         ) -> dict[str, np.ndarray]:
    """Bootstrap trial means by resampling participants with replacement.

    For each dataset in `ordered_datasets` order, draws ``rng.integers(0, n, size=(n_boot, n))``
    (n = participants in that dataset, indexed in sorted participant-id order)
    and averages the resampled participants' z-scores. Returns {dataset: array (n_boot, 24)}, columns in TRIAL_IDS order.
    """
    out = {}
    for dataset, (_, Z) in participant_matrices(zscored).items():
        n = Z.shape[0]
        idx = rng.integers(0, n, size=(n_boot, n))
        out[dataset] = Z[idx].mean(axis=1)
    return out


def trial_mean_intervals(zscored: pd.DataFrame, boot_means: Mapping[str, np.ndarray],
                         level: float = 0.95) -> pd.DataFrame:
    """Trial means with percentile bootstrap intervals.

    Columns dataset, trial, mean_z (full-sample mean), ci_low, ci_high (the
    (1-level)/2 and (1+level)/2 percentiles of the bootstrap means, numpy's linear
    interpolation), n_participants, n_boot.
    """
    means = trial_means(zscored)
    tail = 100 * (1 - level) / 2
    lows, highs, nboot = [], [], []
    for dataset in means["dataset"].unique():
        boot = boot_means[dataset]
        lows.append(np.percentile(boot, tail, axis=0))
        highs.append(np.percentile(boot, 100 - tail, axis=0))
        nboot.append(np.full(len(TRIAL_IDS), boot.shape[0]))
    return means.assign(ci_low=np.concatenate(lows), ci_high=np.concatenate(highs),
                        n_boot=np.concatenate(nboot))


def bootstrap_trial_means(zscored: pd.DataFrame, n_boot: int, rng: np.random.Generator,
                          level: float = 0.95) -> pd.DataFrame:
    """Trial means with 95% participant-bootstrap intervals in one call
    (`resample_trial_means` then `trial_mean_intervals`)."""
    return trial_mean_intervals(zscored, resample_trial_means(zscored, n_boot, rng), level)


def _is_missing(value) -> bool:
    return value is None or (isinstance(value, float) and math.isnan(value))


def _parse_response(raw) -> float | str:
    """The response as a finite float, or a message saying why it is not one."""
    if isinstance(raw, (int, float, np.integer, np.floating)) and not isinstance(raw, bool):
        value = float(raw)
        text = repr(raw)
    else:
        text = "" if _is_missing(raw) else str(raw).strip()
        if text == "":
            return "empty response (expected a number)"
        try:
            value = float(text)
        except ValueError:
            return f"non-numeric response {text!r}"
    if not math.isfinite(value):
        return f"non-finite response {text!r} (expected a finite number)"
    return value


def _raise_if(problems: list[tuple[int, str]], source: str) -> None:
    if not problems:
        return
    problems.sort(key=lambda p: p[0])
    listed = [f"{source}: line {line}: {msg}" for line, msg in problems]
    message = "\n".join(listed[:_MAX_LISTED])
    if len(listed) > _MAX_LISTED:
        message += f"\n... and {len(listed) - _MAX_LISTED} more problem(s)"
    raise HumanDataError(message, line=problems[0][0], problems=listed)


def _line_ranges(lines: list[int]) -> str:
    """[2, 3, 4, 7] -> '2-4, 7'."""
    lines = sorted(lines)
    spans, start, prev = [], lines[0], lines[0]
    for line in lines[1:] + [None]:
        if line is not None and line == prev + 1:
            prev = line
            continue
        spans.append(f"{start}" if start == prev else f"{start}-{prev}")
        if line is not None:
            start = prev = line
    return ", ".join(spans)
