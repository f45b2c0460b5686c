"""A pytest plugin that writes each test's wall and CPU seconds (this process and the
children it waited for) to a CSV: timings that hold up on a shared machine, where
`--durations` wall times grow with the other jobs' load.

    PYTHONPATH=.:bench python -m pytest -q -n 0 -p pytest_cpu --cpu-csv times.csv [-m "not slow"]
    python bench/test_times.py times.csv [other.csv]   # per module, slowest tests, side by side

Rows: nodeid, phase totals (setup + call + teardown), wall_s, cpu_s (own user+system),
child_cpu_s (children reaped during the test), markers (slow or not), and one
"<collection>" row (the imports and parametrisation before the first test).
"""
from __future__ import annotations

import csv
import os
import resource
import time

import pytest


def _cpu() -> tuple[float, float]:
    own = resource.getrusage(resource.RUSAGE_SELF)
    kids = resource.getrusage(resource.RUSAGE_CHILDREN)
    return own.ru_utime + own.ru_stime, kids.ru_utime + kids.ru_stime


def pytest_addoption(parser):
    parser.addoption("--cpu-csv", default=None, help="write each test's wall and CPU seconds to this CSV")


FIELDS = ["nodeid", "wall_s", "cpu_s", "child_cpu_s", "slow"]


class _Recorder:
    """Appends a row per test as it ends (a run stopped half way keeps what it measured)."""

    def __init__(self, path: str):
        self.path = path
        self.rows: list[dict] = []
        self.t0 = time.perf_counter()
        self.c0 = _cpu()
        self.file = open(path, "w", newline="")
        self.writer = csv.DictWriter(self.file, fieldnames=FIELDS)
        self.writer.writeheader()

    def _add(self, row: dict) -> None:
        self.rows.append(row)
        self.writer.writerow(row)
        self.file.flush()

    @pytest.hookimpl(hookwrapper=True, tryfirst=True)
    def pytest_runtest_protocol(self, item, nextitem):
        if not self.rows:  # the first test: everything before it was start-up and collection
            own, kids = _cpu()
            self._add({"nodeid": "<collection>", "wall_s": round(time.perf_counter() - self.t0, 3),
                              "cpu_s": round(own - self.c0[0], 3), "child_cpu_s": round(kids - self.c0[1], 3),
                              "slow": ""})
        t, (own, kids) = time.perf_counter(), _cpu()
        yield
        own2, kids2 = _cpu()
        self._add({"nodeid": item.nodeid, "wall_s": round(time.perf_counter() - t, 3),
                          "cpu_s": round(own2 - own, 3), "child_cpu_s": round(kids2 - kids, 3),
                          "slow": int(item.get_closest_marker("slow") is not None)})

    def pytest_sessionfinish(self, session):
        self.file.close()


def pytest_configure(config):
    path = config.getoption("--cpu-csv")
    if path and getattr(config.option, "numprocesses", None):
        raise pytest.UsageError("--cpu-csv measures the tests of one process: add -n 0 (pyproject's addopts run two)")
    if path:
        config.pluginmanager.register(_Recorder(os.path.abspath(path)), "pytest-cpu-recorder")
