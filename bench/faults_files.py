"""The bad files of bench/faults.py: trial files (stimuli.load_trial), human-data
files (analysis.data.load_human_data) and study downloads (analysis.import_study).
Each `*_cases(tmp)` yields (input, case): a case is a callable that `faults.judge`
runs, or ("accept", callable) for input the format allows."""
from __future__ import annotations

import contextlib
import io
import os
import tempfile
from pathlib import Path

import numpy as np
import pandas as pd

import stimuli
from analysis.data import TRIAL_IDS, load_human_data

BASE = (stimuli.TRIAL_DIR / "1E.yaml").read_text()
X1 = BASE.replace("id: 1E\npair: 1\nlevel: E\n", "id: X1\n")


# ----------------------------------------------------------------------------- trial files


def trial_cases(tmp: Path):
    def text_case(text, name="X1.yaml", load="X1"):
        def run():
            folder = Path(tempfile.mkdtemp(dir=tmp))
            (folder / name).write_bytes(text if isinstance(text, bytes) else text.encode())
            trial = stimuli.load_trial(load, folder)
            return f"loaded {trial.id}"
        return run

    def special(make):
        def run():
            folder = Path(tempfile.mkdtemp(dir=tmp))
            make(folder / "X1.yaml")
            return stimuli.load_trial("X1", folder)
        return run

    def sub(old, new):
        assert old in X1, old
        return text_case(X1.replace(old, new, 1))

    head = X1[: X1.index("target:")]
    grid = "target:\n  blocks:\n" + "".join(f"  - name: t{i}_{j}\n    p_WB: [{0.2127 + i * 0.0254:.4f}, {-0.2373 + j * 0.0254:.4f}, 0.0127]\n"
                                            for i in range(14) for j in range(14))
    b1 = "  - name: b1\n    p_WB: [0.35, 0.0, 0.0127]\n"
    yield "not YAML (`a: b: c`)", text_case("id: X1\na: b: c\n")
    yield "a YAML list, not a mapping", text_case("- 1\n- 2\n")
    yield "empty file", text_case("")
    yield "not UTF-8 (Latin-1 bytes)", text_case(X1.encode().replace(b"scattered blocks", b"scattered \xe9blocks"))
    yield "larger than MAX_TRIAL_BYTES", text_case(X1 + "#" * stimuli.MAX_TRIAL_BYTES)
    yield "symlink to /dev/zero", special(lambda p: p.symlink_to("/dev/zero"))
    yield "a FIFO named X1.yaml", special(lambda p: os.mkfifo(p))
    yield "dangling symlink", special(lambda p: p.symlink_to(p.parent / "gone.yaml"))
    yield "a directory named X1.yaml", special(lambda p: p.mkdir())
    yield "lower-case file name x1.yaml", text_case(X1, name="x1.yaml")
    yield "id field disagrees with the file name", text_case(X1.replace("id: X1", "id: X2"))
    yield "unknown field", sub("dimension:", "colour_scheme: red\ndimension:")
    yield "a key given twice", sub("    count: 3\n", "    count: 3\n    count: 30\n")
    yield "YAML anchor and alias", sub("    min_gap: 0.01\n", "    min_gap: &g 0.01\n    clearance: *g\n")
    yield "Python object tag", text_case("!!python/object/apply:os.system ['true']\n")
    yield "alias bomb (billion laughs)", text_case("a: &a [x, x]\nb: &b [*a, *a]\nc: &c [*b, *b]\n")
    yield "count: 1000000000000", sub("count: 3", "count: 1000000000000")
    yield "count: -1", sub("count: 3", "count: -1")
    yield "count: 2.5", sub("count: 3", "count: 2.5")
    yield "count: three", sub("count: 3", "count: three")
    yield "region x inverted", sub("x: [0.2, 0.55]", "x: [0.55, 0.2]")
    yield "region x infinite", sub("x: [0.2, 0.55]", "x: [-.inf, .inf]")
    yield "region beyond the workspace", sub("x: [0.2, 0.55]", "x: [0.2, 55.0]")
    yield "region x nan", sub("x: [0.2, 0.55]", "x: [.nan, 0.55]")
    yield "min_gap negative", sub("min_gap: 0.01", "min_gap: -0.01")
    yield "clearance 1 km", sub("clearance: 0.02", "clearance: 1000")
    yield "target floor covers the scatter region (100 blocks beside 196)", text_case(head.replace("count: 3", "count: 100") + grid)
    yield "crowded region: passes the area bound, jams the sampler", "crowded"
    yield "target with no blocks", text_case(head + "target:\n  blocks: []\n")
    yield "p_WB with 2 numbers", sub("p_WB: [0.35, 0.0, 0.0127]", "p_WB: [0.35, 0.0]")
    yield "p_WB text", sub("p_WB: [0.35, 0.0, 0.0127]", "p_WB: [0.35, zero, 0.0127]")
    yield "two target blocks in one place", text_case(head + "target:\n  blocks:\n" + b1 + b1.replace("b1", "b2"))
    yield "target block floating 10 cm up", text_case(head + "target:\n  blocks:\n" + b1.replace("0.0127]", "0.1127]"))
    yield "target block below the table", text_case(head + "target:\n  blocks:\n" + b1.replace("0.0127]", "-0.05]"))
    yield "block of size 0", text_case(head + "target:\n  blocks:\n" + b1 + "    size: [0, 0, 0]\n")
    yield "block of size 10 m", text_case(head + "target:\n  blocks:\n" + b1.replace("0.0127]", "5.0]") + "    size: [10, 10, 10]\n")
    yield "yaw as text", sub("p_WB: [0.35, 0.0, 0.0127]", "p_WB: [0.35, 0.0, 0.0127]\n    yaw: left")
    yield "B needs red blocks, A has none", sub("p_WB: [0.35, 0.0, 0.0127]", "p_WB: [0.35, 0.0, 0.0127]\n    colour: red")
    yield "recolour more blocks than listed", sub("    clearance: 0.02\n", "    clearance: 0.02\n  recolour:\n    count: 5\n    colour: red\n")
    yield "duplicate target block names", text_case(head + "target:\n  blocks:\n" + b1 + b1.replace("0.0127]", "0.0381]"))
    yield "pair/level disagree with the id", text_case(BASE.replace("pair: 1", "pair: 2"), name="1E.yaml", load="1E")
    yield "lower-case id in the file", text_case(X1.replace("id: X1", "id: x1"))
    yield "id with spaces", text_case(X1.replace("id: X1", "id: 'X 1'"))
    yield "fixed box without size", sub("initial:", "fixed:\n- name: wall\n  boxes:\n  - p_WO: [0.5, 0.3, 0.05]\ninitial:")
    yield "build site outside the workspace", sub("build_site: [0.35, 0.0]", "build_site: [35.0, 0.0]")
    yield "a 5000-digit integer (count)", sub("count: 3", "count: " + "9" * 5000)
    yield "10,000 target blocks (refused after 29 s of checking before)", text_case(
        head + "target:\n  blocks:\n" + "".join(f"  - name: t{i}\n    p_WB: [{-1.9 + (i % 70) * 0.0508:.4f}, "
                                                 f"{-1.9 + (i // 70) * 0.0254:.4f}, 0.0127]\n" for i in range(10_000)))
    yield "description `</script><script>alert(2)</script>`", ("accept", sub("description: ", "description: '</script><script>alert(2)</script>' #"))


