"""Risk table of the 24 trials over the paper's sigma grid.

    python -m models.risk --table docs/risk_table.csv [--runs runs.csv]
        [--n-sims 100] [--seed 0] [--engine mujoco] [--jobs N] [--sigmas 0.05 0.065 ...]

Writes the tidy (trial, sigma, risk, falls, n, engine) table as CSV, optionally
the per-run table, and prints risk per trial and sigma.
"""
from __future__ import annotations

import sys
import time

from lgp import cli
from lgp.paper import N_SIMS, SIGMA_GRID
from models.risk.core import DEFAULT_ENGINE, risk_table, summarise
from models.risk.engine import ENGINES


PROG = "python -m models.risk"


def main(argv=None) -> int:
    p = cli.parser(PROG, description=__doc__.splitlines()[0])
    p.add_argument("--table", required=True, type=cli.output_file, help="CSV to write: trial, sigma, risk, falls, n, engine")
    p.add_argument("--runs", type=cli.output_file, help="also write the per-run CSV here")
    p.add_argument("--n-sims", type=cli.positive_int, default=N_SIMS, help="simulations per trial and sigma (default %(default)s)")
    p.add_argument("--seed", type=cli.seed, default=0)
    p.add_argument("--engine", choices=sorted(ENGINES), default=DEFAULT_ENGINE)
    p.add_argument("--jobs", type=cli.positive_int, default=None, help="worker processes (default: all cores)")
    p.add_argument("--sigmas", type=cli.sigma, nargs="+", default=list(SIGMA_GRID), help="noise SDs in (0, 1], fractions of d")
    p.add_argument("--trials", type=cli.trial_id, nargs="+", help="trial ids (default: all 24; case-insensitive)")
    args = p.parse_args(argv)

    import stimuli

    trials = stimuli.load_all() if not args.trials else [stimuli.load_trial(t) for t in args.trials]
    t0 = time.perf_counter()
    last = [0.0]

    def progress(done, total):
        now = time.perf_counter()
        if now - last[0] > 5 or done == total:
            last[0] = now
            print(f"  {done}/{total} runs, {now - t0:.0f} s", file=sys.stderr, flush=True)

    runs = risk_table(trials, args.sigmas, args.n_sims, args.seed, args.engine, args.jobs, progress, runs=True)
    table = summarise(runs)
    order = {t.id: k for k, t in enumerate(trials)}
    table = table.sort_values(["trial", "sigma"], key=lambda c: c.map(order) if c.name == "trial" else c).reset_index(drop=True)
    table.to_csv(args.table, index=False)
    if args.runs:
        runs.to_csv(args.runs, index=False)
    wide = table.pivot(index="trial", columns="sigma", values="risk").reindex([t.id for t in trials])
    print(wide.to_string(float_format=lambda x: f"{x:.2f}"))
    print(f"{len(runs)} runs with {args.engine} in {time.perf_counter() - t0:.1f} s -> {args.table}", file=sys.stderr)
    return 0


if __name__ == "__main__":
    raise SystemExit(cli.run_cli(main, prog=PROG))
