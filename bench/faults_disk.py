"""What bench/faults.py finds on disk: damaged cache entries (recomputed, never used)
and output folders that hold what a run did not write (refused, or kept byte-identical).
Each `*_cases(tmp)` yields (input, case) as in bench/faults_files.py."""
from __future__ import annotations

import contextlib
import hashlib
import io
import json
import os
import shutil
import tempfile
from pathlib import Path

import pandas as pd


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


# ----------------------------------------------------------------------------- output folders


def _snapshot(folder: Path) -> dict:
    """path -> sha256 (or link target) of everything under `folder`."""
    out = {}
    for p in sorted(folder.rglob("*")):
        if p.is_symlink():
            out[p.relative_to(folder).as_posix()] = "-> " + os.readlink(p)
        elif p.is_file():
            out[p.relative_to(folder).as_posix()] = hashlib.sha256(p.read_bytes()).hexdigest()
    return out


def _folder(tmp: Path, files, manifest=None):
    """A fresh folder `out` holding `files` (path -> text or bytes), with a manifest.json
    of lgp.reproduce listing `manifest` when given."""
    root = Path(tempfile.mkdtemp(dir=tmp)) / "out"
    for rel, data in files.items():
        (root / rel).parent.mkdir(parents=True, exist_ok=True)
        (root / rel).write_bytes(data.encode() if isinstance(data, str) else data)
    root.mkdir(exist_ok=True)
    if manifest is not None:
        listed = [{"path": r, "sha256": hashlib.sha256((root / r).read_bytes()).hexdigest()} for r in manifest]
        (root / "manifest.json").write_text(json.dumps({"command": ["python -m lgp.reproduce"], "files": listed}))
    return root


def _untouched(make, act):
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


def _kept(make, act, keep):
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


def _swap(root, new, earlier_listed=True):
    """Swap a new run's files `new` into `root` as lgp.owned does at the end of a run."""
    from lgp import owned

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


def _linked(elsewhere: Path, r):
    """`r` with a link `page` to the folder `elsewhere`, and a manifest listing a file through it."""
    elsewhere.mkdir(exist_ok=True)
    (elsewhere / "important.txt").write_text("keep")
    (r / "page").symlink_to(elsewhere)
    (r / "manifest.json").write_text(json.dumps({"command": ["python -m lgp.reproduce"], "files": [
        {"path": "page/important.txt", "sha256": hashlib.sha256(b"keep").hexdigest()}]}))
    return r


def _nested(first, second):
    """`act`: lock `first`, then, inside, `second` (one inside the other)."""
    from lgp.app.manifest import OutputLock

    def act(root):
        (root / first).mkdir(parents=True, exist_ok=True)
        (root / second).mkdir(parents=True, exist_ok=True)
        with OutputLock(root / first, f"python -m lgp.reproduce --out {first}"):
            with OutputLock(root / second):
                return "both locked"
    return act


def _study(files):
    """`act`: stimuli.experiment's check of its output folder."""
    def act(root):
        from stimuli import experiment as ex

        return f"accepted: {ex.check_output_dir(root)}"
    return act


def _render(root):
    """`act`: stimuli.render's check of its output folder (before any picture renders)."""
    import stimuli
    from stimuli.render.run import _refuse_foreign

    _refuse_foreign(root, ["1E-A.png", "1E-B.png"])
    return f"accepted ({len(stimuli.trial_ids())} trials)"


