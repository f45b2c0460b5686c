"""Run-by-run agreement of the risk engines with MuJoCo on the stimuli's noisy
scenes (docs/risk.md, "PhysX"): every trial's B perturbed with runs 0..N-1 of
seed 0 at one sigma, simulated by each engine, verdicts compared run by run.

    python bench/risk_agreement.py [--n-sims 50] [--sigma 0.065] [--engines physx physx:game-defaults]
        [--fall-rule horizontal] [--fall-threshold 0.25]

Prints a markdown table: agreement, runs where only one engine falls, and the
risk of each trial under each engine.
"""
from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

import stimuli  # noqa: E402
from models.risk import RiskModel, risk_table  # noqa: E402


def main(argv=None) -> int:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--n-sims", type=int, default=50)
    p.add_argument("--sigma", type=float, default=0.065)
    p.add_argument("--engines", nargs="+", default=["physx", "physx:game-defaults"])
    p.add_argument("--fall-rule", default="horizontal")
    p.add_argument("--fall-threshold", type=float, default=0.25)
    p.add_argument("--jobs", type=int, default=None)
    args = p.parse_args(argv)
    trials = stimuli.load_paper()
    runs, wall = {}, {}
    for engine in ["mujoco", *args.engines]:
        t0 = time.perf_counter()
        model = RiskModel(engine, None, args.fall_rule, args.fall_threshold)
        runs[engine] = risk_table(trials, [args.sigma], n_sims=args.n_sims, seed=0, model=model, jobs=args.jobs, runs=True)
        wall[engine] = time.perf_counter() - t0
    base = runs["mujoco"]["fell"].to_numpy()
    print(f"sigma = {args.sigma} d, {len(trials)} trials x {args.n_sims} runs (seed 0), fall rule {args.fall_rule} "
          f"> {args.fall_threshold} d\n")
    print("| engine | agreement with MuJoCo | falls only in MuJoCo | falls only in this engine | falls | wall (s) |")
    print("|---|---|---|---|---|---|")
    for engine, df in runs.items():
        fell = df["fell"].to_numpy()
        print(f"| {engine} | {(fell == base).mean():.2%} | {int((base & ~fell).sum())} | {int((fell & ~base).sum())} | "
              f"{int(fell.sum())} | {wall[engine]:.0f} |")
    print()
    ids = [t.id for t in trials]
    print("| engine | " + " | ".join(ids) + " |")
    print("|---|" + "---|" * len(ids))
    for engine, df in runs.items():
        risk = df.groupby("trial")["fell"].mean()
        print(f"| {engine} | " + " | ".join(f"{risk[t]:.2f}" for t in ids) + " |")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
