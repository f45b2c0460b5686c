"""Inspect the plan of one trial: ``python -m lgp.show 7H --seed 0 --sample 0 --html out.html --png out.png``.

A trial of another folder (``lgp.reproduce --stimuli DIR``): ``python -m lgp.show REV
--stimuli stimuli/rearrange --planner search``.

Replays row (trial, sample) of `effort_samples.csv` exactly: the layout of A and
the planner are seeded as `models.effort.physical_effort` seeds them
(`models.effort.plan_of_sample`), so the effort printed here equals that row's.
Prints the action list with per-action kinetic energy, and optionally writes the
3-D replay (HTML, works offline) and a figure of block paths and speeds (PNG).
From a script, use ``lgp.plan(...)`` (lgp/search/; planner="paper" or "search") and ``lgp.app.view.write_html`` /
``lgp.app.view.write_png``; this module is the command line only.
"""
from __future__ import annotations

import sys

from lgp import cli
from lgp.planner.design import check_approach_height

PROG = "python -m lgp.show"


def main(argv=None) -> int:
    parser = cli.parser(PROG, description=__doc__.splitlines()[0])
    parser.add_argument("trial", type=cli.trial_id, help="trial id, e.g. 7H (case-insensitive)")
    parser.add_argument("--stimuli", metavar="DIR", type=cli.input_dir,
                        help="read the trial from the trial files of DIR, as `lgp.reproduce --stimuli` (default: stimuli/trials, the paper's)")
    parser.add_argument("--seed", type=cli.seed, default=0, help="seed of the run, as `lgp.reproduce --seed` (default 0)")
    parser.add_argument("--sample", type=cli.seed, default=0,
                        help="layout index K >= 0: replays row (trial, K) of effort_samples.csv (default 0)")
    parser.add_argument("--html", type=cli.output_file, help="write a self-contained 3-D replay here (a missing folder is created)")
    parser.add_argument("--png", type=cli.output_file, help="write a figure of block paths and speeds here (a missing folder is created)")
    parser.add_argument("--formulation", default="reduced", choices=("reduced", "full"))
    parser.add_argument("--solver", default="snopt", choices=("snopt", "ipopt"))
    parser.add_argument("--approach-height", type=cli.checked(check_approach_height, "approach height"), default=None,
                        help="approach leg (m) of the run, as `lgp.reproduce --approach-height` (default 0.05; 0 = none)")
    parser.add_argument("--slices", type=cli.positive_int, default=None,
                        help="slices per phase of the run, as `lgp.reproduce --slices` (default 20)")
    parser.add_argument("--planner", type=cli.one_of(("paper", "search"), "planner"), default="paper",
                        help="paper (default) or search, as `lgp.reproduce --planner`")
    parser.add_argument("--budget-solves", type=cli.positive_int, default=None,
                        help="--planner search: KOMO solves per layout, as `lgp.reproduce --budget-solves` (default 3)")
    parser.add_argument("--budget-seconds", type=cli.positive_number, default=None,
                        help="--planner search: seconds per layout, as `lgp.reproduce --budget-seconds` (default 120)")
    args = parser.parse_args(argv)
    if args.planner != "search" and (args.budget_solves or args.budget_seconds):
        parser.error("--budget-solves and --budget-seconds apply to --planner search only")

    import stimuli
    from models.effort import describe, plan_of_sample

    trial = stimuli.select_trials([args.trial], args.stimuli)[0][0]
    design = {k: v for k, v in (("approach_height", args.approach_height), ("slices_per_phase", args.slices)) if v is not None}
    if args.planner == "search":
        from lgp.search import Budget

        design |= {"planner": "search", "budget": Budget(solves=args.budget_solves or Budget().solves,
                                                         seconds=args.budget_seconds or Budget().seconds)}
    result = plan_of_sample(trial, args.seed, args.sample, formulation=args.formulation, solver=args.solver, **design)
    komo = result.komo
    print(f"{trial.id}: {trial.description} (seed {args.seed}, sample {args.sample})")
    print(describe(result, digits=12))  # the effort to 12 digits: equal to the row of effort_samples.csv
    if komo is not None:
        print(f"KOMO {komo.formulation} / {komo.solver}: {komo.status}, cost {komo.cost:.4f}, {komo.n_variables} variables, "
              f"{komo.solve_time:.3f} s solving, planned in {result.planning_time:.3f} s")
    title = f"{trial.id}: {trial.description} (seed {args.seed}, sample {args.sample})"
    if args.html or args.png:
        from lgp.app.view import write_html, write_png

        if args.html:
            print("replay:", write_html(result, cli.make_parent(args.html), title))
        if args.png:
            print("figure:", write_png(result, cli.make_parent(args.png), title))
    return 0


if __name__ == "__main__":
    sys.exit(cli.run_cli(main, prog=PROG))
