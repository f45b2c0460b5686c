"""The paper's pipeline end to end: stimuli -> physical effort -> physical risk ->
(analysis, when human data are given) -> tidy CSVs, figures, report.md and the results page index.html (lgp/app/page.py).

    python -m lgp.reproduce --quick                 # a low-precision preview (time: README, docs/benchmarks.md)
    python -m lgp.reproduce                         # M = 30 layouts, N = 100 runs, 11 sigmas
    python -m lgp.reproduce --human-data FILE.csv   # plus the Results section (docs/human-data.md)
    python -m lgp.reproduce --quick --sensitivity   # plus risk by engine x fall rule, effort by design (lgp/app/sensitivity/)
    python -m lgp.reproduce --fall-rule 3d --fall-threshold 0.1   # the risk model with another fall rule
    python -m lgp.reproduce --sigma-grid wide       # risk past the paper's grid (0.05..0.30 d): "Pairs over sigma"
    python -m lgp.reproduce --noise-rule settle     # noisy blocks set onto their supports instead of lifted
    python -m lgp.reproduce --approach-height 0 --slices 40       # effort with another motion design (docs/effort.md)

Every expensive result (effort of one trial, risk curve of one trial) is cached
under ``<out>/cache`` by a hash of the trial file, the parameters and the code that
computes it, and written atomically: a second run is near instant, and a run killed
half way resumes with nothing lost.
"""
from __future__ import annotations

import argparse
import os
import shlex
import signal
import sys
import time
from pathlib import Path

from lgp import cli
from lgp.planner.design import check_approach_height
from lgp.paper import SIGMA_GRIDS
from lgp.executor import WorkerDied, stop_signals
from lgp.executor.cluster import check_address
from lgp.app.progress import log as progress_log
from lgp.app.config import RunConfig
from lgp import owned
from lgp.app.manifest import (MANIFEST, OutputLock, check_output_folder, checked_before_the_lock, manifest_record,
                              write_manifest)
from lgp.app.charts import num
from lgp.app.result import RunResult
from lgp.app.run import check_inputs
from lgp.app.run import run as run_stages
from lgp.app.write import write_all
from lgp.app import build_risk, sensitivity
from lgp.app.config import QUICK
from lgp.errors import InputError

PROG = "python -m lgp.reproduce"

def _log(msg: str) -> None:
    progress_log(msg)  # stderr; above the progress bar on a terminal


def _took(command: str) -> str:
    """'; took 16 s cold, ... [machine]' from bench/commands.py's last run (lgp.cli.measured_time), or ''."""
    text = cli.measured_time(command)
    return f"; took {text}".replace("%", "%%") if text else ""


