"""Benchmark of the model comparison (issue 23); writes the "model comparison"
section of docs/benchmarks.md (other sections are kept).

    python bench/compare.py --results results [--out docs/benchmarks.md]

On the effort and risk tables of a `python -m lgp.reproduce` run (--results), it
times, side by side in one run:

1. the whole human-data analysis, `analysis.run_analysis`, on SIMULATED
   participants (3 datasets x 60; Eq. 1 with b = (0, 1, 4), sigma = 0.065 d,
   noise 1.0), with 1000 bootstrap resamples and 1000 permutations per test, the
   cross-validation redone in every resample (twice: risk fixed and risk redrawn
   from its runs), figures included; against the same call with
   ``compare=False`` (the paper's in-sample analysis only);
2. model recovery, `analysis.recovery.recovery`, 200 studies per cell, 20/60/200
   participants, every sigma of the table, with jobs 1 and 2.
"""
from __future__ import annotations

import argparse
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))
sys.path.insert(0, str(ROOT / "bench"))

from common import machine, write_section  # noqa: E402


def cpu_model() -> str:
    for line in Path("/proc/cpuinfo").read_text().splitlines():
        if line.startswith("model name"):
            return line.split(":", 1)[1].strip()
    return "unknown CPU"


def timed(fn):
    t0, c0 = time.perf_counter(), time.process_time()
    out = fn()
    return out, time.perf_counter() - t0, time.process_time() - c0


def main(argv=None) -> int:
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--results", type=Path, default=ROOT / "results")
    p.add_argument("--out", type=Path, default=ROOT / "docs" / "benchmarks.md")
    p.add_argument("--n-boot", type=int, default=1000)
    p.add_argument("--n-perm", type=int, default=1000)
    p.add_argument("--studies", type=int, default=200)
    args = p.parse_args(argv)

    from analysis.crossval import risk_grid
    from analysis.demo import read_results
    from analysis.recovery import recovery
    from analysis.run import run_analysis
    from analysis.simulate import simulate_participants

    effort, risk = read_results(args.results)
    people = simulate_participants(effort, risk, (0.0, 1.0, 4.0), 0.065, 60, 1.0, np.random.default_rng(0))
    before = machine()
    rows = []
    with tempfile.TemporaryDirectory() as tmp:
        _, w0, c0 = timed(lambda: run_analysis(people, effort, risk, Path(tmp) / "paper", seed=0, n_boot=args.n_boot,
                                               jobs=2, compare=False))
        _, w1, c1 = timed(lambda: run_analysis(people, effort, risk, Path(tmp) / "all", seed=0, n_boot=args.n_boot,
                                               n_perm=args.n_perm, jobs=2))
    rows.append(("`run_analysis`, in-sample only (`compare=False`)", w0, c0))
    rows.append((f"`run_analysis` with the comparison ({args.n_boot} resamples x 3 schemes x 2 risk draws, "
                 f"2 x {args.n_perm} permutations)", w1, c1))
    grid = risk_grid(risk)
    rec = {}
    for jobs in (1, 2):
        (conf, _), w, c = timed(lambda: recovery(effort, grid, n_studies=args.studies, seed=0, jobs=jobs))
        rec[jobs] = conf
        cells = conf.groupby(["source", "true_model", "sigma", "participants"]).ngroups
        rows.append((f"recovery, {cells} cells x {args.studies} studies x 3 procedures, jobs {jobs}", w, c))
    same = rec[1].to_csv(index=False) == rec[2].to_csv(index=False)
    after = machine()
    text = (
        "## model comparison\n\n"
        f"`python bench/compare.py --results {args.results}` on {cpu_model()}; {before} at the start, "
        f"{after} at the end (a shared machine: other helpers' jobs ran beside it). Tables: "
        f"{len(grid.sigmas)} sigmas ({grid.sigmas.min():g}-{grid.sigmas.max():g} d). SIMULATED participants "
        "(3 datasets x 60), not human data.\n\n"
        "| step | wall s | CPU s (this process) |\n|---|---|---|\n"
        + "".join(f"| {name} | {w:.1f} | {c:.1f} |\n" for name, w, c in rows)
        + f"\nThe comparison costs {w1 - w0:.1f} s of wall time beyond the in-sample analysis "
          f"({w1 / w0:.1f}x its time). Recovery tables with jobs 1 and 2 are "
          f"{'byte-identical' if same else 'DIFFERENT'}.\n"
    )
    write_section(args.out, "model comparison", text)
    print(text)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
