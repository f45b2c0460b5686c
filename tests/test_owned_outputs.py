"""A command deletes only what it can prove it wrote (issue 30, data loss): files an
earlier run's manifest lists with the same sha256. A folder of foreign files without
a manifest is refused; a run's files are written beside the earlier run's and
swapped in at the end, so a failed or stopped run leaves those byte-identical; and
locks cover nested and enclosing output folders. The rule lives in lgp/owned.py."""
import hashlib
import json
import os
from pathlib import Path

import pytest

from lgp import owned
from lgp.app import run as app_run
from lgp.app import write as app_write
from lgp.app.manifest import OutputFolderBusy, OutputLock, check_output_folder

ROOT = Path(__file__).resolve().parents[1]
PROG = "python -m lgp.reproduce"


def snapshot(folder: Path, skip=("cache",)) -> dict[str, str]:
    """Every file and link under `folder` (the cache left out): path -> sha256 or link target."""
    out = {}
    for dirpath, dirnames, filenames in os.walk(folder):
        rel_dir = Path(dirpath).relative_to(folder)
        dirnames[:] = [d for d in dirnames if not (rel_dir == Path(".") and d in skip)]
        for name in filenames + [d for d in dirnames if (Path(dirpath) / d).is_symlink()]:
            p = Path(dirpath) / name
            rel = p.relative_to(folder).as_posix()
            out[rel] = "-> " + os.readlink(p) if p.is_symlink() else hashlib.sha256(p.read_bytes()).hexdigest()
    return out


def sha(data: bytes) -> str:
    return hashlib.sha256(data).hexdigest()


def earlier_run(out: Path, files: dict[str, bytes]) -> dict:
    """A folder as an earlier run left it: `files` and a manifest listing them."""
    out.mkdir(parents=True, exist_ok=True)
    for rel, data in files.items():
        (out / rel).parent.mkdir(parents=True, exist_ok=True)
        (out / rel).write_bytes(data)
    manifest = {"command": [PROG, "--out", str(out)],
                "files": [{"path": rel, "bytes": len(d), "sha256": sha(d)} for rel, d in files.items()]}
    (out / "manifest.json").write_text(json.dumps(manifest))
    return manifest


def new_run(out: Path, files: dict[str, bytes]) -> Path:
    """A run's staging folder holding `files` and their manifest."""
    stage = owned.new_staging(out)
    for rel, data in files.items():
        (stage / rel).parent.mkdir(parents=True, exist_ok=True)
        (stage / rel).write_bytes(data)
    (stage / "manifest.json").write_text(json.dumps(
        {"command": [PROG], "files": [{"path": rel, "sha256": sha(d)} for rel, d in files.items()]}))
    return stage


# ----------------------------------------------------------------------------- refusing a folder


def test_a_folder_of_foreign_files_without_a_manifest_is_refused_unless_into_existing(tmp_path):
    out = tmp_path / "thesis"
    (out / "analysis").mkdir(parents=True)
    (out / "analysis" / "thesis.R").write_text("library(lme4)\n")
    (out / "figures").mkdir()
    (out / "figures" / "mine.png").write_bytes(b"\x89PNG mine")
    before = snapshot(out)
    with pytest.raises(owned.ForeignFiles, match=r"holds files no run of python -m lgp.reproduce wrote "
                                                  r"\(analysis, figures\) and no manifest.json.*--into-existing"):
        check_output_folder(out)
    assert check_output_folder(out, into_existing=True) == {}
    assert snapshot(out) == before
    (tmp_path / "empty").mkdir()
    assert check_output_folder(tmp_path / "empty") == {} and check_output_folder(tmp_path / "new") == {}


def test_a_users_file_with_an_output_name_is_refused_even_into_existing(tmp_path):
    out = tmp_path / "out"
    out.mkdir()
    (out / "report.md").write_text("my report\n")
    with pytest.raises(owned.ForeignFiles, match=r"report.md there is not an earlier run's output.*would overwrite it"):
        check_output_folder(out, into_existing=True)
    # an earlier run's report edited since: no longer what the run wrote
    earlier_run(out, {"report.md": b"the run's report\n"})
    assert check_output_folder(out) == {"report.md": {sha(b"the run's report\n")}}
    (out / "report.md").write_text("edited by hand\n")
    with pytest.raises(owned.ForeignFiles, match="report.md there is not an earlier run's output"):
        check_output_folder(out)


