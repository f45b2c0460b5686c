"""How long each command of the README takes: one benchmark run, quoted everywhere.

    python bench/commands.py            # the pipeline, lgp.show and stimuli.sheet, side by side in one run
    python bench/commands.py --only tests     # the fast test subset too (run it after the README quotes these rows)
    python bench/commands.py --only suite     # the whole suite (budget 8 min on 2 quiet cores; the fast subset's is 40 s)
    python bench/commands.py --only quick show sheet   # a subset (the other rows are kept)

Each command runs in a fresh subprocess and a fresh scratch folder, once cold (an
empty cache, the render cache of the pictures too) and, for the pipeline, once more warm (the same command again: all
cached), with ``--jobs 2`` and ``--jobs 1`` (a 2-core and a 1-core machine: the
range a reader's machine is likely in). Writes `lgp/command_times.csv` (package data; one row
per command, jobs and cache state, with the machine: cores, CPU model, load
average before and after) and the "commands" section of docs/benchmarks.md.
README, `python -m lgp.reproduce --help` and docs/results.md quote these rows
through `lgp.command_times.measured_time` (tests/test_readme.py checks that they do).
"""
from __future__ import annotations

import argparse
import csv
import datetime
import os
import shlex
import subprocess
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT / "bench"))
sys.path.insert(0, str(ROOT))

from common import cpu_model, machine, speed_probe, write_section  # noqa: E402

from lgp.cli import COMMAND_TIMES, measured_time  # noqa: E402

#: name -> (command as the README writes it, runs it has: (jobs, cache state) pairs)
COMMANDS = {
    "quick": ("python -m lgp.reproduce --quick", [(2, "cold"), (2, "warm"), (1, "cold")]),
    "full": ("python -m lgp.reproduce", [(2, "cold"), (2, "warm"), (1, "cold")]),
    "show": ("python -m lgp.show 7H --seed 0 --sample 0 --html 7H.html --png 7H.png", [(1, "cold")]),
    "sheet": ("python -m stimuli.sheet --out stimuli.png", [(1, "cold")]),
    "tests": ('python -m pytest -q -m "not slow"', [(2, "cold")]),
    "suite": ("python -m pytest -q", [(2, "cold")]),
}
#: What a plain `python bench/commands.py` runs: not the tests nor the suite (tests/test_readme.py checks
#: that the README quotes this file, so they pass only once it does).
DEFAULT = ("quick", "full", "show", "sheet")
FIELDS = ["command", "jobs", "cache", "wall_s", "cpu_s", "cores", "cpu_model", "load_before", "load_after",
          "probe_before_s", "probe_after_s", "date"]


def _load() -> str:
    return " ".join(f"{x:.1f}" for x in os.getloadavg())


def run(command: str, jobs: int, folder: Path) -> dict:
    """Wall and CPU seconds (children included) of one command, run in `folder`."""
    argv = shlex.split(command)[2:]
    if argv[0] == "lgp.reproduce":
        argv += ["--jobs", str(jobs)]
    if argv[0] == "pytest":
        argv += ["-p", "no:cacheprovider", str(ROOT / "tests")]
    # cold means every cache empty, the render cache (~/.cache/lgp-difficulty/renders) too
    env = {**os.environ, "PYTHONPATH": str(ROOT), "LGP_RENDER_CACHE": str(folder / "render-cache")}
    load_before, probe_before = _load(), speed_probe()
    before = os.times()
    t0 = time.perf_counter()
    proc = subprocess.run([sys.executable, "-m", *argv], cwd=folder, env=env, capture_output=True, text=True)
    wall = time.perf_counter() - t0
    after = os.times()
    if proc.returncode != 0:
        raise SystemExit(f"{command} failed:\n{proc.stdout[-1500:]}\n{proc.stderr[-1500:]}")
    cpu = (after.children_user - before.children_user) + (after.children_system - before.children_system)
    return {"command": command, "jobs": jobs, "wall_s": round(wall, 1), "cpu_s": round(cpu, 1),
            "cores": os.cpu_count(), "cpu_model": cpu_model(), "load_before": load_before, "load_after": _load(),
            "probe_before_s": round(probe_before, 3), "probe_after_s": round(speed_probe(), 3),
            "date": datetime.date.today().isoformat()}


