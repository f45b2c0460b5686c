"""From the CSVs a study downloads to the human-data format the analysis reads.

    python -m analysis.import_study FILES... --out human.csv [--study DIR]

FILES are the CSVs of `python -m stimuli.experiment` studies (one per participant
and session, any of the three tasks: difficulty, time, build; docs/experiment.md).
The output has the columns of docs/human-data.md (dataset, participant, trial,
response) plus study, position, condition, first_in_pair, rt_ms, collapses and
source (file:line), one row per response to the study's trials (the paper's 24,
or with --study DIR the trials its study.json lists: a study built with
``stimuli.experiment --stimuli DIR`` from a designed or generated set); the anchor
trials are left out. Then ``python -m lgp.reproduce --human-data human.csv`` (with
``--stimuli DIR`` for a study of other trials) runs the paper's analysis on it.

Refused, naming the file and line, before anything is written: a file that is not
a study's CSV, a file of another study (another stimulus set, layout or order seed
than the first file's, or than --study DIR's study.json), a participant of a task
who appears twice (in two files or twice in one), a trial id outside the study's
trials (the 24 without --study), a truncated file (a row cut short, or a
participant with fewer trials than the study has), a non-numeric response (the one number parser of ``--human-data``:
``1_70`` and non-ASCII digits are refused in both), and SIMULATED rows mixed with
real ones. Rows of simulated participants (tests only) become datasets
``simulated-<task>``.

Every input is read through the project's bounded reader (lgp.inputs): a FIFO, a
device such as /dev/zero, a directory or a file larger than MAX_FILE_BYTES
(study.json: MAX_STUDY_JSON_BYTES; all files together: MAX_TOTAL_BYTES) is
refused in one line naming the limit, before it is read; so is a field longer
than MAX_FIELD_CHARS or a column named twice. The output is written by the
project's one writer (lgp.atomic): a unique temporary name renamed over --out (two
imports to one --out leave one whole file), no cell a spreadsheet would run as a
formula (``=HYPERLINK(...)``, ``@SUM(...)``, a file named ``=1+2.csv`` in
``source``), and on a full disk an error naming the file with no partial file left.
"""
from __future__ import annotations

import json
import sys
from dataclasses import dataclass
from pathlib import Path

from analysis.data.datasets import StudyDataError  # noqa: F401  (defined beside HumanDataError, not in __main__)
from analysis.data.trialset import using_trials
from analysis.data.validation import MAX_FIELD_CHARS, CsvShapeError, csv_records, parse_response
from lgp import cli
from lgp.inputs import InputFileError, read_bounded
from lgp.paper import TRIAL_IDS

PROG = "python -m analysis.import_study"
#: Columns every study CSV has (stimuli.experiment.COLUMNS; the others are optional here).
REQUIRED = ("study", "task", "participant", "simulated", "condition", "phase", "position", "trial", "response",
            "rt_ms", "n_trials")
TASKS = ("difficulty", "time", "build")
#: Columns of the output, after the four of the human-data format.
EXTRA = ("study", "position", "condition", "first_in_pair", "rt_ms", "collapses", "source")
#: Largest study CSV read (one participant's session is about 10 kB).
MAX_FILE_BYTES = 8_000_000
#: Largest study.json read (a built study's is about 20 kB).
MAX_STUDY_JSON_BYTES = 4_000_000
#: Most bytes read from all FILES together.
MAX_TOTAL_BYTES = 64_000_000


@dataclass(frozen=True)
class StudyFolder:
    """What the importer needs of a built study (its study.json): the study id every
    file must carry and the trials, in the study's order."""
    study: str
    trials: tuple[str, ...]
    source: str  # the study.json it was read from, for messages


def _short(ids) -> str:
    ids = list(ids)
    return ", ".join(ids) if len(ids) <= 6 else f"{ids[0]}, {ids[1]}, ..., {ids[-1]}"


def _read(path: Path, budget: int | None = None) -> tuple[list[str], list[tuple[int, list[str]]], int]:
    """(header, [(line, fields)], bytes read) of a study CSV, read bounded."""
    limit = MAX_FILE_BYTES if budget is None else min(MAX_FILE_BYTES, max(budget, 0))
    name = ("analysis.import_study.MAX_FILE_BYTES" if limit == MAX_FILE_BYTES else
            f"what analysis.import_study.MAX_TOTAL_BYTES = {MAX_TOTAL_BYTES} for all files leaves after the files before it")
    try:
        raw = read_bounded(path, limit, "study CSV", limit_name=name)
    except InputFileError as e:
        raise StudyDataError([str(e)]) from None
    if b"\x00" in raw:  # no study CSV holds NUL: a sparse or binary file, or UTF-16 text
        line = raw[: raw.index(b"\x00")].count(b"\n") + 1
        raise StudyDataError([f"{path}: line {line}: NUL bytes: not a study CSV (a binary file, or UTF-16 text)"])
    try:
        text = raw.decode("utf-8-sig")
    except UnicodeDecodeError as e:
        raise StudyDataError([f"{path}: not UTF-8 text (byte {e.start}): not a study CSV"]) from None
    try:
        lines = csv_records(text, str(path), MAX_FIELD_CHARS)
    except CsvShapeError as e:
        raise StudyDataError([str(e)]) from None
    if not lines:
        raise StudyDataError([f"{path}: empty file: not a study CSV (a header line and one row per response)"])
    return lines[0][1], lines[1:], len(raw)


