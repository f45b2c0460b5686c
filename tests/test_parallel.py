"""Executors: results in input order, an interruption stops queued work at once,
and one pool serves many maps with warm workers."""
import os
import time
from pathlib import Path

import pytest

from lgp.executor import ProcessExecutor, SerialExecutor, executor_for


def _square(x):
    return x * x


def _pid(_):
    return os.getpid()


def _slow_or_fail(arg):
    k, folder = arg
    if k == 0:
        raise KeyboardInterrupt  # what Ctrl-C raises in a worker
    time.sleep(0.3)
    Path(folder, f"{k}.done").touch()
    return k


@pytest.mark.parametrize("make", [SerialExecutor, lambda: ProcessExecutor(2, "spawn")])
def test_results_come_back_in_input_order(make):
    seen = []
    with make() as ex:
        assert ex.map(_square, list(range(12)), lambda k, r: seen.append(k)) == [k * k for k in range(12)]
    assert sorted(seen) == list(range(12))


def test_one_pool_keeps_its_workers_across_maps():
    with ProcessExecutor(2) as ex:
        first = set(ex.map(_pid, range(8)))
        second = set(ex.map(_pid, range(8)))
    assert len(first | second) <= 2 and os.getpid() not in first | second


@pytest.mark.slow  # seconds of waiting on a pool
def test_interruption_cancels_the_queue_and_stops_the_workers(tmp_path):
    tasks = [(k, str(tmp_path)) for k in range(40)]
    with pytest.raises(KeyboardInterrupt):
        ProcessExecutor(2, "spawn").map(_slow_or_fail, tasks)
    time.sleep(1.0)  # a pool that kept going would finish tasks every 0.15 s here
    finished = len(list(tmp_path.glob("*.done")))
    time.sleep(1.0)
    assert len(list(tmp_path.glob("*.done"))) == finished < 39


def test_zero_jobs_is_refused():
    with pytest.raises(ValueError, match="jobs must be >= 1"):
        executor_for(0)
