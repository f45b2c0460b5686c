"""A dead worker never hangs a run (issue 27, item 1): the process executor
notices it, resubmits what the dead worker was running a bounded number of
times, and otherwise stops with one line naming the unit and the signal.

Each case runs in a subprocess with a deadline, so an executor that waits
forever for a lost task fails the test instead of hanging the suite."""
import json
import os
import signal
import subprocess
import sys
import textwrap
import time
from pathlib import Path

import pytest

from tests.test_faults import descendants

pytestmark = pytest.mark.skipif(not Path("/proc/self/stat").exists(), reason="needs Linux /proc")

ROOT = Path(__file__).resolve().parents[1]

_SCRIPT = textwrap.dedent("""
    import json, os, signal, sys, time
    from pathlib import Path
    import lgp.executor
    from lgp.executor import ProcessExecutor
    WorkerDied = getattr(lgp.executor, "WorkerDied", RuntimeError)  # (absent before issue 27)

    MODE, METHOD, MARK = sys.argv[1], sys.argv[2], Path(sys.argv[3])

    def _pid(_):
        return os.getpid()

    def unit(k):
        if MODE == "always" and k == 5:  # this unit kills every worker that runs it
            os.kill(os.getpid(), signal.SIGKILL)
        if MODE == "once" and k == 5 and not MARK.exists():  # only the first try dies
            MARK.touch()
            os.kill(os.getpid(), signal.SIGKILL)
        t = time.monotonic()
        while time.monotonic() - t < 0.1:
            pass
        return k * k

    if __name__ == "__main__":
        seen = []
        try:
            with ProcessExecutor(2, METHOD) as ex:
                if MODE == "between":  # a worker dies while the pool is idle, between two maps
                    pid = ex.map(_pid, [0])[0]
                    os.kill(pid, signal.SIGKILL)
                    time.sleep(0.3)
                out = ex.map(unit, list(range(30)), lambda k, r: seen.append(k))
        except WorkerDied as e:
            print(f"WorkerDied: {e}", file=sys.stderr)
            raise SystemExit(3)
        print(json.dumps({"results": out, "arrived": sorted(seen)}))
""")


def _workers(pid):
    """Descendants of `pid` but spawn's resource tracker (no worker)."""
    out = []
    for p in descendants(pid):
        try:
            if b"resource_tracker" not in Path(f"/proc/{p}/cmdline").read_bytes():
                out.append(p)
        except OSError:
            pass
    return out


