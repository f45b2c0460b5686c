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

This package knows nothing of
the paper: it sits on the ground floor with the scene, so models may take an
``executor=`` argument without importing the application.

The package, by idea: `serial` (the interface, SerialExecutor, default_jobs),
`processes` (ProcessExecutor and its workers), `cluster` (DaskExecutor),
`signals` (stop_signals) and, here, the choice of an executor (`executor_for`,
`executor_for_scheduler`, `borrowed`); every name is importable from lgp.executor.
"""
from __future__ import annotations

from lgp.errors import InputError
from lgp.executor.cluster import CONNECT_TIMEOUT, DaskExecutor, DaskMissing, SchedulerUnreachable  # noqa: F401
from lgp.executor.processes import (MAX_RESTARTS, MAX_TRIES, STALL_SECONDS, ProcessExecutor, WorkerDied,  # noqa: F401
                                    describe_unit)
from lgp.executor.serial import Executor, SerialExecutor, default_jobs  # noqa: F401
from lgp.executor.signals import Interrupted, stop_signals  # noqa: F401


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