def _responses(path: Path, task: str, pid: str, prows: list[tuple[int, dict]], where: str,
               problems: list[str], folder: StudyFolder | None = None) -> list[dict]:
    """Rows of the human-data format of one participant's main-phase answers in one
    file (`prows`: (line, fields) of all their rows, first at `where`); adds to
    `problems` an unknown or repeated trial, a response that is not a number, and a
    study of other than the expected trials (`folder`'s, else the paper's 24) or a
    participant cut short."""
    out: list[dict] = []
    main = [(line, r) for line, r in prows if r["phase"] == "main"]
    trials_seen: dict[str, int] = {}
    n_expected = prows[0][1]["n_trials"]
    expected = folder.trials if folder else tuple(TRIAL_IDS)
    for line, r in main:
        tid = r["trial"].upper()
        if tid not in expected:
            problems.append(
                f"{path}: line {line}: trial {r['trial']!r} is not one of the {len(expected)} trial ids of "
                f"{folder.source} ({_short(expected)})" if folder else
                f"{path}: line {line}: trial {r['trial']!r} is not one of the 24 trial ids (1E, 1H, ..., 12H) of the "
                "paper's study; a study of other trials: give --study DIR (its study.json lists them)")
            continue
        if tid in trials_seen:
            problems.append(f"{path}: line {line}: participant {pid} answered trial {tid} twice (first on line {trials_seen[tid]})")
            continue
        trials_seen[tid] = line
        value = parse_response(r["response"])  # the parser of --human-data: one rule for both
        if isinstance(value, str):
            problems.append(f"{path}: line {line}: {value}")
            continue
        dataset = ("simulated-" if r["simulated"] == "SIMULATED" else "") + task
        out.append({"dataset": dataset, "participant": pid, "trial": tid, "response": r["response"],
                    "study": r["study"], "position": r["position"], "condition": r["condition"],
                    "first_in_pair": r.get("first_in_pair", ""), "rt_ms": r["rt_ms"],
                    "collapses": r.get("collapses", ""), "source": f"{path.name}:{line}"})
    if n_expected != str(len(expected)):
        problems.append(f"{where}: the study has {n_expected} trials, not the {len(expected)} of {folder.source}" if folder else
                        f"{where}: the study has {n_expected} trials, not the paper's 24: a study of other trials needs "
                        "--study DIR (its study.json lists them)")
    elif len(main) < len(expected):
        last = prows[-1][0]
        problems.append(f"{path}: line {last}: truncated: participant {pid} ({task}) has {len(main)} of "
                        f"{len(expected)} trials; the file ends after line {last}")
    return out


def import_files(paths, study: str | StudyFolder | None = None) -> list[dict]:
    """Rows of the human-data format from study CSVs `paths`; `study` the id every file
    must carry (default: the first file's), or a StudyFolder (`study_folder`): its id
    and its trials (default: the paper's 24). Raises StudyDataError listing every problem."""
    folder = study if isinstance(study, StudyFolder) else None
    study = folder.study if folder else study
    problems: list[str] = []
    out: list[dict] = []
    seen: dict[tuple[str, str], str] = {}  # (task, participant) -> where first seen
    first_file = None
    simulated_kinds: dict[bool, str] = {}
    budget = MAX_TOTAL_BYTES
    for path in map(Path, paths):
        try:
            header, rows, size = _read(path, budget)
        except StudyDataError as e:
            problems += e.problems
            continue
        budget -= size
        missing = [c for c in REQUIRED if c not in header]
        if missing:
            problems.append(f"{path}: line 1: not a study CSV of stimuli.experiment (missing column(s) {', '.join(missing)})")
            continue
        col = {c: header.index(c) for c in header}
        by_participant: dict[tuple[str, str], list[tuple[int, dict]]] = {}
        for line, fields in rows:
            if len(fields) != len(header):
                problems.append(f"{path}: line {line}: truncated row ({len(fields)} of {len(header)} fields)")
                continue
            r = {c: fields[i].strip() for c, i in col.items()}
            if study is None:
                study, first_file = r["study"], f"{path}"
            if r["study"] != study:
                problems.append(f"{path}: line {line}: from another study ({r['study']!r}, not {study!r} of "
                                f"{first_file or 'the --study folder'}): other trials, layouts or order seed")
                break
            if r["task"] not in TASKS:
                problems.append(f"{path}: line {line}: unknown task {r['task']!r}; expected one of {', '.join(TASKS)}")
                continue
            by_participant.setdefault((r["task"], r["participant"]), []).append((line, r))
        for (task, pid), prows in by_participant.items():
            where = f"{path}: line {prows[0][0]}"
            if not pid:
                problems.append(f"{where}: empty participant")
                continue
            if (task, pid) in seen:
                problems.append(f"{where}: participant {pid} of the {task} task again (already in {seen[task, pid]})")
                continue
            seen[task, pid] = where
            sim = {r["simulated"] == "SIMULATED" for _, r in prows}
            for s in sim:
                simulated_kinds.setdefault(s, where)
            out += _responses(path, task, pid, prows, where, problems, folder)
    if len(simulated_kinds) == 2:
        problems.append(f"{simulated_kinds[True]}: SIMULATED participants mixed with real ones (real data from "
                        f"{simulated_kinds[False]}): import them separately")
    if not problems and not out:
        problems.append("no responses to import")
    if problems:
        raise StudyDataError(problems)
    return out


