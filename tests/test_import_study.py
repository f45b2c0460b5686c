"""`python -m analysis.import_study` under bad input and faults: every
refusal one line with exit 1 (2 for usage), no formula reaches its CSV, every read
bounded (a FIFO or /dev/zero never hangs or fills memory), unique temporary names
and an atomic rename, the number parser of ``--human-data``, and a full disk named.

Every response file made here is marked SIMULATED: none of it is human data."""
from __future__ import annotations

import csv
import errno
import io
import json
import os
import subprocess
import sys
import threading
from pathlib import Path

import pytest

from analysis import import_study, load_human_data
from analysis.data import HumanDataError, MAX_FIELD_CHARS
from bench.common import deadline
from lgp.atomic import DiskFull
from test_study import STUDY, _study_csv, _write

ROOT = Path(__file__).resolve().parents[1]


def _run(args, capsys) -> tuple[int, str]:
    try:
        code = import_study.cli.run_cli(import_study.main, [str(a) for a in args], prog=import_study.PROG)
    except SystemExit as e:  # argparse: usage errors
        code = e.code
    err = capsys.readouterr().err.strip()
    return code, err


def _refused(capsys, args, tmp_path, code=1) -> str:
    out = tmp_path / "refused" / "human.csv"
    got, err = _run([*args, "--out", out], capsys)
    assert got == code and len(err.splitlines()) == 1 and err.startswith("python -m analysis.import_study: error: "), err
    assert not out.parent.exists() or not list(out.parent.iterdir())  # nothing written, no temporary file
    return err


def _edit(text: str, row: int, column: str, value: str) -> str:
    lines = list(csv.reader(text.splitlines()))
    lines[row][lines[0].index(column)] = value
    buf = io.StringIO()
    csv.writer(buf, lineterminator="\n").writerows(lines)
    return buf.getvalue()


@pytest.mark.slow  # a fresh interpreter importing pandas (about 1-2 s)
def test_run_as_a_module_a_refusal_is_one_line_with_exit_1(tmp_path):
    """StudyDataError lived in __main__ and was not known to the CLI: 15 lines of traceback."""
    a = _write(tmp_path / "a.csv", _study_csv(0, trials=None).replace(",1E,", ",13E,", 1))
    r = subprocess.run([sys.executable, "-m", "analysis.import_study", a, "--out", str(tmp_path / "h.csv")],
                       capture_output=True, text=True, cwd=ROOT, env={**os.environ, "PYTHONPATH": str(ROOT)})
    assert r.returncode == 1, r.stderr
    assert r.stderr.count("\n") == 1 and r.stderr.startswith("python -m analysis.import_study: error: "), r.stderr
    assert "trial '13E' is not one of the 24" in r.stderr and "Traceback" not in r.stderr


def test_the_study_error_is_a_known_error_of_the_project_wherever_it_is_raised():
    from lgp.cli import is_known_error

    assert import_study.StudyDataError.__module__ == "analysis.data.datasets"  # not __main__ when run with -m
    assert is_known_error(import_study.StudyDataError(["x"]))


def test_no_formula_reaches_the_csv_from_a_field_or_a_file_name(capsys, tmp_path):
    text = _edit(_study_csv(0), 3, "condition", "@SUM(A1:A9)")
    a = _write(tmp_path / "=1+2.csv", text)
    out = tmp_path / "human.csv"
    code, err = _run([a, "--out", out], capsys)
    assert code == 0, err
    cells = [c for row in csv.reader(out.read_text().splitlines()) for c in row]
    risky = [c for c in cells if c and c[0] in "=+@\t\r" or (c[:1] == "-" and not c[1:].replace(".", "").isdigit())]
    assert not risky, risky
    assert "'@SUM(A1:A9)" in cells and "'=1+2.csv:4" in cells
    # a formula as the response is no number: refused, naming file and line
    b = _write(tmp_path / "b.csv", _edit(_study_csv(1), 3, "response", '=HYPERLINK("http://x","y")'))
    assert "b.csv: line 4: non-numeric response '=HYPERLINK(" in _refused(capsys, [b], tmp_path)


@pytest.mark.parametrize("value, why", [("1_70", "no '_' digit separators"), ("\u0661\u0667", "ASCII digits 0-9"),
                                        ("\uff11\uff17", "ASCII digits 0-9"), ("9" * 5000, "beyond the range of a float")],
                         ids=["separator", "arabic-indic", "full-width", "5000-digits"])
