"""Process pools that stop at once when interrupted.

`concurrent.futures` finishes every queued task before a pool shuts down, even
after Ctrl-C, so an interrupted run would keep computing for minutes. Here an
exception (KeyboardInterrupt included) cancels what is queued and terminates the
workers; results already returned have been handed to the caller.
"""
from __future__ import annotations

from concurrent.futures import ProcessPoolExecutor, as_completed
from typing import Callable, Iterable, Sequence


def map_in_processes(fn: Callable, args: Sequence, jobs: int, mp_context, on_result: Callable | None = None) -> list:
    """[fn(a) for a in args] over `jobs` processes, in input order.

    `on_result(index, result)` is called as each result arrives (for progress).
    """
    results: list = [None] * len(args)
    pool = ProcessPoolExecutor(max_workers=jobs, mp_context=mp_context)
    try:
        futures = {pool.submit(fn, a): k for k, a in enumerate(args)}
        for future in as_completed(futures):
            k = futures[future]
            results[k] = future.result()
            if on_result is not None:
                on_result(k, results[k])
    except BaseException:
        _terminate(pool, futures.keys() if "futures" in locals() else ())
        raise
    pool.shutdown(wait=True)
    return results


def _terminate(pool: ProcessPoolExecutor, futures: Iterable) -> None:
    for future in futures:
        future.cancel()
    for process in list((getattr(pool, "_processes", None) or {}).values()):
        process.terminate()
    pool.shutdown(wait=False, cancel_futures=True)