def parse_args(argv=None) -> RunConfig:
    """The command line, checked: every count, sigma, trial id and path is refused
    here, in one line, before any work (lgp.cli); the run's RunConfig."""
    p = cli.parser(PROG, description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    _input_arguments(p)
    _effort_and_work_arguments(p)
    _precision_arguments(p)
    build_risk.add_arguments(p, cli)
    _analysis_arguments(p)
    sensitivity.add_arguments(p)
    args = p.parse_args(argv)
    _check_arguments(args, p)
    args.command = "python -m lgp.reproduce " + shlex.join(str(a) for a in (argv if argv is not None else sys.argv[1:]))
    config = RunConfig.from_args(args)  # every default filled in, once
    if config.sigma_from:  # another lab's sigma joins the grid (lgp/app/sigma_from.py)
        from dataclasses import replace

        from lgp.app.sigma_from import grid_with, read_sigma_from

        try:
            config = replace(config, sigmas=grid_with(config.sigmas, read_sigma_from(config.sigma_from)))
        except InputError as e:
            p.exit(2, f"{p.prog}: error: {e}\n")
    return config


def _input_arguments(p) -> None:
    """Where the run writes, its trials, M, N, the sigma grid and the risk model."""
    from models.risk.model import FALL_RULES, NOISE_RULES

    D = RunConfig.default
    p.add_argument("--out", default=D("out"), type=cli.output_dir,
                   help="output directory (default: results/); at the end this run's files replace those of the earlier "
                        "run listed in its manifest.json (its cache is kept); nothing else there is deleted")
    p.add_argument("--into-existing", action="store_true",
                   help="write into an --out that holds other files and no manifest.json of an earlier run, beside "
                        "those files (none is deleted or overwritten); without it such a folder is refused")
    p.add_argument("--stimuli", metavar="DIR", type=cli.input_dir,
                   help="run on the trial files of DIR (default: stimuli/trials, the paper's): all of them unless --trials "
                   "names some; pair table only for pairs whose E and H files are both there")
    p.add_argument("--trials", nargs="+", type=cli.trial_id_or_all,
                   help="trial ids (case-insensitive), or 'all' for every trial file (default: the paper's 24)")
    p.add_argument("--samples", type=cli.bounded_count("MAX_SAMPLES"), help=f"M, random layouts of A per trial (default {D('samples')}; --quick {QUICK['samples']})")
    p.add_argument("--n-sims", type=cli.bounded_count("MAX_N_SIMS"), help=f"N, noisy simulations per trial and sigma (default {D('n_sims')}; --quick {QUICK['n_sims']})")
    grid = p.add_mutually_exclusive_group()
    grid.add_argument("--sigmas", type=cli.sigma, nargs="+", help="noise levels in (0, 1], units of d (default: 0.05..0.10 step 0.005)")
    grid.add_argument("--sigma-grid", choices=list(SIGMA_GRIDS),
                      help="a named sigma grid: paper (default) or wide (0.05..0.30 d step 0.01 plus the paper's points)")
    p.add_argument("--noise-rule", choices=NOISE_RULES,
                   help="heights of the noisy blocks: lift (default) or settle (every block rests on what lies beneath it; "
                        "docs/risk.md)")
    p.add_argument("--engine", help="physics engine for risk: mujoco, drake, physx (optional extra) (default: mujoco)")
    p.add_argument("--profile", help="engine profile: faithful (default) or, for physx, game-defaults (UNFAITHFUL; docs/risk.md)")
    p.add_argument("--fall-rule", default=D("fall_rule"), type=cli.one_of(FALL_RULES, "fall rule"),
                   help="a run falls by horizontal or 3d displacement, case-insensitive (default %(default)s)")
    p.add_argument("--fall-threshold", type=float, default=D("fall_threshold"), help="fall threshold in units of d (default %(default)s)")


def _effort_and_work_arguments(p) -> None:
    """The effort's motion design and planner, the processes, --sigma-from and the seed."""
    D = RunConfig.default
    p.add_argument("--approach-height", type=cli.checked(check_approach_height, "approach height"), default=None,
                   help="effort: vertical approach/retreat leg (m) at every grasp and place; 0 = a clearance constraint "
                        f"instead (default {D('approach_height'):g}; docs/effort.md)")
    p.add_argument("--slices", type=cli.positive_int, default=None,
                   help=f"effort: KOMO slices per 1 s phase (default {D('slices')}; docs/effort.md, time discretisation)")
    p.add_argument("--planner", type=cli.one_of(("paper", "search"), "planner"), default=D("planner"),
                   help="effort: paper (the paper's pipeline, default) or search (best-first over skeletons, lgp.search; "
                        "docs/effort.md)")
    p.add_argument("--budget-solves", type=cli.positive_int, default=None,
                   help="--planner search: at most this many KOMO solves per layout (default 3)")
    p.add_argument("--budget-seconds", type=cli.positive_number, default=None,
                   help="--planner search: at most this many seconds per layout (default 120)")
    cli.add_jobs_argument(p, D("jobs"), "processes, or LocalCluster workers with --scheduler local-dask, >= 1 "
                          "(default: all cores, %(default)s here)")
    p.add_argument("--scheduler", type=cli.checked(check_address, "scheduler address"), help="run the work units on Dask: tcp://HOST:8786 (a running scheduler) or local-dask "
                   "(a LocalCluster of --jobs workers); default: a local process pool. Needs the [dask] extra (docs/scaling.md)")
    p.add_argument("--sigma-from", metavar="FILE", type=cli.input_file,
                   help="summary.json of python -m analysis.mental_jenga: that sigma (the paper's unit) is simulated too "
                        "and reported beside this run's, with the pair table at it (docs/mental-jenga.md)")
    p.add_argument("--seed", type=cli.seed, default=D("seed"))


def _precision_arguments(p) -> None:
    """Bootstrap, human data, --quick, the cache, replays and risk chunks."""
    D = RunConfig.default
    p.add_argument("--n-boot", type=cli.bounded_count("MAX_N_BOOT"), help=f"bootstrap resamples (default {D('n_boot')}; --quick {QUICK['n_boot']})")
    p.add_argument("--human-data", type=cli.input_file, help="CSV of human responses (docs/human-data.md) naming exactly the run's trials (the paper's 24, "
                        "or every trial of --stimuli DIR)")
    p.add_argument("--max-participants", type=cli.positive_int, default=None,
                   help=f"with --human-data: most participants the file may hold (default {D('max_participants')}; memory grows with "
                        "participants x bootstrap resamples, docs/human-data.md)")
    p.add_argument("--quick", action="store_true",
                   help=f"a low-precision preview: M = {QUICK['samples']}, N = {QUICK['n_sims']}, {len(QUICK['sigmas'])} sigmas"
                        + _took("python -m lgp.reproduce --quick"))
    p.add_argument("--no-cache", action="store_true", help="recompute everything")
    p.add_argument("--no-replays", action="store_true", help="skip the 3-D replays of the results page (replays/<trial>.html)")
    p.add_argument("--risk-chunk", type=cli.positive_int, default=D("risk_chunk"), help="trials simulated per process-pool batch (an interruption loses at most one)")


def _analysis_arguments(p) -> None:
    """The options of the analysis and its beyond-the-paper parts."""
    D = RunConfig.default
    p.add_argument("--risk-measure", choices=["final", "max", "expected", "any", "care", "sequential"],
                   help="with --build-risk and --human-data: this build-risk aggregate replaces R in Eq. 1")
    p.add_argument("--per-participant-sigma", action="store_true", help="with --human-data: each participant's sigma")
    p.add_argument("--allow-simulated", action="store_true",
                   help="with --human-data: accept datasets of SIMULATED participants (simulated-*, tests only); "
                        "every table and figure made from them says SIMULATED")
    p.add_argument("--n-perm", type=cli.bounded_count("MAX_N_PERM"),
                   help=f"with --human-data: permutations per permutation test of the risk term (default {D('n_perm')}; "
                        f"--quick {QUICK['n_perm']})")
    p.add_argument("--recovery", action="store_true",
                   help="model recovery on SIMULATED studies from our effort and risk tables (recovery/; analysis.recovery)")
    p.add_argument("--recovery-studies", type=cli.positive_int,
                   help=f"with --recovery: simulated studies per cell (default {D('recovery_studies')}; "
                        f"--quick {QUICK['recovery_studies']})")
    p.add_argument("--participant-betas", choices=["shared", "participant"], default=D("participant_betas"),
                   help="betas of --per-participant-sigma (default: b2/b1 shared per dataset)")
    p.add_argument("--verbose", action="store_true",
                   help="print a line per trial and stage as it finishes, and every file written at the end")


def _check_arguments(args, p) -> None:
    """Refuse, in one line, what argparse cannot: engine and rules, planner budgets,
    options that need another, --trials all with others; cap --jobs at the cores."""
    try:  # bad engine, profile, rule or threshold: one line, before any work
        from models.risk import RiskModel

        if args.engine is not None or args.profile is not None:
            args.engine = RiskModel(args.engine, args.profile).engine
        RunConfig.from_args(args).risk_model
        sensitivity.check_arguments(args)
    except ValueError as e:
        p.exit(2, f"{p.prog}: error: {e}\n")
    if args.planner != "search" and (args.budget_solves or args.budget_seconds):
        p.error("--budget-solves and --budget-seconds apply to --planner search only")
    if args.planner == "search":
        from lgp.search import Budget

        args.budget = Budget(solves=args.budget_solves or Budget().solves, seconds=args.budget_seconds or Budget().seconds)
    if args.risk_measure and not (args.build_risk and args.human_data):
        p.error("--risk-measure needs --build-risk and --human-data")
    if args.per_participant_sigma and not args.human_data:
        p.error("--per-participant-sigma needs --human-data FILE")
    if args.allow_simulated and not args.human_data:
        p.error("--allow-simulated needs --human-data FILE")
    if args.trials and "all" in args.trials and len(set(args.trials)) > 1:
        p.error("--trials all runs every trial file; give it alone")
    if not (args.scheduler or "").lower().startswith(("tcp://", "tls://", "ws://", "wss://")):  # a cluster has its own cores
        args.jobs = cli.capped_jobs(args.jobs, p.prog, args.oversubscribe)


def main(argv=None) -> int:
    args = parse_args(argv)
    with stop_signals() as stop:  # `timeout`, `kill` and schedulers stop a run as Ctrl-C does
        try:
            return run(args, argv)
        except owned.ForeignFiles as e:  # a folder this run may not write into: one line, exit 2
            print(f"{PROG}: error: {cli.one_line(e)}", file=sys.stderr)
            return cli.EXIT_USAGE
        except WorkerDied as e:  # one line that also says what is kept
            print(f"{PROG}: error: {e}; {_resume_note(args)}", file=sys.stderr)
            return cli.EXIT_DATA
        except BaseException as e:
            if stop.received is None and not isinstance(e, KeyboardInterrupt):
                raise
            sig = stop.received or getattr(e, "signal", signal.SIGINT)
            how = "terminated (SIGTERM)" if sig == signal.SIGTERM else "interrupted"
            print(f"{PROG}: {how}; {_resume_note(args)}", file=sys.stderr)
            return 128 + int(sig)


def _resume_note(args) -> str:
    """What a stopped run leaves to resume from: the cache, only if there is one."""
    cache = Path(args.out) / "cache"
    if args.no_cache:
        return "nothing cached (--no-cache)"
    if cache.is_dir() and any(p.name.endswith(".csv") and not p.name.startswith(".") for p in cache.iterdir()):
        return f"finished trials are cached in {cache}, rerun to resume"
    return "nothing was cached yet (stopped before the first result)"


def run(args: RunConfig, argv=None) -> int:
    """The pipeline of one run's settings `args` (parse_args; see `main`): exit code 0."""
    reproduce(args, argv)
    return 0


def reproduce(config: RunConfig, argv=None) -> RunResult:
    """Run `config` into its output folder and return what it computed.

    The inputs are checked before the folder is touched; then, with the folder
    locked, `result = run(config)` and `write_all(result, stage)` write every output
    into a staging folder, which replaces the earlier run's own files at the end
    (lgp/owned.py): a failed or stopped run leaves the earlier run's files untouched."""
    t0 = time.perf_counter()
    inputs = check_inputs(config)  # every input validated before anything is written or computed
    out = Path(config.out)
    checked_before_the_lock(check_output_folder, out, config.into_existing)  # a folder of foreign files: refused now, before any work
    created = _missing_folders(out)
    new_cache = not (out / "cache").exists()
    out.mkdir(parents=True, exist_ok=True)
    ok = False
    try:
        with OutputLock(out, config.command):  # one run per output folder (and none inside or around it), for the whole run
            earlier = check_output_folder(out, config.into_existing)  # again, now that no other run can change it
            owned.remove_stale_staging(out)
            stage = owned.new_staging(out)  # this run's files, moved into `out` when all are written
            try:
                result = run_stages(config, stage, inputs)
                write_all(result, stage)
                files = _finish(result, out, stage, earlier, argv, t0)
                ok = True
            finally:
                owned.remove_staging(stage)  # a failed or stopped run: the earlier run's files are untouched
    finally:
        if not ok:
            _remove_if_empty(out, created, new_cache)
    if result.human and result.analysis is not None:
        print(human_data_summary(result.analysis))
    print(end_of_run(time.perf_counter() - t0, result.record, out, len(files)))
    return result


def _finish(result: RunResult, final: Path, stage: Path, earlier: dict, argv, t0: float) -> list[Path]:
    """Write the manifest of the staging folder and swap it into `final`; the files now in `final`."""
    config = result.config
    # Every file of the staging folder is this run's (the outputs and what they
    # brought along, e.g. replays/meshcat.min.js): the manifest lists them all.
    files = [stage / f for f in owned.staged_files(stage)]
    write_manifest(stage, files, command=[PROG, *(sys.argv[1:] if argv is None else argv)],
                   **manifest_record(result, round(time.perf_counter() - t0, 1)))
    # The swap: this run's files replace the earlier run's own (lgp/owned.py); nothing else is touched.
    removed = owned.swap_in(final, stage, earlier, MANIFEST)
    if removed:
        _log(f"removed the outputs of an earlier run from {final} that this run did not write again: "
             f"{', '.join(owned.summarise(removed))} (the cache is kept)")
    files = [final / Path(f).relative_to(stage) for f in files]
    if config.verbose:
        print(f"Outputs of this run in {final.resolve()} (listed in {MANIFEST}):")
        for path in files + [final / MANIFEST]:
            print(f"  {path}")
    return files


def _missing_folders(out: Path) -> list[Path]:
    """The folders `out.mkdir(parents=True)` would create, deepest first."""
    missing = []
    while not out.exists() and not out.is_symlink() and out != out.parent:
        missing.append(out)
        out = out.parent
    return missing


def _remove_if_empty(out: Path, created: list[Path], new_cache: bool) -> None:
    """After a failed run: the folders it created that hold nothing (an empty cache
    included; a cache with results stays, to resume from)."""
    if new_cache:
        try:
            (out / "cache").rmdir()
        except OSError:
            pass
    for folder in created:
        try:
            folder.rmdir()
        except OSError:
            return


def human_data_summary(analysis) -> str:
    """One line on the fit of the human data: the chosen sigma, and Eq. 1 (full)
    against effort-only on held-out pairs (leave-one-pair-out RMSE of z-scored
    judgments per dataset, lower is better; in sample Eq. 1 cannot lose)."""
    import pandas as pd

    from analysis.data import ordered_datasets

    settings = analysis["settings"].iloc[0]
    simulated = " (SIMULATED participants)" if bool(settings.get("simulated", False)) else ""
    text = f"human data{simulated}: sigma = {num(settings['sigma'])} d ({settings.get('sigma_rule', 'chosen by RMSE')})"
    comparison = analysis.get("model_comparison")
    if isinstance(comparison, pd.DataFrame) and len(comparison):
        held = comparison[comparison["scheme"] == "leave-one-pair-out"].set_index(["dataset", "model"])["rmse"]
        parts = []
        for d in ordered_datasets(comparison["dataset"].unique()):
            if (d, "full") in held.index and (d, "effort") in held.index:
                full, effort = float(held[d, "full"]), float(held[d, "effort"])
                verdict = "Eq. 1 better" if full < effort else "effort-only better" if effort < full else "tie"
                parts.append(f"{d} {full:.3f} vs {effort:.3f} ({verdict})")
        if parts:
            text += "; held-out pairs, RMSE of Eq. 1 vs effort-only: " + ", ".join(parts)
    return text + "; details in index.html#human"


def _home(path) -> str:
    """A path with the user's home written ~ (shorter, and the same on every account)."""
    p, home = str(path), str(Path.home())
    return "~" + p[len(home):] if home != "/" and (p == home or p.startswith(home + os.sep)) else p


def end_of_run(seconds: float, cache, out: Path, n_files: int) -> str:
    """The two lines a run ends with: how long, what was computed, what was reused
    and from where, and where to look ("done in 16 s (120 results computed, 48
    reused: 48 trial pictures from the render cache shared by every run,
    ~/.cache/lgp-difficulty/renders); open results/index.html")."""
    from stimuli.render import render_cache_dir

    extra = getattr(cache, "files", {})  # the page's pictures and replays, beside the result tables
    computed = cache.misses + cache.recomputed + sum(n for (_, o), n in extra.items() if o == "miss")
    pictures = sum(n for (kind, o), n in extra.items() if o == "hit" and kind == "picture")
    own = cache.hits + sum(n for (kind, o), n in extra.items() if o == "hit" and kind != "picture")
    where = []
    if own:
        where.append(f"{own} from this folder's cache {getattr(cache, 'root', out / 'cache')}")
    if pictures:
        where.append(f"{pictures} trial pictures from the render cache shared by every run, {_home(render_cache_dir())}")
    reused = f"{own + pictures} reused" + (": " + "; ".join(where) if where else "")
    return (f"done in {cli.duration_text(seconds)} ({computed} results computed, {reused}); open {out / 'index.html'}\n"
            f"the {n_files} files written are listed in {out / 'manifest.json'} (--verbose prints them)")


if __name__ == "__main__":
    raise SystemExit(cli.run_cli(main, prog=PROG))
