"""Reading and validating a tidy human-response CSV (docs/human-data.md): the bounded,
encoding-aware read, one vectorised test per rule, and messages that name the CSV
line and the rule broken (`load_human_data`, `validate_human_data`)."""
from __future__ import annotations

import codecs
import csv
import io
import math
import re
from pathlib import Path
from typing import Iterable

import numpy as np
import pandas as pd

from analysis.data.datasets import DATASETS, REQUIRED_COLUMNS, SIMULATED_PREFIX, HumanDataError, is_simulated_dataset
from analysis.data.trialset import trial_ids
from lgp.paper import TRIAL_IDS

#: Problems listed in one HumanDataError message before "... and N more".
_MAX_LISTED = 20
#: Most participants (all datasets together) a human-data file may hold unless the
#: caller raises it (``--max-participants``): memory grows with participants x
#: bootstrap resamples (bench/human_data.py measures the largest accepted file).
MAX_PARTICIPANTS = 5_000
#: Bytes a human-data file may have per allowed participant (24 rows of up to
#: 200 bytes): the file is read through the bounded reader, at most this many bytes.
BYTES_PER_PARTICIPANT = 24 * 200
#: Most characters one CSV field (cell) may hold, in human data and in the study
#: CSVs `analysis.import_study` reads: ids, responses and notes are short; a longer
#: field is a damaged or hostile file (Python's csv module stops at 131072 itself).
MAX_FIELD_CHARS = 10_000


def load_human_data(path: str | Path, *, allow_simulated: bool = False,
                    max_participants: int = MAX_PARTICIPANTS) -> pd.DataFrame:
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

    A file with more than `max_participants` participants, or more than
    `max_participants` x BYTES_PER_PARTICIPANT bytes, is refused in one line
    (never read past that many bytes); so is anything but a regular file (a
    FIFO, a device, a dangling symbolic link).
    """
    path = Path(path)
    max_participants = int(max_participants)
    text = _read_text(path, max_participants * BYTES_PER_PARTICIPANT)
    try:
        records = csv_records(text, str(path))
    except CsvShapeError as e:
        raise HumanDataError(str(e), line=e.line) from None
    if not records:
        raise HumanDataError(f"{path}: line 1: empty file, expected a header with "
                             f"columns {', '.join(REQUIRED_COLUMNS)}", line=1)
    header = records[0][1]
    rows, lines = [], []
    for line_num, record in records[1:]:
        if all(not field.strip() for field in record):
            continue  # blank line
        # Short rows are padded so the missing field fails its own check below.
        record = record + [""] * (len(header) - len(record))
        rows.append(record[: len(header)])
        lines.append(line_num)
    missing = [c for c in REQUIRED_COLUMNS if c not in header]
    if missing:
        raise HumanDataError(f"{path}: line 1 (header): missing column(s) {', '.join(missing)}; "
                             f"found {', '.join(header) or 'none'}", line=1)
    if not rows:
        raise HumanDataError(f"{path}: line 1 (header): no responses after the header; expected one row "
                             f"per (dataset, participant, trial)", line=1)
    i_d, i_p = header.index("dataset"), header.index("participant")
    people = len({(r[i_d].strip(), r[i_p].strip()) for r in rows})
    if people > max_participants:
        raise HumanDataError(f"{path}: {people} participants, more than the {max_participants} allowed "
                             "(--max-participants raises the limit; memory grows with participants x bootstrap "
                             "resamples, docs/human-data.md)", line=None)
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
        col = table[column]
        table[column] = col.where(col.notna(), "").astype(str).str.strip()
    table["trial"] = table["trial"].str.upper()  # "1e" is 1E: lgp.paper.canonical_trial_id, as on every command line
    if len(table) == 0:
        raise HumanDataError(f"{source}: no responses; expected one row per (dataset, participant, trial)", line=1)

    # One vectorised test per rule; messages only for the rows that break it. A
    # stable sort by line in _raise_if keeps each line's problems in rule order.
    allowed = set(DATASETS) | ({SIMULATED_PREFIX + d for d in DATASETS} if allow_simulated else set())
    line = table["line"].to_numpy()
    problems: list[tuple[int, str]] = []
    for k in np.flatnonzero(~table["dataset"].isin(allowed).to_numpy()):
        dataset = table["dataset"].iat[k]
        hint = (" (simulated participants are not human data; pass allow_simulated=True "
                "only in tests)" if is_simulated_dataset(dataset) else "")
        problems.append((line[k], f"unknown dataset {dataset!r}; expected one of "
                                  f"{', '.join(sorted(allowed))}{hint}"))
    for k in np.flatnonzero((table["participant"] == "").to_numpy()):
        problems.append((line[k], "empty participant id"))
    for k in np.flatnonzero(~table["trial"].isin(trial_ids()).to_numpy()):
        problems.append((line[k], f"unknown trial id {table['trial'].iat[k]!r}; expected one of the run's trials "
                                  f"{_trial_list()}"))
    values, bad = _parse_responses(table["response"])
    problems += [(line[k], message) for k, message in bad]
    problems.sort(key=lambda p: p[0])  # stable: rule order within a line
    _raise_if(problems, source)
    table["response"] = values

    keys = ["dataset", "participant", "trial"]
    duplicated = table.duplicated(keys, keep=False)
    for _, group in table[duplicated].groupby(keys, sort=False):
        first, *others = group["line"].tolist()
        for line_k in others:
            d, p, t = group.iloc[0][keys]
            problems.append((line_k, f"duplicate response of participant {p!r} in dataset {d!r} "
                                     f"to trial {t} (first given on line {first})"))
    _raise_if(problems, source)

    # Trials are known and unique per participant now, so fewer than 24 rows means
    # some are missing; only those participants are looked at one by one.
    by_participant = table.groupby(["dataset", "participant"], sort=False)
    sizes = by_participant["trial"].transform("size")
    for (dataset, participant), group in table[sizes < len(trial_ids())].groupby(["dataset", "participant"], sort=False):
        answered = set(group["trial"])
        absent = [t for t in trial_ids() if t not in answered]
        line_list = group["line"].tolist()
        problems.append((min(line_list), f"participant {participant!r} in dataset {dataset!r} "
                                         f"(rows on lines {line_ranges(line_list)}) is missing "
                                         f"trial(s) {', '.join(absent)}"))
    _raise_if(problems, source)
    problems += _unscalable(table)
    _raise_if(problems, source)
    _raise_if(_nobody_left(table), source)
    return table


def _trial_list() -> str:
    """The trial set, short: '1E, 1H, ..., 12H' for the paper's, else every id."""
    ids = trial_ids()
    return f"{ids[0]}, {ids[1]}, ..., {ids[-1]}" if ids == tuple(TRIAL_IDS) else ", ".join(ids)


