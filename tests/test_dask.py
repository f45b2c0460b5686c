"""The Dask backend gives the numbers of the process pool: same CSVs with 1 or 2
LocalCluster workers, nothing lost or duplicated when a worker is killed mid-run,
Ctrl-C cancels what is queued, an unreachable scheduler fails fast with one line,
and only the client writes the cache."""
import os
import signal
import socket
import sys
import time
from pathlib import Path

import pandas as pd
import pytest

from lgp.executor import DaskExecutor, SchedulerUnreachable, SerialExecutor

pytestmark = pytest.mark.slow  # every case starts a cluster or a subprocess


@pytest.fixture(autouse=True, scope="module")
def _distributed():
    """dask.distributed, imported when a case runs, not at collection (the fast
    subset, which has no case here, does not pay its ~0.5 s import)."""
    pytest.importorskip("distributed")
    import cloudpickle  # comes with distributed

    # Workers unpickle functions by module name; this test file is not importable there.
    cloudpickle.register_pickle_by_value(sys.modules[__name__])
    yield
    _stop_dask_offload_thread()


def _stop_dask_offload_thread() -> None:
    """distributed keeps a thread ("Dask-Offload") alive after its clients close. A
    process with a second thread starts its worker pools by spawn, not fork
    (lgp.executor), and a spawned worker imports the pipeline again: ~2.5 CPU-s per
    worker of every later pool in this pytest process. Swap in a fresh executor (it
    starts a thread only when used again) and let the old thread end."""
    from concurrent.futures import ThreadPoolExecutor

    import distributed.utils

    old = distributed.utils._offload_executor
    distributed.utils._offload_executor = ThreadPoolExecutor(max_workers=1, thread_name_prefix="Dask-Offload")
    old.shutdown(wait=True)

#: Three trials, one layout each: 3 plans and the runs of 3 trials x 2 sigmas to share out over the workers
#: (equal tables do not depend on the run's size; a second layout doubles each run's plans).
RUN = ["--trials", "1E", "4H", "10E", "--samples", "1", "--n-sims", "4", "--sigmas", "0.05", "0.08", "--no-replays"]


def _slow_square(x):
    time.sleep(0.05)
    return x * x


@pytest.mark.slow
def test_local_dask_with_one_or_two_workers_writes_the_process_pools_csvs(tmp_path):
    # in this process, one after the other (the pipeline's imports paid once): the
    # pool's workers and the Dask workers are processes of their own all the same
    from lgp import reproduce

    for out, *extra in [(tmp_path / "pool", "--jobs", "2"), (tmp_path / "dask1", "--scheduler", "local-dask", "--jobs", "1"),
                        (tmp_path / "dask2", "--scheduler", "local-dask", "--jobs", "2")]:
        assert reproduce.main(["--out", str(out), *RUN, *extra]) == 0, out.name
    for run in ("dask1", "dask2"):
        for name in ("effort.csv", "risk.csv"):
            assert (tmp_path / run / name).read_bytes() == (tmp_path / "pool" / name).read_bytes(), (run, name)
        # per-layout table: identical but for the wall-clock planning time
        a = pd.read_csv(tmp_path / "pool" / "effort_samples.csv").drop(columns="solve_time")
        b = pd.read_csv(tmp_path / run / "effort_samples.csv").drop(columns="solve_time")
        pd.testing.assert_frame_equal(a, b, check_exact=True)


@pytest.mark.slow
def test_a_worker_killed_mid_run_loses_and_duplicates_nothing():
    items = list(range(40))
    calls = []
    with DaskExecutor("local-dask", jobs=2) as ex:
        pids = list(ex.client.run(os.getpid).values())
        assert len(pids) == 2

        def arrived(k, result):
            calls.append(k)
            if len(calls) == 5:  # tasks are running on both workers now
                os.kill(pids[0], signal.SIGKILL)

        results = ex.map(_slow_square, items, arrived)
        after = set(ex.client.run(os.getpid).values())
    assert pids[0] not in after  # the worker really died (its nanny started a new one)
    assert results == [x * x for x in items]
    assert sorted(calls) == items  # each result reported exactly once


