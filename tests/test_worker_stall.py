"""A stopped worker never hangs a run (issue 30): a worker that is stopped
(SIGSTOP, Ctrl-Z) or otherwise makes no progress used to hang a run forever at
``[effort] 11/12``. The process executor watches the CPU time of each worker that
runs a unit; one whose CPU time does not move for ``stall_seconds`` is killed and
its unit retried, and a unit that stalls in each of its tries stops the map in one
line. A unit that is merely slow (its CPU time moves) is never taken for stalled.

The cases run in a subprocess with a deadline and LGP_STALL_SECONDS=1.5, so a
map that waits forever fails the test instead of hanging the suite."""
import json
import os
import signal
import subprocess
import sys
import textwrap
import time
from pathlib import Path

import pytest

from lgp.executor.processes import STALL_ENV, _cpu_and_state, stall_seconds_default
from tests.conftest import pool_run_signalling_a_worker, result_csvs, run_signalling_a_worker

pytestmark = pytest.mark.skipif(not Path("/proc/self/stat").exists(), reason="needs Linux /proc")

ROOT = Path(__file__).resolve().parents[1]

_SCRIPT = textwrap.dedent("""
    import json, os, signal, sys, time
    from pathlib import Path
    from lgp.executor import ProcessExecutor, WorkerDied

    MODE, MARK = sys.argv[1], Path(sys.argv[2])

    def busy(seconds):  # computes: its worker's CPU time moves
        t = time.monotonic()
        while time.monotonic() - t < seconds:
            pass

    def unit(k):
        if k == 5 and (MODE == "stop-always" or (MODE == "stop-once" and not MARK.exists())):
            MARK.touch()
            os.kill(os.getpid(), signal.SIGSTOP)  # as `kill -STOP <worker>` from another shell
        if MODE == "slow" and k == 5:
            busy(4.0)  # longer than the stall limit, on the CPU all along
        else:
            time.sleep(0.1)  # a unit that takes a while (its index moves: progress; asleep, the suite's other worker keeps the CPU)
        return k * k

    if __name__ == "__main__":
        seen = []
        try:
            with ProcessExecutor(2, "fork") as ex:
                out = ex.map(unit, list(range(16)), lambda k, r: seen.append(k))
        except WorkerDied as e:
            print(f"WorkerDied: {e}", file=sys.stderr)
            raise SystemExit(3)
        print(json.dumps({"results": out, "arrived": sorted(seen)}))
""")


def _run(tmp_path, mode, stop_after=None, deadline=90.0):
    script = tmp_path / "units.py"
    script.write_text(_SCRIPT)
    return run_signalling_a_worker([sys.executable, str(script), mode, str(tmp_path / "mark")], tmp_path,
                                   {**os.environ, "PYTHONPATH": str(ROOT), STALL_ENV: "1.5"},
                                   None if stop_after is None else signal.SIGSTOP, stop_after or 0.0, deadline,
                                   "a worker was stopped")


@pytest.mark.slow  # a subprocess pool, a worker stopped for 1.5 s
def test_a_worker_stopped_from_outside_is_replaced_and_the_map_completes(tmp_path):
    code, out, err = _run(tmp_path, "plain", stop_after=0.5)
    assert code == 0, err[-3000:]
    got = json.loads(out)
    assert got["results"] == [k * k for k in range(16)] and got["arrived"] == list(range(16))
    line = [ln for ln in err.splitlines() if "made no progress" in ln]
    assert len(line) == 1 and "stopped (state T: SIGSTOP or Ctrl-Z)" in line[0] and "resubmitting" in line[0], err


@pytest.mark.slow  # a subprocess pool, a unit stopping its worker once
def test_a_unit_whose_worker_stops_once_is_retried(tmp_path):
    code, out, err = _run(tmp_path, "stop-once")
    assert code == 0, err[-3000:]
    assert json.loads(out)["results"] == [k * k for k in range(16)]
    assert "made no progress" in err and "unit 5 of 16" in err


