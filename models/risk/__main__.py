"""Risk table of the 24 trials over the paper's sigma grid.

    python -m models.risk --table docs/risk_table.csv [--runs runs.csv]
        [--n-sims 100] [--seed 0] [--engine mujoco|drake|physx] [--profile faithful|game-defaults]
        [--fall-rule horizontal|3d] [--fall-threshold 0.25] [--noise-rule lift|settle] [--jobs N]
        [--sigmas 0.05 0.065 ... | --sigma-grid paper|wide]
        [--precision risk_precision.csv [--precision-levels 0.5 0.1]]

Writes the tidy (trial, sigma, risk, falls, n, the model's columns, risk_low,
risk_high) table as CSV, optionally the per-run table and
the required precision sigma* per trial (models/risk/precision.py), and prints
risk per trial and sigma.

    python -m models.risk --build-risk 7H [6E ...] [--sigmas 0.065 0.1] [--samples 30]
        [--n-sims 100] [--mode stages|sequential] [--out stages.csv]

Risk through the build (models/risk/build.py): prints each trial's stage curve
(mean risk per stage over the layouts) and its aggregates; `--out` writes the
tidy stage table.
"""
from __future__ import annotations

from lgp.atomic import write_csv_atomic

import sys
import time

from lgp import cli
from lgp.paper import N_SIMS, PAPER_SIGMA, SAMPLES, SIGMA_GRID, SIGMA_GRIDS
from models.risk.core import risk_table, summarise
from models.risk.engine import ENGINES, PROFILES
from models.risk.model import DEFAULT_MODEL, FALL_RULES, FALL_THRESHOLD, NOISE_RULES, RiskModel
from models.risk.precision import PRECISION_LEVELS


PROG = "python -m models.risk"


def _parser():
    """The command line of `main`."""
    p = cli.parser(PROG, description=__doc__.splitlines()[0])
    p.add_argument("--table", type=cli.output_file, help="CSV to write: trial, sigma, risk, falls, n, the model's columns, risk_low, risk_high")
    p.add_argument("--runs", type=cli.output_file, help="also write the per-run CSV here")
    p.add_argument("--n-sims", type=cli.bounded_count("MAX_N_SIMS"), default=N_SIMS, help="simulations per trial and sigma (default %(default)s)")
    p.add_argument("--seed", type=cli.seed, default=0)
    p.add_argument("--engine", default=DEFAULT_MODEL.engine, help=f"physics engine: {', '.join(ENGINES)} (default %(default)s)")
    p.add_argument("--profile", help="engine profile: " + "; ".join(f"{e}: {', '.join(v)}" for e, v in PROFILES.items())
                   + " (default: faithful; game-defaults is unfaithful, docs/risk.md)")
    p.add_argument("--fall-rule", type=cli.one_of(FALL_RULES, "fall rule"), default=DEFAULT_MODEL.fall_rule.value, help=f"{' or '.join(FALL_RULES)} displacement (default %(default)s)")
    p.add_argument("--fall-threshold", type=float, default=FALL_THRESHOLD, help="fall threshold in units of d (default %(default)s)")
    cli.add_jobs_argument(p, None, "worker processes (default: all cores)")
    p.add_argument("--noise-rule", choices=NOISE_RULES, default=DEFAULT_MODEL.noise_rule.value,
                   help="heights of the noisy blocks: lift (default, blocks may start above their support) or settle "
                        "(every block rests on what lies beneath it; docs/risk.md)")
    grid = p.add_mutually_exclusive_group()
    grid.add_argument("--sigmas", type=cli.sigma, nargs="+", default=None, help="noise SDs in (0, 1], fractions of d")
    grid.add_argument("--sigma-grid", choices=list(SIGMA_GRIDS), default=None,
                      help="a named grid: paper (0.05..0.10 d step 0.005, the default) or wide (0.05..0.30 d step 0.01 "
                           "plus the paper's points)")
    p.add_argument("--precision", type=cli.output_file, help="also write the required precision sigma* per trial (CSV) here")
    p.add_argument("--precision-levels", type=cli.precision_level, nargs="+", default=list(PRECISION_LEVELS),
                   help="risk levels of sigma*, each in (0, 1) (default 0.5 0.1)")
    p.add_argument("--mode", choices=["stages", "sequential"], default="stages",
                   help="with --build-risk: each stage on its own (default) or one build carried through (sequential)")
    p.add_argument("--trials", type=cli.trial_id, nargs="+", help="trial ids (default: all 24; case-insensitive)")
    p.add_argument("--build-risk", nargs="+", metavar="TRIAL", type=cli.trial_id_or_all,
                   help="print the stage curve of these trials ('all': the 24)")
    p.add_argument("--samples", type=cli.bounded_count("MAX_SAMPLES"), default=SAMPLES, help="layouts of A per trial for --build-risk (default %(default)s)")
    p.add_argument("--out", type=cli.output_file, help="with --build-risk: write the stage table (CSV) here")
    return p