def crowded(tmp: Path):
    old = stimuli.start.SCATTER_SECONDS
    stimuli.start.SCATTER_SECONDS = 1.0
    try:
        folder = Path(tempfile.mkdtemp(dir=tmp))
        (folder / "X1.yaml").write_text(X1.replace("count: 3", "count: 140").replace("x: [0.2, 0.55]", "x: [-0.2, 0.2]")
                                        .replace("y: [-0.25, 0.25]", "y: [0.1, 0.5]"))
        return stimuli.load_trial("X1", folder)
    finally:
        stimuli.start.SCATTER_SECONDS = old


# ----------------------------------------------------------------------------- human data


def _responses(n=3, dataset="difficulty", seed=0):
    rng = np.random.default_rng(seed)
    return pd.DataFrame({"dataset": dataset, "participant": np.repeat([f"p{k}" for k in range(n)], 24),
                         "trial": np.tile(TRIAL_IDS, n), "response": rng.normal(size=24 * n).round(3)})


def human_cases(tmp: Path):
    def csv(df=None, text=None, raw=None, **kw):
        def run():
            path = Path(tempfile.mkdtemp(dir=tmp)) / "h.csv"
            if raw is not None:
                path.write_bytes(raw)
            elif text is not None:
                path.write_text(text)
            else:
                df.to_csv(path, index=False)
            t = load_human_data(path, **kw)
            return f"loaded {len(t)} rows"
        return run

    def special(make):
        def run():
            path = Path(tempfile.mkdtemp(dir=tmp)) / "h.csv"
            make(path)
            return load_human_data(path)
        return run

    good = _responses()
    text = good.to_csv(index=False)

    def edit(row, column, value):
        df = good.copy()
        df[column] = df[column].astype(object)
        df.loc[row, column] = value
        return csv(df)

    yield "empty file", csv(text="")
    yield "header only", csv(text="dataset,participant,trial,response\n")
    yield "missing column response", csv(good.drop(columns="response"))
    yield "unknown dataset", edit(0, "dataset", "effort")
    yield "a simulated dataset as human data", csv(good.assign(dataset="simulated-time"))
    yield "unknown trial id 13E", edit(0, "trial", "13E")
    yield "response text", edit(0, "response", "fast")
    yield "response inf", edit(0, "response", "inf")
    yield "response nan", edit(0, "response", "nan")
    yield "response empty", edit(0, "response", "")
    yield "response 1e308 (mean overflows)", csv(good.assign(response=np.where(good.index < 24, 1e308, good["response"])))
    yield "responses near 1e-299 (SD underflows)", csv(good.assign(response=good["response"].abs() * 1e-299))
    yield "every participant constant", csv(good.assign(response=4.0))
    yield "duplicate row", csv(pd.concat([good, good.iloc[[0]]]))
    yield "a participant missing a trial", csv(good.drop(index=5))
    yield "empty participant id", edit(0, "participant", "")
    yield "UTF-16 without byte-order mark", csv(raw=text.encode("utf-16-le"))
    yield "Latin-1 byte", csv(raw=text.replace("difficulty", "difficult\xe9", 1).encode("latin-1"))
    yield "digit separators 1_000", edit(0, "response", "1_000")
    yield "short rows", csv(text="dataset,participant,trial,response\ndifficulty,p0\n")
    yield "NUL bytes", csv(raw=text.encode().replace(b"p0", b"p\x000", 1))
    yield "a FIFO", special(lambda p: os.mkfifo(p))
    yield "symlink to /dev/zero", special(lambda p: p.symlink_to("/dev/zero"))
    yield "dangling symlink", special(lambda p: p.symlink_to(p.parent / "gone.csv"))
    yield "a directory", special(lambda p: p.mkdir())
    yield "11 participants, limit 10", csv(_responses(11), max_participants=10)
    yield "240 kB for 2 participants, limit 48 kB", csv(_responses(2).assign(note="x" * 5000), max_participants=10)
    yield "column `response` twice in the header", csv(text="dataset,participant,trial,response,response\n"
                                                            + "".join(f"difficulty,p0,{t},1,2\n" for t in TRIAL_IDS))
    yield "a 200 kB field", edit(0, "participant", "p" * 200_000)
    yield "response in Arabic-Indic digits", edit(0, "response", "\u0661\u0667")
    yield "response a 5000-digit integer", edit(0, "response", "9" * 5000)
    yield "lower-case trial ids 1e", ("accept", csv(good.assign(trial=good["trial"].str.lower())))
    yield "UTF-16 with byte-order mark", ("accept", csv(raw=text.encode("utf-16")))
    yield "UTF-8 with byte-order mark", ("accept", csv(raw=b"\xef\xbb\xbf" + text.encode()))
    yield "formula participant ids (=cmd|..., +SUM, @SUM)", ("accept", csv(good.assign(participant=good["participant"].map(
        {"p0": "=cmd|' /C calc'!A0", "p1": "+SUM(1+1)", "p2": "@SUM(A1)"}))))
    yield "extra columns", ("accept", csv(good.assign(age=30)))
    yield "blank lines and CRLF line ends", ("accept", csv(raw=text.replace("\n", "\r\n\r\n").encode()))
    yield "one constant participant among others", ("accept", csv(pd.concat([good, _responses(1).assign(participant="c", response=2.0)])))