def _nobody_left(table: pd.DataFrame) -> list[tuple[int, str]]:
    """Datasets in which no participant can be z-scored: every one gave one
    response on all trials (the paper's exclusion drops them all), or their
    responses differ by so little that the SD underflows to 0 (tiny numbers such
    as 1e-310). Such a dataset leaves nothing to fit, so it is refused here,
    before any work, naming the rule."""
    out = []
    keys = [table["dataset"], table["participant"]]
    r = table["response"]
    with np.errstate(all="ignore"):
        g = r.groupby(keys, sort=False)
        stats = pd.DataFrame({"spread": g.max() - g.min(), "sd": g.std(ddof=0), "biggest": r.abs().groupby(keys, sort=False).max()})
    stats["first_line"] = table["line"].groupby(keys, sort=False).min()
    for dataset, group in stats.groupby(level=0, sort=False):
        constant = group["spread"] == 0
        underflow = ~constant & ~(group["sd"] > 0)
        if len(group) and (constant | underflow).all():
            line = int(group["first_line"].min())
            if underflow.any():
                out.append((line, f"dataset {dataset!r}: no participant can be z-scored: {int(constant.sum())} gave the "
                                  f"same response on every trial and {int(underflow.sum())} gave responses so close to 0 "
                                  f"(largest |response| {group.loc[underflow, 'biggest'].max():.3g}) that their SD "
                                  "underflows to 0; rescale the responses"))
            else:
                out.append((line, f"dataset {dataset!r}: every one of its {len(group)} participant(s) gave the same "
                                  "response on every trial, so all are excluded (as in the paper) and none is left "
                                  "to fit"))
    # one participant with an underflowing SD among good ones would break z-scoring later: name them now
    for (dataset, participant), row in stats.iterrows():
        if row["spread"] != 0 and not row["sd"] > 0 and not any(m.startswith(f"dataset {dataset!r}") for _, m in out):
            out.append((int(row["first_line"]), f"participant {participant!r} in dataset {dataset!r}: responses so close to 0 "
                                                f"(largest |response| {row['biggest']:.3g}) that their SD underflows to 0: "
                                                "responses too small to z-score; rescale them"))
    return out