def study_folder(folder: str | Path) -> StudyFolder:
    """The study id and trial ids in a study folder's study.json (read bounded: a
    FIFO or /dev/zero there is refused, not waited on or read to the end)."""
    path = Path(folder) / "study.json"
    try:
        data = read_bounded(path, MAX_STUDY_JSON_BYTES, "study.json",
                            limit_name="analysis.import_study.MAX_STUDY_JSON_BYTES")
    except InputFileError as e:
        raise StudyDataError([f"{e}: not a study folder of stimuli.experiment (no readable study.json)"]) from None
    try:
        manifest = json.loads(data)
        study = manifest["study"]
    except (ValueError, KeyError, TypeError):
        raise StudyDataError([f"{path}: not a study folder of stimuli.experiment (study.json holds no study id)"]) from None
    if not isinstance(study, str) or not study:
        raise StudyDataError([f"{path}: not a study folder of stimuli.experiment (its study id {study!r} is not a name)"])
    entries = manifest.get("trials")
    ids = [e.get("id") if isinstance(e, dict) else None for e in entries] if isinstance(entries, list) else []
    if not ids or not all(isinstance(t, str) and t.strip() for t in ids):
        raise StudyDataError([f"{path}: not a study folder of stimuli.experiment (study.json lists no trials: "
                              "'trials' must be a list of entries with an id each)"])
    trials = tuple(t.strip().upper() for t in ids)
    twice = sorted({t for t in trials if trials.count(t) > 1})
    if twice:
        raise StudyDataError([f"{path}: study.json lists trial {twice[0]} twice: not a study of stimuli.experiment"])
    return StudyFolder(study, trials, f"{path}")


def study_of_folder(folder: str | Path) -> str:
    """The study id in a study folder's study.json (`study_folder`)."""
    return study_folder(folder).study


def write_human_data(rows: list[dict], out: str | Path) -> Path:
    """Write `rows` as the human-data CSV `out`, whole or not at all, through the
    project's one writer (unique temporary name, atomic rename, spreadsheet-safe
    cells, DiskFull naming `out` with nothing partial left)."""
    import pandas as pd

    from lgp.atomic import write_csv_atomic

    columns = ["dataset", "participant", "trial", "response", *EXTRA]
    table = pd.DataFrame([[r.get(c, "") for c in columns] for r in rows], columns=columns, dtype=object)
    return write_csv_atomic(table, out)


def main(argv=None) -> int:
    import argparse

    p = cli.parser(PROG, description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("files", nargs="+", metavar="FILE", type=cli.input_file, help="CSV files downloaded from a study")
    p.add_argument("--out", required=True, type=cli.output_file, help="human-data CSV to write (docs/human-data.md)")
    p.add_argument("--study", metavar="DIR", type=cli.input_dir,
                   help="the study folder: every file must come from it; its study.json's trials are the trials "
                        "(default: the paper's 24)")
    args = p.parse_args(argv)
    folder = study_folder(args.study) if args.study else None
    rows = import_files(args.files, folder)
    # The same checks the analysis makes (docs/human-data.md), before the file is written,
    # on the study's trial set (what lgp.reproduce --stimuli DIR --human-data checks).
    import pandas as pd

    from analysis.data import validate_human_data

    with using_trials(folder.trials if folder else TRIAL_IDS):
        validate_human_data(pd.DataFrame(rows).astype({"response": float}), allow_simulated=True)
    write_human_data(rows, args.out)
    counts = pd.DataFrame(rows).groupby("dataset")["participant"].nunique()
    print(f"{args.out}: " + ", ".join(f"{d} {n} participant(s)" for d, n in counts.items())
          + f" from {len(args.files)} file(s)", file=sys.stdout)
    return 0


if __name__ == "__main__":
    raise SystemExit(cli.run_cli(main, prog=PROG))