@pytest.mark.slow
def test_pipeline_tables_survive_a_killed_worker_and_the_client_writes_the_cache(tmp_path, monkeypatch):
    import stimuli
    import lgp.app.cache
    from lgp.app.cache import Cache
    from lgp.app.stages import effort_tables, risk_tables

    trials = [stimuli.load_trial(t) for t in ("1E", "4H")]
    calm = (effort_tables(trials, 2, 0, SerialExecutor(), Cache(tmp_path / "calm")),
            risk_tables(trials, (0.05, 0.08), 4, 0, None, SerialExecutor(), Cache(tmp_path / "calm")))

    written = []
    real = lgp.app.cache.write_bytes_atomic  # every cache entry is written through it
    monkeypatch.setattr(lgp.app.cache, "write_bytes_atomic", lambda data, path: written.append(Path(path)) or real(data, path))

    class Killer(DaskExecutor):
        """Kills one worker process as soon as the first result of each map arrives."""

        def map(self, fn, items, on_result=None):
            state = {"killed": False}

            def arrived(k, r):
                if not state["killed"]:
                    state["killed"] = True
                    os.kill(next(iter(self.client.run(os.getpid).values())), signal.SIGKILL)
                if on_result:
                    on_result(k, r)

            return super().map(fn, items, arrived)

    with Killer("local-dask", jobs=2) as ex:
        cache = Cache(tmp_path / "dask")
        shaken = (effort_tables(trials, 2, 0, ex, cache), risk_tables(trials, (0.05, 0.08), 4, 0, None, ex, cache))
    pd.testing.assert_frame_equal(calm[0].drop(columns="solve_time"), shaken[0].drop(columns="solve_time"), check_exact=True)
    pd.testing.assert_frame_equal(calm[1], shaken[1], check_exact=True)
    # every cache file was written by this process (the client), none by a worker
    on_disk = {p.resolve() for p in (tmp_path / "dask").glob("*.csv")}
    assert on_disk and on_disk == {p.resolve() for p in written if (tmp_path / "dask") in p.parents}


def _sleep_and_mark(arg):
    k, folder = arg
    time.sleep(0.2)
    Path(folder, f"{k}.done").touch()
    return k


@pytest.mark.slow
def test_interruption_cancels_the_queued_futures(tmp_path):
    with DaskExecutor("local-dask", jobs=1) as ex:
        def interrupt(k, r):
            raise KeyboardInterrupt

        with pytest.raises(KeyboardInterrupt):
            ex.map(_sleep_and_mark, [(k, str(tmp_path)) for k in range(30)], interrupt)
        time.sleep(1.0)
        finished = len(list(tmp_path.glob("*.done")))
        time.sleep(1.0)
        assert len(list(tmp_path.glob("*.done"))) == finished < 10


@pytest.mark.slow  # the pipeline's imports
def test_refused_scheduler_address_fails_at_once_with_one_line(tmp_path, capsys):
    from lgp import cli, reproduce

    t0 = time.perf_counter()
    code = cli.run_cli(reproduce.main, ["--scheduler", "tcp://127.0.0.1:1", "--trials", "1E", "--out", str(tmp_path / "r")],
                       prog=reproduce.PROG)
    assert code == 1
    lines = [l for l in capsys.readouterr().err.splitlines() if l.strip() and not l.startswith("lgp.reproduce:")]
    assert len(lines) == 1 and lines[0].startswith("python -m lgp.reproduce: error: no Dask scheduler answered at tcp://127.0.0.1:1")
    assert time.perf_counter() - t0 < 60


@pytest.mark.slow  # waits out the connect timeout
def test_silent_scheduler_address_times_out_within_the_bound():
    # A socket that accepts TCP connections but never speaks Dask's protocol.
    server = socket.socket()
    server.bind(("127.0.0.1", 0))
    server.listen(8)
    port = server.getsockname()[1]
    try:
        t0 = time.perf_counter()
        with pytest.raises(SchedulerUnreachable, match=f"tcp://127.0.0.1:{port}: something accepts connections there but sent nothing within 1 s"):
            DaskExecutor(f"tcp://127.0.0.1:{port}", timeout=1.0)
        assert time.perf_counter() - t0 < 10
    finally:
        server.close()
