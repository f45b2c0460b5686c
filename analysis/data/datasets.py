"""The names of the human-data format: the paper's datasets, the prefix that marks
simulated participants, the required columns, their order, and the error a table
that breaks a rule of the format raises (`HumanDataError`)."""
from __future__ import annotations

from typing import Iterable

import pandas as pd

#: The paper's three datasets: Difficulty Estimation, Time Estimation, Build Task.
DATASETS: tuple[str, ...] = ("difficulty", "time", "build")
#: Dataset names of simulated participants carry this prefix (e.g. ``simulated-time``)
#: in every table, file and figure made from them.
SIMULATED_PREFIX = "simulated-"
#: Columns a human-data CSV must have.
REQUIRED_COLUMNS: tuple[str, ...] = ("dataset", "participant", "trial", "response")


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


class StudyDataError(ValueError):
    """A study's downloaded CSV cannot be imported (`analysis.import_study`); the
    message names the file and line of each problem. Defined here, not in the
    importer, so that the class is the project's (one line, exit 1) even when the
    importer runs as ``python -m analysis.import_study`` (its module is __main__)."""

    def __init__(self, problems: list[str]):
        super().__init__("\n".join(problems))
        self.problems = tuple(problems)


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