def _unscalable(table: pd.DataFrame) -> list[tuple[int, str]]:
    """Participants whose responses cannot be z-scored in floating point: mean or
    SD overflow (a response of 1e308), as (first line, message)."""
    keys = [table["dataset"], table["participant"]]
    with np.errstate(over="ignore", invalid="ignore"):
        grouped = table["response"].groupby(keys, sort=False)
        stats = pd.DataFrame({"mean": grouped.mean(), "sd": grouped.std(ddof=0),
                              "biggest": table["response"].abs().groupby(keys, sort=False).max()})
    broken = stats[~(np.isfinite(stats["mean"]) & np.isfinite(stats["sd"]))]
    out = []
    for (dataset, participant), row in broken.iterrows():
        line_list = table.loc[(table["dataset"] == dataset) & (table["participant"] == participant), "line"].tolist()
        out.append((min(line_list), f"participant {participant!r} in dataset {dataset!r} (rows on lines "
                                    f"{line_ranges(line_list)}): responses too large to z-score (largest "
                                    f"|response| {row['biggest']:.3g}; the mean or SD overflows)"))
    return out


def _is_missing(value) -> bool:
    return value is None or (isinstance(value, float) and math.isnan(value))


#: A number as a CSV cell writes it: optional sign, ASCII digits with an optional
#: decimal point, optional exponent. Stricter than Python's float(), which also
#: takes ``1_000`` and non-ASCII digits (``١٧``, ``１７``).
_NUMBER = re.compile(r"[+-]?(?:[0-9]+\.?[0-9]*|\.[0-9]+)(?:[eE][+-]?[0-9]+)?")
_NON_FINITE = {"inf", "infinity", "nan"}


def parse_response(raw) -> float | str:
    """The response as a finite float, or a message saying why it is not one: the
    one number parser of human data (``--human-data``) and of the study CSVs
    `analysis.import_study` reads. Refuses ``1_70`` (digit separators), non-ASCII
    digits, text, ``inf``/``nan`` and numbers beyond the float range (a 5000-digit
    integer)."""
    if isinstance(raw, (int, float, np.integer, np.floating)) and not isinstance(raw, bool):
        value = float(raw)
        text = repr(raw)
    else:
        text = "" if _is_missing(raw) else str(raw).strip()
        if text == "":
            return "empty response (expected a number)"
        if _NUMBER.fullmatch(text) or text.lower().lstrip("+-") in _NON_FINITE:
            value = float(text)
        elif "_" in text and _NUMBER.fullmatch(text.replace("_", "")):
            return f"non-numeric response {_short(text)} (a CSV number has no '_' digit separators)"
        elif any(ch.isdigit() and not ch.isascii() for ch in text):
            return f"non-numeric response {_short(text)} (a CSV number is written in the ASCII digits 0-9)"
        else:
            return f"non-numeric response {_short(text)}"
    if not math.isfinite(value):
        if len(text) > 40:
            return f"response {_short(text)} is beyond the range of a float (about 1.8e308)"
        return f"non-finite response {text!r} (expected a finite number)"
    return value


def _short(text: str, n: int = 40) -> str:
    """repr of `text`, cut to about `n` characters (a 200 kB cell stays one line)."""
    return repr(text) if len(text) <= n else repr(text[:n]) + f"... ({len(text)} characters)"


class CsvShapeError(ValueError):
    """A CSV whose shape breaks a rule before any cell is looked at: a field
    longer than MAX_FIELD_CHARS, a column named twice, broken quoting. ``line``
    is the line of the problem."""

    def __init__(self, message: str, line: int):
        super().__init__(message)
        self.line = line


def csv_records(text: str, source: str, max_field: int = MAX_FIELD_CHARS) -> list[tuple[int, list[str]]]:
    """[(line, fields)] of CSV `text`, the header first (its names stripped); empty
    records left out. Raises CsvShapeError naming `source` and the line for a
    field longer than `max_field` characters, a header that names a column twice
    (which of the two would be the response?) or broken quoting. The one CSV
    reader of human data and of `analysis.import_study`."""
    reader = csv.reader(io.StringIO(text, newline=""))
    out: list[tuple[int, list[str]]] = []
    try:
        for record in reader:
            if not record:
                continue
            if max(map(len, record)) > max_field:
                k = max(range(len(record)), key=lambda i: len(record[i]))
                raise CsvShapeError(f"{source}: line {reader.line_num}: field {k + 1} holds {len(record[k])} characters, "
                                    f"more than the {max_field} allowed in one field (MAX_FIELD_CHARS)", reader.line_num)
            out.append((reader.line_num, record))
    except csv.Error as e:
        line = reader.line_num
        if "field larger than field limit" in str(e):
            raise CsvShapeError(f"{source}: line {line}: a field longer than the {max_field} characters allowed "
                                "in one field (MAX_FIELD_CHARS)", line) from None
        raise CsvShapeError(f"{source}: line {line}: broken CSV ({e}): the file is truncated or damaged", line) from None
    if out:
        header = [name.strip() for name in out[0][1]]
        out[0] = (out[0][0], header)
        seen: dict[str, int] = {}
        for k, name in enumerate(header, start=1):
            if name in seen and name:
                raise CsvShapeError(f"{source}: line {out[0][0]} (header): column {name!r} given twice (columns "
                                    f"{seen[name]} and {k}); each column once", out[0][0])
            seen.setdefault(name, k)
    return out