def output_cases(tmp: Path):
    """What lgp.reproduce and stimuli.experiment do with a folder that holds what they
    did not write: a refusal must leave it byte-identical; a kept case must keep
    every foreign file byte-identical while the run's own files are replaced."""
    from lgp.app.manifest import check_output_folder

    thesis = {"analysis/thesis.R": "library(lme4)\n", "figures/mine.png": b"\x89PNG mine", "report.md": "mine\n",
              "index.html": "<p>mine</p>"}
    yield ("lgp.reproduce --out DIR: the user's analysis/thesis.R, figures/mine.png, report.md, index.html, "
           "no manifest (all deleted before)"), _untouched(lambda: _folder(tmp, thesis), check_output_folder)
    checkout = {"analysis/__init__.py": "", "lgp/__init__.py": "", "README.md": "# project\n", "docs/faults.md": "x"}
    yield "lgp.reproduce --out . in a checkout (deleted the analysis/ package before)", \
        _untouched(lambda: _folder(tmp, checkout), check_output_folder)
    yield "--into-existing, the user's report.md where a run writes one", \
        _untouched(lambda: _folder(tmp, thesis), lambda r: check_output_folder(r, into_existing=True))
    yield "--into-existing beside analysis/thesis.R and figures/mine.png", _kept(
        lambda: _folder(tmp, {k: v for k, v in thesis.items() if "/" in k}),
        lambda r: f"accepted: {check_output_folder(r, into_existing=True)}", ["analysis/thesis.R", "figures/mine.png"])
    yield "a manifest.json of another program", _untouched(
        lambda: _folder(tmp, {"manifest.json": '{"name": "web app"}', "app.js": "x"}), check_output_folder)
    yield "manifest.json linked to /dev/zero", _untouched(
        lambda: (lambda r: ((r / "manifest.json").symlink_to("/dev/zero"), r)[1])(_folder(tmp, {"report.md": "x"})),
        check_output_folder)
    yield "an earlier run's report.md edited by hand", _untouched(
        lambda: (lambda r: ((r / "report.md").write_text("edited\n"), r)[1])(_folder(tmp, {"report.md": "run\n"}, ["report.md"])),
        check_output_folder)

    yield "a new run's file over the user's figures/orderings.csv (at the swap)", _untouched(
        lambda: _folder(tmp, {"effort.csv": "old", "figures/orderings.csv": "mine"}, ["effort.csv"]),
        lambda r: _swap(r, {"effort.csv": "new", "figures/orderings.csv": "run's"}))
    yield "a rerun beside the user's figures/mine.png, notes.md and an edited listed risk.csv", _kept(
        lambda: (lambda r: ((r / "risk.csv").write_text("edited"), r)[1])(
            _folder(tmp, {"effort.csv": "old", "risk.csv": "old", "figures/a.png": "old", "figures/mine.png": "mine",
                          "notes.md": "mine"}, ["effort.csv", "risk.csv", "figures/a.png"])),
        lambda r: _swap(r, {"effort.csv": "new"}), ["figures/mine.png", "notes.md", "risk.csv"])
    elsewhere = tmp / "elsewhere"

    yield "the manifest lists page/important.txt, page a link to a folder outside", _kept(
        lambda: _linked(elsewhere, _folder(tmp, {})),
        lambda r: _swap(r, {}) + f"; outside: {(elsewhere / 'important.txt').read_text()}", ["page"])

    yield "two runs: --out rn, then --out rn/figures", _untouched(lambda: _folder(tmp, {}), _nested("rn", "rn/figures"))
    yield "two runs: --out rn/figures, then --out rn", _untouched(lambda: _folder(tmp, {}), _nested("rn/figures", "rn"))

    yield "stimuli.experiment --out DIR: thesis.tex, no study.json", _untouched(lambda: _folder(tmp, {"thesis.tex": "x"}), _study({}))
    stray = {"study": "abc", "build": "b", "files": {"index.html": hashlib.sha256(b"theirs").hexdigest()}}
    yield "stimuli.experiment: a stray study.json and the user's index.html (wiped before)", _untouched(
        lambda: _folder(tmp, {"thesis.tex": "x", "index.html": "mine", "study.json": json.dumps(stray)}), _study({}))
    yield "stimuli.experiment: a study.json of another program", _untouched(
        lambda: _folder(tmp, {"study.json": '{"x": 1}'}), _study({}))

    yield "stimuli.render --out DIR: the user's 1E-A.png and thesis.txt, no renders.json (overwritten before)", _untouched(
        lambda: _folder(tmp, {"1E-A.png": b"\x89PNG my photograph", "thesis.txt": "x"}), _render)
    yield "stimuli.render: a renders.json of another program", _untouched(
        lambda: _folder(tmp, {"renders.json": '{"pictures": "queue"}'}), _render)
    from lgp.owned import csv_record, json_record, refuse_foreign_folder

    for command, record, ours in (("analysis.mental_jenga", "summary.json", json_record("rules", "human_means")),
                                  ("analysis.power", "power.csv", csv_record("world", "procedure", "verdict")),
                                  ("stimuli.design", "design.json", json_record("written", "config"))):
        yield f"{command}: the user's own {record} beside their notes (licensed writing before)", _untouched(
            lambda record=record: _folder(tmp, {record: "mine\n", "notes.md": "mine"}),
            lambda r, record=record, ours=ours: refuse_foreign_folder(r, record, is_ours=ours))
