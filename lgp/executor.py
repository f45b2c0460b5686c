"""Executors: how the expensive maps of the pipeline (effort per (trial, layout),
risk per (trial, chunk of runs)) are spread over processes.

One interface, ``Executor.map(fn, items, on_result=None) -> list`` (results in
input order; ``on_result(index, result)`` as each arrives, for progress), with

- ``SerialExecutor``: in this process;
- ``ProcessExecutor(jobs)``: a pool of warm worker processes kept for the
  executor's whole life, so a run imports Drake and compiles models once per
  worker, not once per trial. An exception in the caller (Ctrl-C included)
  cancels what is queued and terminates the workers at once; workers die with
  their parent, even on ``kill -9`` (Linux: PR_SET_PDEATHSIG). Create it in the
  main thread: the kernel ties that signal to the thread that started the worker.

``stop_signals()`` makes SIGTERM stop a command as Ctrl-C does.

- ``DaskExecutor(address)``: the tasks of a ``dask.distributed`` cluster (a
  running scheduler ``tcp://HOST:8786``, or ``"local-dask"`` for a LocalCluster
  on this machine). Dask is an optional extra (``pip install -e ".[dask]"``),
  imported only when a DaskExecutor is made. Workers compute and return results;
  the caller (the client) assembles them in input order and writes every file.

This module knows nothing of
the paper: it sits on the ground floor with the scene, so models may take an
``executor=`` argument without importing the application.
"""
from __future__ import annotations

import os
import signal
import sys
import threading
from typing import Any, Callable, Protocol, Sequence

from lgp.errors import InputError


class Executor(Protocol):
    jobs: int

    def map(self, fn: Callable, items: Sequence, on_result: Callable[[int, Any], None] | None = None) -> list: ...

    def close(self) -> None: ...


class SerialExecutor:
    """Runs every item in this process, in order."""

    jobs = 1

    def map(self, fn, items, on_result=None) -> list:
        results = []
        for k, item in enumerate(items):
            results.append(fn(item))
            if on_result is not None:
                on_result(k, results[-1])
        return results

    def close(self) -> None:
        pass

    def __enter__(self):
        return self

    def __exit__(self, *exc):
        self.close()


def default_jobs() -> int:
    """Cores this process may use."""
    return len(os.sched_getaffinity(0)) if hasattr(os, "sched_getaffinity") else (os.cpu_count() or 1)


def _start_method() -> str:
    """fork where it is safe (POSIX, no other threads in this process): workers
    start at once and callers need no ``if __name__ == "__main__"`` guard; spawn
    otherwise."""
    import multiprocessing as mp

    if "fork" in mp.get_all_start_methods() and threading.active_count() == 1:
        return "fork"
    return "spawn"


def _die_with_parent(parent_pid: int) -> None:
    """Worker initialiser: the worker dies with its parent, whatever kills the parent.

    - Linux: the kernel sends SIGKILL to this worker when its parent dies
      (PR_SET_PDEATHSIG), so even ``kill -9`` of the run leaves no orphan; SIGKILL
      rather than SIGTERM because a worker cannot catch it and live on.
    - SIGTERM gets its default action back (a forked worker inherits the parent's
      handlers, e.g. `stop_signals`'s): ``Pool.terminate`` sends SIGTERM and
      must kill the worker, not raise in it.
    - Ctrl-C is the parent's to handle, so SIGINT is ignored here.
    """
    signal.signal(signal.SIGINT, signal.SIG_IGN)
    signal.signal(signal.SIGTERM, signal.SIG_DFL)
    if sys.platform.startswith("linux"):
        import ctypes

        PR_SET_PDEATHSIG = 1
        try:
            ctypes.CDLL("libc.so.6", use_errno=True).prctl(PR_SET_PDEATHSIG, signal.SIGKILL)
        except OSError:  # pragma: no cover - no libc by that name
            pass
    if os.getppid() != parent_pid:  # the parent died before prctl took effect (re-parented, not always to pid 1)
        os._exit(1)


class Interrupted(KeyboardInterrupt):
    """KeyboardInterrupt raised by `stop_signals`; ``signal`` is the signal received."""

    def __init__(self, signum: int):
        self.signal = signal.Signals(signum)
        super().__init__(f"stopped by {self.signal.name}")