# ----------------------------------------------------------------------------- study downloads (analysis.import_study)


def _study_csv(participant: int, study: str = "abc123abc123", simulated: bool = True, edit=None) -> str:
    """A download as study.js writes it (SIMULATED answers); `edit(rows)` changes the rows."""
    import csv as csvmod
    import io

    from stimuli import experiment as ex

    trials = [{"id": t, "pair": int(t[:-1]), "level": t[-1]} for t in TRIAL_IDS]
    base = {c: "" for c in ex.COLUMNS} | {"study": study, "task": "difficulty", "participant": participant,
                                         "simulated": "SIMULATED" if simulated else "", "n_trials": 24}
    rows = [base | {"phase": "anchor", "position": k, "trial": a, "response": 50, "rt_ms": 900}
            for k, a in enumerate(("ANCHOR-EASY", "ANCHOR-HARD"), start=1)]
    rows += [base | {"phase": "main", "position": t["position"], "trial": t["id"], "condition": t["condition"],
                     "first_in_pair": t["first_in_pair"], "response": t["position"] + participant, "rt_ms": 1000}
             for t in ex.trial_order(trials, participant)]
    rows = [{k: str(v) for k, v in r.items()} for r in rows]
    header = list(ex.COLUMNS)
    if edit is not None:
        header, rows = edit(header, rows)
    buf = io.StringIO()
    w = csvmod.writer(buf, lineterminator="\n")
    w.writerow(header)
    w.writerows([[r.get(c, "") for c in ex.COLUMNS] for r in rows])
    return buf.getvalue()