def _parse_responses(raw: pd.Series) -> tuple[np.ndarray, list[tuple[int, str]]]:
    """Vectorised `parse_response` over a column: (floats, [(row, message)] for
    the rows that are not finite numbers). Plain number cells are converted in
    one pass; only the others go through `parse_response` one by one."""
    values = np.full(len(raw), np.nan)
    if pd.api.types.is_numeric_dtype(raw) and not pd.api.types.is_bool_dtype(raw):
        with np.errstate(invalid="ignore"):
            values[:] = raw.to_numpy(dtype=float)
        ok = np.isfinite(values)
    else:
        cells = raw.to_numpy(dtype=object)
        text = pd.Series(cells, dtype=object).str.strip()  # NaN where a cell is not a string
        ok = np.array(text.str.fullmatch(_NUMBER.pattern).fillna(False), dtype=bool)
        with np.errstate(over="ignore"):
            values[ok] = text[ok].to_numpy(dtype=object).astype(float)
        ok &= np.isfinite(values)
    bad = []
    for k in np.flatnonzero(~ok):
        parsed = parse_response(raw.iat[k])
        if isinstance(parsed, str):
            bad.append((k, parsed))
        else:
            values[k] = parsed
    return values, bad


def _read_text(path: Path, max_bytes: int = MAX_PARTICIPANTS * BYTES_PER_PARTICIPANT) -> str:
    """The file's text: UTF-8 (with or without BOM), or UTF-16/32 when a byte-order
    mark says so; anything else raises HumanDataError naming file, line and encoding.
    Read through the bounded reader (lgp.inputs): a regular file of at most `max_bytes`."""
    from lgp.inputs import InputFileError, read_bounded

    try:
        data = read_bounded(path, max_bytes, "human-data file",
                            limit_name=f"room for {max_bytes // BYTES_PER_PARTICIPANT} participants; --max-participants raises it")
    except InputFileError as e:
        raise HumanDataError(str(e), line=None) from None
    for bom, encoding in ((codecs.BOM_UTF32_LE, "utf-32"), (codecs.BOM_UTF32_BE, "utf-32"),
                          (codecs.BOM_UTF8, "utf-8-sig"), (codecs.BOM_UTF16_LE, "utf-16"),
                          (codecs.BOM_UTF16_BE, "utf-16")):
        if data.startswith(bom):
            break
    else:
        encoding = "utf-8"
        if b"\x00" in data:  # no CSV text holds NUL; UTF-16/32 text of ASCII is full of them
            line = data[: data.index(b"\x00")].count(b"\n") + 1
            raise HumanDataError(f"{path}: line {line}: not UTF-8 text (NUL bytes: UTF-16 or UTF-32 without a "
                                 "byte-order mark?); save the file as UTF-8", line=line)
    try:
        return data.decode(encoding)
    except UnicodeDecodeError as e:
        line = data[: e.start].count(b"\n") + 1 if encoding == "utf-8" else None
        where = f"line {line}" if line else "file"
        raise HumanDataError(f"{path}: {where}: not {encoding.upper().replace('-SIG', '')} text (byte "
                             f"0x{data[e.start]:02x} at offset {e.start}); save the file as UTF-8 (a "
                             "UTF-16 or UTF-32 file needs its byte-order mark)", line=line) from None


def _raise_if(problems: list[tuple[int, str]], source: str) -> None:
    if not problems:
        return
    problems.sort(key=lambda p: p[0])
    listed = [f"{source}: line {line}: {msg}" for line, msg in problems]
    message = "\n".join(listed[:_MAX_LISTED])
    if len(listed) > _MAX_LISTED:
        message += f"\n... and {len(listed) - _MAX_LISTED} more problem(s)"
    raise HumanDataError(message, line=problems[0][0], problems=listed)


def line_ranges(lines: list[int]) -> str:
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