class stop_signals:
    """Context manager for command-line entry points: SIGINT (Ctrl-C) and SIGTERM
    (what ``timeout``, ``kill`` and job schedulers send) both raise `Interrupted`
    in the main thread, so a run stops the same way on either: the executor
    terminates its workers, atomic writes leave no partial file, and the caller
    prints one line. ``received`` keeps the first signal even when the exception is
    converted on its way up (a C extension being imported turns it into an
    ImportError), so the caller can still tell a stop from a failure. The previous
    handlers are restored on exit; outside the main thread this does nothing."""

    SIGNALS = (signal.SIGINT, signal.SIGTERM)

    def __enter__(self):
        self.received: signal.Signals | None = None
        self._previous = {}
        if threading.current_thread() is threading.main_thread():
            self._previous = {s: signal.signal(s, self._raise) for s in self.SIGNALS}
        return self

    def _raise(self, signum, frame):
        if self.received is None:
            self.received = signal.Signals(signum)
        raise Interrupted(signum)

    def __exit__(self, *exc):
        for s, handler in self._previous.items():
            signal.signal(s, handler)


class ProcessExecutor:
    """A pool of `jobs` warm worker processes (multiprocessing.Pool), created on
    first use and kept until `close()`."""

    def __init__(self, jobs: int | None = None, start_method: str | None = None):
        self.jobs = default_jobs() if jobs is None else int(jobs)
        if self.jobs < 1:
            raise InputError(f"jobs must be >= 1, got {jobs}")
        self.start_method = start_method
        self._pool = None

    def start(self) -> "ProcessExecutor":
        """Start the workers now (by default they start on the first map)."""
        self._get_pool()
        return self

    def _get_pool(self):
        if self._pool is None:
            import multiprocessing as mp

            ctx = mp.get_context(self.start_method or _start_method())
            self._pool = ctx.Pool(self.jobs, initializer=_die_with_parent, initargs=(os.getpid(),))
        return self._pool

    def map(self, fn, items, on_result=None) -> list:
        items = list(items)
        results: list = [None] * len(items)
        if not items:
            return results
        pool = self._get_pool()
        try:
            for k, result, error in pool.imap_unordered(_indexed, [(fn, k, it) for k, it in enumerate(items)]):
                if error is not None:
                    raise error
                results[k] = result
                if on_result is not None:
                    on_result(k, result)
        except BaseException:
            self.terminate()
            raise
        return results

    def terminate(self) -> None:
        """Stop at once: queued work is dropped and the workers are killed."""
        if self._pool is not None:
            self._pool.terminate()
            self._pool.join()
            self._pool = None

    def close(self) -> None:
        if self._pool is not None:
            self._pool.close()
            self._pool.join()
            self._pool = None

    def __enter__(self):
        return self

    def __exit__(self, *exc):
        if exc[0] is None:
            self.close()
        else:
            self.terminate()


def _indexed(args):
    fn, k, item = args
    try:
        return k, fn(item), None
    except Exception:
        raise  # the pool carries it to the caller
    except BaseException as e:  # a Pool worker would die on it and the map would hang
        return k, None, e


class SchedulerUnreachable(ConnectionError):
    """A Dask scheduler address that does not answer within the timeout."""


class DaskMissing(ImportError):
    """The Dask backend was asked for but dask.distributed is not installed."""


#: Seconds to wait for a Dask scheduler to answer before giving up.
CONNECT_TIMEOUT = 10.0


