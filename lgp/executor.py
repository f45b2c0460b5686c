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
  A worker that dies is noticed at once: its units are resubmitted to fresh
  workers a bounded number of times, then `WorkerDied` names the unit and the
  signal (never a hang).

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


class WorkerDied(RuntimeError):
    """A worker process died (killed by a signal, out of memory, a crash in C code)
    while running a unit, and the unit was not retried or failed again.
    ``unit`` is the index of the item, ``signal`` the signal name (or the exit code)."""

    def __init__(self, message: str, unit: int | None = None, signal: str | None = None):
        super().__init__(message)
        self.unit = unit
        self.signal = signal


#: Tries of a unit whose worker died under it (1 = never retried); a map also
#: gives up after MAX_RESTARTS broken pools, whoever was at fault.
MAX_TRIES = 2
MAX_RESTARTS = 4


def _how_it_died(exitcode) -> str:
    if exitcode is None:
        return "unknown cause"
    if exitcode < 0:
        try:
            return signal.Signals(-exitcode).name
        except ValueError:
            return f"signal {-exitcode}"
    return f"exit status {exitcode}"


def describe_unit(fn, item, limit: int = 100) -> str:
    """A short name of a work unit for a message: ``fn(7H, 0, 3)``; an element with
    an ``id`` or ``label`` (a trial, a scene) is named by it, an array by its shape."""
    def one(x):
        for attr in ("id", "label"):
            if isinstance(getattr(x, attr, None), str):
                return getattr(x, attr)
        if isinstance(x, (int, float, str, bool)) or x is None:
            return repr(x)
        if hasattr(x, "shape"):
            return f"array{tuple(x.shape)}"
        if isinstance(x, (tuple, list)) and len(x) <= 4 and all(isinstance(v, (int, float, str)) for v in x):
            return repr(tuple(x))
        return type(x).__name__
    parts = [one(x) for x in item] if isinstance(item, tuple) else [one(item)]
    text = f"{getattr(fn, '__name__', 'task')}({', '.join(parts)})"
    return text if len(text) <= limit else text[: limit - 3] + "..."


# Per worker: its slot in the shared table of (pid, running unit) rows.
_SLOTS = None
_SLOT = -1


def _worker_init(parent_pid: int, slots, lock) -> None:
    """ProcessExecutor's worker initialiser: `_die_with_parent`, then claim a row of
    the shared table where the worker notes the unit it runs (shared memory, so a
    worker killed mid-unit leaves the parent a record of what it was doing)."""
    global _SLOTS, _SLOT
    _die_with_parent(parent_pid)
    with lock:
        for i in range(0, len(slots), 2):
            if slots[i] == 0:
                slots[i], slots[i + 1] = os.getpid(), -1
                _SLOTS, _SLOT = slots, i
                break


def _tracked(fn, k, item):
    if _SLOTS is not None:
        _SLOTS[_SLOT + 1] = k
    try:
        return fn(item)
    finally:
        if _SLOTS is not None:
            _SLOTS[_SLOT + 1] = -1


def _noop():
    return os.getpid()


