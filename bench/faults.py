"""The bad-input probe of docs/faults.md (issue 27): every bad trial file, human-data
file, API argument and cache entry tried, and what the project does with it.

    python bench/faults.py [--out docs/faults.md]

Each case runs in this process under a 20 s deadline (SIGALRM) and is judged:

- ``refused``: an error of the project's own (what a command line prints as one
  line ``prog: error: ...``, lgp.cli.is_known_error), naming the rule, in time;
- ``recomputed``: a cache entry reported as damaged and computed again;
- ``accepted (by design)``: input the format allows (a lower-case trial id, a
  UTF-16 file with its byte-order mark, ...), said so in the table;
- anything else (a traceback, a hang, bad input accepted) is a ``FAILURE``.

It writes the "## Bad inputs tried" section of docs/faults.md (the rest is kept)
and prints the figures. The faults of a running pipeline (killed workers,
concurrent runs, a full disk, ...) are the tests listed in docs/faults.md.
"""
from __future__ import annotations

import argparse
import contextlib
import hashlib
import io
import itertools
import os
import shutil
import sys
import tempfile
import time
from pathlib import Path

import numpy as np
import pandas as pd

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))
sys.path.insert(0, str(ROOT / "bench"))

from common import Deadline, deadline, machine, write_section  # noqa: E402

import stimuli  # noqa: E402
from analysis.data import TRIAL_IDS, load_human_data  # noqa: E402
from lgp.cli import is_known_error, one_line  # noqa: E402

BASE = (stimuli.TRIAL_DIR / "1E.yaml").read_text()
X1 = BASE.replace("id: 1E\npair: 1\nlevel: E\n", "id: X1\n")


def judge(run, accept=False) -> tuple[str, str]:
    """(verdict, what happened) of one case."""
    t0 = time.monotonic()
    try:
        with deadline(20):
            result = run()
    except Deadline as e:
        return "FAILURE", f"hung: {e}"
    except MemoryError:
        return "FAILURE", "MemoryError"
    except Exception as e:  # noqa: BLE001 - judged here
        took = time.monotonic() - t0
        if accept:
            return "FAILURE", f"refused good input: {one_line(e)}"
        if is_known_error(e):
            return "refused", f"{type(e).__name__}: {one_line(e)} ({took:.1f} s)"
        return "FAILURE", f"traceback: {type(e).__name__}: {e}"
    if isinstance(result, str) and result.startswith("recomputed"):
        return "recomputed", result
    if accept:
        return "accepted (by design)", result if isinstance(result, str) else "accepted"
    return "FAILURE", f"accepted: {result!r}"[:200]


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


