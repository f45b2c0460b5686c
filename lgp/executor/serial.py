"""The executor interface (`Executor.map(fn, items, on_result=None) -> list`), the
executor that runs everything in this process, and the cores this process may use."""
from __future__ import annotations

import os
from typing import Any, Callable, Protocol, Sequence


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
