"""Benchmark of the main job, `python -m lgp.reproduce`: cold (empty cache) and warm
(everything cached) runs with --jobs 1 and --jobs 2, side by side in one run;
writes the "reproduce" section of docs/benchmarks.md (other sections are kept).

    python bench/reproduce.py                 # the paper's full run (slow: 4 cold runs)
    python bench/reproduce.py --quick         # the --quick run instead
    python bench/reproduce.py --jobs 2        # only --jobs 2

Each configuration runs in a fresh subprocess with a fresh output folder; the
stage times come from the run's own log lines. Numbers depend on the machine's
load: the section records the load average before and after.
"""
from __future__ import annotations

import argparse
import os
import re
import subprocess
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT / "bench"))

from common import machine, write_section  # noqa: E402


def run(args: list[str], out: Path) -> dict:
    """Wall and CPU seconds of one `python -m lgp.reproduce` (children included)."""
    env = {**os.environ, "PYTHONPATH": str(ROOT)}
    before = os.times()
    t0 = time.perf_counter()
    proc = subprocess.run([sys.executable, "-m", "lgp.reproduce", "--out", str(out), "--verbose", *args],
                          cwd=ROOT, env=env, capture_output=True, text=True)
    wall = time.perf_counter() - t0
    after = os.times()
    if proc.returncode != 0:
        raise SystemExit(f"lgp.reproduce {' '.join(args)} failed:\n{proc.stderr[-2000:]}")
    cpu = (after.children_user - before.children_user) + (after.children_system - before.children_system)
    risk = sum(float(s) for s in re.findall(r"^\[risk\] simulated .*? in ([0-9.]+) s$", proc.stderr, re.M))
    return {"wall": wall, "cpu": cpu, "risk": risk}


def main(argv=None) -> int:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--quick", action="store_true", help="benchmark `--quick` instead of the full run")
    p.add_argument("--jobs", type=int, nargs="+", default=[1, 2])
    p.add_argument("--out", type=Path, default=ROOT / "docs" / "benchmarks.md")
    args = p.parse_args(argv)

    flags = ["--quick"] if args.quick else []
    start = machine()
    rows = []
    with tempfile.TemporaryDirectory() as tmp:
        for jobs in args.jobs:
            out = Path(tmp) / f"jobs{jobs}"
            cold = run([*flags, "--jobs", str(jobs)], out)
            warm = run([*flags, "--jobs", str(jobs)], out)
            rows.append((jobs, cold, warm))
            print(f"--jobs {jobs}: cold {cold['wall']:.1f} s wall ({cold['cpu']:.0f} CPU-s), warm {warm['wall']:.1f} s", flush=True)
    end = machine()
    what = "`python -m lgp.reproduce --quick`" if args.quick else "`python -m lgp.reproduce` (M = 30, N = 100, 11 sigmas, 24 trials)"
    lines = [
        "## reproduce --quick" if args.quick else "## reproduce",
        "",
        f"The main job end to end, {what}; written by `python bench/reproduce.py{' --quick' if args.quick else ''}`. "
        "Each row is a fresh subprocess and a fresh output folder (cold: empty cache; warm: the same command again). "
        "Configurations ran one after the other in one benchmark run.",
        "",
        f"- before: {start}",
        f"- after: {end}",
        "",
        "| --jobs | cold wall (s) | cold CPU (s) | of which risk stage wall (s) | warm wall (s) |",
        "|---|---|---|---|---|",
    ]
    for jobs, cold, warm in rows:
        lines.append(f"| {jobs} | {cold['wall']:.1f} | {cold['cpu']:.0f} | {cold['risk']:.1f} | {warm['wall']:.1f} |")
    if len(rows) > 1:
        base = rows[0][1]["wall"]
        lines += ["", "Cold wall time relative to --jobs " + str(rows[0][0]) + ": "
                  + ", ".join(f"--jobs {j}: {c['wall'] / base:.2f}" for j, c, _ in rows) + "."]
    write_section(args.out, "reproduce --quick" if args.quick else "reproduce", "\n".join(lines))
    print(f"wrote the reproduce section of {args.out}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