def import_cases(tmp: Path):
    from analysis import import_study

    def run_import(files, study=None, check=None):
        """The command line's checks and work (import_study.main), under run_cli's rules."""
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

    def text(name, body):
        def make(folder):
            path = folder / name
            path.write_bytes(body if isinstance(body, bytes) else body.encode())
            return path
        return make

    def special(name, how):
        def make(folder):
            path = folder / name
            how(path)
            return path
        return make

    def edited(row, column, value, participant=0):
        def edit(header, rows):
            rows[row][column] = value
            return header, rows
        return text(f"p{participant}.csv", _study_csv(participant, edit=edit))

    def study_dir(how):
        def make(folder):
            d = folder / "study"
            d.mkdir()
            how(d / "study.json")
            return d
        return make

    def sparse(n):
        def how(path):
            with open(path, "wb") as f:
                f.truncate(n)
        return how

    good = text("p0.csv", _study_csv(0))
    yield "a FIFO as a study CSV", run_import([special("fifo.csv", os.mkfifo)])
    yield "a study CSV linked to /dev/zero", run_import([special("zero.csv", lambda p: p.symlink_to("/dev/zero"))])
    yield "a directory as a study CSV", run_import([special("dir.csv", lambda p: p.mkdir())])
    yield f"a study CSV larger than MAX_FILE_BYTES (sparse, {import_study.MAX_FILE_BYTES + 1} bytes)", \
        run_import([special("big.csv", sparse(import_study.MAX_FILE_BYTES + 1))])
    def lowered_total(run):
        def patched():
            old = import_study.MAX_TOTAL_BYTES
            import_study.MAX_TOTAL_BYTES = int(2.5 * len(_study_csv(0)))
            try:
                return run()
            finally:
                import_study.MAX_TOTAL_BYTES = old
        return patched
    yield "3 files past MAX_TOTAL_BYTES together (lowered to 2.5 files' bytes for the probe)", lowered_total(
        run_import([text(f"p{k}.csv", _study_csv(k)) for k in range(3)]))
    yield "NUL bytes (a sparse file)", run_import([special("nul.csv", sparse(1000))])
    yield "study.json a FIFO (--study)", run_import([good], study=study_dir(os.mkfifo))
    yield "study.json linked to /dev/zero (--study)", run_import([good], study=study_dir(lambda p: p.symlink_to("/dev/zero")))
    yield "study.json larger than MAX_STUDY_JSON_BYTES (sparse)", run_import(
        [good], study=study_dir(sparse(import_study.MAX_STUDY_JSON_BYTES + 1)))
    yield "study.json not JSON", run_import([good], study=study_dir(lambda p: p.write_text("{study: ")))
    yield "empty file", run_import([text("e.csv", "")])
    yield "not UTF-8 (Latin-1 byte)", run_import([text("l.csv", _study_csv(0).encode().replace(b"abc123", b"abc\xe923", 1))])
    yield "not a study CSV (the tidy human-data format)", run_import([text("t.csv", "dataset,participant,trial,response\n")])
    yield "a file of another study", run_import([good, text("p1.csv", _study_csv(1, study="other0study0"))])
    yield "one participant twice", run_import([good, text("again.csv", _study_csv(0))])
    yield "trial 13E", run_import([edited(3, "trial", "13E")])
    yield "a row cut short", run_import([text("cut.csv", _study_csv(0)[:-30])])
    yield "response `1_70`", run_import([edited(3, "response", "1_70")])
    yield "response in Arabic-Indic digits", run_import([edited(3, "response", "\u0661\u0667")])
    yield "response a 5000-digit integer", run_import([edited(3, "response", "9" * 5000)])
    yield "response `=HYPERLINK(...)`", run_import([edited(3, "response", '=HYPERLINK("http://x","y")')])
    yield "response inf", run_import([edited(3, "response", "inf")])
    yield "SIMULATED mixed with real rows", run_import([good, text("real.csv", _study_csv(1, simulated=False))])
    yield "a 200 kB field", run_import([edited(3, "condition", "x" * 200_000)])
    yield "column `response` twice in the header", run_import(
        [text("twice.csv", _study_csv(0).replace("rt_ms", "response", 1))])

    def no_formula(out):
        import csv as csvmod

        cells = [c for row in csvmod.reader(out.read_text().splitlines()) for c in row]
        risky = [c for c in cells if c and c[0] in "=+@\t\r"]
        if risky:
            raise AssertionError(f"formula cells written: {risky[:3]}")
        return "written as text ('@SUM..., '=1+2.csv:4)"
    yield "`@SUM(A1:A9)` in a field", ("accept", run_import([edited(3, "condition", "@SUM(A1:A9)")], check=no_formula))
    yield "a file named `=1+2.csv`", ("accept", run_import([text("=1+2.csv", _study_csv(0))], check=no_formula))
    yield "UTF-8 with byte-order mark", ("accept", run_import([text("bom.csv", b"\xef\xbb\xbf" + _study_csv(0).encode())]))


class UsageRefusal(Exception):
    """argparse refused the command line (exit 2, one line): judged as a refusal."""


UsageRefusal.__module__ = "analysis.import_study"  # a refusal of the command, as is_known_error counts them


# ----------------------------------------------------------------------------- counts on the command line


