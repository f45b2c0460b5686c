"""What every benchmark script shares: the machine's description and writing one
'## name' section of docs/benchmarks.md (other sections are kept)."""
from __future__ import annotations

import contextlib
import os
import platform
import re
import signal
from pathlib import Path


#: The speed probe's work: a fixed mix of interpreted Python and numpy (the two
#: kinds of work of the suite), one thread.
PROBE_LOOPS = 4_000_000


def speed_probe(repeats: int = 3) -> float:
    """CPU seconds of a fixed single-thread job (the least of `repeats`): the same
    code takes more CPU seconds when the machine's cores are slower (a shared host's
    neighbours, a lower clock), so a timing from another hour can be put beside it.
    About 0.3 s on this project's 2-core AMD EPYC machine."""
    import time

    import numpy as np

    a = np.random.default_rng(0).random((30, 30)) + 30 * np.eye(30)  # small: no BLAS threads
    best = float("inf")
    for _ in range(repeats):
        t = time.process_time()
        x = 0
        for i in range(PROBE_LOOPS):
            x += i * i % 7
        for _ in range(6000):
            np.linalg.solve(a, a[:, 0])
        best = min(best, time.process_time() - t)
    return best


def cpu_model() -> str:
    """The CPU's model name from /proc/cpuinfo (the architecture where there is none)."""
    try:
        for line in Path("/proc/cpuinfo").read_text().splitlines():
            if line.lower().startswith("model name"):
                return line.split(":", 1)[1].strip()
    except OSError:
        pass
    return platform.processor() or platform.machine()


def machine() -> str:
    """Cores, CPU model, architecture and load averages now (1, 5, 15 min)."""
    cores = len(os.sched_getaffinity(0)) if hasattr(os, "sched_getaffinity") else os.cpu_count()
    load = ", ".join(f"{x:.1f}" for x in os.getloadavg())
    return f"{os.cpu_count()} cores ({cores} usable), {cpu_model()}, {platform.machine()}, load average {load} (1/5/15 min)"


def write_section(out: Path, name: str, text: str) -> None:
    """Replace the '## name' section of `out` (up to the next '## ' heading) or append it."""
    old = out.read_text() if out.exists() else "# Benchmarks\n"
    pattern = re.compile(rf"^## {re.escape(name)}[ \t]*$.*?(?=^## |\Z)", re.S | re.M)
    if pattern.search(old):
        new = pattern.sub(lambda _: text.rstrip("\n") + "\n\n", old, count=1)
    else:
        new = old.rstrip("\n") + "\n\n" + text.rstrip("\n") + "\n"
    out.write_text(new.rstrip("\n") + "\n")


class Deadline(Exception):
    """Raised by `deadline` when its time is up."""


@contextlib.contextmanager
def deadline(seconds: float):
    """Raise Deadline in this (main) thread after `seconds` (SIGALRM): a blocking open
    of a FIFO or an endless read is interrupted (bench/faults.py, tests/test_bad_inputs.py)."""
    def ring(signum, frame):
        raise Deadline(f"still running after {seconds:g} s")

    old = signal.signal(signal.SIGALRM, ring)
    signal.setitimer(signal.ITIMER_REAL, seconds)
    try:
        yield
    finally:
        signal.setitimer(signal.ITIMER_REAL, 0)
        signal.signal(signal.SIGALRM, old)
