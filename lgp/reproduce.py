"""The paper's pipeline end to end: stimuli -> physical effort -> physical risk ->
(analysis, when human data are given) -> tidy CSVs, figures, report.md and the results page index.html (lgp/app/page.py).

    python -m lgp.reproduce --quick                 # a low-precision preview (time: README, docs/benchmarks.md)
    python -m lgp.reproduce                         # M = 30 layouts, N = 100 runs, 11 sigmas
    python -m lgp.reproduce --human-data FILE.csv   # plus the Results section (docs/human-data.md)
    python -m lgp.reproduce --quick --sensitivity   # plus risk by engine x fall rule (lgp/app/sensitivity.py)
    python -m lgp.reproduce --fall-rule 3d --fall-threshold 0.1   # the risk model with another fall rule
    python -m lgp.reproduce --approach-height 0 --slices 40       # effort with another motion design (docs/effort.md)

Every expensive result (effort of one trial, risk curve of one trial) is cached
under ``<out>/cache`` by a hash of the trial file, the parameters and the code that
computes it, and written atomically: a second run is near instant, and a run killed
half way resumes with nothing lost.
"""
from __future__ import annotations

import argparse
from collections import Counter
import signal
import sys
import time
from pathlib import Path

import numpy as np
import pandas as pd

import stimuli
from lgp import cli
from lgp.paper import N_BOOT, N_SIMS, PAPER_SIGMA, SAMPLES, SIGMA_GRID, TRIAL_IDS
from lgp.executor import default_jobs, executor_for_scheduler, stop_signals
from lgp.app.progress import Progress
from lgp.app.progress import log as progress_log
from lgp.app.cache import LIBRARIES, Cache, files_digest, input_key, library_versions, modules_digest, write_csv_atomic
from lgp.app.manifest import TimedCache, clear_previous, expand, file_sha256, input_hash, write_manifest
from lgp.app.page import write_index
from lgp.app.progress import Stopwatch
from lgp.app.replays import write_replays
from lgp.app.report import append_report, engine_description, pairs_csv_table, write_report
from lgp.app.stages import check_targets, risk_key_inputs, risk_tables
from lgp.app import sensitivity
from lgp.app.sensitivity import planner_choice

PROG = "python -m lgp.reproduce"

QUICK = {"samples": 3, "n_sims": 20, "sigmas": (0.05, 0.065, 0.08, 0.1), "n_boot": 200}


def _log(msg: str) -> None:
    progress_log(msg)  # stderr; above the progress bar on a terminal


def effort_key_inputs() -> dict:
    """What an effort table depends on besides the trial and the parameters: the
    source of every project module physical_effort can run (stimuli draws the
    layouts of A), the arm's model files, and the numerical libraries (SNOPT is Drake's)."""
    return {"code": modules_digest("models.effort", "stimuli"),
            "data": files_digest("models/*.sdf", "models/*.urdf", "models/*.yaml"),
            "libraries": library_versions(("drake", "numpy", "scipy", "pandas"))}


def effort_key(trial, samples: int, seed: int, approach_height: float | None = None,
               slices_per_phase: int | None = None, planner: str = "paper", budget=None) -> str:
    """The cache key of one trial's effort table: the trial file, M, the seed, the
    planner's design (approach height, slices per phase), for planner="search"
    the planner and its budget (lgp.search.Budget), and effort_key_inputs()."""
    from lgp.planner import APPROACH, SLICES_PER_PHASE, check_design
    from lgp.search import Budget, check_planner

    h, S = check_design(APPROACH if approach_height is None else approach_height,
                        SLICES_PER_PHASE if slices_per_phase is None else slices_per_phase)
    searched = {"planner": planner, "budget": repr(budget or Budget())} if check_planner(planner) == "search" else {}
    return input_key(trial=trial.id, digest=trial.digest, samples=samples, seed=seed, approach_height=h,
                     slices_per_phase=S, **searched, **effort_key_inputs())