def test_a_manifest_of_another_program_is_never_replaced(tmp_path):
    out = tmp_path / "web"
    out.mkdir()
    (out / "manifest.json").write_text('{"name": "my web app", "icons": []}')
    for into in (False, True):
        with pytest.raises(owned.ForeignFiles, match="manifest.json was not written by python -m lgp.reproduce"):
            check_output_folder(out, into_existing=into)
    (out / "manifest.json").unlink()
    (out / "manifest.json").symlink_to("/dev/zero")
    with pytest.raises(owned.ForeignFiles, match="manifest.json was not written"):
        check_output_folder(out)


def _checkout(tmp_path) -> Path:
    """A copy of a checkout-like folder: packages analysis/ and lgp/, docs, a README, a report.md."""
    checkout = tmp_path / "checkout"
    for rel in ("analysis/__init__.py", "analysis/run.py", "lgp/__init__.py", "docs/faults.md", "README.md",
                "figures/fig1.png", "report.md"):
        (checkout / rel).parent.mkdir(parents=True, exist_ok=True)
        (checkout / rel).write_text(f"the project's {rel}\n")
    return checkout


def test_out_dot_in_a_checkout_is_refused_and_into_existing_would_not_overwrite_its_files(tmp_path, monkeypatch):
    checkout = _checkout(tmp_path)
    before = snapshot(checkout, skip=())
    monkeypatch.chdir(checkout)
    with pytest.raises(owned.ForeignFiles, match=r"--out \. holds files no run .*\(README.md, analysis, docs, figures, \.\.\.\)"):
        check_output_folder(Path("."))
    with pytest.raises(owned.ForeignFiles, match="report.md there is not an earlier run's output"):
        check_output_folder(Path("."), into_existing=True)
    assert snapshot(checkout, skip=()) == before