def _run_import(tmp: Path, files, study=None, check=None):
    """A case: the command line's checks and work (import_study.main) on the files
    `files` make in a fresh folder, under run_cli's rules."""
    from analysis import import_study

    def run():
        folder = Path(tempfile.mkdtemp(dir=tmp))
        paths = [make(folder) for make in files]
        args = [str(x) for x in paths] + ["--out", str(folder / "out" / "human.csv")]
        if study is not None:
            args += ["--study", str(study(folder))]
        err = io.StringIO()
        with open(os.devnull, "w") as null, contextlib.redirect_stdout(null), contextlib.redirect_stderr(err):
            try:
                import_study.main(args)
            except SystemExit as e:  # argparse's usage check (exit 2): one line
                raise UsageRefusal(f"exit {e.code}: {err.getvalue().strip()}") from None
        out = folder / "out" / "human.csv"
        return check(out) if check else f"wrote {out.name}"
    return run


def _text(name, body):
    """A maker of the file `name` holding `body` (text or bytes)."""
    def make(folder):
        path = folder / name
        path.write_bytes(body if isinstance(body, bytes) else body.encode())
        return path
    return make


def _special(name, how):
    """A maker of the path `name` made by `how(path)` (a FIFO, a link, a folder ...)."""
    def make(folder):
        path = folder / name
        how(path)
        return path
    return make


def _edited(row, column, value, participant=0):
    """A maker of participant `participant`'s download with one cell changed."""
    def edit(header, rows):
        rows[row][column] = value
        return header, rows
    return _text(f"p{participant}.csv", _study_csv(participant, edit=edit))


def _study_dir(how):
    """A maker of a --study folder whose study.json is made by `how(path)`."""
    def make(folder):
        d = folder / "study"
        d.mkdir()
        how(d / "study.json")
        return d
    return make


def _sparse(n):
    """`how` for a sparse file of `n` NUL bytes (no disk used)."""
    def how(path):
        with open(path, "wb") as f:
            f.truncate(n)
    return how


def _lowered_total(run):
    """`run` with import_study.MAX_TOTAL_BYTES lowered to 2.5 downloads' bytes, so
    three small files are past it."""
    from analysis import import_study

    def patched():
        old = import_study.MAX_TOTAL_BYTES
        import_study.MAX_TOTAL_BYTES = int(2.5 * len(_study_csv(0)))
        try:
            return run()
        finally:
            import_study.MAX_TOTAL_BYTES = old
    return patched