def command_cases(tmp: Path):
    def argv_case(module, argv):
        def run():
            import importlib

            main = importlib.import_module(module).main if module != "lgp.reproduce" else importlib.import_module(module).parse_args
            err = io.StringIO()
            with contextlib.redirect_stderr(err):
                try:
                    result = main(argv)
                except SystemExit as e:
                    raise UsageRefusal(f"exit {e.code}: {err.getvalue().strip()}") from None
            return f"accepted: {result}"
        return run

    big = "1000000000000"
    yield "lgp.reproduce --n-sims 1000000000000 (a MemoryError after minutes before)", argv_case("lgp.reproduce", ["--n-sims", big])
    yield "lgp.reproduce --n-boot 1000000000000", argv_case("lgp.reproduce", ["--n-boot", big])
    yield "lgp.reproduce --samples 1000000000", argv_case("lgp.reproduce", ["--samples", "1000000000"])
    yield "lgp.reproduce --n-perm 1000000000", argv_case("lgp.reproduce", ["--n-perm", "1000000000"])
    yield "models.risk --n-sims 1000000000000", argv_case("models.risk.__main__", ["--n-sims", big])
    yield "models.effort --samples 1000000000", argv_case("models.effort.__main__", ["--samples", "1000000000"])
    yield "analysis.demo --n-boot 1000000000000", argv_case("analysis.demo", ["--n-boot", big])
    yield "stimuli.generate --count 1000000000000", argv_case("stimuli.generate", ["--out", "/nonexistent/x", "--count", big])

    yield "lgp.reproduce --scheduler tcp:// (no host)", argv_case("lgp.reproduce", ["--scheduler", "tcp://"])
    yield "lgp.reproduce --scheduler inproc://x", argv_case("lgp.reproduce", ["--scheduler", "inproc://x"])

    def loop_case(make, module="lgp.reproduce", flag="--stimuli"):
        def run():
            folder = Path(tempfile.mkdtemp(dir=tmp))
            try:
                return argv_case(module, [flag, str(make(folder))])()
            finally:
                shutil.rmtree(folder, ignore_errors=True)
        return run
    yield "lgp.reproduce --stimuli DIR, DIR a loop of symbolic links (\"does not exist\" before)", loop_case(
        lambda f: (f / "loop").symlink_to("loop") or f / "loop")

    def anchor_fifo():
        from stimuli import experiment as ex

        folder = Path(tempfile.mkdtemp(dir=tmp))
        try:
            os.mkfifo(folder / "anchor.yaml")
            return ex.load_anchor(folder / "anchor.yaml", "easy", set())
        finally:
            shutil.rmtree(folder, ignore_errors=True)
    yield "stimuli.experiment --anchor-easy FIFO (\"no such file\" before)", anchor_fifo

    def lock_fifo():
        from lgp.app.manifest import OutputLock

        folder = Path(tempfile.mkdtemp(dir=tmp))
        try:
            os.mkfifo(folder / OutputLock.NAME)
            with OutputLock(folder, "probe"):
                return "locked"
        finally:
            shutil.rmtree(folder, ignore_errors=True)
    yield "<out>/.lgp-run.lock a FIFO (\"[Errno 22] Invalid argument\" before)", lock_fifo

    def peer(reply):
        def run():
            import socket
            import threading

            from lgp.executor import DaskExecutor

            server = socket.socket()
            server.bind(("127.0.0.1", 0))
            server.listen(4)

            def serve():
                try:
                    c, _ = server.accept()
                    if reply:
                        c.sendall(reply)
                    time.sleep(3)
                    c.close()
                except OSError:
                    pass
            threading.Thread(target=serve, daemon=True).start()
            try:
                DaskExecutor(f"tcp://127.0.0.1:{server.getsockname()[1]}", timeout=2.0).close()
                return "connected"
            finally:
                server.close()
        return run
    yield "--scheduler at a peer answering junk (MemoryError, Client.__del__ traceback, 20 s before)", peer(b"junk junk " * 50)
    yield "--scheduler at an HTTP server (silent until asked; 14 s then a traceback before)", peer(None)

    def jobs():
        from lgp import cli
        from lgp.reproduce import parse_args

        err = io.StringIO()
        with contextlib.redirect_stderr(err):
            got = parse_args(["--jobs", "400"]).jobs
        if got <= cli.usable_cores() and "--oversubscribe" in err.getvalue():
            return f"accepted: capped at {got}: {err.getvalue().strip()}"
        raise AssertionError(f"--jobs 400 gave {got} workers")
    yield "lgp.reproduce --jobs 400 on 2 cores (started 400 workers)", ("accept", jobs)


# ----------------------------------------------------------------------------- the API


