"""An interrupted process pool stops its queued work instead of finishing it."""
import multiprocessing as mp
import time
from pathlib import Path

import pytest

from lgp.parallel import map_in_processes


def _square(x):
    return x * x


def _slow_or_fail(arg):
    k, folder = arg
    if k == 0:
        raise KeyboardInterrupt  # what Ctrl-C raises in a worker
    time.sleep(0.3)
    Path(folder, f"{k}.done").touch()
    return k


def test_results_come_back_in_input_order():
    seen = []
    assert map_in_processes(_square, list(range(12)), 2, mp.get_context("spawn"), lambda k, r: seen.append(k)) == [k * k for k in range(12)]
    assert sorted(seen) == list(range(12))


def test_interruption_cancels_the_queue_and_stops_the_workers(tmp_path):
    tasks = [(k, str(tmp_path)) for k in range(40)]
    with pytest.raises(KeyboardInterrupt):
        map_in_processes(_slow_or_fail, tasks, 2, mp.get_context("spawn"))
    time.sleep(1.0)  # a pool that kept going would finish tasks every 0.15 s here
    finished = len(list(tmp_path.glob("*.done")))
    time.sleep(1.0)
    assert len(list(tmp_path.glob("*.done"))) == finished < 39
