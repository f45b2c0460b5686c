"""Design a stimulus set that can tell effort, risk and simpler stories apart.

    python -m stimuli.design --out DIR --trials 24 --seed 0

screens --candidates task candidates (stimuli/design/grammar.py) cheaply,
checks the finalists faithfully (effort: M layouts planned; risk: N MuJoCo runs
per sigma over the prior), chooses --trials of them by the design objective
(stimuli/design/objective.py) and writes the trial files, design.csv, the
predictors' correlation matrix beside the paper's 24, the screen's check, the
power table (analysis.power) and a contact sheet (stimuli/design/outputs.py).
The same seed writes the same set. Run the set with
``python -m lgp.reproduce --stimuli DIR``. docs/design.md.
"""
from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

from lgp import cli
from lgp.command_times import cpu_seconds
from lgp.errors import InputError

PROG = "python -m stimuli.design"


def parse_args(argv=None):
    from stimuli.design.grammar import MAX_BLOCKS
    from stimuli.design.run import DesignConfig
    from stimuli.design.screen import PRIOR_HI, PRIOR_LO, SCREEN_RUNS

    D = DesignConfig()
    p = cli.parser(PROG, description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--out", required=True, type=cli.output_dir, help="folder for the designed set (created if missing)")
    size = p.add_mutually_exclusive_group()
    size.add_argument("--trials", type=int, default=None, help=f"trials in the set, >= 4 (>= 5 with the power table; default {D.trials})")
    size.add_argument("--pairs", type=int, default=None,
                      help="design 2 x PAIRS trials and pair them (by effort; E the lower risk): ids 1E, 1H, ...")
    p.add_argument("--seed", type=cli.seed, default=D.seed)
    p.add_argument("--candidates", type=int, default=D.candidates, help="candidates screened (default %(default)s)")
    p.add_argument("--budget", type=int, default=MAX_BLOCKS, help="most blocks per trial, >= 1 (default %(default)s, the paper's most)")
    p.add_argument("--sigma-prior", type=float, nargs=2, metavar=("LOW", "HIGH"), default=[PRIOR_LO, PRIOR_HI],
                   help="the sigma prior, uniform, in (0, 1] units of d (default %(default)s)")
    p.add_argument("--finalists", type=int, default=None, help="finalists checked faithfully (default 1.5 x --trials)")
    p.add_argument("--samples", type=int, default=D.samples, help="M, layouts of A per finalist's effort (default %(default)s)")
    p.add_argument("--n-sims", type=int, default=D.n_sims, help="N, MuJoCo runs per finalist and sigma (default %(default)s)")
    p.add_argument("--screen-runs", type=int, default=SCREEN_RUNS, help="static Monte Carlo runs per candidate and sigma (default %(default)s)")
    p.add_argument("--engine", help="physics engine of the faithful check (default: the risk model's, mujoco)")
    p.add_argument("--jobs", type=cli.positive_int, default=2, help="processes (default %(default)s)")
    p.add_argument("--scheduler", help="run the work on Dask as lgp.reproduce does (tcp://HOST:8786 or local-dask)")
    p.add_argument("--no-paper", action="store_true", help="skip the paper's 24 beside the set (correlations, power)")
    p.add_argument("--no-render", action="store_true", help="skip the rendered contact sheet")
    p.add_argument("--studies", type=int, default=100, help="simulated studies per world of the power table (default %(default)s)")
    p.add_argument("--no-power", action="store_true", help="skip the power table (analysis.power)")
    args = p.parse_args(argv)
    trials = 2 * args.pairs if args.pairs is not None else (D.trials if args.trials is None else args.trials)
    cfg = DesignConfig(trials=trials, pairs=args.pairs is not None, seed=args.seed, candidates=args.candidates, budget=args.budget,
                       prior=tuple(args.sigma_prior), finalists=args.finalists, samples=args.samples, n_sims=args.n_sims,
                       screen_runs=args.screen_runs, engine=args.engine)
    from stimuli.design.run import check_config

    try:
        check_config(cfg)
        if args.studies < 1:
            raise InputError(f"--studies must be >= 1, got {args.studies}")
        from analysis.power_worlds import MIN_TRIALS

        if not args.no_power and trials < MIN_TRIALS:
            raise InputError(f"--trials {trials}: the power table's comparison needs at least {MIN_TRIALS} trials "
                             "(or --no-power)")
    except ValueError as e:
        p.error(str(e))  # one line, exit 2, before anything is written
    return args, cfg


def main(argv=None) -> int:
    args, cfg = parse_args(argv)
    from lgp.app.cache import Cache
    from lgp.app.progress import log
    from lgp.executor import executor_for_scheduler
    from stimuli.design import outputs
    from stimuli.design.run import faithful, run_design, wide

    out = Path(args.out)
    previous = claim_folder(out)
    out.mkdir(parents=True, exist_ok=True)
    for name in previous:  # the set an earlier design run wrote here (its design.json lists them)
        (out / name).unlink(missing_ok=True)
    cache = Cache(out / "cache")
    t0, cpu0 = time.perf_counter(), cpu_seconds()
    with executor_for_scheduler(args.scheduler, args.jobs) as ex:
        design = run_design(cfg, out, ex, cache, log)
        paths = outputs.write_set(design, out)
        import stimuli

        designed = [stimuli.load_file(p) for p in paths]
        paper = None
        if not args.no_paper:
            from stimuli.design.run import paper_features

            t1 = time.perf_counter()
            paper_trials = stimuli.load_paper()
            log(f"the paper's 24 beside it: M = {cfg.samples}, N = {cfg.n_sims} x {len(cfg.faithful_sigmas)} sigmas (cached stages)")
            p_effort, p_risk = faithful(paper_trials, cfg, ex, cache)
            paper = (paper_features(cfg).merge(p_effort[["trial", "effort"]], on="trial")
                     .merge(wide(p_risk), left_on="trial", right_index=True))
            design.timings["paper"] = time.perf_counter() - t1
        outputs.write_tables(design, out, paper)
        if not args.no_power:
            from stimuli.design import power

            t3 = time.perf_counter()
            if power.write_power(out, cfg, ex, cache, args.studies, args.jobs, log, include_paper=not args.no_paper):
                design.timings["power"] = time.perf_counter() - t3
        if not args.no_render:
            t2 = time.perf_counter()
            from stimuli.render import contact_sheet, render_trials

            render_trials(designed, out / "pictures", seed=cfg.seed, executor=ex, log=log)
            contact_sheet(out / "pictures", out / "contact_sheet.png")
            design.timings["render"] = time.perf_counter() - t2
    design.timings["command"] = time.perf_counter() - t0
    design.timings["cpu"] = cpu_seconds() - cpu0
    outputs.write_json({"written": [p.name for p in paths], "config": cfg.__dict__ | {"sigmas": cfg.sigmas, "faithful_sigmas": cfg.faithful_sigmas}, "objective": design.terms,
                        "timings_s": design.timings, "screened": cfg.candidates, "passed_screen": len(design.pool),
                        "discards": dict(design.reasons)}, out / "design.json")
    t = design.terms
    print(f"wrote {len(paths)} designed trials to {out.resolve()}: |r| max {t['max_abs_r']:.2f}, rising {t['rising']:.0%}, "
          f"{design.timings['command']:.0f} s (python -m lgp.reproduce --stimuli {args.out})")
    return 0



def claim_folder(out: Path) -> list[str]:
    """The trial files an earlier design run wrote into `out` (its design.json's
    "written"), to be replaced. InputError if `out` holds anything and no design.json
    (not a design run's folder), or trial files (*.yaml) this command did not write:
    a user's folder is never written into."""
    import json

    if not out.is_dir():
        return []
    mine: list[str] = []
    record = out / "design.json"
    if record.is_file():
        try:
            mine = [str(n) for n in json.loads(record.read_text()).get("written", [])]
        except (ValueError, AttributeError, TypeError):
            mine = []
    from lgp.owned import json_record, refuse_foreign_folder

    refuse_foreign_folder(out, "design.json", is_ours=json_record("written", "config"))
    foreign = sorted(p.name for p in out.glob("*.yaml") if p.name not in mine)
    if foreign:
        from lgp.errors import InputError

        raise InputError(f"--out {out} holds trial files this command did not write ({', '.join(foreign[:5])}"
                           f"{' ...' if len(foreign) > 5 else ''}); choose an empty or new folder")
    return [n for n in mine if "/" not in n and n.endswith(".yaml")]


if __name__ == "__main__":
    sys.exit(cli.run_cli(main, prog=PROG))
