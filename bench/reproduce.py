"""Benchmark of the main job, `python -m lgp.reproduce`: cold (empty cache) and warm
(everything cached) runs with --jobs 1 and --jobs 2, side by side in one run;
writes the "reproduce" section of docs/benchmarks.md (other sections are kept).

    python bench/reproduce.py                 # the paper's full run (slow: 4 cold runs)
    python bench/reproduce.py --quick         # the --quick run instead
    python bench/reproduce.py --jobs 2        # only --jobs 2
    python bench/reproduce.py --grids         # cold default run vs cold --sigma-grid wide, side by side

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
    p.add_argument("--grids", action="store_true",
                   help="cold default run and cold --sigma-grid wide run, alternating, --jobs 2")
    p.add_argument("--repeats", type=int, default=1, help="with --grids: pairs of runs")
    p.add_argument("--keep", type=Path, help="with --grids: keep the runs' output folders under this folder")
    args = p.parse_args(argv)
    if args.grids:
        return grids(args)

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


def cpu_model() -> str:
    for line in Path("/proc/cpuinfo").read_text().splitlines():
        if line.startswith("model name"):
            return line.split(":", 1)[1].strip()
    return "unknown CPU"


def grids(args) -> int:
    """Cold `python -m lgp.reproduce` against cold `--sigma-grid wide`, alternating, one
    benchmark run: the wide grid's cost as a ratio measured side by side."""
    flags = ["--quick"] if args.quick else []
    start = machine()
    rows = []
    with tempfile.TemporaryDirectory() as tmp:
        tmp = args.keep or tmp
        for k in range(args.repeats):
            for name, extra in (("paper grid (default)", []), ("--sigma-grid wide", ["--sigma-grid", "wide"])):
                r = run([*flags, *extra, "--jobs", "2", "--no-replays"], Path(tmp) / f"{k}{len(extra)}")
                rows.append((name, r))
                print(f"{name}: {r['wall']:.1f} s wall, risk stage {r['risk']:.1f} s", flush=True)
    end = machine()
    base = [r["wall"] for n, r in rows if not n.startswith("--")]
    wide = [r["wall"] for n, r in rows if n.startswith("--")]
    lines = [
        "## reproduce: wide sigma grid",
        "",
        f"Cold `python -m lgp.reproduce{' --quick' if args.quick else ''} --jobs 2 --no-replays` (11 sigmas) against the same "
        "with `--sigma-grid wide` (31 sigmas: 0.05..0.30 d step 0.01 plus the paper's points), alternating, each a "
        "fresh subprocess and empty cache; written by `python bench/reproduce.py --grids`. Goal: wide "
        "within 2.5x the default.",
        "",
        f"- machine: {cpu_model()}",
        f"- before: {start}",
        f"- after: {end}",
        "",
        "| run | cold wall (s) | cold CPU (s) | of which risk stage wall (s) |",
        "|---|---|---|---|",
    ]
    for name, r in rows:
        lines.append(f"| {name} | {r['wall']:.1f} | {r['cpu']:.0f} | {r['risk']:.1f} |")
    lines += ["", "The wide grid has 31/11 = 2.8x the runs, and a run past the paper's grid costs more: a falling run "
              "simulates until a block has moved 1 d, a standing one stops at rest (mean simulated time per run 0.22 s "
              "on the wide grid against 0.12 s on the paper's, MuJoCo, lift, N = 100). Trials whose B is identical "
              "(1H = 9E = 9H = 11E = 11H, 2E = 2H) are simulated once in both runs."]
    lines += ["", f"Wide / default cold wall time: {sum(wide) / sum(base):.2f} (risk stage: "
              f"{sum(r['risk'] for n, r in rows if n.startswith('--')) / max(sum(r['risk'] for n, r in rows if not n.startswith('--')), 1e-9):.2f})."]
    write_section(args.out, "reproduce: wide sigma grid" + (" (--quick)" if args.quick else ""), "\n".join(lines))
    print(f"wrote the wide-grid section of {args.out}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