def test_one_number_parser_refuses_the_same_responses_in_the_import_and_in_human_data(capsys, tmp_path, value, why):
    a = _write(tmp_path / "a.csv", _edit(_study_csv(0), 3, "response", value))
    err = _refused(capsys, [a], tmp_path)
    assert "a.csv: line 4: " in err and why in err and len(err) < 400, err
    good = tmp_path / "good.csv"
    import_study.write_human_data(import_study.import_files([_write(tmp_path / "c.csv", _study_csv(0))]), good)
    human = _edit(good.read_text(), 1, "response", value)
    (tmp_path / "bad-human.csv").write_text(human)
    with pytest.raises(HumanDataError, match=why.replace("(", r"\(")):
        load_human_data(tmp_path / "bad-human.csv", allow_simulated=True)


def test_a_fifo_or_dev_zero_as_study_json_is_refused_not_waited_on(capsys, tmp_path):
    a = _write(tmp_path / "a.csv", _study_csv(0))
    fifo, zero = tmp_path / "fifo-study", tmp_path / "zero-study"
    fifo.mkdir(), zero.mkdir()
    os.mkfifo(fifo / "study.json")
    (zero / "study.json").symlink_to("/dev/zero")
    with deadline(10):
        err = _refused(capsys, [a, "--study", fifo], tmp_path)
    assert "study.json: a FIFO (named pipe), not a regular file" in err
    with deadline(10):
        err = _refused(capsys, [a, "--study", zero], tmp_path)
    assert "study.json: a character device (a symbolic link to /dev/zero)" in err


def test_a_huge_or_special_study_csv_is_refused_naming_the_limit(capsys, tmp_path):
    big = tmp_path / "big.csv"
    with open(big, "wb") as f:  # sparse: no disk used
        f.truncate(import_study.MAX_FILE_BYTES + 1)
    with deadline(10):
        err = _refused(capsys, [big], tmp_path)
    assert f"big.csv: study CSV is {import_study.MAX_FILE_BYTES + 1} bytes, more than the " in err
    assert "MAX_FILE_BYTES" in err
    zero = tmp_path / "zero.csv"
    zero.symlink_to("/dev/zero")
    os.mkfifo(tmp_path / "fifo.csv")
    with deadline(10):  # the command line's own check: not a regular file, exit 2
        assert "is a character device (a symbolic link to /dev/zero), not a regular file" in _refused(capsys, [zero], tmp_path, code=2)
        assert "is a FIFO (named pipe), not a regular file" in _refused(capsys, [tmp_path / "fifo.csv"], tmp_path, code=2)
        with pytest.raises(import_study.StudyDataError, match="FIFO"):
            import_study.import_files([tmp_path / "fifo.csv"])


def test_all_files_together_are_bounded_too(tmp_path, monkeypatch):
    files = [_write(tmp_path / f"{p}.csv", _study_csv(p)) for p in range(3)]
    size = Path(files[0]).stat().st_size
    monkeypatch.setattr(import_study, "MAX_TOTAL_BYTES", int(2.5 * size))
    with pytest.raises(import_study.StudyDataError, match="2.csv: study CSV is .* bytes, more than the .* allowed "
                                                          r"\(what analysis.import_study.MAX_TOTAL_BYTES"):
        import_study.import_files(files)


def test_a_200_kb_field_and_a_column_named_twice_are_refused_in_one_line(capsys, tmp_path):
    a = _write(tmp_path / "a.csv", _edit(_study_csv(0), 3, "condition", "x" * 200_000))
    err = _refused(capsys, [a], tmp_path)
    assert f"a.csv: line 4: a field longer than the {MAX_FIELD_CHARS} characters allowed" in err and len(err) < 300
    b = _write(tmp_path / "b.csv", _edit(_study_csv(0), 3, "condition", "x" * (MAX_FIELD_CHARS + 1)))
    assert f"holds {MAX_FIELD_CHARS + 1} characters, more than the {MAX_FIELD_CHARS} allowed" in _refused(capsys, [b], tmp_path)
    text = _study_csv(0)
    header, rest = text.split("\n", 1)
    c = _write(tmp_path / "c.csv", header.replace("rt_ms", "response", 1) + "\n" + rest)
    assert "c.csv: line 1 (header): column 'response' given twice" in _refused(capsys, [c], tmp_path)


def test_human_data_with_a_column_named_twice_or_a_200_kb_field_is_refused(tmp_path):
    rows = "".join(f"difficulty,p0,{t},{k},{k}\n" for k, t in enumerate(import_study.TRIAL_IDS))
    (tmp_path / "h.csv").write_text("dataset,participant,trial,response,response\n" + rows)
    with pytest.raises(HumanDataError, match=r"line 1 \(header\): column 'response' given twice \(columns 4 and 5\)"):
        load_human_data(tmp_path / "h.csv")
    (tmp_path / "f.csv").write_text("dataset,participant,trial,response\n" + rows.replace(",p0,", ",p" + "0" * 200_000 + ",", 1))
    with deadline(10), pytest.raises(HumanDataError, match=f"line 2: a field longer than the {MAX_FIELD_CHARS} characters"):
        load_human_data(tmp_path / "f.csv")