def api_cases():
    from models.risk import RiskModel, physical_risk
    from models.risk.structures import tower

    def risk(sigma=0.05, **kw):
        return lambda: physical_risk(tower(2), sigma, **{"n_sims": 3, "seed": 0, **kw})

    def model(**kw):  # the risk model is checked when made, inside the probe
        return lambda: physical_risk(tower(2), 0.05, n_sims=3, seed=0, model=RiskModel(**kw))

    for value in (float("inf"), 1e308, float("nan"), 1.5, -0.1, "0.1"):
        yield f"physical_risk sigma={value!r}", risk(value)
    for value in (2.5, "4", True, 0, 10**12):
        yield f"physical_risk n_sims={value!r}", risk(n_sims=value)
    for value in (None, -1, 1.5):
        yield f"physical_risk seed={value!r}", risk(seed=value)
    yield "physical_risk fall_rule='sideways'", model(fall_rule="sideways")
    yield "physical_risk fall_threshold=0", model(fall_threshold=0)
    yield "physical_risk engine='bullet'", model(engine="bullet")

    import lgp

    B = stimuli.load_trial("1E").target
    yield "lgp.plan(None, B)", lambda: lgp.plan(None, B)
    yield "lgp.plan(B, None)", lambda: lgp.plan(B, None)


# ----------------------------------------------------------------------------- cache entries


def table(trial, v):
    return pd.DataFrame({"trial": [trial] * 2, "sigma": [0.05, 0.1], "risk": [v, v / 2]})