def effort_tables(trials, samples: int, seed: int, executor, cache: Cache, approach_height: float | None = None,
                  slices_per_phase: int | None = None, log: bool = True, planner: str = "paper",
                  budget=None, verbose: bool = True) -> pd.DataFrame:
    """Per (trial, sample) effort, one cached file per trial (and design: the
    planner's `approach_height` and `slices_per_phase`, defaults when None; the
    `planner`, "paper" or "search" with its `budget`).

    The layouts of every uncached trial are one stream of work units on the run's
    one executor (warm workers plan across trial boundaries); a trial's file is
    written as soon as its last layout arrives, so an interruption loses at most
    the trials still in flight.
    """
    from models.effort import effort_of_unit, effort_table, effort_units

    from lgp.planner import APPROACH, SLICES_PER_PHASE

    design = {"approach_height": APPROACH if approach_height is None else approach_height,
              "slices_per_phase": SLICES_PER_PHASE if slices_per_phase is None else slices_per_phase}
    if planner != "paper":
        design |= {"planner": planner, "budget": budget}
    keys = {t.id: effort_key(t, samples, seed, **design) for t in trials}
    tables: dict[str, pd.DataFrame] = {}
    for t in trials:
        cached = cache.get("effort", keys[t.id])
        if cached is not None:
            tables[t.id] = cached
    todo = [t for t in trials if t.id not in tables]
    units = [u for t in todo for u in effort_units(t, samples, seed, **design)]
    owner = [u[0] for u in units]
    pending = Counter(t.id for t in owner)
    rows: dict[str, list[dict]] = {t.id: [] for t in todo}
    t0 = time.perf_counter()
    if units:
        fixed = sum(1 for t in todo if not t.initial.is_random)
        _log(f"effort: {len(units)} plans to make for {len(todo)} trial(s)"
             + (f" ({len(todo) - fixed} x {samples} random layouts of A, and {fixed} trial(s) whose A has no random "
                "blocks, planned once)" if fixed and samples > 1 else f" x {samples} layouts of A")
             + (f"; {len(trials) - len(todo)} trial(s) reused from the cache" if len(todo) < len(trials) else ""))
    bar = Progress("effort", len(units), "plans", what="motion plans")

    def arrived(k, row):
        bar.advance()
        trial = owner[k]
        rows[trial.id].append(row)
        pending[trial.id] -= 1
        if pending[trial.id] == 0:
            tables[trial.id] = cache.put("effort", keys[trial.id], effort_table(trial, samples, rows[trial.id]))
            df = tables[trial.id]
            if log and verbose:
                _log(f"[effort {len(tables):2d}/{len(trials)}] {trial.id:>3}: {df['effort'].mean():9.4f} J*s over {len(df)} layouts"
                     f"  (planned, {time.perf_counter() - t0:.1f} s into the stage)")

    for t in trials:
        if log and verbose and t.id in tables and t.id not in rows:
            _log(f"[effort {trials.index(t) + 1:2d}/{len(trials)}] {t.id:>3}: {tables[t.id]['effort'].mean():9.4f} J*s"
                 f" over {len(tables[t.id])} layouts  (cached)")
    with bar:
        executor.map(effort_of_unit, units, arrived)
    return pd.concat([tables[t.id] for t in trials], ignore_index=True)


def _took(command: str) -> str:
    """'; took 16 s cold, ... [machine]' from bench/commands.py's last run (lgp.cli.measured_time), or ''."""
    text = cli.measured_time(command)
    return f"; took {text}".replace("%", "%%") if text else ""


