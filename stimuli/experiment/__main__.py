"""python -m stimuli.experiment --task difficulty|time|build --out DIR (see stimuli/experiment/__init__.py)."""
from __future__ import annotations

import argparse
import sys
from pathlib import Path

from lgp import cli
from stimuli import experiment as ex

PROG = "python -m stimuli.experiment"


def main(argv=None) -> int:
    from lgp.app.manifest import checked_before_the_lock
    from stimuli.render import DEFAULT_SIZE, parse_size

    p = cli.parser(PROG, description=ex.__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--task", required=True, choices=ex.TASKS,
                   help="difficulty (Difficulty Estimation), time (Time Estimation) or build (the lab's Build Task console)")
    p.add_argument("--out", required=True, type=cli.output_dir, help="study folder to write (created; an earlier build's own files there are replaced, "
                        "collected data and every other file kept)")
    p.add_argument("--into-existing", action="store_true",
                   help="write into an --out that holds other files and no study.json, beside them (none is deleted)")
    p.add_argument("--stimuli", metavar="DIR", type=cli.input_dir, help="folder of trial files (default: stimuli/trials, the paper's 24)")
    p.add_argument("--anchor-easy", metavar="FILE", default=str(ex.DEFAULT_ANCHORS[0]),
                   help="trial file of the easy anchor shown first (default: stimuli/experiment/anchors/ANCHOR-EASY.yaml)")
    p.add_argument("--anchor-hard", metavar="FILE", default=str(ex.DEFAULT_ANCHORS[1]),
                   help="trial file of the hard anchor shown second (default: stimuli/experiment/anchors/ANCHOR-HARD.yaml)")
    p.add_argument("--seed", type=cli.seed, default=0, help="layout of A: sample 0 of this seed, as effort's (default 0)")
    p.add_argument("--order-seed", type=cli.seed, default=0, help="seed of the trial orders (docs/experiment.md; default 0)")
    p.add_argument("--size", type=parse_size, default=DEFAULT_SIZE, help="picture size WIDTHxHEIGHT (default 960x640)")
    p.add_argument("--time-max", type=cli.positive_int, default=ex.TIME_MAX_S, help="time task: slider from 0 to this many seconds (default 180)")
    p.add_argument("--jatos", action="store_true", help="load JATOS's jatos.js and submit the CSV to JATOS at the end")
    cli.add_jobs_argument(p, 2, "rendering processes (default 2)")
    args = p.parse_args(argv)
    args.jobs = cli.capped_jobs(args.jobs, p.prog, args.oversubscribe)
    try:  # every input is checked before anything is written: a bad one is a usage error (exit 2)
        plan = ex.plan_study(args.task, args.stimuli, (args.anchor_easy, args.anchor_hard), args.seed, args.order_seed)
        checked_before_the_lock(ex.check_output_dir, Path(args.out), args.into_existing)
    except ex.StudyError as e:
        p.error(str(e))
    if not plan.has_pairs:
        print(f"{PROG}: note: no easy/hard pairs (<n>E and <n>H) among the trials: pair counterbalancing is off, "
              "each participant sees the trials in their own random order", file=sys.stderr)
    try:
        manifest = ex.build_study(plan, args.out, args.size, args.jobs, args.jatos, args.time_max,
                                  into_existing=args.into_existing)
    except ex.StudyError as e:  # the folder changed since the check (under the lock): still one line, exit 2
        p.error(str(e))
    print(f"{args.out}/index.html: {args.task} study {manifest['study']} (build {manifest['build']}), "
          f"{len(manifest['trials'])} trials, {len(manifest['anchors'])} anchors, jsPsych {manifest['jspsych']}")
    return 0


if __name__ == "__main__":
    raise SystemExit(cli.run_cli(main, prog=PROG))