def _write_csv(path: Path, old: list[dict], rows: list[dict]) -> list[dict]:
    """The CSV's earlier rows with this run's `rows` in place of those of the commands
    they measure: a command that has no new row yet (it failed, or the run was stopped)
    keeps its earlier rows."""
    order = {COMMANDS[n][0]: k for k, n in enumerate(COMMANDS)}
    measured = {r["command"] for r in rows}
    table = sorted([r for r in old if r["command"] not in measured] + rows, key=lambda r: (order.get(r["command"], 99), -int(r["jobs"]), r["cache"]))
    with path.open("w", newline="") as f:
        w = csv.DictWriter(f, fieldnames=FIELDS)
        w.writeheader()
        for r in table:
            w.writerow({k: r.get(k, "") for k in FIELDS})  # rows from before the probe: none
    return table


def _shown(path: Path) -> str:
    """`path` relative to the repository when it lies inside it, else as given."""
    path = path.resolve()
    return path.relative_to(ROOT).as_posix() if path.is_relative_to(ROOT) else str(path)


def main(argv=None) -> int:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--only", nargs="+", choices=list(COMMANDS), help="run only these (other rows of the CSV are kept)")
    p.add_argument("--csv", type=Path, default=COMMAND_TIMES)
    p.add_argument("--out", type=Path, default=ROOT / "docs" / "benchmarks.md")
    args = p.parse_args(argv)

    names = args.only or list(DEFAULT)
    old = []
    if args.csv.exists():
        with args.csv.open() as f:
            old = list(csv.DictReader(f))
    start, rows = machine(), []
    with tempfile.TemporaryDirectory() as tmp:
        for name in names:
            command, runs = COMMANDS[name]
            for jobs, cache in runs:
                folder = Path(tmp) / f"{name}-jobs{jobs}"  # a warm run reuses the cold run's folder and cache
                folder.mkdir(exist_ok=True)
                row = {**run(command, jobs, folder), "cache": cache}
                rows.append(row)
                _write_csv(args.csv, old, rows)  # after every row: a later failure keeps what was measured
                print(f"{command}  --jobs {jobs} {cache}: {row['wall_s']} s wall, {row['cpu_s']} CPU-s "
                      f"(load {row['load_before']} -> {row['load_after']})", flush=True)
    end = machine()
    table = _write_csv(args.csv, old, rows)
    lines = ["## commands", "",
             "How long the README's commands take; written by `python bench/commands.py` (rows: "
             f"`{_shown(args.csv)}`). Each row is a fresh subprocess in a fresh folder, one after the other "
             "in one benchmark run; cold = empty cache, warm = the same command again. `--jobs 1` stands for a "
             "1-core machine. The machine was shared with other jobs: the load average is written per row, and "
             "the speed probe's CPU seconds before and after (bench/common.py `speed_probe`: a fixed one-thread job; "
             "it took 0.26-0.41 s within minutes here, while the same suite's CPU seconds moved by up to a "
             "third between two hours): a much slower machine shows in both.", "",
             f"- before: {start}", f"- after: {end}", "",
             "| command | --jobs | cache | wall (s) | CPU (s) | load before -> after | probe before -> after (s) |",
             "|---|---|---|---|---|---|---|"]
    for r in table:
        probe = f"{r['probe_before_s']} -> {r['probe_after_s']}" if r.get("probe_before_s") else "not measured"
        lines.append(f"| `{r['command']}` | {r['jobs']} | {r['cache']} | {r['wall_s']} | {r['cpu_s']} | "
                     f"{r['load_before']} -> {r['load_after']} | {probe} |")
    lines += ["", "Quoted as (README, `--help`, docs/results.md, through `lgp.cli.measured_time`):", ""]
    lines += [f"- `{COMMANDS[n][0]}`: {measured_time(COMMANDS[n][0], args.csv)}" for n in COMMANDS
              if measured_time(COMMANDS[n][0], args.csv)]
    write_section(args.out, "commands", "\n".join(lines))
    print(f"wrote {args.csv} and the commands section of {args.out}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
