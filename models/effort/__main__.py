"""Physical effort of every trial file, or of the trials named.

    python -m models.effort --samples 30 --jobs 2 --out effort_samples.csv
    python -m models.effort 2E 2H --approach-height 0 --slices 40
    python -m models.effort 7H --planner search --budget-solves 5   # the search (lgp.search)

Prints one line per trial (mean effort, its SD over the layouts, actions, planning
time) and with ``--out`` writes the tidy (trial, sample) table. The command line
lives here, not in models/effort/__init__.py, so that editing it (a help string,
an argument check in lgp.cli) does not change the effort cache key.
"""
from __future__ import annotations

from lgp.atomic import write_csv_atomic

import sys

import pandas as pd

from lgp import cli
from lgp.paper import SAMPLES
from lgp.planner import APPROACH, PLANNERS, SLICES_PER_PHASE, Budget, Design, EffortSpec, check_approach_height
from models.effort import physical_effort

PROG = "python -m models.effort"


def main(argv=None) -> int:
    parser = cli.parser(PROG, description="Physical effort of every trial file, or of the trials named.")
    parser.add_argument("trials", nargs="*", type=cli.trial_id,
                        help="trial ids (case-insensitive; default: every trial file in stimuli/trials, "
                             "the paper's 24 and any others there)")
    parser.add_argument("--samples", type=cli.bounded_count("MAX_SAMPLES"), default=SAMPLES, help="layouts per trial (default %(default)s)")
    parser.add_argument("--seed", type=cli.seed, default=0)
    cli.add_jobs_argument(parser, 1, "worker processes (default 1)")
    parser.add_argument("--out", type=cli.output_file, help="write the per-sample table (CSV) here")
    parser.add_argument("--approach-height", type=cli.checked(check_approach_height, "approach height"), default=APPROACH,
                        help="vertical approach/retreat leg (m) at every grasp and place; 0 = clearance constraint "
                             "instead (default %(default)s)")
    parser.add_argument("--slices", type=cli.positive_int, default=SLICES_PER_PHASE,
                        help="KOMO slices per 1 s phase (default %(default)s)")
    parser.add_argument("--planner", type=cli.one_of(PLANNERS, "planner"), default="paper",
                        help="paper: the paper's pipeline (default); search: best-first over skeletons (lgp.search)")
    parser.add_argument("--budget-solves", type=cli.positive_int, default=None,
                        help=f"search: at most this many KOMO solves per layout (default {Budget().solves})")
    parser.add_argument("--budget-seconds", type=cli.positive_number, default=None,
                        help=f"search: at most this many seconds per layout (default {Budget().seconds:g})")
    args = parser.parse_args(argv)
    args.jobs = cli.capped_jobs(args.jobs, parser.prog, args.oversubscribe)
    if args.planner != "search" and (args.budget_solves or args.budget_seconds):
        parser.error("--budget-solves and --budget-seconds apply to --planner search only")
    budget = None
    if args.planner == "search":
        defaults = Budget()
        budget = Budget(solves=args.budget_solves or defaults.solves, seconds=args.budget_seconds or defaults.seconds)
    spec = EffortSpec(Design(args.approach_height, args.slices), args.planner, budget)

    import stimuli

    trials = [stimuli.load_trial(t) for t in args.trials] if args.trials else stimuli.load_all()
    tables = []
    for trial in trials:
        mean, table = physical_effort(trial, samples=args.samples, seed=args.seed, jobs=args.jobs, spec=spec)
        tables.append(table)
        searched = f"  gap {table['gap'].mean():7.4f} J s" if "gap" in table else ""
        print(f"{trial.id:>4}  effort {mean:8.4f} J s  sd {table['effort'].std(ddof=1) if len(table) > 1 else 0.0:7.4f}  "
              f"actions {table['n_actions'].iloc[0]:3d}  {table['solve_time'].mean():6.3f} s/plan{searched}", flush=True)
    table = pd.concat(tables, ignore_index=True)
    if args.out:
        write_csv_atomic(table, cli.make_parent(args.out))
    return 0


if __name__ == "__main__":
    sys.exit(cli.run_cli(main, prog=PROG))
