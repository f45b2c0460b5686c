"""Figures of the Results section drawn from SIMULATED participants (not human data).

    python -m analysis.demo --results results --out docs/simulated

The paper's responses are not public. To show what `lgp.reproduce --human-data`
produces, this draws simulated participants from the full model (Eq. 1) on the
model's own effort and risk tables (from `python -m lgp.reproduce`), with stated
betas, sigma and noise, and runs the analysis on them. Every file it writes is
named ``simulated_*`` and every figure title says "SIMULATED participants". The
numbers say nothing about people; they show the figures and check the pipeline.
"""
from __future__ import annotations

import argparse
from pathlib import Path

import numpy as np
import pandas as pd

from analysis.run import run_analysis
from lgp.paper import PAPER_SIGMA
from analysis.simulate import simulate_participants

#: Stated, not fitted: risky effort costs 4x safe effort; n as in the paper's datasets.
BETAS = (0.0, 1.0, 4.0)
SIGMA = PAPER_SIGMA
PARTICIPANTS = {"difficulty": 59, "time": 60, "build": 20}
NOISE_SD = 0.1


def main(argv=None) -> None:
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--results", default="results", help="output folder of python -m lgp.reproduce")
    p.add_argument("--out", default="results/simulated")
    p.add_argument("--seed", type=int, default=0)
    p.add_argument("--n-boot", type=int, default=1000)
    args = p.parse_args(argv)
    results = Path(args.results)
    effort = pd.read_csv(results / "effort_samples.csv", dtype={"trial": str})
    risk = pd.read_csv(results / "risk.csv", dtype={"trial": str})
    rng = np.random.default_rng(args.seed)
    people = simulate_participants(effort, risk, BETAS, SIGMA, PARTICIPANTS, NOISE_SD, rng, datasets=list(PARTICIPANTS))
    run_analysis(people, effort, risk, args.out, seed=args.seed, n_boot=args.n_boot, jobs=2)
    print(f"SIMULATED-participant analysis written to {Path(args.out).resolve()}")


if __name__ == "__main__":
    main()
