"""`ProcessExecutor`: a pool of warm worker processes that die with their parent,
whose deaths are noticed at once and whose units are resubmitted a bounded number
of times (`WorkerDied`, MAX_TRIES, MAX_RESTARTS); the workers' initialiser and the
shared table where each notes the unit it runs.

A worker that makes no progress (stopped by SIGSTOP or Ctrl-Z in another shell,
or stuck without using the CPU) would hang a map forever: the map watches the CPU
time of every worker that runs a unit (Linux: /proc/<pid>/stat) and kills one
whose CPU time has not moved for `stall_seconds` (STALL_SECONDS, 300 s, or the
environment's LGP_STALL_SECONDS); its unit is then retried like a dead worker's,
and a unit that stalls in each of its tries stops the map in one line. The
pipeline's units use the CPU all the time, so a loaded machine slows them
(their CPU time still moves) but never trips the watchdog."""
from __future__ import annotations

import os
import signal
import sys
import threading
import time

from lgp.errors import InputError
from lgp.executor.serial import default_jobs


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
#: Seconds a worker running a unit may go without CPU time before it is taken for
#: stalled (stopped, or stuck) and killed; LGP_STALL_SECONDS overrides it.
STALL_SECONDS = 300.0
STALL_ENV = "LGP_STALL_SECONDS"


def stall_seconds_default() -> float:
    """STALL_SECONDS, or the environment's LGP_STALL_SECONDS when it is a number > 0."""
    import math

    try:
        value = float(os.environ.get(STALL_ENV, ""))
    except ValueError:
        return STALL_SECONDS
    return value if math.isfinite(value) and value > 0 else STALL_SECONDS


def _cpu_and_state(pid: int) -> tuple[int, str] | None:
    """(CPU clock ticks used, state letter) of process `pid` from /proc, None if unknown."""
    try:
        with open(f"/proc/{pid}/stat", "rb") as f:
            data = f.read()
    except OSError:
        return None
    fields = data.rpartition(b")")[2].split()
    try:
        return int(fields[11]) + int(fields[12]), fields[0].decode()
    except (IndexError, ValueError):
        return None


def _how_it_died(exitcode) -> str:
    if exitcode is None:
        return "unknown cause"
    if exitcode < 0:
        try:
            return signal.Signals(-exitcode).name
        except ValueError:
            return f"signal {-exitcode}"
    return f"exit status {exitcode}"