@pytest.mark.slow  # 4 threads x 15 writes of a 960-row file: about 3 s on a loaded machine
def test_two_imports_to_one_out_at_once_leave_one_whole_file(tmp_path):
    """The fixed temporary name `.human.csv.tmp` of old let two imports write one file."""
    rows = {p: import_study.import_files([_write(tmp_path / f"{p}.csv", _study_csv(p))]) * 40 for p in (0, 1)}
    out = tmp_path / "out" / "human.csv"
    out.parent.mkdir()
    errors = []

    def write(p):
        try:
            for _ in range(15):
                import_study.write_human_data(rows[p], out)
        except Exception as e:  # noqa: BLE001 - collected for the assertion
            errors.append(e)

    threads = [threading.Thread(target=write, args=(p,)) for p in (0, 1, 0, 1)]
    for t in threads:
        t.start()
    for t in threads:
        t.join()
    assert not errors, errors
    assert [p.name for p in out.parent.iterdir()] == ["human.csv"]  # no temporary left
    body = out.read_text().splitlines()
    assert len(body) == 1 + 40 * 24 and len({line.split(",")[1] for line in body[1:]}) == 1  # one writer's file, whole


def test_a_full_disk_names_the_file_and_leaves_no_partial_file(capsys, tmp_path, monkeypatch):
    a = _write(tmp_path / "a.csv", _study_csv(0))
    real = Path.write_bytes

    def full(self, data):
        if self.name.startswith(".human.csv"):
            real(self, data[: len(data) // 2])  # what a full disk leaves: part of the file
            raise OSError(errno.ENOSPC, os.strerror(errno.ENOSPC))
        return real(self, data)

    monkeypatch.setattr(Path, "write_bytes", full)
    err = _refused(capsys, [a], tmp_path)
    assert "human.csv: No space left on device: the disk is full, so it was not written" in err
    assert sorted(p.name for p in tmp_path.iterdir()) == ["a.csv", "refused"]
    with pytest.raises(DiskFull):
        import_study.write_human_data(import_study.import_files([a]), tmp_path / "refused" / "human.csv")


# ----------------------------------------------------------------------------- a study of other trials (issue 34 item 5)

DESIGNED = ("D01", "D02", "D03", "D04")  # a 4-trial set as stimuli.design names it: no easy/hard pairs


def _designed_study(tmp_path, trials=DESIGNED) -> Path:
    """A study folder as `stimuli.experiment --stimuli DIR` writes it, as far as the
    importer reads it: study.json's study id and its trial entries (ids in file order)."""
    from stimuli import experiment as ex

    folder = tmp_path / "study-designed"
    folder.mkdir()
    entries = [{"id": t, "pair": None, "level": None, "start": f"img/{t}-A.png", "finish": f"img/{t}-B.png",
                "description": ""} for t in trials]
    (folder / ex.MANIFEST).write_text(json.dumps({"study": "d0d0d0d0d0d0", "task": "difficulty", "build": "b",
                                                  "trials": entries, "anchors": [], "files": {}}))
    return folder


def _designed_csv(participant: int, trials=DESIGNED, shown=None) -> str:
    """One participant's download of the designed study: the order study.js shows an
    unpaired set in (stimuli.experiment.trial_order), n_trials the set's size."""
    from stimuli import experiment as ex

    order = ex.trial_order([{"id": t, "pair": None, "level": None} for t in trials], participant)
    if shown:
        order = [{**t, "id": shown.get(t["id"], t["id"])} for t in order]
    text = _study_csv(participant, study="d0d0d0d0d0d0", trials=order)
    for row in range(1, text.count("\n")):
        text = _edit(text, row, "n_trials", str(len(trials)))
    return text


def test_a_designed_studys_downloads_import_on_its_own_trials_and_load_as_the_runs_human_data(capsys, tmp_path):
    from analysis.data import using_trials
    from stimuli import experiment as ex

    folder = _designed_study(tmp_path)
    files = [_write(tmp_path / f"p{p}.csv", _designed_csv(p)) for p in (0, 1)]
    out = tmp_path / "human.csv"
    code, err = _run([*files, "--study", folder, "--out", out], capsys)
    assert code == 0, err
    with using_trials(DESIGNED):  # what lgp.reproduce --stimuli DIR --human-data reads
        human = load_human_data(out, allow_simulated=True)
    assert len(human) == 2 * 4 and set(human["trial"]) == set(DESIGNED)
    for p in (0, 1):  # each answer is the one the file gave (position + participant), on the trial it was given to
        order = ex.trial_order([{"id": t, "pair": None, "level": None} for t in DESIGNED], p)
        mine = human[human.participant == str(p)].set_index("trial")["response"].to_dict()
        assert mine == {t["id"]: t["position"] + p for t in order}
    # the same file against the paper's 24 (no --study) is refused, saying what to give
    err = _refused(capsys, files, tmp_path)
    assert "p0.csv: line 4: trial 'D" in err and "is not one of the 24 trial ids" in err and "give --study DIR" in err, err


def test_a_trial_outside_the_designed_studys_set_is_refused_naming_file_line_trial_and_set(capsys, tmp_path):
    folder = _designed_study(tmp_path)
    good = _write(tmp_path / "p0.csv", _designed_csv(0))
    a = _write(tmp_path / "p1.csv", _designed_csv(1, shown={"D03": "D13"}))
    err = _refused(capsys, [good, a, "--study", folder], tmp_path)
    line = 1 + 2 + next(k for k, r in enumerate(list(csv.DictReader(io.StringIO(Path(a).read_text())))[2:], 1)
                        if r["trial"] == "D13")
    assert (f"p1.csv: line {line}: trial 'D13' is not one of the 4 trial ids of {folder / 'study.json'} "
            "(D01, D02, D03, D04)") in err, err
    # a paper trial is no trial of the designed study either
    b = _write(tmp_path / "p2.csv", _designed_csv(2, shown={"D01": "1E"}))
    assert "trial '1E' is not one of the 4 trial ids of" in _refused(capsys, [b, "--study", folder], tmp_path)
    # a participant with fewer trials than the designed set: truncated, counted against its 4
    c = _write(tmp_path / "p3.csv", "".join(_designed_csv(3).splitlines(keepends=True)[:5]))
    assert "p3.csv: line 5: truncated: participant 3 (difficulty) has 2 of 4 trials" in _refused(capsys, [c, "--study", folder], tmp_path)


def test_a_study_json_without_a_trial_list_is_no_study_folder(capsys, tmp_path):
    a = _write(tmp_path / "a.csv", _study_csv(0))
    for k, trials in enumerate(([], "1E", [{"pair": 1}], [{"id": "1E"}, {"id": "1e"}])):
        folder = tmp_path / f"s{k}"
        folder.mkdir()
        (folder / "study.json").write_text(json.dumps({"study": STUDY, "trials": trials}))
        err = _refused(capsys, [a, "--study", folder], tmp_path)
        assert f"s{k}/study.json: " in err and ("lists no trials" in err or "lists trial 1E twice" in err), err


@pytest.mark.slow  # one lgp.reproduce --quick run on 6 generated trials: about 8 s
def test_a_generated_studys_downloads_import_and_run_through_reproduce_on_its_own_trials(capsys, tmp_path):
    """The loop of issue 34 item 5: a stimulus folder (stimuli.generate, as stimuli.design
    writes one) -> its study's study.json (the builder's own trial entries and study id)
    -> downloads of SIMULATED participants -> analysis.import_study --study ->
    lgp.reproduce --stimuli DIR --human-data, fitted on the folder's trials."""
    import pandas as pd

    import stimuli
    from lgp import reproduce
    from stimuli import experiment as ex
    from stimuli.generate import generate

    stim = tmp_path / "stim"
    generate(stim, 6, seed=2)
    trials = stimuli.load_all(stim)
    entries = [ex._trial_entry(t) for t in trials]
    sid = ex.study_id(trials, [], 0, 0)
    folder = tmp_path / "study"
    folder.mkdir()
    (folder / ex.MANIFEST).write_text(json.dumps({"study": sid, "trials": entries}))
    ids = tuple(e["id"] for e in entries)
    files = []
    for p in range(4):
        text = _study_csv(p, study=sid, trials=ex.trial_order(entries, p))
        for row in range(1, text.count("\n")):
            text = _edit(text, row, "n_trials", str(len(ids)))
        files.append(_write(tmp_path / f"p{p}.csv", text))
    human = tmp_path / "human.csv"
    code, err = _run([*files, "--study", folder, "--out", human], capsys)
    assert code == 0, err
    out = tmp_path / "r"
    assert reproduce.main(["--quick", "--stimuli", str(stim), "--samples", "1", "--n-sims", "8", "--sigmas", "0.065", "0.1",
                           "--jobs", "1", "--n-boot", "20", "--n-perm", "9", "--no-replays", "--out", str(out),
                           "--human-data", str(human), "--allow-simulated"]) == 0
    fits = pd.read_csv(out / "analysis" / "simulated_fits.csv")
    assert (fits["n_trials"] == len(ids)).all() and set(fits["model"]) >= {"full", "effort", "risk"}
    assert sorted(pd.read_csv(out / "effort.csv")["trial"].unique()) == sorted(ids)