@pytest.mark.slow  # the command line's imports (~8 s cold)
def test_out_dot_in_a_checkout_is_refused_in_one_line_and_nothing_changes(tmp_path, capsys, monkeypatch):
    from lgp import reproduce

    checkout = _checkout(tmp_path)
    before = snapshot(checkout, skip=())
    monkeypatch.chdir(checkout)
    assert reproduce.main(["--trials", "1E", "--samples", "1", "--n-sims", "2", "--jobs", "1", "--out", "."]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and err[0].startswith("python -m lgp.reproduce: error: --out . holds files no run"), err
    assert snapshot(checkout, skip=()) == before


# ----------------------------------------------------------------------------- the swap


def test_the_swap_removes_only_the_earlier_runs_own_files_and_keeps_everything_else(tmp_path):
    out = tmp_path / "out"
    earlier = earlier_run(out, {"effort.csv": b"old effort\n", "risk.csv": b"old risk\n", "figures/a.png": b"old a",
                                "figures/b.png": b"old b", "recovery/x.csv": b"old x\n", "report.md": b"old report\n"})
    (out / "figures" / "mine.png").write_bytes(b"the user's figure")     # foreign, inside an output folder
    (out / "notes.md").write_text("the user's notes\n")                  # foreign, at the top
    (out / "risk.csv").write_bytes(b"old risk, edited by hand\n")        # listed, but changed since
    (out / "cache").mkdir()
    (out / "cache" / "effort-k.csv").write_text("entry\n")
    elsewhere = tmp_path / "elsewhere"
    elsewhere.mkdir()
    (elsewhere / "x.csv").write_text("behind a link\n")
    (out / "recovery" / "x.csv").unlink()
    (out / "recovery").rmdir()
    (out / "recovery").symlink_to(elsewhere)                             # a listed file behind a link
    keep = {k: v for k, v in snapshot(out).items() if k in ("figures/mine.png", "notes.md", "risk.csv", "recovery")}
    stage = new_run(out, {"effort.csv": b"new effort\n", "figures/a.png": b"new a", "index.html": b"<html>"})

    removed = owned.swap_in(out, stage, owned.manifest_entries(earlier), "manifest.json")

    assert removed == ["figures/b.png", "report.md"]
    after = snapshot(out)
    assert {k: after[k] for k in keep} == keep
    assert (elsewhere / "x.csv").read_text() == "behind a link\n" and (out / "cache" / "effort-k.csv").exists()
    assert (out / "effort.csv").read_bytes() == b"new effort\n" and (out / "figures" / "a.png").read_bytes() == b"new a"
    assert json.loads((out / "manifest.json").read_text())["files"][0]["path"] == "effort.csv"
    assert not [p for p in out.iterdir() if p.name.startswith(owned.STAGING_PREFIX)]


def test_a_new_file_over_a_foreign_one_moves_nothing(tmp_path):
    out = tmp_path / "out"
    earlier = earlier_run(out, {"effort.csv": b"old\n"})
    (out / "figures").mkdir()
    (out / "figures" / "orderings.csv").write_text("the user's table\n")
    before = snapshot(out)
    stage = new_run(out, {"effort.csv": b"new\n", "figures/orderings.csv": b"run's table\n"})
    with pytest.raises(owned.ForeignFiles, match=r"figures/orderings.csv would replace what this command did not write"):
        owned.swap_in(out, stage, owned.manifest_entries(earlier), "manifest.json")
    owned.remove_staging(stage)
    assert snapshot(out) == before and not list(out.glob(".lgp-new-*"))


def test_a_staging_folder_is_removed_only_when_it_is_a_runs(tmp_path):
    stage = new_run(tmp_path, {"effort.csv": b"x"})
    user = tmp_path / ".lgp-new-mine"  # the user's folder of that name, without the mark
    user.mkdir()
    (user / "keep.txt").write_text("keep")
    owned.remove_stale_staging(tmp_path)
    assert not stage.exists() and (user / "keep.txt").read_text() == "keep"


def test_an_interim_manifest_proves_both_runs_files(tmp_path):
    """A process killed while moving its files in leaves a manifest listing both runs'
    files: every file in the folder is still provably the command's own."""
    data = {"files": [{"path": "effort.csv", "sha256": sha(b"new")}], "files_earlier": {"effort.csv": sha(b"old"),
                                                                                       "report.md": sha(b"r")}}
    assert owned.manifest_entries(data) == {"effort.csv": {sha(b"new"), sha(b"old")}, "report.md": {sha(b"r")}}


# ----------------------------------------------------------------------------- locks over a tree


@pytest.mark.parametrize("first, second", [("rn", "rn/figures"), ("rn/figures", "rn"), ("a/b", "a/b/c/d")])
def test_two_runs_in_nested_folders_cannot_both_proceed(tmp_path, first, second):
    (tmp_path / first).mkdir(parents=True, exist_ok=True)
    (tmp_path / second).mkdir(parents=True, exist_ok=True)
    with OutputLock(tmp_path / first, f"{PROG} --out {first}"):
        with pytest.raises(OutputFolderBusy, match=rf"the output folder of another run \(process {os.getpid()}"):
            with OutputLock(tmp_path / second):
                pass
        assert not (tmp_path / second / OutputLock.NAME).exists()  # the refused run let go of its own folder
    with OutputLock(tmp_path / second):  # free again
        pass


def test_runs_in_sibling_folders_both_proceed(tmp_path):
    (tmp_path / "a").mkdir()
    (tmp_path / "b").mkdir()
    with OutputLock(tmp_path / "a"), OutputLock(tmp_path / "b"):
        pass


def test_the_nested_message_names_the_inner_run(tmp_path):
    (tmp_path / "rn" / "figures").mkdir(parents=True)
    with OutputLock(tmp_path / "rn" / "figures", f"{PROG} --out rn/figures"):
        with pytest.raises(OutputFolderBusy, match=rf"holds {tmp_path / 'rn' / 'figures'}, the output folder of another "
                                                   rf"run \(process {os.getpid()}: {PROG} --out rn/figures\)"):
            with OutputLock(tmp_path / "rn"):
                pass


# ----------------------------------------------------------------------------- whole runs


@pytest.mark.slow  # one tiny run, four that fail at each stage, and one that replaces it
def test_a_run_that_fails_at_any_stage_leaves_the_earlier_runs_files_byte_identical(tmp_path, capsys, monkeypatch):
    import yaml

    import stimuli
    from lgp import reproduce
    from lgp.atomic import DiskFull
    from lgp.cli import is_known_error

    out = tmp_path / "results"
    out.mkdir()
    (out / "thesis.tex").write_text("\\chapter{mine}\n")  # the user's: the first run needs --into-existing
    tiny = ["--trials", "1E", "--samples", "1", "--n-sims", "2", "--sigmas", "0.065", "--jobs", "1", "--n-boot", "10",
            "--no-replays", "--out", str(out)]
    assert reproduce.main(tiny) == 2
    assert reproduce.main([*tiny, "--into-existing"]) == 0
    capsys.readouterr()
    before = snapshot(out)

    def unchanged():
        assert snapshot(out) == before
        assert not list(out.glob(owned.STAGING_PREFIX + "*"))

    # an unreachable scheduler: fails as the work starts
    with pytest.raises(Exception) as e:
        reproduce.main([*tiny, "--seed", "1", "--scheduler", "tcp://127.0.0.1:1"])
    assert is_known_error(e.value)
    unchanged()
    # a trial whose B is unstable: refused at the first check of the work
    folder = tmp_path / "trials"
    folder.mkdir()
    data = yaml.safe_load((stimuli.TRIAL_DIR / "6E.yaml").read_text())
    data.update(id="13E", pair=13, level="E")
    data["target"]["blocks"] = [{"name": "b1", "p_WB": [0.35, 0.0, 0.0127]},
                                {"name": "b2", "p_WB": [0.35 + 0.7 * 0.0254, 0.0, 0.0381]}]  # overhangs 70 %
    (folder / "13E.yaml").write_text(yaml.safe_dump(data))
    with pytest.raises(Exception, match="13E-B: unstable before any noise"):
        reproduce.main([*tiny[2:], "--trials", "13E", "--stimuli", str(folder)])
    unchanged()
    # Ctrl-C in the risk stage of a run with new settings
    real_risk = app_run.risk_tables

    def interrupted(*a, **k):
        raise KeyboardInterrupt

    monkeypatch.setattr(app_run, "risk_tables", interrupted)
    assert reproduce.main([*tiny, "--seed", "2"]) == 130
    unchanged()
    monkeypatch.setattr(app_run, "risk_tables", real_risk)
    # a full disk while writing the report
    def full(*a, **k):
        raise DiskFull(28, "No space left on device: the disk is full", str(out / "report.md"))

    monkeypatch.setattr(app_write, "write_report", full)
    with pytest.raises(DiskFull):
        reproduce.main([*tiny, "--seed", "2"])
    unchanged()
    monkeypatch.undo()
    # a failed run into a new folder leaves no empty folder behind
    with pytest.raises(Exception):
        reproduce.main([*tiny[:-1], str(tmp_path / "new" / "deep"), "--scheduler", "tcp://127.0.0.1:1"])
    assert not (tmp_path / "new").exists()
    # and a run that succeeds replaces the earlier run's files; the user's stay
    assert reproduce.main([*tiny, "--seed", "2"]) == 0
    assert (out / "thesis.tex").read_text() == "\\chapter{mine}\n"
    manifest = json.loads((out / "manifest.json").read_text())
    assert manifest["parameters"]["seed"] == 2
    listed = {f["path"] for f in manifest["files"]}
    assert set(snapshot(out)) == listed | {"manifest.json", "thesis.tex"}


# ----------------------------------------------------------------------------- study folders (stimuli.experiment)


@pytest.fixture
def quick_builds(tmp_path, monkeypatch):
    """build_study without npm or the renderer: jsPsych's files and the pictures are
    stand-ins (what is tested is which files a build writes, keeps and removes)."""
    from stimuli import experiment as ex

    nm = tmp_path / "node_modules"
    for src in ex.JSPSYCH_FILES:
        (nm / src).parent.mkdir(parents=True, exist_ok=True)
        (nm / src).write_text(f"// {src}\n")
    renders = tmp_path / "renders"
    renders.mkdir()

    def render(plan, size, jobs, log):
        pictures = []
        for t in [*plan.trials, *plan.anchors]:
            for state in ("A", "B"):
                (renders / f"{t.id}-{state}.png").write_bytes(f"{t.id}-{state}".encode())
                pictures.append({"trial": t.id, "file": f"{t.id}-{state}.png"})
        return renders, {"pictures": pictures, "renderer": "stand-in", "camera": {"width": 96, "height": 64}, "cameras": {}}

    monkeypatch.setattr(ex, "ensure_jspsych", lambda log=None: nm)
    monkeypatch.setattr(ex, "_render", render)
    return ex


def _trials(folder: Path, ids) -> Path:
    import stimuli

    folder.mkdir(exist_ok=True)
    for old in folder.glob("*.yaml"):
        old.unlink()
    for tid in ids:
        (folder / f"{tid}.yaml").write_text((stimuli.TRIAL_DIR / f"{tid}.yaml").read_text())
    return folder


def test_a_rebuild_keeps_the_studys_collected_data_and_removes_only_its_own_files(tmp_path, quick_builds):
    ex = quick_builds
    study = tmp_path / "study1"
    trials = _trials(tmp_path / "trials", ["1E", "1H", "7H"])
    ex.build_study(ex.plan_study("difficulty", trials), study, log=lambda m: None)
    assert (study / "img" / "7H-A.png").exists() and (study / "study.json").exists()
    (study / "data").mkdir()
    (study / "data" / "lgp-difficulty-p1.csv").write_text("study,task,participant\nabc,difficulty,1\n")  # collected
    (study / "img" / "my-photo.jpg").write_bytes(b"the lab's photo")
    (study / "notes.md").write_text("participant 1 came late\n")
    kept = {k: v for k, v in snapshot(study).items() if k in ("data/lgp-difficulty-p1.csv", "img/my-photo.jpg", "notes.md")}

    _trials(trials, ["1E", "1H"])  # a rebuild without 7H
    ex.build_study(ex.plan_study("difficulty", trials), study, log=lambda m: None)
    after = snapshot(study)
    assert {k: after[k] for k in kept} == kept
    assert not (study / "img" / "7H-A.png").exists() and (study / "img" / "1H-B.png").exists()
    listed = set(json.loads((study / "study.json").read_text())["files"])
    assert set(after) == listed | set(kept) | {"study.json"}


def test_a_stray_study_json_does_not_license_wiping_the_folder(tmp_path, quick_builds):
    """A folder with thesis.tex and a study.json copied from elsewhere (listing files
    that are not there, or not with those contents): the manifest rule deletes nothing."""
    ex = quick_builds
    trials = _trials(tmp_path / "trials", ["1E", "1H"])
    ex.build_study(ex.plan_study("difficulty", trials), tmp_path / "elsewhere", log=lambda m: None)
    folder = tmp_path / "thesis"
    folder.mkdir()
    (folder / "thesis.tex").write_text("\\chapter{mine}\n")
    (folder / "lib").mkdir()
    (folder / "lib" / "jspsych.js").write_text("// my own edited copy\n")
    (folder / "study.json").write_text((tmp_path / "elsewhere" / "study.json").read_text())
    before = snapshot(folder)
    with pytest.raises(ex.StudyError, match=r"study would|would replace what this command did not write"):
        ex.build_study(ex.plan_study("difficulty", trials), folder, log=lambda m: None)
    assert snapshot(folder) == before and not list(folder.glob(".lgp-*"))
    (folder / "lib" / "jspsych.js").unlink()
    (folder / "lib").rmdir()
    ex.build_study(ex.plan_study("difficulty", trials), folder, log=lambda m: None)
    assert (folder / "thesis.tex").read_text() == "\\chapter{mine}\n" and (folder / "index.html").exists()


def test_a_folder_without_a_study_is_refused_and_into_existing_keeps_its_files(tmp_path, quick_builds):
    ex = quick_builds
    trials = _trials(tmp_path / "trials", ["1E", "1H"])
    folder = tmp_path / "busy"
    folder.mkdir()
    (folder / "thesis.tex").write_text("keep me")
    with pytest.raises(ex.StudyError, match=r"holds no study \(study.json\): refusing to write into it \(thesis.tex\)"):
        ex.check_output_dir(folder)
    ex.build_study(ex.plan_study("build", trials), folder, log=lambda m: None, into_existing=True)
    assert (folder / "thesis.tex").read_text() == "keep me" and (folder / "study.json").exists()
    (folder / "study.json").write_text('{"name": "another program"}')
    with pytest.raises(ex.StudyError, match="study.json was not written by python -m stimuli.experiment"):
        ex.check_output_dir(folder, into_existing=True)


def test_a_failed_build_leaves_the_earlier_study_byte_identical(tmp_path, quick_builds, monkeypatch):
    ex = quick_builds
    trials = _trials(tmp_path / "trials", ["1E", "1H"])
    study = tmp_path / "study"
    ex.build_study(ex.plan_study("time", trials), study, log=lambda m: None)
    before = snapshot(study)

    def full(*a, **k):
        raise OSError(28, "No space left on device")

    monkeypatch.setattr(ex.shutil, "copyfile", full)
    with pytest.raises(OSError):
        ex.build_study(ex.plan_study("difficulty", trials), study, log=lambda m: None)
    assert snapshot(study) == before and not list(study.glob(".lgp-*"))
    with pytest.raises(OSError):
        ex.build_study(ex.plan_study("difficulty", trials), tmp_path / "new" / "study", log=lambda m: None)
    assert not (tmp_path / "new").exists()


@pytest.mark.slow  # the command line's imports
def test_a_run_inside_or_around_a_running_ones_folder_is_refused_before_it_writes(tmp_path):
    from lgp import reproduce

    tiny = ["--trials", "1E", "--samples", "1", "--n-sims", "2", "--jobs", "1", "--no-replays"]
    (tmp_path / "rn" / "figures").mkdir(parents=True)
    with OutputLock(tmp_path / "rn", f"{PROG} --out rn"):
        with pytest.raises(OutputFolderBusy, match="lies inside"):
            reproduce.main([*tiny, "--out", str(tmp_path / "rn" / "figures" / "new")])
        assert not (tmp_path / "rn" / "figures" / "new").exists()  # the folder it made is gone again
    earlier_run(tmp_path / "rn", {})  # rn: an earlier run's folder, so only the lock can stop the run
    with OutputLock(tmp_path / "rn" / "figures", f"{PROG} --out rn/figures"):
        with pytest.raises(OutputFolderBusy, match="holds"):
            reproduce.main([*tiny, "--out", str(tmp_path / "rn")])
    assert sorted(p.relative_to(tmp_path).as_posix() for p in tmp_path.rglob("*")) == \
        ["rn", "rn/figures", "rn/manifest.json"]


# ----------------------------------------------------------------------------- record files of commands without a manifest


def test_a_users_file_named_like_a_commands_record_does_not_license_writing_beside_it(tmp_path):
    """refuse_foreign_folder: a summary.json, power.csv ... of the user's is not the
    command's record (it lacks the record's keys or columns), so the folder is refused."""
    from lgp.owned import csv_record, json_record, refuse_foreign_folder

    out = tmp_path / "mine"
    out.mkdir()
    (out / "summary.json").write_text('{"title": "my own summary"}')
    (out / "power.csv").write_text("participant,response\n1,3\n")
    before = snapshot(out)
    with pytest.raises(owned.ForeignFiles, match="its summary.json was not written by this command"):
        refuse_foreign_folder(out, "summary.json", is_ours=json_record("rules", "human_means"))
    with pytest.raises(owned.ForeignFiles, match="its power.csv was not written by this command"):
        refuse_foreign_folder(out, "power.csv", is_ours=csv_record("world", "procedure", "verdict"))
    assert snapshot(out) == before
    # the commands' own records pass
    (out / "summary.json").write_text('{"rules": {}, "human_means": {}, "timing": {}}')
    (out / "power.csv").write_text("world,procedure,verdict,count,n_studies\n")
    refuse_foreign_folder(out, "summary.json", is_ours=json_record("rules", "human_means"))
    refuse_foreign_folder(out, "power.csv", is_ours=csv_record("world", "procedure", "verdict"))
    (out / "summary.json").unlink()
    (out / "summary.json").symlink_to(out / "power.csv")  # a link is never a record
    with pytest.raises(owned.ForeignFiles):
        refuse_foreign_folder(out, "summary.json", is_ours=json_record("rules", "human_means"))


def test_stimuli_design_refuses_a_users_design_json_in_one_line(tmp_path, capsys):
    from lgp.cli import run_cli
    from stimuli.design.__main__ import main

    user = tmp_path / "mine"
    user.mkdir()
    (user / "design.json").write_text('{"my": "interior design notes"}')
    code = run_cli(main, ["--out", str(user), "--candidates", "10", "--trials", "5"], prog="python -m stimuli.design")
    assert code == 2 and "its design.json was not written by this command" in capsys.readouterr().err
    assert [p.name for p in user.iterdir()] == ["design.json"]
