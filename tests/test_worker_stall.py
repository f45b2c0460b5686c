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
from tests.test_worker_death import _workers

pytestmark = pytest.mark.skipif(not Path("/proc/self/stat").exists(), reason="needs Linux /proc")

ROOT = Path(__file__).resolve().parents[1]

_SCRIPT = textwrap.dedent("""
    import json, os, signal, sys, time
    from pathlib import Path
    from lgp.executor import ProcessExecutor, WorkerDied

    MODE, MARK = sys.argv[1], Path(sys.argv[2])

    def busy(seconds):
        t = time.monotonic()
        while time.monotonic() - t < seconds:
            pass

    def unit(k):
        if k == 5 and (MODE == "stop-always" or (MODE == "stop-once" and not MARK.exists())):
            MARK.touch()
            os.kill(os.getpid(), signal.SIGSTOP)  # as `kill -STOP <worker>` from another shell
        busy(4.0 if (MODE == "slow" and k == 5) else 0.1)
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
    env = {**os.environ, "PYTHONPATH": str(ROOT), STALL_ENV: "1.5"}
    t0 = time.monotonic()
    proc = subprocess.Popen([sys.executable, str(script), mode, str(tmp_path / "mark")], cwd=tmp_path, env=env,
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    if stop_after is not None:  # the probe: SIGSTOP one worker from outside, mid-map
        while len(_workers(proc.pid)) < 2 and time.monotonic() - t0 < 30:
            time.sleep(0.02)
        time.sleep(stop_after)
        workers = _workers(proc.pid)
        assert workers, "the map ended before a worker could be stopped"
        os.kill(workers[0], signal.SIGSTOP)
    try:
        out, err = proc.communicate(timeout=deadline)
    except subprocess.TimeoutExpired:
        proc.kill()
        out, err = proc.communicate()
        pytest.fail(f"the map hung: still running {deadline:g} s after a worker was stopped\n{err[-2000:]}")
    return proc.returncode, out, err, time.monotonic() - t0


@pytest.mark.slow  # a subprocess pool, a worker stopped for 1.5 s
def test_a_worker_stopped_from_outside_is_replaced_and_the_map_completes(tmp_path):
    code, out, err, took = _run(tmp_path, "plain", stop_after=0.5)
    assert code == 0, err[-3000:]
    got = json.loads(out)
    assert got["results"] == [k * k for k in range(16)] and got["arrived"] == list(range(16))
    line = [ln for ln in err.splitlines() if "made no progress" in ln]
    assert len(line) == 1 and "stopped (state T: SIGSTOP or Ctrl-Z)" in line[0] and "resubmitting" in line[0], err


@pytest.mark.slow  # a subprocess pool, a unit stopping its worker once
def test_a_unit_whose_worker_stops_once_is_retried(tmp_path):
    code, out, err, took = _run(tmp_path, "stop-once")
    assert code == 0, err[-3000:]
    assert json.loads(out)["results"] == [k * k for k in range(16)]
    assert "made no progress" in err and "unit 5 of 16" in err


@pytest.mark.slow  # a subprocess pool, a unit stopping its worker twice
def test_a_unit_that_stalls_in_every_try_stops_the_map_in_one_line(tmp_path):
    code, out, err, took = _run(tmp_path, "stop-always")
    assert code == 3, err[-3000:]
    line = [ln for ln in err.splitlines() if ln.startswith("WorkerDied:")]
    assert len(line) == 1 and "Traceback" not in err, err
    assert "made no progress for" in line[0] and "unit 5 of 16, unit(5)" in line[0], line[0]
    assert "its worker stalled in each of its 2 tries" in line[0] and "LGP_STALL_SECONDS" in line[0], line[0]


@pytest.mark.slow  # a 4 s unit under a 1.5 s stall limit
def test_a_slow_unit_that_uses_the_cpu_is_never_taken_for_stalled(tmp_path):
    code, out, err, took = _run(tmp_path, "slow")
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
