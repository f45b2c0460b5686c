"""The 24 construction trials of the paper (Figure 1) as data files, and their loader.

Each trial is a YAML file in ``stimuli/trials/`` (format: ``stimuli/README.md``).
``load_trial("7H")`` returns a validated :class:`Trial`; ``load_paper()`` the paper's
24 trials (lgp.paper.TRIAL_IDS) in order 1E, 1H, ..., 12H; ``load_all()`` those plus
any extra trial file a user drops in (sorted after). Every loader takes a
``directory`` (default ``stimuli/trials``) to read another set of trial files.
"""
from __future__ import annotations

import errno
import hashlib
import os
from dataclasses import replace
from pathlib import Path

import yaml

from lgp.paper import TRIAL_IDS, canonical_trial_id
from lgp.scene import StimulusError
from stimuli.reading import (MAX_TRIAL_BYTES, safe_load_yaml, read_trial_bytes,  # noqa: F401
                             yaml_error_line)
from stimuli.start import (MAX_REGION_EXTENT, SCATTER_SECONDS, ScatterRegion, StartState,  # noqa: F401
                           room_check)
from stimuli.trial import FREE_ID, TRIAL_ID, Trial, parse_trial  # noqa: F401

TRIAL_DIR = Path(__file__).parent / "trials"


def load_file(path: str | Path, data: bytes | None = None) -> Trial:
    """Read, parse and validate one trial file (at most MAX_TRIAL_BYTES; `data`:
    its bytes, already read)."""
    path = Path(path)
    data = read_trial_bytes(path) if data is None else data
    try:
        text = data.decode("utf-8")
    except UnicodeDecodeError as e:
        raise StimulusError(f"{path}: cannot read the trial file as UTF-8 text ({e})") from None
    try:
        fields = safe_load_yaml(text, str(path))
    except yaml.YAMLError as e:
        raise StimulusError(f"{path}: {yaml_error_line(e)}") from None
    if not isinstance(fields, dict):
        raise StimulusError(f"{path}: a trial file is a mapping of fields (id, pair, level, initial, target, ...), got {type(fields).__name__}")
    trial = parse_trial(fields, path)
    return replace(trial, sha256=hashlib.sha256(data).hexdigest())


def _sort_key(tid: str):
    m = TRIAL_ID.match(tid)
    return (int(m.group(1)), m.group(2)) if m else (10**6, tid)


def trial_ids(directory: str | Path | None = None) -> list[str]:
    """Ids of every trial file in `directory` (default ``stimuli/trials``), in order."""
    directory = TRIAL_DIR if directory is None else Path(directory)
    return sorted((p.stem for p in directory.glob("*.yaml")), key=_sort_key)


_cache: dict[tuple[str, str], Trial] = {}


def load_trial(trial_id: str, directory: str | Path | None = None) -> Trial:
    """The trial ``trial_id`` (e.g. ``"7H"``; case-insensitive, ``"7h"`` too) from `directory` (default
    ``stimuli/trials``), validated."""
    directory = TRIAL_DIR if directory is None else Path(directory)
    trial_id = canonical_trial_id(trial_id)
    path = directory / f"{trial_id}.yaml"
    if not path.exists():
        if path.is_symlink():
            try:
                os.stat(path)
            except OSError as e:
                if e.errno == errno.ELOOP:
                    raise StimulusError(f"no trial {trial_id!r}: {path} is a loop of symbolic links (it leads back "
                                        f"to itself through {os.readlink(path)})") from None
            raise StimulusError(f"no trial {trial_id!r}: {path} is a symbolic link to {os.readlink(path)}, which does not exist")
        misnamed = [p.name for p in directory.glob("*.yaml") if p.stem.upper() == trial_id and p.stem != trial_id]
        if misnamed:
            raise StimulusError(f"no trial {trial_id!r}: {directory} has {misnamed[0]}, but a trial file is named by its "
                                f"id in upper case: rename it {trial_id}.yaml")
        raise StimulusError(f"no trial {trial_id!r}: {path} does not exist (known: {', '.join(trial_ids(directory))})")
    data = read_trial_bytes(path)
    key = (str(path), hashlib.sha256(data).hexdigest())
    if key not in _cache:
        trial = load_file(path, data)
        if trial.id != trial_id:
            raise StimulusError(f"{path}: file name says {trial_id} but the id field says {trial.id}")
        _cache[key] = trial
    return _cache[key]


def load_all(directory: str | Path | None = None) -> list[Trial]:
    """Every trial in `directory`: 1E, 1H, ..., 12H, then any others (e.g. a
    user's 13E). The paper's set alone is `load_paper`."""
    return [load_trial(t, directory) for t in trial_ids(directory)]


def load_paper(directory: str | Path | None = None) -> list[Trial]:
    """The paper's 24 trials (lgp.paper.TRIAL_IDS, in the paper's order) from
    `directory`, ignoring any other trial file there."""
    return [load_trial(t, directory) for t in TRIAL_IDS]


def extra_ids(directory: str | Path | None = None) -> list[str]:
    """Ids of the trial files in `directory` that are not among the paper's 24."""
    return [t for t in trial_ids(directory) if t not in TRIAL_IDS]


def select_trials(ids: list[str] | None = None, directory: str | Path | None = None) -> tuple[list[Trial], list[str]]:
    """The trials of a run and the ids of the trial files it leaves out.

    With no `ids`: the paper's 24 from the default folder (the other trial files
    there are left out and returned, for the caller to name), or every trial file
    of `directory` when one is given. ``["all"]``: every trial file. Otherwise the
    trials named. Raises StimulusError for a `directory` with no trial files.
    """
    if not ids and directory is not None:  # a user's stimulus set: every trial file in it
        if not trial_ids(directory):
            raise StimulusError(f"--stimuli {directory}: no trial files (*.yaml) there")
        return load_all(directory), []
    if not ids:
        return load_paper(directory), extra_ids(directory)
    if [t.lower() for t in ids] == ["all"]:
        return load_all(directory), []
    return [load_trial(t, directory) for t in ids], []


def declared_pairs(trials) -> list[int]:
    """The pairs whose easy and hard trials (ids ``<pair>E``, ``<pair>H``) are both among `trials`."""
    ids = {t.id for t in trials}
    return sorted({t.pair for t in trials if t.pair is not None and {f"{t.pair}E", f"{t.pair}H"} <= ids})