def _no_formula(out):
    """A check of the written CSV: no cell a spreadsheet would run as a formula."""
    import csv as csvmod

    cells = [c for row in csvmod.reader(out.read_text().splitlines()) for c in row]
    risky = [c for c in cells if c and c[0] in "=+@\t\r"]
    if risky:
        raise AssertionError(f"formula cells written: {risky[:3]}")
    return "written as text ('@SUM..., '=1+2.csv:4)"


def import_cases(tmp: Path):
    from analysis import import_study

    def run_import(files, study=None, check=None):
        return _run_import(tmp, files, study, check)

    good = _text("p0.csv", _study_csv(0))
    yield "a FIFO as a study CSV", run_import([_special("fifo.csv", os.mkfifo)])
    yield "a study CSV linked to /dev/zero", run_import([_special("zero.csv", lambda p: p.symlink_to("/dev/zero"))])
    yield "a directory as a study CSV", run_import([_special("dir.csv", lambda p: p.mkdir())])
    yield f"a study CSV larger than MAX_FILE_BYTES (sparse, {import_study.MAX_FILE_BYTES + 1} bytes)", \
        run_import([_special("big.csv", _sparse(import_study.MAX_FILE_BYTES + 1))])
    yield "3 files past MAX_TOTAL_BYTES together (lowered to 2.5 files' bytes for the probe)", _lowered_total(
        run_import([_text(f"p{k}.csv", _study_csv(k)) for k in range(3)]))
    yield "NUL bytes (a sparse file)", run_import([_special("nul.csv", _sparse(1000))])
    yield "study.json a FIFO (--study)", run_import([good], study=_study_dir(os.mkfifo))
    yield "study.json linked to /dev/zero (--study)", run_import([good], study=_study_dir(lambda p: p.symlink_to("/dev/zero")))
    yield "study.json larger than MAX_STUDY_JSON_BYTES (sparse)", run_import(
        [good], study=_study_dir(_sparse(import_study.MAX_STUDY_JSON_BYTES + 1)))
    yield "study.json not JSON", run_import([good], study=_study_dir(lambda p: p.write_text("{study: ")))
    yield "empty file", run_import([_text("e.csv", "")])
    yield "not UTF-8 (Latin-1 byte)", run_import([_text("l.csv", _study_csv(0).encode().replace(b"abc123", b"abc\xe923", 1))])
    yield "not a study CSV (the tidy human-data format)", run_import([_text("t.csv", "dataset,participant,trial,response\n")])
    yield "a file of another study", run_import([good, _text("p1.csv", _study_csv(1, study="other0study0"))])
    yield "one participant twice", run_import([good, _text("again.csv", _study_csv(0))])
    yield "trial 13E", run_import([_edited(3, "trial", "13E")])
    yield "a row cut short", run_import([_text("cut.csv", _study_csv(0)[:-30])])
    yield "response `1_70`", run_import([_edited(3, "response", "1_70")])
    yield "response in Arabic-Indic digits", run_import([_edited(3, "response", "\u0661\u0667")])
    yield "response a 5000-digit integer", run_import([_edited(3, "response", "9" * 5000)])
    yield "response `=HYPERLINK(...)`", run_import([_edited(3, "response", '=HYPERLINK("http://x","y")')])
    yield "response inf", run_import([_edited(3, "response", "inf")])
    yield "SIMULATED mixed with real rows", run_import([good, _text("real.csv", _study_csv(1, simulated=False))])
    yield "a 200 kB field", run_import([_edited(3, "condition", "x" * 200_000)])
    yield "column `response` twice in the header", run_import(
        [_text("twice.csv", _study_csv(0).replace("rt_ms", "response", 1))])

    yield "`@SUM(A1:A9)` in a field", ("accept", run_import([_edited(3, "condition", "@SUM(A1:A9)")], check=_no_formula))
    yield "a file named `=1+2.csv`", ("accept", run_import([_text("=1+2.csv", _study_csv(0))], check=_no_formula))
    yield "UTF-8 with byte-order mark", ("accept", run_import([_text("bom.csv", b"\xef\xbb\xbf" + _study_csv(0).encode())]))


class UsageRefusal(Exception):
    """argparse refused the command line (exit 2, one line): judged as a refusal."""


UsageRefusal.__module__ = "analysis.import_study"  # a refusal of the command, as is_known_error counts them
