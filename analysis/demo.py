"""Figures of the Results section drawn from SIMULATED participants (not human data).

    python -m analysis.demo --results results --out docs/simulated

The paper's responses are not public. To show what `lgp.reproduce --human-data`
produces, this draws simulated participants from the full model (Eq. 1) on the
model's own effort and risk tables (from `python -m lgp.reproduce`), with stated
betas, sigma and noise, and runs the analysis on them. Every file it writes is
named ``simulated_*`` and every figure title says "SIMULATED participants". The
numbers say nothing about people; they show the figures and check the pipeline.

The heuristic baselines (analysis.heuristics: B's height, blocks, stacked blocks,
transport distance, actions, support depth, and effort + height, effort +
stacked) are computed from the paper's trial files at the run's M and --seed and
passed to the analysis as lgp.reproduce --human-data passes them, with the sets
of identical B's for the folds by structure; so the demo's comparison tables and
figures show them.
"""
from __future__ import annotations

import argparse
from pathlib import Path

import numpy as np
import pandas as pd

from analysis.run import run_analysis
from analysis.simulate import read_results, simulate_participants  # noqa: F401 (read_results: demo's own name)
from lgp import cli
from lgp.paper import PAPER_SIGMA

#: Stated, not fitted: risky effort costs 4x safe effort; n as in the paper's datasets.
BETAS = (0.0, 1.0, 4.0)
SIGMA = PAPER_SIGMA
PARTICIPANTS = {"difficulty": 59, "time": 60, "build": 20}
NOISE_SD = 0.1


PROG = "python -m analysis.demo"


def heuristics(effort: pd.DataFrame, seed: int):
    """(features, same): the heuristic predictors of the paper's 24 trials at the
    effort table's M (its samples per trial) and `seed`, and the sets of trials
    whose B is identical (analysis.heuristics)."""
    import stimuli
    from analysis.heuristics import identical_targets, trial_features

    paper = stimuli.load_paper()
    samples = int(effort.groupby("trial")["sample"].nunique().max())
    return trial_features(paper, samples, seed), identical_targets(paper)


def main(argv=None) -> int:
    p = cli.parser(PROG, description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--results", default="results", type=cli.input_dir, help="output folder of python -m lgp.reproduce")
    p.add_argument("--out", default="results/simulated", type=cli.output_dir)
    p.add_argument("--seed", type=cli.seed, default=0)
    p.add_argument("--n-boot", type=cli.bounded_count("MAX_N_BOOT"), default=1000)
    p.add_argument("--n-perm", type=cli.positive_int, default=1000, help="permutations per permutation test")
    p.add_argument("--betas", type=float, nargs=3, metavar=("B0", "B1", "B2"), default=BETAS,
                   help="Eq. 1 of the simulated participants (b1 = b2: effort only) (default %(default)s)")
    p.add_argument("--noise", type=float, default=NOISE_SD, help="per-participant noise SD (default %(default)s)")
    args = p.parse_args(argv)
    if not (np.isfinite(args.noise) and args.noise >= 0):
        p.error(f"--noise must be a finite number >= 0, got {args.noise!r}")
    effort, risk = read_results(Path(args.results))
    rng = np.random.default_rng(args.seed)
    people = simulate_participants(effort, risk, tuple(args.betas), SIGMA, PARTICIPANTS, args.noise, rng,
                                   datasets=list(PARTICIPANTS))
    features, same = heuristics(effort, args.seed)
    run_analysis(people, effort, risk, args.out, seed=args.seed, n_boot=args.n_boot, n_perm=args.n_perm, jobs=2,
                 features=features, same=same)
    print(f"SIMULATED-participant analysis written to {Path(args.out).resolve()}")
    return 0


if __name__ == "__main__":
    raise SystemExit(cli.run_cli(main, prog=PROG))
