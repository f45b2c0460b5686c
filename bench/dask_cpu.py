"""Where the Dask overhead of bench/scale.py goes: the same effort units on a
1-process pool and a 1-worker LocalCluster, timed outside (wall) and inside each
task (wall and CPU of the task's thread).

    python bench/dask_cpu.py        # writes the "dask overhead" section of docs/benchmarks.md
"""
from __future__ import annotations

import sys
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))
sys.path.insert(0, str(ROOT / "bench"))

from common import machine, write_section  # noqa: E402

TRIALS = ("1E", "4E", "7E", "11H")
SAMPLES = 2


def timed(unit):
    """effort_of_unit, returning (wall s, CPU s of this thread) spent inside the task."""
    from models.effort import effort_of_unit

    t, c = time.perf_counter(), time.thread_time()
    effort_of_unit(unit)
    return time.perf_counter() - t, time.thread_time() - c


def warm(_):
    import models.effort  # noqa: F401
    import models.risk  # noqa: F401

    return 0


def main() -> int:
    import stimuli
    from lgp.executor import DaskExecutor, ProcessExecutor
    from models.effort import effort_units

    units = [u for t in TRIALS for u in effort_units(stimuli.load_trial(t), SAMPLES, 0)]
    before = machine()
    rows = []
    for name, make in (("process pool, 1 process", lambda: ProcessExecutor(1)),
                       ("LocalCluster, 1 worker", lambda: DaskExecutor("local-dask", 1))):
        ex = make()
        ex.map(warm, [0, 0])
        t0 = time.perf_counter()
        res = ex.map(timed, units)
        wall = time.perf_counter() - t0
        ex.close()
        rows.append((name, wall, sum(r[0] for r in res), sum(r[1] for r in res)))
        print(f"{name:26s} wall {wall:.2f} s, inside tasks {rows[-1][2]:.2f} s wall, {rows[-1][3]:.2f} s CPU", flush=True)
    lines = ["## dask overhead", "",
             f"`python bench/dask_cpu.py`: {len(units)} effort plans ({', '.join(TRIALS)}, {SAMPLES} layouts each) on one "
             f"worker of each backend, one after the other (before: {before}; after: {machine()}).", "",
             "| backend | wall (s) | inside tasks, wall (s) | inside tasks, CPU (s) |", "|---|---|---|---|"]
    lines += [f"| {n} | {w:.2f} | {iw:.2f} | {ic:.2f} |" for n, w, iw, ic in rows]
    (p, d) = rows
    lines += ["", f"CPU time inside the tasks differs by {100 * (d[3] / p[3] - 1):+.0f} % and the scheduling around them "
              f"costs {d[1] - d[2]:.2f} s against {p[1] - p[2]:.2f} s for the pool. A task's wall time was "
              f"{d[2] / d[3]:.1f}x its CPU time under Dask and {p[2] / p[3]:.1f}x in the pool: where that ratio is well "
              "above 1 the machine is loaded, and a Dask worker's nanny process and the scheduler's thread compete "
              "for the same cores."]
    write_section(ROOT / "docs" / "benchmarks.md", "dask overhead", "\n".join(lines))
    print("\n".join(lines))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