class ProcessExecutor:
    """A pool of `jobs` warm worker processes (concurrent.futures.ProcessPoolExecutor),
    created on first use and kept until `close()`.

    A worker that dies (SIGKILL, the out-of-memory killer, a segfault) breaks the
    pool; the map notices at once (BrokenProcessPool), says so in one line on
    stderr, starts fresh workers and resubmits every unit that had not finished.
    The unit the dead worker was running is tried at most MAX_TRIES times, and a
    map survives at most MAX_RESTARTS broken pools; past either it raises
    `WorkerDied` naming the unit and the signal. Results that arrived before are
    kept (``on_result`` has seen each of them exactly once)."""

    def __init__(self, jobs: int | None = None, start_method: str | None = None):
        self.jobs = default_jobs() if jobs is None else int(jobs)
        if self.jobs < 1:
            raise InputError(f"jobs must be >= 1, got {jobs}")
        self.start_method = start_method
        self._pool = None
        self._procs: list = []
        self._slots = None
        self.restarts = 0  # broken pools replaced over this executor's life

    def start(self) -> "ProcessExecutor":
        """Start the workers now (by default they start on the first map)."""
        pool = self._get_pool()
        for f in [pool.submit(_noop) for _ in range(self.jobs)]:
            f.result()
        return self

    def _get_pool(self):
        if self._pool is None:
            import multiprocessing as mp
            from concurrent.futures import ProcessPoolExecutor as Pool

            ctx = mp.get_context(self.start_method or _start_method())
            self._slots = ctx.RawArray("q", 2 * (self.jobs + 2))
            self._pool = Pool(self.jobs, mp_context=ctx, initializer=_worker_init,
                              initargs=(os.getpid(), self._slots, ctx.Lock()))
            self._procs = []
        return self._pool

    def _processes(self) -> list:
        """Every worker process of the current pool seen so far (kept after they die,
        for their exit codes)."""
        known = {p.pid for p in self._procs}
        for p in list(getattr(self._pool, "_processes", {}).values()):
            if p.pid not in known:
                self._procs.append(p)
        return self._procs

    def _post_mortem(self, running: set[int]) -> list[tuple[int, int | None, str]]:
        """(pid, unit it was running or None, how it died) of every dead worker."""
        table = {int(self._slots[i]): int(self._slots[i + 1]) for i in range(0, len(self._slots), 2) if self._slots[i]}
        dead = []
        for p in self._processes():
            p.join(timeout=1.0)  # a killed worker is reaped at once
            if p.exitcode not in (None, 0):
                k = table.get(p.pid, -1)
                dead.append((p.pid, k if k in running else None, _how_it_died(p.exitcode)))
        return dead

    def map(self, fn, items, on_result=None) -> list:
        from collections import deque
        from concurrent.futures import ALL_COMPLETED, FIRST_COMPLETED, wait
        from concurrent.futures.process import BrokenProcessPool

        items = list(items)
        results: list = [None] * len(items)
        if not items:
            return results
        todo = set(range(len(items)))
        tries = [0] * len(items)
        restarts = 0
        window = 2 * self.jobs + 2
        try:
            while todo:
                pool = self._get_pool()
                queue = deque(sorted(todo))
                inflight: dict = {}
                broken = False
                while (queue or inflight) and not broken:
                    try:  # a few units ahead of the workers, not the whole list at once
                        while queue and len(inflight) < window:
                            inflight[pool.submit(_tracked, fn, queue[0], items[queue[0]])] = queue[0]
                            queue.popleft()
                    except BrokenProcessPool:  # a worker died between maps, or just now
                        broken = True
                    self._processes()
                    done, _ = wait(list(inflight), timeout=10.0 if broken else 1.0, return_when=ALL_COMPLETED if broken else FIRST_COMPLETED)
                    for f in done:
                        k = inflight.pop(f)
                        error = f.exception()
                        if isinstance(error, BrokenProcessPool):
                            broken = True
                            continue
                        if error is not None:
                            raise error
                        results[k] = f.result()
                        todo.discard(k)
                        if on_result is not None:
                            on_result(k, results[k])
                    if broken and inflight:  # the break fails every future still pending, at once
                        done, _ = wait(list(inflight), timeout=10.0)
                        for f in done:
                            k = inflight.pop(f)
                            if f.exception() is None:
                                results[k] = f.result()
                                todo.discard(k)
                                if on_result is not None:
                                    on_result(k, results[k])
                if not broken:
                    continue
                # The pool is broken: which worker died, running what?
                dead = self._post_mortem(todo)
                # A broken pool SIGTERMs its other workers: those died of the break, not of their units.
                first = [d for d in dead if d[2] != "SIGTERM"]
                dead = first or dead
                self._discard_pool()
                restarts += 1
                self.restarts += 1
                culprits = [(pid, k, how) for pid, k, how in dead if k is not None]
                for _, k, _ in culprits:
                    tries[k] += 1
                what = "; ".join(f"worker process {pid} died ({how})" + (
                    f" while running unit {k} of {len(items)}, {describe_unit(fn, items[k])}" if k is not None else "")
                    for pid, k, how in dead) or "a worker process died"
                worst = max(culprits, key=lambda c: tries[c[1]], default=None)
                if worst is not None and tries[worst[1]] >= MAX_TRIES:
                    pid, k, how = worst
                    raise WorkerDied(f"worker process {pid} died ({how}) while running unit {k} of {len(items)}, "
                                     f"{describe_unit(fn, items[k])}: its worker died in each of its {tries[k]} tries; "
                                     "stopped (results that arrived are kept)", unit=k, signal=how)
                if restarts > MAX_RESTARTS:
                    k = worst[1] if worst else None
                    raise WorkerDied(f"{what}; {restarts} broken pools in one map, gave up "
                                     "(results that arrived are kept)", unit=k, signal=worst[2] if worst else None)
                print(f"lgp.executor: {what}; starting new workers and resubmitting the {len(todo)} unfinished "
                      f"unit(s) (restart {restarts} of at most {MAX_RESTARTS})", file=sys.stderr, flush=True)
        except BaseException:
            self.terminate()
            raise
        return results

    def _discard_pool(self) -> None:
        """Forget a broken pool (its workers are gone or being terminated)."""
        self.terminate()

    def terminate(self) -> None:
        """Stop at once: queued work is dropped and the workers are killed."""
        pool = self._pool
        if pool is None:
            return
        procs = self._processes()
        self._pool, self._procs = None, []
        for p in procs:
            if p.exitcode is None:
                p.terminate()
        pool.shutdown(wait=False, cancel_futures=True)
        for p in procs:
            p.join(timeout=5.0)
            if p.exitcode is None:
                p.kill()
                p.join(timeout=1.0)
        thread = getattr(pool, "_executor_manager_thread", None)
        if thread is not None:  # it sees the dead workers and exits; never wait for it forever
            thread.join(timeout=5.0)

    def close(self) -> None:
        if self._pool is not None:
            self._pool.shutdown(wait=True)
            self._pool, self._procs = None, []

    def __enter__(self):
        return self

    def __exit__(self, *exc):
        if exc[0] is None:
            self.close()
        else:
            self.terminate()


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