class DaskExecutor:
    """The same ``map`` on a ``dask.distributed`` cluster.

    `address` is a scheduler address (``tcp://HOST:8786``) or ``"local-dask"``:
    start a ``distributed.LocalCluster`` of `jobs` single-threaded worker
    processes (None: all cores) and close it with the executor. Each item is one
    task with its own key; results come back to this process (the client) and
    are returned in input order, so the numbers do not depend on the number of
    workers or on which worker ran what. A worker that dies mid-task has its
    tasks rescheduled by Dask; each item's result is kept once, by index. An
    exception here (Ctrl-C included) cancels every pending future of the map.
    """

    def __init__(self, address: str = "local-dask", jobs: int | None = None, timeout: float = CONNECT_TIMEOUT,
                 client=None):
        try:
            from distributed import Client, LocalCluster
        except ImportError:  # pragma: no cover - depends on the install
            raise DaskMissing('the Dask backend (--scheduler) needs the optional extra: pip install -e ".[dask]"') from None
        self.address = address
        self._cluster = None
        if client is not None:
            self.client = client
            self._own_client = False
        elif address == "local-dask":
            n = default_jobs() if jobs is None else int(jobs)
            if n < 1:
                raise InputError(f"jobs must be >= 1, got {jobs}")
            self._cluster = LocalCluster(n_workers=n, threads_per_worker=1, processes=True,
                                         dashboard_address=None, silence_logs=50)
            self.client = Client(self._cluster, set_as_default=False)
            self._own_client = True
        else:
            try:
                self.client = _connect(Client, address, timeout)
            except Exception as e:  # refused, timed out, or something else answered (not a scheduler)
                raise SchedulerUnreachable(f"no Dask scheduler answered at {address} within {timeout:g} s ({e.__class__.__name__})") from None
            self._own_client = True
        self._batch = 0

    @property
    def jobs(self) -> int:
        """Worker threads the cluster has now (at least 1)."""
        info = self.client.scheduler_info()
        return max(1, sum(w.get("nthreads", 1) for w in info.get("workers", {}).values()))

    def map(self, fn, items, on_result=None) -> list:
        from distributed import as_completed

        items = list(items)
        results: list = [None] * len(items)
        if not items:
            return results
        self._batch += 1
        # Explicit keys: identical items stay distinct tasks, and a future's index is its key.
        tag = f"{getattr(fn, '__name__', 'task')}-{id(self):x}-{self._batch}"
        keys = [f"{tag}-{k}" for k in range(len(items))]
        index = {key: k for k, key in enumerate(keys)}
        futures = self.client.map(fn, items, key=keys, pure=False)
        got = [False] * len(items)
        try:
            for future, result in as_completed(futures, with_results=True, loop=self.client.loop):
                k = index[future.key]
                if got[k]:  # cannot happen with one future per key; guards the "no duplicates" promise
                    continue
                got[k] = True
                results[k] = result
                if on_result is not None:
                    on_result(k, result)
        except BaseException:
            self.client.cancel(futures, force=True)
            raise
        finally:
            del futures
        return results

    def terminate(self) -> None:
        self.close()

    def close(self) -> None:
        if self._own_client and self.client is not None:
            self.client.close()
            self.client = None
        if self._cluster is not None:
            self._cluster.close()
            self._cluster = None

    def __enter__(self):
        return self

    def __exit__(self, *exc):
        self.close()


def _connect(Client, address: str, timeout: float):
    """A Client for `address`, or an exception within about `timeout` s.

    A plain TCP connection is tried first: a refused or silent address then
    fails at once and cleanly (a half-made Client would complain on exit)."""
    import socket
    from urllib.parse import urlsplit

    parts = urlsplit(address if "://" in address else f"tcp://{address}")
    if parts.scheme in ("tcp", "tls") and parts.hostname:
        socket.create_connection((parts.hostname, parts.port or 8786), timeout=timeout).close()
    # Client's own timeout does not cover a peer that accepts TCP and then stays
    # silent, so the connection is made in a daemon thread with a hard deadline.
    box: dict = {}

    def connect():
        try:
            box["client"] = Client(address, timeout=f"{timeout}s", set_as_default=False)
        except BaseException as e:  # handed to the caller
            box["error"] = e

    thread = threading.Thread(target=connect, name="dask-connect", daemon=True)
    thread.start()
    thread.join(timeout + 1.0)
    if thread.is_alive():
        raise TimeoutError(f"no answer within {timeout:g} s")
    if "error" in box:
        raise box["error"]
    return box["client"]


def executor_for_scheduler(scheduler: str | None, jobs: int | None = None):
    """The executor a ``--scheduler`` value names: None -> local processes
    (executor_for(jobs)); ``local-dask`` -> a LocalCluster of `jobs` workers;
    ``tcp://HOST:PORT`` (or any Dask address) -> that running scheduler."""
    if scheduler is None:
        return executor_for(jobs)
    return DaskExecutor(scheduler, jobs)


def executor_for(jobs: int | None) -> SerialExecutor | ProcessExecutor:
    """SerialExecutor for one job, a ProcessExecutor otherwise (None: all cores)."""
    jobs = default_jobs() if jobs is None else int(jobs)
    if jobs < 1:
        raise InputError(f"jobs must be >= 1, got {jobs}")
    return SerialExecutor() if jobs == 1 else ProcessExecutor(jobs)


class borrowed:
    """Context manager: the caller's executor (left open) or a fresh one for `jobs`
    (closed on exit)."""

    def __init__(self, executor: Executor | None, jobs: int | None):
        self.own = executor is None
        self.executor = executor_for(jobs) if executor is None else executor

    def __enter__(self):
        return self.executor

    def __exit__(self, *exc):
        if self.own:
            if exc[0] is None or not hasattr(self.executor, "terminate"):
                self.executor.close()
            else:
                self.executor.terminate()
