"""One run per output folder, and replacing an earlier run's outputs never reaches
outside the folder (issue 27, items 3 and 10; issue 30: only a run's own files)."""
import json
import os
import signal
import subprocess
import sys
import threading
import time
from pathlib import Path

import pytest

from lgp import owned
from lgp.app.manifest import OutputFolderBusy, OutputLock, check_output_folder
from lgp.atomic import write_bytes_atomic

ROOT = Path(__file__).resolve().parents[1]
def _env() -> dict:
    """The environment of a subprocess, read when it starts (not at import: the suite's
    render cache, conftest.suite_render_cache, is set after the modules are collected)."""
    return {**os.environ, "PYTHONPATH": str(ROOT)}


# ----------------------------------------------------------------------------- item 3: the lock


def test_a_second_lock_on_a_folder_names_the_holder(tmp_path):
    with OutputLock(tmp_path, "python -m lgp.reproduce --out x"):
        with pytest.raises(OutputFolderBusy, match=rf"in use by another run \(process {os.getpid()}: python -m lgp.reproduce --out x\)"):
            # flock locks are per open file: a second open in this process conflicts too
            with OutputLock(tmp_path):
                pass
    with OutputLock(tmp_path):  # released on exit
        pass


def test_the_lock_is_released_when_its_holder_is_killed(tmp_path):
    holder = subprocess.Popen([sys.executable, "-c", "import sys, time; from lgp.app.manifest import OutputLock\n"
                               f"with OutputLock({str(tmp_path)!r}, 'holder'):\n    print('held', flush=True); time.sleep(60)"],
                              env=_env(), stdout=subprocess.PIPE, text=True)
    assert holder.stdout.readline().strip() == "held"
    with pytest.raises(OutputFolderBusy, match=f"process {holder.pid}: holder"):
        with OutputLock(tmp_path):
            pass
    holder.send_signal(signal.SIGKILL)
    holder.wait(10)
    with OutputLock(tmp_path):
        pass


@pytest.mark.slow  # a lock holder and a run, both subprocesses
def test_a_run_in_a_held_folder_says_who_holds_it_and_touches_nothing(tmp_path):
    out = tmp_path / "out"
    out.mkdir()
    (out / "effort.csv").write_text("the other run's\n")
    (out / "manifest.json").write_text(json.dumps({"command": ["python -m lgp.reproduce"], "files": [
        {"path": "effort.csv", "sha256": __import__("hashlib").sha256(b"the other run's\n").hexdigest()}]}))
    with OutputLock(out, "python -m lgp.reproduce --out out (the other run)"):
        t0 = time.monotonic()
        r = subprocess.run([sys.executable, "-m", "lgp.reproduce", "--trials", "1E", "--samples", "1", "--n-sims", "2",
                            "--out", str(out)], cwd=ROOT, env=_env(), capture_output=True, text=True, timeout=120)
    assert r.returncode == 1, r.stderr[-2000:]
    lines = r.stderr.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith("python -m lgp.reproduce: error: ") and \
        f"in use by another run (process {os.getpid()}: python -m lgp.reproduce --out out (the other run))" in lines[0], r.stderr
    assert (out / "effort.csv").read_text() == "the other run's\n"
    assert time.monotonic() - t0 < 60



