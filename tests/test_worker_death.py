"""A dead worker never hangs a run (issue 27, item 1): the process executor
notices it, resubmits what the dead worker was running a bounded number of
times, and otherwise stops with one line naming the unit and the signal.

Each case runs in a subprocess with a deadline, so an executor that waits
forever for a lost task fails the test instead of hanging the suite."""
import json
import os
import signal
import sys
import textwrap
from pathlib import Path

import pytest

from tests.conftest import pool_run_signalling_a_worker, result_csvs, run_signalling_a_worker

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
        time.sleep(0.1)  # a unit that takes a while (asleep: the suite's other worker keeps the CPU)
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


def _run(tmp_path, mode, method, kill_after=None, deadline=60.0):
    script = tmp_path / "units.py"
    script.write_text(_SCRIPT)
    return run_signalling_a_worker([sys.executable, str(script), mode, method, str(tmp_path / "mark")], tmp_path,
                                   {**os.environ, "PYTHONPATH": str(ROOT)}, None if kill_after is None else signal.SIGKILL,
                                   kill_after or 0.0, deadline, "a worker died")


@pytest.mark.slow  # a subprocess pool, a worker killed
@pytest.mark.parametrize("method", ["fork", "spawn"])
def test_a_worker_killed_from_outside_is_replaced_and_the_map_completes(tmp_path, method):
    code, out, err = _run(tmp_path, "plain", method, kill_after=0.8)
    assert code == 0, err[-3000:]
    got = json.loads(out)
    assert got["results"] == [k * k for k in range(30)]
    assert got["arrived"] == list(range(30))  # every unit reported once, none twice
    assert "died" in err and "SIGKILL" in err  # said on stderr, one line


@pytest.mark.slow  # a subprocess pool, a worker killed
def test_a_worker_that_died_between_two_maps_is_replaced(tmp_path):
    code, out, err = _run(tmp_path, "between", "fork")
    assert code == 0, err[-3000:]
    assert json.loads(out)["results"] == [k * k for k in range(30)]


@pytest.mark.slow  # a subprocess pool, a worker killed
def test_a_unit_that_kills_its_worker_once_is_retried(tmp_path):
    code, out, err = _run(tmp_path, "once", "fork")
    assert code == 0, err[-3000:]
    assert json.loads(out)["results"] == [k * k for k in range(30)]


def test_a_unit_that_always_kills_its_worker_stops_the_map_in_one_line(tmp_path):
    code, out, err = _run(tmp_path, "always", "fork")
    assert code == 3, err[-3000:]
    line = [ln for ln in err.splitlines() if ln.startswith("WorkerDied:")]
    assert len(line) == 1, err
    assert "unit 5 " in line[0] and "SIGKILL" in line[0] and "unit(5)" in line[0], line[0]
    assert "Traceback" not in err, err


@pytest.mark.slow
@pytest.mark.parametrize("stage, cue", [("effort", "[effort  1/2]"), ("risk", "[effort] ")])
def test_reproduce_survives_a_worker_killed_mid_stage_with_identical_csvs(tmp_path, stage, cue, pool_run_undisturbed):
    """The issue's probe: kill -9 one worker of a default (process-pool) run while
    it plans or simulates; the run ends by itself, exit 0, with the CSVs of an
    undisturbed run (bar the wall-clock solve_time)."""
    code, err = pool_run_signalling_a_worker(tmp_path / "hit", cue, signal.SIGKILL, pause=0.3)
    assert code == 0, err[-3000:]
    assert "died (SIGKILL)" in err, err[-3000:]
    want, got = result_csvs(pool_run_undisturbed), result_csvs(tmp_path / "hit")
    for name in want:
        assert got[name].equals(want[name]), name
