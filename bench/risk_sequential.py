"""Benchmark of the sequential noisy build (models.risk.build, mode="sequential"):
all 24 trials at N = 100 and three sigmas on 2 cores, beside the same trials'
independent stages (mode="stages") in the same run; writes the "risk: sequential
build" section of docs/benchmarks.md (other sections are kept).

    python bench/risk_sequential.py [--samples 1] [--jobs 2]

One plan per trial (layout 0) unless --samples says more: a tower's plan is the
same for every layout, while a floor's 30 layouts are 30 builds of 15 stages.
"""
from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))
sys.path.insert(0, str(ROOT / "bench"))

from common import machine, write_section  # noqa: E402

SIGMAS = (0.065, 0.1, 0.15)


def cpu_model() -> str:
    for line in Path("/proc/cpuinfo").read_text().splitlines():
        if line.startswith("model name"):
            return line.split(":", 1)[1].strip()
    return "unknown CPU"


def main(argv=None) -> int:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--samples", type=int, default=1)
    p.add_argument("--jobs", type=int, default=2)
    p.add_argument("--n-sims", type=int, default=100)
    p.add_argument("--out", type=Path, default=ROOT / "docs" / "benchmarks.md")
    args = p.parse_args(argv)

    import pandas as pd

    import stimuli
    from lgp.executor import ProcessExecutor
    from models.risk.build import build_risk, build_risk_aggregates

    trials = stimuli.load_paper()
    start = machine()
    times, tables = {}, {}
    with ProcessExecutor(args.jobs) as ex:
        ex.start()
        build_risk(trials[0], SIGMAS[0], n_sims=2, samples=1, executor=ex, jobs=args.jobs)  # warm the workers
        for mode in ("sequential", "stages"):
            t0 = time.perf_counter()
            tables[mode] = pd.concat([build_risk(t, list(SIGMAS), n_sims=args.n_sims, samples=args.samples, seed=0,
                                                 executor=ex, jobs=args.jobs, mode=mode) for t in trials])
            times[mode] = time.perf_counter() - t0
            print(f"{mode}: {times[mode]:.1f} s", flush=True)
    end = machine()
    sims = {m: int(t["reached"].sum()) if m == "sequential" else int(len(t.drop_duplicates(["trial", "sigma", "stage"])) * args.n_sims)
            for m, t in tables.items()}
    agg = build_risk_aggregates(pd.concat(tables.values()))
    lines = [
        "## risk: sequential build",
        "",
        f"`build_risk(trial, {list(SIGMAS)}, n_sims={args.n_sims}, samples={args.samples}, mode=...)` for all 24 trials, "
        f"--jobs {args.jobs}, MuJoCo, one process pool; written by `python bench/risk_sequential.py`. The sequential "
        "build simulates, per run, every stage until it collapses; the independent stages simulate each distinct "
        "stage scene once per run.",
        "",
        f"- machine: {cpu_model()}",
        f"- before: {start}",
        f"- after: {end}",
        "",
        "| mode | wall (s) | stage simulations | per simulation (ms wall) |",
        "|---|---|---|---|",
    ]
    for m in ("sequential", "stages"):
        lines.append(f"| {m} | {times[m]:.1f} | {sims[m]} | {1000 * times[m] / max(sims[m], 1):.2f} |")
    lines += ["", f"Sequential / stages wall time: {times['sequential'] / times['stages']:.2f}. Goal: sequential within 60 s.",
              "", "Sequential-build risk (fraction of runs that collapse at some stage) by sigma:", "",
              "| trial | " + " | ".join(f"{s:g}" for s in SIGMAS) + " |", "|---|" + "---|" * len(SIGMAS)]
    for trial, g in agg.groupby("trial", sort=False):
        lines.append(f"| {trial} | " + " | ".join(f"{v:.2f}" for v in g.sort_values("sigma")["sequential"]) + " |")
    write_section(args.out, "risk: sequential build", "\n".join(lines))
    print(f"wrote the 'risk: sequential build' section of {args.out}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