def test_a_run_that_finds_the_holders_staging_half_made_is_told_who_holds_the_folder(tmp_path):
    # The holder makes its staging folder (mkdtemp) and then its mark: a second run's
    # early check, made without the lock, can see the folder unmarked in between (a
    # CI failure of test_two_real_runs_in_one_folder_...: "holds files no run ...
    # wrote (.lgp-new-f69dngu1)", exit 2). The holder is the reason to refuse: exit 1,
    # named; nothing touched. Without a holder the same folder is foreign (exit 2).
    from lgp import reproduce

    out = tmp_path / "out"
    (out / ".lgp-new-abcd1234").mkdir(parents=True)
    argv = ["--trials", "1E", "--samples", "1", "--n-sims", "2", "--out", str(out)]
    with OutputLock(out, "python -m lgp.reproduce --out out (the holder)"):
        with pytest.raises(OutputFolderBusy, match=rf"in use by another run \(process {os.getpid()}: python -m lgp.reproduce --out out \(the holder\)\)"):
            reproduce.run(reproduce.parse_args(argv), argv)
    assert sorted(p.name for p in out.iterdir()) == [".lgp-new-abcd1234"]
    assert reproduce.main(argv) == 2  # no holder: an unmarked folder is not a run's
    assert sorted(p.name for p in out.iterdir()) == [".lgp-new-abcd1234"]


def test_a_study_build_that_finds_the_holders_staging_half_made_is_told_who_holds_the_folder(tmp_path, capsys):
    # The same race for python -m stimuli.experiment (its early check is also made without the lock).
    from lgp import cli
    from stimuli.experiment.__main__ import PROG, main

    out = tmp_path / "study"
    (out / ".lgp-new-abcd1234").mkdir(parents=True)
    argv = ["--task", "difficulty", "--out", str(out)]
    with OutputLock(out, "python -m stimuli.experiment --out study (the holder)"):
        assert cli.run_cli(main, argv, prog=PROG) == 1
    assert f"in use by another run (process {os.getpid()}: python -m stimuli.experiment --out study (the holder))" in capsys.readouterr().err
    with pytest.raises(SystemExit) as stop:  # no holder: refused as a folder of foreign files (argparse, exit 2)
        main(argv)
    assert stop.value.code == 2 and "holds no study" in capsys.readouterr().err
    assert sorted(p.name for p in out.iterdir()) == [".lgp-new-abcd1234"]

def test_concurrent_writers_of_one_file_use_unique_temporary_names(tmp_path):
    path, errors = tmp_path / "page" / "10E.png", []

    def write(k):
        try:
            for _ in range(50):
                write_bytes_atomic(bytes([k]) * 10000, path)
        except Exception as e:  # a shared temporary name fails here (renamed away by the other)
            errors.append(e)

    threads = [threading.Thread(target=write, args=(k,)) for k in range(4)]
    for t in threads:
        t.start()
    for t in threads:
        t.join()
    assert errors == []
    data = path.read_bytes()
    assert len(data) == 10000 and len(set(data)) == 1  # whole, one writer's
    assert [p.name for p in path.parent.iterdir()] == ["10E.png"]