def _worker_fate(pid: int, how: str) -> str:
    """"worker process N died (SIGKILL)", or for a stalled one "worker process N made
    no progress for 300 s, stopped (...): killed (...)"."""
    if how.startswith("made no progress"):
        return f"worker process {pid} {how}"
    return f"worker process {pid} died ({how})"


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

    def __init__(self, jobs: int | None = None, start_method: str | None = None, stall_seconds: float | None = None):
        self.jobs = default_jobs() if jobs is None else int(jobs)
        if self.jobs < 1:
            raise InputError(f"jobs must be >= 1, got {jobs}")
        self.stall_seconds = stall_seconds_default() if stall_seconds is None else float(stall_seconds)
        if not self.stall_seconds > 0:
            raise InputError(f"stall_seconds must be > 0, got {stall_seconds}")
        self.start_method = start_method
        self._watch: dict[int, tuple[int, int, float]] = {}  # pid -> (unit, CPU ticks, when they last moved)
        self._stalled: dict[int, str] = {}  # pid -> why the watchdog killed it
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

    def _watchdog(self) -> None:
        """Kill a worker whose CPU time has not moved for `stall_seconds` while it
        runs a unit (see the module docstring); the pool then breaks and the map
        retries the unit like a dead worker's, naming the stall."""
        if self._slots is None or not sys.platform.startswith("linux"):
            return
        now = time.monotonic()
        table = {int(self._slots[i]): int(self._slots[i + 1]) for i in range(0, len(self._slots), 2) if self._slots[i]}
        for p in self._processes():
            if p.exitcode is not None or p.pid in self._stalled:
                continue
            unit = table.get(p.pid, -1)
            seen = _cpu_and_state(p.pid)
            if seen is None:
                self._watch.pop(p.pid, None)
                continue
            ticks, state = seen
            stopped = state in ("T", "t")
            if unit < 0 and not stopped:  # idle: waiting for work uses no CPU, and that is fine
                self._watch.pop(p.pid, None)
                continue
            last = self._watch.get(p.pid)
            if last is None or last[0] != unit or last[1] != ticks:
                self._watch[p.pid] = (unit, ticks, now)
                continue
            if now - last[2] >= self.stall_seconds:  # busy without CPU time, or stopped while idle (it would
                # never take work again, and the pool's shutdown would wait for it forever)
                why = ("stopped (state T: SIGSTOP or Ctrl-Z)" if state in ("T", "t") else f"state {state}")
                self._stalled[p.pid] = (f"made no progress for {now - last[2]:.0f} s, {why}: killed "
                                        f"(no CPU time for {self.stall_seconds:g} s; {STALL_ENV} sets the limit)")
                try:
                    os.kill(p.pid, signal.SIGKILL)
                except OSError:
                    pass

    def _post_mortem(self, running: set[int]) -> list[tuple[int, int | None, str]]:
        """(pid, unit it was running or None, how it died) of every dead worker."""
        table = {int(self._slots[i]): int(self._slots[i + 1]) for i in range(0, len(self._slots), 2) if self._slots[i]}
        # The pool's manager thread reaps the workers of a broken pool (it SIGTERMs
        # the living, then joins all). Two threads reaping one child race: the
        # loser's waitpid fails (ECHILD) and reads no exit code, so a SIGKILLed
        # worker could look alive. Let the manager finish first, then read codes.
        thread = getattr(self._pool, "_executor_manager_thread", None)
        if thread is not None:
            thread.join(timeout=10.0)
        dead = []
        for p in self._processes():
            p.join(timeout=1.0)  # a killed worker is reaped at once
            if p.exitcode not in (None, 0):
                k = table.get(p.pid, -1)
                how = self._stalled.pop(p.pid, None) or _how_it_died(p.exitcode)
                dead.append((p.pid, k if k in running else None, how))
        return dead

    def map(self, fn, items, on_result=None) -> list:
        items = list(items)
        results: list = [None] * len(items)
        if not items:
            return results
        todo = set(range(len(items)))
        tries = [0] * len(items)
        restarts = 0
        try:
            while todo:
                if not self._run_on_pool(fn, items, todo, results, on_result):
                    continue
                restarts += 1
                self._after_break(fn, items, todo, tries, restarts)
        except BaseException:
            self.terminate()
            raise
        return results

    def _run_on_pool(self, fn, items, todo: set[int], results: list, on_result) -> bool:
        """Run the units `todo` on the pool (a few ahead of the workers, not the whole
        list at once), filling `results` and emptying `todo`; True when the pool broke
        (a worker died), with every result that arrived kept."""
        from collections import deque
        from concurrent.futures import ALL_COMPLETED, FIRST_COMPLETED, wait
        from concurrent.futures.process import BrokenProcessPool

        def arrived(k, f):
            results[k] = f.result()
            todo.discard(k)
            if on_result is not None:
                on_result(k, results[k])

        window = 2 * self.jobs + 2
        pool = self._get_pool()
        queue = deque(sorted(todo))
        inflight: dict = {}
        broken = False
        while (queue or inflight) and not broken:
            try:
                while queue and len(inflight) < window:
                    inflight[pool.submit(_tracked, fn, queue[0], items[queue[0]])] = queue[0]
                    queue.popleft()
            except BrokenProcessPool:  # a worker died between maps, or just now
                broken = True
            self._processes()
            if not broken:
                self._watchdog()
            done, _ = wait(list(inflight), timeout=10.0 if broken else 1.0, return_when=ALL_COMPLETED if broken else FIRST_COMPLETED)
            for f in done:
                k = inflight.pop(f)
                error = f.exception()
                if isinstance(error, BrokenProcessPool):
                    broken = True
                    continue
                if error is not None:
                    raise error
                arrived(k, f)
            if broken and inflight:  # the break fails every future still pending, at once
                done, _ = wait(list(inflight), timeout=10.0)
                for f in done:
                    k = inflight.pop(f)
                    if f.exception() is None:
                        arrived(k, f)
        return broken

    def _after_break(self, fn, items, todo: set[int], tries: list[int], restarts: int) -> None:
        """The pool broke: find which worker died running what, count a try against
        its unit, and raise WorkerDied when a unit killed its worker MAX_TRIES times or
        the map broke more than MAX_RESTARTS pools; else say so and let new workers go on."""
        dead = self._post_mortem(todo)
        # A broken pool SIGTERMs its other workers: those died of the break, not of their units.
        first = [d for d in dead if d[2] != "SIGTERM"]
        dead = first or dead
        self._discard_pool()
        self.restarts += 1
        culprits = [(pid, k, how) for pid, k, how in dead if k is not None]
        for _, k, _ in culprits:
            tries[k] += 1
        what = "; ".join(_worker_fate(pid, how) + (
            f" while running unit {k} of {len(items)}, {describe_unit(fn, items[k])}" if k is not None else "")
            for pid, k, how in dead) or "a worker process died"
        worst = max(culprits, key=lambda c: tries[c[1]], default=None)
        if worst is not None and tries[worst[1]] >= MAX_TRIES:
            pid, k, how = worst
            fate = "stalled" if how.startswith("made no progress") else "died"
            raise WorkerDied(f"{_worker_fate(pid, how)} while running unit {k} of {len(items)}, "
                             f"{describe_unit(fn, items[k])}: its worker {fate} in each of its {tries[k]} tries; "
                             "stopped (results that arrived are kept)", unit=k, signal=how)
        if restarts > MAX_RESTARTS:
            k = worst[1] if worst else None
            raise WorkerDied(f"{what}; {restarts} broken pools in one map, gave up "
                             "(results that arrived are kept)", unit=k, signal=worst[2] if worst else None)
        print(f"lgp.executor: {what}; starting new workers and resubmitting the {len(todo)} unfinished "
              f"unit(s) (restart {restarts} of at most {MAX_RESTARTS})", file=sys.stderr, flush=True)

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
        self._watch = {}
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
            for p in self._processes():  # a stopped worker never exits: shutdown would wait for it forever
                seen = _cpu_and_state(p.pid) if p.exitcode is None else None
                if seen is not None and seen[1] in ("T", "t"):
                    print(f"lgp.executor: worker process {p.pid} is stopped (state T: SIGSTOP or Ctrl-Z): killed at "
                          "the end of the run", file=sys.stderr, flush=True)
                    p.kill()
            self._pool.shutdown(wait=True)
            self._pool, self._procs = None, []

    def __enter__(self):
        return self

    def __exit__(self, *exc):
        if exc[0] is None:
            self.close()
        else:
            self.terminate()