def parse_args(argv=None) -> argparse.Namespace:
    """The command line, checked: every count, sigma, trial id and path is refused
    here, in one line, before any work (lgp.cli)."""
    from lgp.app.build_risk import BUILD_SIGMAS
    from models.risk.engine import DEFAULT_FALL_RULE, FALL_RULES, FALL_THRESHOLD

    p = cli.parser(PROG, description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--out", default="results", type=cli.output_dir,
                   help="output directory (default: results/); an earlier run's outputs in it are removed, its cache kept")
    p.add_argument("--stimuli", metavar="DIR", type=cli.input_dir,
                   help="run on the trial files of DIR (default: stimuli/trials, the paper's): all of them unless --trials "
                   "names some; pair table only for pairs whose E and H files are both there")
    p.add_argument("--trials", nargs="+", type=cli.trial_id_or_all,
                   help="trial ids (case-insensitive), or 'all' for every trial file (default: the paper's 24)")
    p.add_argument("--samples", type=cli.positive_int, help="M, random layouts of A per trial (default 30; --quick 3)")
    p.add_argument("--n-sims", type=cli.positive_int, help="N, noisy simulations per trial and sigma (default 100; --quick 20)")
    p.add_argument("--sigmas", type=cli.sigma, nargs="+", help="noise levels in (0, 1], units of d (default: 0.05..0.10 step 0.005)")
    p.add_argument("--engine", help="physics engine for risk: mujoco, drake, physx (optional extra) (default: mujoco)")
    p.add_argument("--profile", help="engine profile: faithful (default) or, for physx, game-defaults (UNFAITHFUL; docs/risk.md)")
    p.add_argument("--fall-rule", default=DEFAULT_FALL_RULE, type=cli.one_of(FALL_RULES, "fall rule"),
                   help="a run falls by horizontal (default) or 3d displacement (case-insensitive)")
    p.add_argument("--fall-threshold", type=float, default=FALL_THRESHOLD, help="fall threshold in units of d (default %(default)s)")
    p.add_argument("--approach-height", type=cli.approach_height, default=None,
                   help="effort: vertical approach/retreat leg (m) at every grasp and place; 0 = a clearance constraint "
                        "instead (default 0.05; docs/effort.md)")
    p.add_argument("--slices", type=cli.positive_int, default=None,
                   help="effort: KOMO slices per 1 s phase (default 20; docs/effort.md, time discretisation)")
    p.add_argument("--planner", type=cli.one_of(("paper", "search"), "planner"), default="paper",
                   help="effort: paper (the paper's pipeline, default) or search (best-first over skeletons, lgp.search; "
                        "docs/effort.md)")
    p.add_argument("--budget-solves", type=cli.positive_int, default=None,
                   help="--planner search: at most this many KOMO solves per layout (default 3)")
    p.add_argument("--budget-seconds", type=cli.positive_number, default=None,
                   help="--planner search: at most this many seconds per layout (default 120)")
    p.add_argument("--jobs", type=cli.positive_int, default=default_jobs(),
                   help="processes, or LocalCluster workers with --scheduler local-dask, >= 1 (default: all cores, %(default)s here)")
    p.add_argument("--scheduler", help="run the work units on Dask: tcp://HOST:8786 (a running scheduler) or local-dask "
                   "(a LocalCluster of --jobs workers); default: a local process pool. Needs the [dask] extra (docs/scaling.md)")
    p.add_argument("--seed", type=cli.seed, default=0)
    p.add_argument("--n-boot", type=cli.positive_int, help="bootstrap resamples (default 1000; --quick 200)")
    p.add_argument("--human-data", type=cli.input_file, help="CSV of human responses (docs/human-data.md); needs the paper's 24 trials")
    p.add_argument("--quick", action="store_true",
                   help="a low-precision preview: M = 3, N = 20, 4 sigmas" + _took("python -m lgp.reproduce --quick"))
    p.add_argument("--no-cache", action="store_true", help="recompute everything")
    p.add_argument("--no-replays", action="store_true", help="skip the 3-D replays of the results page (replays/<trial>.html)")
    p.add_argument("--risk-chunk", type=cli.positive_int, default=6, help="trials simulated per process-pool batch (an interruption loses at most one)")
    p.add_argument("--build-risk", action="store_true", help="also risk through the build, at --build-sigmas (lgp/app/build_risk.py)")
    p.add_argument("--build-sigmas", type=cli.sigma, nargs="+",
                   help=f"noise levels of --build-risk in (0, 1] (default {' '.join(f'{s:g}' for s in BUILD_SIGMAS)})")
    p.add_argument("--risk-measure", choices=["final", "max", "expected", "any", "care"],
                   help="with --build-risk and --human-data: this build-risk aggregate replaces R in Eq. 1")
    p.add_argument("--per-participant-sigma", action="store_true", help="with --human-data: each participant's sigma")
    p.add_argument("--participant-betas", choices=["shared", "participant"], default="shared",
                   help="betas of --per-participant-sigma (default: b2/b1 shared per dataset)")
    p.add_argument("--verbose", action="store_true",
                   help="print a line per trial and stage as it finishes, and every file written at the end")
    sensitivity.add_arguments(p)
    args = p.parse_args(argv)
    try:  # bad engine, profile, rule or threshold: one line, before any work
        from models.risk import DEFAULT_ENGINE, check_fall_rule, engine_name

        if args.engine is not None or args.profile is not None:
            args.engine = engine_name(args.engine or DEFAULT_ENGINE, args.profile)
        check_fall_rule(args.fall_rule, args.fall_threshold)
        sensitivity.check_arguments(args)
    except ValueError as e:
        p.exit(2, f"{p.prog}: error: {e}\n")
    if args.planner != "search" and (args.budget_solves or args.budget_seconds):
        p.error("--budget-solves and --budget-seconds apply to --planner search only")
    args.budget = None
    if args.planner == "search":
        from lgp.search import Budget

        args.budget = Budget(solves=args.budget_solves or Budget().solves, seconds=args.budget_seconds or Budget().seconds)
    if args.risk_measure and not (args.build_risk and args.human_data):
        p.error("--risk-measure needs --build-risk and --human-data")
    if args.per_participant_sigma and not args.human_data:
        p.error("--per-participant-sigma needs --human-data FILE")
    args.command = "python -m lgp.reproduce " + " ".join(argv if argv is not None else sys.argv[1:])
    q = QUICK if args.quick else {}
    args.samples = args.samples if args.samples is not None else q.get("samples", SAMPLES)
    args.n_sims = args.n_sims if args.n_sims is not None else q.get("n_sims", N_SIMS)
    args.sigmas = tuple(dict.fromkeys(args.sigmas or q.get("sigmas", SIGMA_GRID)))
    args.n_boot = args.n_boot if args.n_boot is not None else q.get("n_boot", N_BOOT)
    from lgp.planner import APPROACH, SLICES_PER_PHASE

    args.approach_height = APPROACH if args.approach_height is None else args.approach_height
    args.slices = SLICES_PER_PHASE if args.slices is None else args.slices
    if args.trials:
        args.trials = list(dict.fromkeys(args.trials))  # 7h and 7H are one trial
        if "all" in args.trials and len(args.trials) > 1:
            p.error("--trials all runs every trial file; give it alone")
    return args