@pytest.mark.slow
def test_two_real_runs_in_one_folder_one_runs_the_other_is_refused(tmp_path):
    out = tmp_path / "out"
    first = subprocess.Popen([sys.executable, "-m", "lgp.reproduce", "--trials", "7H", "4H", "--samples", "2", "--n-sims", "10",
                              "--sigmas", "0.05", "0.1", "--jobs", "1", "--no-replays", "--out", str(out)],
                             cwd=ROOT, env=_env(), stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    deadline = time.monotonic() + 120
    while not (out / OutputLock.NAME).exists() and time.monotonic() < deadline and first.poll() is None:
        time.sleep(0.02)
    # the first run is stopped (kill -STOP) while it holds the folder, however long the
    # second takes to start on a loaded machine, and continued once the second is refused
    os.kill(first.pid, signal.SIGSTOP)
    try:
        assert (out / OutputLock.NAME).exists(), "the first run never took the folder"
        second = subprocess.run([sys.executable, "-m", "lgp.reproduce", "--trials", "1E", "--samples", "2", "--n-sims", "8",
                                 "--seed", "1", "--no-replays", "--out", str(out)], cwd=ROOT, env=_env(), capture_output=True,
                                text=True, timeout=120)
    finally:
        os.kill(first.pid, signal.SIGCONT)
    _, err = first.communicate(timeout=300)
    assert first.returncode == 0, err[-2000:]
    assert second.returncode == 1 and f"process {first.pid}" in second.stderr, second.stderr
    manifest = json.loads((out / "manifest.json").read_text())
    assert manifest["parameters"]["trials"] == ["7H", "4H"]
    import hashlib

    for f in manifest["files"]:  # the manifest describes the files in the folder
        assert hashlib.sha256((out / f["path"]).read_bytes()).hexdigest() == f["sha256"], f["path"]


# ----------------------------------------------------------------------------- item 10: clearing (issue 30: lgp/owned.py)


def _folder(tmp_path, listed):
    out = tmp_path / "out"
    out.mkdir()
    (out / "manifest.json").write_text(json.dumps({"command": ["python -m lgp.reproduce"],
                                                   "files": [{"path": p, "sha256": "0" * 64} for p in listed]}))
    return out


def test_a_run_never_deletes_through_a_symlinked_subfolder(tmp_path):
    elsewhere = tmp_path / "elsewhere"
    elsewhere.mkdir()
    (elsewhere / "important.txt").write_text("keep me")
    out = _folder(tmp_path, ["page/important.txt"])
    entries = owned.manifest_entries(json.loads((out / "manifest.json").read_text()))
    entries["page/important.txt"].add(__import__("hashlib").sha256(b"keep me").hexdigest())  # even with its hash
    (out / "page").symlink_to(elsewhere)
    assert owned.own_files(out, entries) == {}  # behind a link: never the run's own
    stage = owned.new_staging(out)
    (stage / "manifest.json").write_text("{}")
    assert owned.swap_in(out, stage, entries, "manifest.json") == []
    assert (elsewhere / "important.txt").read_text() == "keep me" and (out / "page").is_symlink()


def test_paths_outside_the_folder_and_links_are_never_a_runs_own(tmp_path):
    outside = tmp_path / "outside.csv"
    outside.write_text("keep")
    digest = __import__("hashlib").sha256(b"keep").hexdigest()
    out = _folder(tmp_path, [])
    (out / "risk.csv").symlink_to(outside)
    entries = {p: {digest} for p in ["risk.csv", "../outside.csv", str(outside), "", "."]}
    assert owned.own_files(out, entries) == {}
    with pytest.raises(owned.ForeignFiles, match="risk.csv there is not an earlier run's output"):
        check_output_folder(out)  # a link where a run writes: refused, the link kept
    assert outside.read_text() == "keep" and (out / "risk.csv").is_symlink()


def test_a_manifest_linked_to_dev_zero_is_not_read(tmp_path):
    out = tmp_path / "out"
    out.mkdir()
    (out / "manifest.json").symlink_to("/dev/zero")
    (out / "report.md").write_text("old")
    t0 = time.monotonic()
    with pytest.raises(owned.ForeignFiles, match="manifest.json was not written by python -m lgp.reproduce"):
        check_output_folder(out)
    assert time.monotonic() - t0 < 5 and (out / "report.md").read_text() == "old"


def test_a_stop_before_any_result_does_not_claim_a_cache(tmp_path):
    from lgp.reproduce import _resume_note, parse_args

    args = parse_args(["--out", str(tmp_path / "out")])
    assert _resume_note(args) == "nothing was cached yet (stopped before the first result)"
    (tmp_path / "out" / "cache").mkdir(parents=True)
    (tmp_path / "out" / "cache" / "effort-abc.csv").write_text("x")
    assert _resume_note(args).startswith("finished trials are cached in")


def test_a_compute_times_file_linked_to_dev_zero_is_not_read(tmp_path):
    from lgp.app.manifest import TIMES, TimedCache

    (tmp_path / "cache").mkdir()
    (tmp_path / "cache" / TIMES).symlink_to("/dev/zero")
    t0 = time.monotonic()
    assert TimedCache(tmp_path / "cache").load_times() == {}
    assert time.monotonic() - t0 < 5