def cache_cases(tmp: Path):
    from lgp.app.cache import entry_bytes

    def rewrite(f):
        return lambda p, c: p.write_bytes(f(p.read_bytes()))

    def old_format(p, c):
        body = table("1E", 0.2).to_csv(index=False).encode()
        p.write_bytes(b"# lgp.cache v1 rows=2 sha256=%s\n" % hashlib.sha256(body).hexdigest().encode() + body)

    def replace_with(make):
        def damage(p, c):
            p.unlink()
            make(p)
        return damage

    yield "truncated", rewrite(lambda b: b[: len(b) // 2])
    yield "emptied", rewrite(lambda b: b"")
    yield "one digit changed", rewrite(lambda b: b.replace(b"0.2", b"0.3"))
    yield "a line lost", rewrite(lambda b: b"\n".join(b.split(b"\n")[:-2]) + b"\n")
    yield "not UTF-8", rewrite(lambda b: b + b"\xff\xfe")
    yield "header stripped", rewrite(lambda b: b.split(b"\n", 1)[1])
    yield "another trial's entry copied over it (7H over 1E)", lambda p, c: shutil.copy(c.path("risk", "bbbb"), p)
    yield "written by the old format (no key)", old_format
    yield "symlink to /dev/zero", replace_with(lambda p: p.symlink_to("/dev/zero"))
    yield "a FIFO", replace_with(lambda p: os.mkfifo(p))
    yield "dangling symlink", replace_with(lambda p: p.symlink_to(p.parent / "gone"))
    def outside(p):
        (p.parent.parent / "out.csv").write_bytes(entry_bytes(table("1E", 0.2), "risk", "aaaa"))
        p.symlink_to(p.parent.parent / "out.csv")

    yield "symlink to a sound entry outside the cache", replace_with(outside)
    yield "a directory", replace_with(lambda p: p.mkdir())


def resigned_cases(tmp: Path):
    """Entries whose checksum holds (re-signed after the edit) but whose values are wrong."""
    from lgp.app.cache import Cache
    from lgp.app.manifest import TimedCache

    effort = pd.DataFrame({"trial": ["1E"] * 2, "sample": [0, 1], "effort": [0.5, 0.7], "n_actions": [4, 4],
                           "solve_time": [1.0, 1.1], "solver": "snopt", "status": "kSolutionFound"})
    runs = pd.DataFrame({"trial": "7H", "sigma": [0.05, 0.05, 0.1, 0.1], "run": [0, 1, 0, 1], "fell": [True, False] * 2,
                         "engine": "mujoco", "fall_rule": "horizontal", "fall_threshold": 0.25, "noise_rule": "lift"})

    def case(kind, df, column=None, value=None, rows=None):
        def run():
            root = Path(tempfile.mkdtemp(dir=tmp)) / "cache"
            bad = df.copy()
            if column is not None:
                bad[column] = bad[column].astype(object)
                bad.loc[1, column] = value
            Cache(root).put(kind, "k", bad)  # written and signed as a sound entry would be
            fresh = Cache(root)
            err = io.StringIO()
            with contextlib.redirect_stderr(err):
                got = fresh.get(kind, "k", rows=rows)
            if got is None and fresh.recomputed == 1 and fresh.computed == 1:
                return f"recomputed: {err.getvalue().strip().split(': ', 2)[-1][:150]}"
            return f"used: {got.to_dict('list') if got is not None else None}"
        return run

    yield "re-signed effort entry with effort `abc` (a TypeError before)", case("effort", effort, "effort", "abc")
    yield "re-signed effort entry with effort -1e308 (published as -3.3e+307,inf)", case("effort", effort, "effort", -1e308)
    yield "re-signed effort entry with effort inf", case("effort", effort, "effort", float("inf"))
    yield "re-signed risk runs with fell `maybe`", case("riskruns", runs, "fell", "maybe")
    yield "re-signed risk runs with sigma 2", case("riskruns", runs, "sigma", 2.0)
    yield "re-signed risk runs with rows missing", case("riskruns", runs, rows=6)

    def times():
        root = Path(tempfile.mkdtemp(dir=tmp)) / "cache"
        root.mkdir()
        (root / "compute_times.json").write_text('{"x": null, "y": "abc"}')
        cache = TimedCache(root)
        with cache.stage():
            cache.put("effort", "k", effort)
        return f"recomputed: the bad times dropped, the rerun goes on ({cache.load_times()})"
    yield "compute_times.json `{\"x\": null}` (crashed every rerun)", times


# ----------------------------------------------------------------------------- output folders (issue 30)


def _snapshot(folder: Path) -> dict:
    """path -> sha256 (or link target) of everything under `folder`."""
    out = {}
    for p in sorted(folder.rglob("*")):
        if p.is_symlink():
            out[p.relative_to(folder).as_posix()] = "-> " + os.readlink(p)
        elif p.is_file():
            out[p.relative_to(folder).as_posix()] = hashlib.sha256(p.read_bytes()).hexdigest()
    return out


def output_cases(tmp: Path):
    """What lgp.reproduce and stimuli.experiment do with a folder that holds what they
    did not write: a refusal must leave it byte-identical; a kept case must keep
    every foreign file byte-identical while the run's own files are replaced."""
    import json

    from lgp import owned
    from lgp.app.manifest import OutputLock, check_output_folder

    def folder(files, manifest=None):
        root = Path(tempfile.mkdtemp(dir=tmp)) / "out"
        for rel, data in files.items():
            (root / rel).parent.mkdir(parents=True, exist_ok=True)
            (root / rel).write_bytes(data.encode() if isinstance(data, str) else data)
        root.mkdir(exist_ok=True)
        if manifest is not None:
            listed = [{"path": r, "sha256": hashlib.sha256((root / r).read_bytes()).hexdigest()} for r in manifest]
            (root / "manifest.json").write_text(json.dumps({"command": ["python -m lgp.reproduce"], "files": listed}))
        return root

    def untouched(make, act):
        """A refusal case: `act(root)` must raise, the folder byte-identical."""
        def run():
            root = make()
            before = _snapshot(root)
            try:
                act(root)
            except BaseException:
                if _snapshot(root) != before:
                    return "FAILURE: refused, but the folder changed"
                raise
            return "went ahead"
        return run

    def kept(make, act, keep):
        """A case that proceeds: the files in `keep` must stay byte-identical."""
        def run():
            root = make()
            before = {k: v for k, v in _snapshot(root).items() if k in keep}
            said = act(root)
            after = _snapshot(root)
            lost = [k for k in keep if after.get(k) != before.get(k)]
            if lost:
                raise AssertionError(f"lost or changed: {lost}")
            return f"{said}; kept byte-identical: {', '.join(keep)}"
        return ("accept", run)

    thesis = {"analysis/thesis.R": "library(lme4)\n", "figures/mine.png": b"\x89PNG mine", "report.md": "mine\n",
              "index.html": "<p>mine</p>"}
    yield ("lgp.reproduce --out DIR: the user's analysis/thesis.R, figures/mine.png, report.md, index.html, "
           "no manifest (all deleted before)"), untouched(lambda: folder(thesis), check_output_folder)
    checkout = {"analysis/__init__.py": "", "lgp/__init__.py": "", "README.md": "# project\n", "docs/faults.md": "x"}
    yield "lgp.reproduce --out . in a checkout (deleted the analysis/ package before)", \
        untouched(lambda: folder(checkout), check_output_folder)
    yield "--into-existing, the user's report.md where a run writes one", \
        untouched(lambda: folder(thesis), lambda r: check_output_folder(r, into_existing=True))
    yield "--into-existing beside analysis/thesis.R and figures/mine.png", kept(
        lambda: folder({k: v for k, v in thesis.items() if "/" in k}),
        lambda r: f"accepted: {check_output_folder(r, into_existing=True)}", ["analysis/thesis.R", "figures/mine.png"])
    yield "a manifest.json of another program", untouched(
        lambda: folder({"manifest.json": '{"name": "web app"}', "app.js": "x"}), check_output_folder)
    yield "manifest.json linked to /dev/zero", untouched(
        lambda: (lambda r: ((r / "manifest.json").symlink_to("/dev/zero"), r)[1])(folder({"report.md": "x"})),
        check_output_folder)
    yield "an earlier run's report.md edited by hand", untouched(
        lambda: (lambda r: ((r / "report.md").write_text("edited\n"), r)[1])(folder({"report.md": "run\n"}, ["report.md"])),
        check_output_folder)

    def swap(root, new, earlier_listed=True):
        entries = owned.manifest_entries(json.loads((root / "manifest.json").read_text()))
        stage = owned.new_staging(root)
        for rel, data in new.items():
            (stage / rel).parent.mkdir(parents=True, exist_ok=True)
            (stage / rel).write_text(data)
        (stage / "manifest.json").write_text(json.dumps({"command": ["python -m lgp.reproduce"], "files": []}))
        try:
            removed = owned.swap_in(root, stage, entries, "manifest.json")
        finally:
            owned.remove_staging(stage)
        return f"removed the earlier run's own {removed}"

    yield "a new run's file over the user's figures/orderings.csv (at the swap)", untouched(
        lambda: folder({"effort.csv": "old", "figures/orderings.csv": "mine"}, ["effort.csv"]),
        lambda r: swap(r, {"effort.csv": "new", "figures/orderings.csv": "run's"}))
    yield "a rerun beside the user's figures/mine.png, notes.md and an edited listed risk.csv", kept(
        lambda: (lambda r: ((r / "risk.csv").write_text("edited"), r)[1])(
            folder({"effort.csv": "old", "risk.csv": "old", "figures/a.png": "old", "figures/mine.png": "mine",
                    "notes.md": "mine"}, ["effort.csv", "risk.csv", "figures/a.png"])),
        lambda r: swap(r, {"effort.csv": "new"}), ["figures/mine.png", "notes.md", "risk.csv"])
    elsewhere = tmp / "elsewhere"

    def linked(r):
        elsewhere.mkdir(exist_ok=True)
        (elsewhere / "important.txt").write_text("keep")
        (r / "page").symlink_to(elsewhere)
        (r / "manifest.json").write_text(json.dumps({"command": ["python -m lgp.reproduce"], "files": [
            {"path": "page/important.txt", "sha256": hashlib.sha256(b"keep").hexdigest()}]}))
        return r

    yield "the manifest lists page/important.txt, page a link to a folder outside", kept(
        lambda: linked(folder({})), lambda r: swap(r, {}) + f"; outside: {(elsewhere / 'important.txt').read_text()}",
        ["page"])

    def nested(first, second):
        def act(root):
            (root / first).mkdir(parents=True, exist_ok=True)
            (root / second).mkdir(parents=True, exist_ok=True)
            with OutputLock(root / first, f"python -m lgp.reproduce --out {first}"):
                with OutputLock(root / second):
                    return "both locked"
        return act

    yield "two runs: --out rn, then --out rn/figures", untouched(lambda: folder({}), nested("rn", "rn/figures"))
    yield "two runs: --out rn/figures, then --out rn", untouched(lambda: folder({}), nested("rn/figures", "rn"))

    def study(files):
        def act(root):
            from stimuli import experiment as ex

            return f"accepted: {ex.check_output_dir(root)}"
        return act

    yield "stimuli.experiment --out DIR: thesis.tex, no study.json", untouched(lambda: folder({"thesis.tex": "x"}), study({}))
    stray = {"study": "abc", "build": "b", "files": {"index.html": hashlib.sha256(b"theirs").hexdigest()}}
    yield "stimuli.experiment: a stray study.json and the user's index.html (wiped before)", untouched(
        lambda: folder({"thesis.tex": "x", "index.html": "mine", "study.json": json.dumps(stray)}), study({}))
    yield "stimuli.experiment: a study.json of another program", untouched(
        lambda: folder({"study.json": '{"x": 1}'}), study({}))


def main(argv=None) -> int:
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--out", type=Path, default=ROOT / "docs" / "faults.md")
    args = p.parse_args(argv)
    rows = []
    with tempfile.TemporaryDirectory() as tmp:
        tmp = Path(tmp)
        groups = [("trial file", trial_cases(tmp)), ("human data", human_cases(tmp)),
                  ("study import", import_cases(tmp)), ("output folder", output_cases(tmp)), ("command line", command_cases(tmp)), ("API", api_cases()),
                  ("cache entry", itertools.chain(((n, _cache_run(d, tmp)) for n, d in cache_cases(tmp)),
                                                  resigned_cases(tmp)))]
        for group, cases in groups:
            for name, run in cases:
                accept = False
                if isinstance(run, tuple):
                    accept, run = True, run[1]
                if run == "crowded":
                    run = lambda: crowded(tmp)  # noqa: E731
                verdict, what = judge(run, accept)
                rows.append((group, name, verdict, what.replace("|", "\\|").replace(str(tmp), "TMP").replace(str(ROOT), "<repo>")))
                print(f"{verdict:>22}  {group}: {name}: {what[:150]}", flush=True)
    bad = [r for r in rows if not r[2].startswith("accepted")]
    refused = [r for r in bad if r[2] in ("refused", "recomputed")]
    accepted = [r for r in rows if r[2].startswith("accepted")]
    lines = ["## Bad inputs tried", "",
             f"`python bench/faults.py` on {machine()}: **{len(refused)} of {len(bad)} bad inputs refused** in one "
             "named line (or, for a cache entry, reported and recomputed), none after a hang or a traceback; "
             f"{len(accepted)} inputs the formats allow were accepted as designed. "
             f"By kind: " + ", ".join(f"{g} {sum(1 for r in refused if r[0] == g)}/{sum(1 for r in bad if r[0] == g)}"
                                      for g in ("trial file", "human data", "study import", "output folder", "command line", "API",
                                                "cache entry")) + ".", "",
             "| kind | input | verdict | what the project does |", "|---|---|---|---|"]
    bar = "\\|"
    lines += [f"| {g} | {n.replace('|', bar)} | {v} | {w[:220]} |" for g, n, v, w in rows]
    write_section(args.out, "Bad inputs tried", "\n".join(lines) + "\n")
    print(f"{len(refused)}/{len(bad)} bad inputs refused; {len(accepted)} accepted by design")
    return 0 if len(refused) == len(bad) else 1


def _cache_run(damage, tmp):
    """A case: two sound entries, `damage` done to the first, then a fresh Cache reads it."""
    from lgp.app.cache import Cache

    def run():
        root = Path(tempfile.mkdtemp(dir=tmp)) / "cache"
        cache = Cache(root)
        cache.put("risk", "aaaa", table("1E", 0.2))
        cache.put("risk", "bbbb", table("7H", 0.9))
        damage(cache.path("risk", "aaaa"), cache)
        fresh = Cache(root)
        with open(os.devnull, "w") as null, contextlib.redirect_stderr(null):
            got = fresh.get("risk", "aaaa")
        if got is None and fresh.count("recomputed") == 1:
            return "recomputed (reported in one line on stderr, never used)"
        return f"used: {got['trial'].tolist() if got is not None else None}"
    return run


if __name__ == "__main__":
    raise SystemExit(main())