@pytest.mark.slow  # a subprocess pool, a unit stopping its worker twice
def test_a_unit_that_stalls_in_every_try_stops_the_map_in_one_line(tmp_path):
    code, out, err = _run(tmp_path, "stop-always")
    assert code == 3, err[-3000:]
    line = [ln for ln in err.splitlines() if ln.startswith("WorkerDied:")]
    assert len(line) == 1 and "Traceback" not in err, err
    assert "made no progress for" in line[0] and "unit 5 of 16, unit(5)" in line[0], line[0]
    assert "its worker stalled in each of its 2 tries" in line[0] and "LGP_STALL_SECONDS" in line[0], line[0]


@pytest.mark.slow  # a 4 s unit under a 1.5 s stall limit
def test_a_slow_unit_that_uses_the_cpu_is_never_taken_for_stalled(tmp_path):
    code, out, err = _run(tmp_path, "slow")
    assert code == 0 and "no progress" not in err, err[-3000:]
    assert json.loads(out)["results"] == [k * k for k in range(16)]


def test_a_stopped_process_reads_as_stopped_with_no_cpu_progress():
    child = subprocess.Popen([sys.executable, "-c", "while True: pass"])
    try:
        time.sleep(0.3)
        os.kill(child.pid, signal.SIGSTOP)
        time.sleep(0.1)
        ticks, state = _cpu_and_state(child.pid)
        time.sleep(0.3)
        assert _cpu_and_state(child.pid) == (ticks, "T") and state == "T"
    finally:
        child.kill()
        child.wait()
    assert _cpu_and_state(child.pid) is None  # gone


def test_the_stall_limit_comes_from_the_environment_when_it_is_a_number(monkeypatch):
    monkeypatch.setenv(STALL_ENV, "42")
    assert stall_seconds_default() == 42.0
    for bad in ("abc", "-1", "nan", "0"):
        monkeypatch.setenv(STALL_ENV, bad)
        assert stall_seconds_default() == 300.0


@pytest.mark.slow  # a real lgp.reproduce run and its undisturbed twin (shared with test_worker_death)
def test_reproduce_survives_a_worker_stopped_mid_effort_with_identical_csvs(tmp_path, pool_run_undisturbed):
    """The issue's probe: `kill -STOP` one worker of a default (process-pool) run while
    it plans (it hung forever at [effort] 11/12); with LGP_STALL_SECONDS=2 the run
    replaces the worker, ends by itself, exit 0, with an undisturbed run's CSVs."""
    code, err = pool_run_signalling_a_worker(tmp_path / "hit", "[effort  1/2]", signal.SIGSTOP, **{STALL_ENV: "2"})
    assert code == 0, err[-3000:]
    assert "made no progress" in err and "SIGSTOP" in err, err[-3000:]
    want, got = result_csvs(pool_run_undisturbed), result_csvs(tmp_path / "hit")
    for name in want:
        assert got[name].equals(want[name]), name


_IDLE = textwrap.dedent("""
    import json, os, signal, sys, time
    from lgp.executor import ProcessExecutor

    def pid(_):
        t = time.monotonic()
        while time.monotonic() - t < 0.2:
            pass
        return os.getpid()

    def unit(k):
        t = time.monotonic()
        while time.monotonic() - t < 0.05:
            pass
        return k

    if __name__ == "__main__":
        with ProcessExecutor(2, "fork") as ex:
            pids = sorted(set(ex.map(pid, range(6))))
            os.kill(pids[0], signal.SIGSTOP)  # stopped while idle, between two maps
            time.sleep(0.2)
            out = ex.map(unit, list(range(20)))
        print(json.dumps(out))
""")


@pytest.mark.slow  # a subprocess pool and a 1.5 s stall limit
def test_a_worker_stopped_while_idle_neither_hangs_the_next_map_nor_the_close(tmp_path):
    """An idle worker takes no unit once stopped; the other does the map, but the
    pool's shutdown waited for the stopped one forever."""
    script = tmp_path / "idle.py"
    script.write_text(_IDLE)
    try:
        r = subprocess.run([sys.executable, str(script)], cwd=tmp_path, capture_output=True, text=True, timeout=90,
                           env={**os.environ, "PYTHONPATH": str(ROOT), STALL_ENV: "1.5"})
    except subprocess.TimeoutExpired:
        pytest.fail("the map or the close hung on a worker stopped while idle")
    assert r.returncode == 0, r.stderr[-3000:]
    assert json.loads(r.stdout) == list(range(20))
    assert "stopped (state T: SIGSTOP or Ctrl-Z)" in r.stderr, r.stderr
