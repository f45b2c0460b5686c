"""Convergence of physical effort in the time discretisation: effort of every trial
(layout `--sample`, seed `--seed`) at 10, 20, 40 and 80 slices per phase, with the
relative change from the finest and the planning time. Writes a tidy CSV and
prints the markdown table of docs/effort.md.

    python bench/slices.py --out slices.csv [--slices 10 20 40 80] [--trials 2E 7H]
"""
from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

import pandas as pd

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))
sys.path.insert(0, str(ROOT / "bench"))

import stimuli  # noqa: E402
from common import machine  # noqa: E402
from models.effort import kinetic_energy, plan_of_sample  # noqa: E402


def main(argv=None) -> int:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--slices", type=int, nargs="+", default=[10, 20, 40, 80])
    p.add_argument("--trials", nargs="+")
    p.add_argument("--seed", type=int, default=0)
    p.add_argument("--sample", type=int, default=0)
    p.add_argument("--out", type=Path, required=True)
    args = p.parse_args(argv)

    print(f"# {machine()}", flush=True)
    trials = [stimuli.load_trial(t) for t in args.trials] if args.trials else stimuli.load_all()
    rows = []
    for trial in trials:
        for slices in args.slices:
            t0 = time.perf_counter()
            try:
                plan = plan_of_sample(trial, args.seed, args.sample, slices_per_phase=slices)
                effort, n_actions, status = kinetic_energy(plan), len(plan.actions), "ok"
            except Exception as e:  # a discretisation too coarse for the skeleton: recorded, not hidden
                effort, n_actions, status = float("nan"), 0, f"{type(e).__name__}: {e}"
            rows.append({"trial": trial.id, "slices_per_phase": slices, "effort": effort,
                         "plan_time": time.perf_counter() - t0, "n_actions": n_actions, "status": status})
            print(f"{trial.id:>4} {slices:3d} slices: effort {effort:.6f} J s in {rows[-1]['plan_time']:.2f} s  {status}", flush=True)
        pd.DataFrame(rows).to_csv(args.out, index=False)
    print(f"# {machine()}", flush=True)
    df = pd.DataFrame(rows)
    finest = df[df["slices_per_phase"] == max(args.slices)].set_index("trial")["effort"]
    df["rel_to_finest"] = df["effort"] / df["trial"].map(finest) - 1
    wide = df.pivot(index="trial", columns="slices_per_phase", values="rel_to_finest").reindex([t.id for t in trials])
    times = df.groupby("slices_per_phase")["plan_time"].mean()
    print("| trial | " + " | ".join(f"{s} slices" for s in args.slices) + " |")
    print("|---|" + "---|" * len(args.slices))
    for tid, row in wide.iterrows():
        print(f"| {tid} | " + " | ".join("fails" if v != v else f"{v * 100:+.2f}%" for v in row) + " |")
    print("| mean plan time (s) | " + " | ".join(f"{times[s]:.2f}" for s in args.slices) + " |")
    df.to_csv(args.out, index=False)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
