"""The trial set the analysis runs on: the paper's 24 (lgp.paper.TRIAL_IDS) unless
a caller says otherwise with `using_trials` (lgp.reproduce --stimuli DIR with
--human-data: the run's own trials). Every analysis function that lays trials out
reads `trial_ids()`; pair tables, pair-based tests and leave-one-pair-out folds
read `pair_numbers()`, the pairs n whose nE and nH are both in the set (none for a
set such as stimuli.generate's G0001 ...)."""
from __future__ import annotations

import contextvars
import re
from contextlib import contextmanager
from typing import Iterable, Iterator

from lgp.errors import InputError
from lgp.paper import TRIAL_IDS

_TRIALS: contextvars.ContextVar[tuple[str, ...]] = contextvars.ContextVar("analysis_trials", default=tuple(TRIAL_IDS))


def trial_ids() -> tuple[str, ...]:
    """The trial ids of the analysis, in order (default the paper's 24)."""
    return _TRIALS.get()


def pair_numbers(trials: Iterable[str] | None = None) -> tuple[int, ...]:
    """Numbers n of the pairs whose easy (nE) and hard (nH) trial are both in
    `trials` (default `trial_ids()`), in order of first appearance."""
    ids = list(trial_ids() if trials is None else trials)
    have, out = set(ids), []
    for t in ids:
        m = re.fullmatch(r"(\d+)[EH]", str(t))
        if m and int(m.group(1)) not in out and f"{m.group(1)}E" in have and f"{m.group(1)}H" in have:
            out.append(int(m.group(1)))
    return tuple(out)


def is_paper_set() -> bool:
    return trial_ids() == tuple(TRIAL_IDS)


@contextmanager
def using_trials(ids: Iterable[str]) -> Iterator[tuple[str, ...]]:
    """Within the block, the analysis runs on trials `ids` (upper-cased, distinct)."""
    ids = tuple(str(t).strip().upper() for t in ids)
    if len(set(ids)) != len(ids) or not ids:
        raise InputError(f"trial set must be distinct, non-empty ids, got {', '.join(ids) or 'none'}")
    token = _TRIALS.set(ids)
    try:
        yield ids
    finally:
        _TRIALS.reset(token)