def main(argv=None) -> int:
    args = parse_args(argv)
    with stop_signals() as stop:  # `timeout`, `kill` and schedulers stop a run as Ctrl-C does
        try:
            return run(args, argv)
        except BaseException as e:
            if stop.received is None and not isinstance(e, KeyboardInterrupt):
                raise
            sig = stop.received or getattr(e, "signal", signal.SIGINT)
            how = "terminated (SIGTERM)" if sig == signal.SIGTERM else "interrupted"
            resume = "nothing cached (--no-cache)" if args.no_cache else f"finished trials are cached in {Path(args.out) / 'cache'}, rerun to resume"
            print(f"{PROG}: {how}; {resume}", file=sys.stderr)
            return 128 + int(sig)


def run(args, argv=None) -> int:
    """The pipeline for parsed command-line `args` (see `main`)."""
    t0 = time.perf_counter()
    clock = Stopwatch()  # wall time per stage, for the results page
    # Validate every input before anything is written or computed.
    trials, extra = stimuli.select_trials(args.trials, args.stimuli)
    if extra:
        _log(f"the trial folder also holds {', '.join(extra)} (not among the paper's 24): "
             f"run them with --trials {' '.join(extra)} or --trials all")
    human = None
    if args.human_data:
        from analysis import load_human_data

        human = load_human_data(args.human_data)
        if not {t.id for t in trials} >= set(TRIAL_IDS):
            raise ValueError("--human-data needs the paper's 24 trials (the fits compare the 12 pairs); drop --trials")
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    removed = clear_previous(out)  # this folder describes this run only (lgp/app/manifest.py)
    if removed:
        _log(f"removed the outputs of an earlier run from {out}: {', '.join(removed)} (the cache is kept)")
    cache = TimedCache(out / "cache", enabled=not args.no_cache)
    _log(f"lgp.reproduce: {len(trials)} trials, M={args.samples}, N={args.n_sims}, {len(args.sigmas)} sigmas, jobs={args.jobs}"
         f"{', scheduler ' + args.scheduler if args.scheduler else ''}; cache {cache.root}")

    # One executor for the whole run: its workers start now, before this process
    # imports Drake or MuJoCo, and stay warm across trials and stages.
    # SchedulerUnreachable / DaskMissing: one line from lgp.cli, exit 1
    with executor_for_scheduler(args.scheduler, args.jobs) as executor, cache.stage():
        if hasattr(executor, "start"):
            executor.start()
        with cli.deferred_interrupt():  # Drake loads here; a Ctrl-C meanwhile waits until it has
            import models.effort  # noqa: F401
            import models.risk  # noqa: F401
        from models.effort import summarise_effort
        check_targets(trials, args.engine, cache, args.fall_rule, args.fall_threshold)  # an unstable B fails now, not after the effort stage
        effort_samples = effort_tables(trials, args.samples, args.seed, executor, cache, verbose=args.verbose,
                                       approach_height=args.approach_height, slices_per_phase=args.slices,
                                       **planner_choice(args))
        clock.lap("effort")
        effort = summarise_effort(effort_samples, trials)
        risk = risk_tables(trials, args.sigmas, args.n_sims, args.seed, args.engine, executor, cache, args.risk_chunk,
                           fall_rule=args.fall_rule, fall_threshold=args.fall_threshold, verbose=args.verbose)
        clock.lap("risk")
        sensitive = sensitivity.run_sections(sensitivity.Context(args, trials, executor, cache, out, risk_key_inputs, _log,
                                                                     effort_tables=effort_tables)) \
            if args.sensitivity else []
        if args.sensitivity:
            clock.lap("sensitivity")
        if args.build_risk:
            from lgp.app import build_risk

            stages = build_risk.build_risk_tables(trials, args.build_sigmas or build_risk.BUILD_SIGMAS, args.n_sims,
                                                   args.samples, args.seed, args.engine, executor, cache,
                                                   fall_rule=args.fall_rule, fall_threshold=args.fall_threshold,
                                                   approach_height=args.approach_height)
            clock.lap("build risk")
        replays = None if args.no_replays else write_replays(
            trials, args.seed, out / "replays", cache, executor, _log,
            planner_options={"approach_height": args.approach_height, "slices_per_phase": args.slices, **planner_choice(args)})
        clock.lap("replays")
    sigma = PAPER_SIGMA if any(np.isclose(args.sigmas, PAPER_SIGMA)) else args.sigmas[len(args.sigmas) // 2]
    written = [write_csv_atomic(effort_samples, out / "effort_samples.csv"), write_csv_atomic(effort, out / "effort.csv"),
               write_csv_atomic(risk, out / "risk.csv")]
    if replays:
        written += [Path(p) for p in replays.values()]
    sections, build = [], None
    for s in sensitive:  # --sensitivity (lgp/app/sensitivity.py)
        written += s.files
        sections.append("\n".join(s.lines))
    if args.build_risk:
        paths, section, build = build_risk.build_risk_outputs(stages, out, args.command)
        written += paths
        sections.append(section)
    pairs, analysis = None, None
    if {t.id for t in trials} >= set(TRIAL_IDS):
        # Pair orderings, figures and fits are the paper's: on its 24 trials only;
        # other trials of the run are in the effort and risk tables.
        from analysis import run_analysis
        from analysis.pairs import pair_orderings

        paper = [t for t in trials if t.id in TRIAL_IDS]
        extra = [t.id for t in trials if t.id not in TRIAL_IDS]
        if extra:
            _log(f"pair table, figures and fits use the paper's 24 trials; {', '.join(extra)} are in the effort and risk tables only")
        e_samples, e_mean, r = (df[df["trial"].isin(TRIAL_IDS)] for df in (effort_samples, effort, risk))
        pairs = pair_orderings(e_mean, r, sigma, {t.pair: t.dimension for t in paper})
        written.append(write_csv_atomic(pairs_csv_table(pairs), out / "pairs.csv"))
        analysis = run_analysis(human, e_samples, r, out / ("analysis" if human is not None else "figures"),
                                seed=args.seed, n_boot=args.n_boot, jobs=args.jobs, sigma=None if human is not None else sigma,
                                build_risk=None if human is None or build is None else build[build["trial"].isin(TRIAL_IDS)],
                                risk_measure=args.risk_measure, pair_names={t.pair: t.dimension for t in paper})
        written += [Path(path) for path in analysis["files"]["path"]]
        if args.per_participant_sigma:
            from lgp.app.participant_sigma import participant_sigma_outputs

            paths, section = participant_sigma_outputs(human, e_samples, r, out, args.participant_betas, args.command)
            written += paths
            sections.append(section)
    else:
        from analysis.pairs import declared_pair_orderings

        declared = stimuli.declared_pairs(trials)
        pairs = declared_pair_orderings(effort, risk, sigma, {t.pair: t.dimension for t in trials}, declared) if declared else None
        if pairs is not None:
            written.append(write_csv_atomic(pairs_csv_table(pairs), out / "pairs.csv"))
        _log("not all of the paper's 24 trials: no figures or fits (they need all 24); "
             + (f"pair table for the {len(pairs)} pair(s) whose E and H trials are both in the run" if pairs is not None
                else "no pair table (no trial files declare both trials of a pair)"))
    clock.lap("analysis")
    software = {"libraries": library_versions(), "engine": risk_key_inputs(args.engine)["engine_settings"]}
    compute = cache.compute_time()
    report = write_report(out, args, effort, risk, pairs, analysis if human is not None else None,
                          time.perf_counter() - t0, software, compute)
    if sections:
        append_report(report, sections)
    written.append(report)
    written.append(write_index(out, args, trials, effort_samples, risk, sigma, pairs, analysis, cache, clock, replays))
    if (out / "page").is_dir():
        written.append(out / "page")
    if args.verbose:
        _log(f"cache: {cache.summary()}")
    parameters = {"trials": [t.id for t in trials], "samples": args.samples, "n_sims": args.n_sims,
                  "sigmas": list(args.sigmas), "sigma_of_pairs": sigma if pairs is not None else None,
                  "engine": args.engine, "seed": args.seed, "n_boot": args.n_boot, "quick": args.quick,
                  "no_cache": args.no_cache, "build_risk": args.build_risk, "build_sigmas": args.build_sigmas,
                  "risk_measure": args.risk_measure, "per_participant_sigma": args.per_participant_sigma,
                  "profile": args.profile, "fall_rule": args.fall_rule, "fall_threshold": args.fall_threshold,
                  "sensitivity": args.sensitivity, "approach_height": args.approach_height,
                  "slices_per_phase": args.slices, **{k: repr(v) if k == "budget" else v for k, v in planner_choice(args).items()}}
    inputs = {"trial_files": {t.id: t.digest for t in trials},
              "human_data_sha256": file_sha256(args.human_data) if args.human_data else None}
    files = list(dict.fromkeys(expand(written)))
    manifest = write_manifest(out, files, command=[PROG, *(sys.argv[1:] if argv is None else argv)],
                              parameters=parameters, inputs=inputs, input_hash=input_hash(**parameters, **inputs),
                              engine=engine_description(args.engine, software["engine"]), software=software,
                              run_time_s=round(time.perf_counter() - t0, 1),
                              compute_time_s=round(compute[0], 1), compute_time_unknown_results=compute[1])
    if args.verbose:
        print(f"Outputs of this run in {out.resolve()} (listed in {manifest.name}):")
        for path in files + [manifest]:
            print(f"  {path}")
    print(end_of_run(time.perf_counter() - t0, cache, out, len(files)))
    return 0


def end_of_run(seconds: float, cache, out: Path, n_files: int) -> str:
    """The two lines a run ends with: how long, what was computed or reused, and
    where to look ("done in 16 s (120 results computed, 0 reused from the cache);
    open results/index.html")."""
    extra = getattr(cache, "files", {})  # the page's pictures and replays, beside the result tables
    computed = cache.misses + sum(n for (_, o), n in extra.items() if o == "miss")
    reused = cache.hits + sum(n for (_, o), n in extra.items() if o == "hit")
    took = f"{seconds:.0f} s" if seconds >= 10 else f"{seconds:.1f} s"
    if seconds >= 120:
        took = f"{int(seconds // 60)} min {seconds % 60:02.0f} s"
    return (f"done in {took} ({computed} results computed, {reused} reused from the cache); open {out / 'index.html'}\n"
            f"the {n_files} files written are listed in {out / 'manifest.json'} (--verbose prints them)")


if __name__ == "__main__":
    raise SystemExit(cli.run_cli(main, prog=PROG))