def main(argv=None) -> int:
    p = _parser()
    args = p.parse_args(argv)
    args.jobs = cli.capped_jobs(args.jobs, p.prog, args.oversubscribe)
    args.sigmas = list(SIGMA_GRIDS[args.sigma_grid] if args.sigma_grid else args.sigmas or SIGMA_GRID)
    try:
        args.model = RiskModel.from_args(args)
    except ValueError as e:
        p.exit(2, f"{p.prog}: error: {e}\n")
    if args.build_risk:
        try:
            return _build_risk(args)
        except (ValueError, KeyError, FileNotFoundError) as e:
            p.exit(2, f"{p.prog}: error: {e}\n")
    if not args.table:
        p.error("--table is required (or --build-risk TRIAL)")

    import stimuli

    try:
        trials = stimuli.load_all() if not args.trials else [stimuli.load_trial(t) for t in args.trials]
    except ValueError as e:  # StimulusError: unknown trial
        p.exit(2, f"{p.prog}: error: {e}\n")
    t0 = time.perf_counter()
    last = [0.0]
    simulated = [0]

    def progress(done, total):  # runs simulated: a trial whose B repeats an earlier one's shares its runs
        now = time.perf_counter()
        simulated[0] = total
        if now - last[0] > 5 or done == total:
            last[0] = now
            print(f"  {done}/{total} runs simulated, {now - t0:.0f} s", file=sys.stderr, flush=True)

    runs = risk_table(trials, args.sigmas, args.n_sims, args.seed, args.model, args.jobs, progress, runs=True)
    table = summarise(runs)
    order = {t.id: k for k, t in enumerate(trials)}
    table = table.sort_values(["trial", "sigma"], key=lambda c: c.map(order) if c.name == "trial" else c).reset_index(drop=True)
    write_csv_atomic(table, cli.make_parent(args.table))
    if args.runs:
        write_csv_atomic(runs, cli.make_parent(args.runs))
    if args.precision:
        from models.risk.precision import precision_text, required_precision

        precision = required_precision(runs, args.precision_levels, seed=args.seed)
        write_csv_atomic(precision, cli.make_parent(args.precision))
        for level, g in precision.groupby("level", sort=False):
            print(f"sigma* (risk reaches {level:g}): " + ", ".join(f"{r['trial']} {precision_text(r)}" for _, r in g.iterrows()))
    wide = table.pivot(index="trial", columns="sigma", values="risk").reindex([t.id for t in trials])
    print(wide.to_string(float_format=lambda x: f"{x:.2f}"))
    engine = args.model.engine
    label = engine if ENGINES[engine].faithful else f"{engine} (UNFAITHFUL profile: fails the faithfulness suite, docs/risk.md)"
    shared = f" ({simulated[0]} simulated; trials with the same B share their runs)" if simulated[0] != len(runs) else ""
    print(f"{len(runs)} runs{shared} with {label}, {args.model.describe()}, "
          f"in {time.perf_counter() - t0:.1f} s -> {args.table}", file=sys.stderr)
    return 0


def _build_risk(args) -> int:
    import pandas as pd

    import stimuli
    from models.risk.build import build_risk, build_risk_aggregates, stage_curve

    ids = list(stimuli.trial_ids()) if args.build_risk == ["all"] else args.build_risk
    sigmas = [PAPER_SIGMA] if args.sigmas == list(SIGMA_GRID) and not args.sigma_grid else args.sigmas
    t0 = time.perf_counter()
    tables = []
    for tid in ids:
        trial = stimuli.load_trial(tid)
        t1 = time.perf_counter()
        stages = build_risk(trial, sigmas, n_sims=args.n_sims, samples=args.samples, seed=args.seed,
                            model=args.model, jobs=args.jobs, mode=args.mode)
        tables.append(stages)
        curve = stage_curve(stages)
        for sigma, c in curve.groupby("sigma", sort=False):
            head = "sequential build, share of runs collapsing at each stage" if args.mode == "sequential" else "risk by stage"
            print(f"{tid} sigma {sigma:g} d: {head} (mean over {args.samples} layouts; blocks in structure)")
            for _, row in c.iterrows():
                bar = "#" * int(round(40 * row["risk"]))
                print(f"  stage {row['stage']:2d}  {row['blocks_in_structure']:4.1f} blocks  "
                      f"risk {row['risk']:.3f}  {bar}")
        agg = build_risk_aggregates(stages).dropna(axis=1, how="all")
        print(agg.drop(columns=["engine"]).to_string(index=False, float_format=lambda x: f"{x:.3f}"))
        print(f"  ({time.perf_counter() - t1:.1f} s)", file=sys.stderr, flush=True)
    if args.out:
        write_csv_atomic(pd.concat(tables, ignore_index=True), cli.make_parent(args.out))
    print(f"{len(ids)} trial(s) in {time.perf_counter() - t0:.1f} s" + (f" -> {args.out}" if args.out else ""), file=sys.stderr)
    return 0


if __name__ == "__main__":
    raise SystemExit(cli.run_cli(main, prog=PROG))