def _run(tmp_path, mode, method, kill_after=None, deadline=60.0):
    script = tmp_path / "units.py"
    script.write_text(_SCRIPT)
    env = {**os.environ, "PYTHONPATH": str(ROOT)}
    t0 = time.monotonic()
    proc = subprocess.Popen([sys.executable, str(script), mode, method, str(tmp_path / "mark")], cwd=tmp_path,
                            env=env, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    if kill_after is not None:  # kill one worker from outside, mid-map
        while len(_workers(proc.pid)) < 2 and time.monotonic() - t0 < 30:
            time.sleep(0.02)
        time.sleep(kill_after)
        workers = _workers(proc.pid)
        assert workers, "the map ended before a worker could be killed"
        os.kill(workers[0], signal.SIGKILL)
    try:
        out, err = proc.communicate(timeout=deadline)
    except subprocess.TimeoutExpired:
        proc.kill()
        out, err = proc.communicate()
        pytest.fail(f"the map hung: still running {deadline:g} s after a worker died\n{err[-2000:]}")
    return proc.returncode, out, err, time.monotonic() - t0


@pytest.mark.slow  # a subprocess pool, a worker killed
@pytest.mark.parametrize("method", ["fork", "spawn"])
def test_a_worker_killed_from_outside_is_replaced_and_the_map_completes(tmp_path, method):
    code, out, err, took = _run(tmp_path, "plain", method, kill_after=0.8)
    assert code == 0, err[-3000:]
    got = json.loads(out)
    assert got["results"] == [k * k for k in range(30)]
    assert got["arrived"] == list(range(30))  # every unit reported once, none twice
    assert "died" in err and "SIGKILL" in err  # said on stderr, one line


@pytest.mark.slow  # a subprocess pool, a worker killed
def test_a_worker_that_died_between_two_maps_is_replaced(tmp_path):
    code, out, err, took = _run(tmp_path, "between", "fork")
    assert code == 0, err[-3000:]
    assert json.loads(out)["results"] == [k * k for k in range(30)]


@pytest.mark.slow  # a subprocess pool, a worker killed
def test_a_unit_that_kills_its_worker_once_is_retried(tmp_path):
    code, out, err, took = _run(tmp_path, "once", "fork")
    assert code == 0, err[-3000:]
    assert json.loads(out)["results"] == [k * k for k in range(30)]


def test_a_unit_that_always_kills_its_worker_stops_the_map_in_one_line(tmp_path):
    code, out, err, took = _run(tmp_path, "always", "fork")
    assert code == 3, err[-3000:]
    line = [ln for ln in err.splitlines() if ln.startswith("WorkerDied:")]
    assert len(line) == 1, err
    assert "unit 5 " in line[0] and "SIGKILL" in line[0] and "unit(5)" in line[0], line[0]
    assert "Traceback" not in err, err


RUN = [sys.executable, "-m", "lgp.reproduce", "--trials", "7H", "4H", "--samples", "8", "--n-sims", "60",
       "--sigmas", "0.05", "0.1", "--jobs", "2", "--no-replays", "--verbose"]  # --verbose: the per-trial lines the cues wait for


def _csvs(out: Path) -> dict:
    import pandas as pd

    tables = {name: pd.read_csv(out / name) for name in ("effort_samples.csv", "effort.csv", "risk.csv")}
    tables["effort_samples.csv"] = tables["effort_samples.csv"].drop(columns="solve_time")  # wall clock
    return tables


@pytest.fixture(scope="module")
def undisturbed(tmp_path_factory) -> Path:
    """The output folder of RUN without a kill and without a cache (made once, read by both stages' cases)."""
    out = tmp_path_factory.mktemp("ref")
    env = {**os.environ, "PYTHONPATH": str(ROOT)}
    ref = subprocess.run(RUN + ["--no-cache", "--out", str(out)], cwd=ROOT, env=env,
                         capture_output=True, text=True, timeout=300)
    assert ref.returncode == 0, ref.stderr[-3000:]
    return out


@pytest.mark.slow
@pytest.mark.parametrize("stage, cue", [("effort", "[effort  1/2]"), ("risk", "[effort] ")])
def test_reproduce_survives_a_worker_killed_mid_stage_with_identical_csvs(tmp_path, stage, cue, undisturbed):
    """The issue's probe: kill -9 one worker of a default (process-pool) run while
    it plans or simulates; the run ends by itself, exit 0, with the CSVs of an
    undisturbed run (bar the wall-clock solve_time)."""
    import threading

    env = {**os.environ, "PYTHONPATH": str(ROOT)}
    proc = subprocess.Popen(RUN + ["--out", str(tmp_path / "hit")], cwd=ROOT, env=env, stdout=subprocess.PIPE,
                            stderr=subprocess.PIPE, text=True)
    lines, seen = [], threading.Event()

    def read():
        for line in proc.stderr:
            lines.append(line)
            if cue in line:
                seen.set()

    reader = threading.Thread(target=read, daemon=True)
    reader.start()
    assert seen.wait(240), "".join(lines)[-3000:]
    time.sleep(0.3)
    victims = _workers(proc.pid)
    assert victims
    os.kill(victims[0], signal.SIGKILL)
    try:
        proc.wait(timeout=240)
    except subprocess.TimeoutExpired:
        proc.kill()
        pytest.fail("the run hung after a worker was killed:\n" + "".join(lines)[-3000:])
    reader.join(5)
    err = "".join(lines)
    assert proc.returncode == 0, err[-3000:]
    assert "died (SIGKILL)" in err, err[-3000:]
    want, got = _csvs(undisturbed), _csvs(tmp_path / "hit")
    for name in want:
        assert got[name].equals(want[name]), name
