"""Wall times in words: the one duration format of every command line, progress line
and page (`duration_text`), and the measured times of the README's commands that
README, ``--help`` and docs/results.md quote (`measured_time`, from the rows
``python bench/commands.py`` writes to the package's command_times.csv), and the one
CPU clock of a command's own report (`cpu_seconds`).

Imports nothing of the project, so `lgp.cli` (on the ground floor) re-exports both.
"""
from __future__ import annotations

import csv
import resource
from pathlib import Path


#: How long the README's commands took: rows written by ``python bench/commands.py``.
#: Package data, not docs/: ``--help`` of an installed copy quotes them too.
COMMAND_TIMES = Path(__file__).resolve().parent / "command_times.csv"


def cpu_seconds() -> float:
    """User + system CPU seconds of this process and of the child processes it has
    waited for (a closed pool's workers, box2dweb's Node processes): differences of
    two readings are a command's CPU."""
    own, kids = resource.getrusage(resource.RUSAGE_SELF), resource.getrusage(resource.RUSAGE_CHILDREN)
    return own.ru_utime + own.ru_stime + kids.ru_utime + kids.ru_stime


def duration_text(seconds: float) -> str:
    """A wall time for a reader, the one format of every command line, progress
    line and page: "4.2 s", "16 s", "2 min 06 s", "1 h 05 min"."""
    s = max(0.0, float(seconds))
    if s < 10:
        return f"{s:.1f} s"
    if s < 120:
        return f"{s:.0f} s"
    if s < 3600:
        return f"{int(s // 60)} min {s % 60:02.0f} s"
    return f"{int(s // 3600)} h {s % 3600 // 60:02.0f} min"


def measured_time(command: str, path: Path | str | None = None) -> str | None:
    """How long `command` (as the README writes it) took in the last ``bench/commands.py``
    run, with the machine, as the one phrase README, ``--help`` and docs/results.md quote,
    e.g. ``16 s cold (20 CPU-s), 2.1 s cached (--jobs 2); 25 s cold with --jobs 1 [2 cores,
    AMD EPYC, load average 3.1-4.0; bench/commands.py]``. None when it was not measured."""
    path = COMMAND_TIMES if path is None else Path(path)
    try:
        with open(path, newline="") as f:
            rows = [r for r in csv.DictReader(f) if r["command"] == command]
    except OSError:
        return None
    if not rows:
        return None
    at = {(int(r["jobs"]), r["cache"]): float(r["wall_s"]) for r in rows}
    cpu = {(int(r["jobs"]), r["cache"]): float(r["cpu_s"]) for r in rows}
    most = max(j for j, _ in at)
    parts = []
    if (most, "cold") in at:
        # CPU seconds beside the wall time: they hardly change with the machine's load
        parts.append(duration_text(at[most, "cold"]) + (" cold" if (most, "warm") in at else "")
                     + (f" ({cpu[most, 'cold']:.0f} CPU-s)" if cpu[most, "cold"] >= 10 else ""))
    if (most, "warm") in at:
        parts.append(duration_text(at[most, "warm"]) + " cached")
    text = ", ".join(parts) + (f" (--jobs {most})" if any(j != most for j, _ in at) else "")
    others = sorted({j for j, _ in at if j != most}, reverse=True)
    for j in others:
        text += f"; {duration_text(at[j, 'cold'])} cold with --jobs {j}" if (j, "cold") in at else ""
    loads = [float(r[k].split()[0]) for r in rows for k in ("load_before", "load_after")]
    load = f"{min(loads):.1f}" if max(loads) - min(loads) < 0.05 else f"{min(loads):.1f}-{max(loads):.1f}"
    return f"{text} [{rows[0]['cores']} cores, {rows[0]['cpu_model']}, load average {load}; bench/commands.py]"
