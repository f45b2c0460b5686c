"""`run(config) -> RunResult`: the paper's pipeline of one RunConfig, computed.

The core (the check that B stands, effort, risk, the required precision, the pair
tables and the analysis) runs here; every feature beyond the paper is a Stage of
STAGES (lgp.app.result.Stage), run in its phase: "compute" with the run's one
executor, "analysis" after the analysis. Nothing here writes a result table,
report or page (lgp.app.write does, from the RunResult); the files workers make
(replays, trial pictures) go into `workdir`, the run's staging folder.
"""
from __future__ import annotations

import datetime
import os
import platform
import time
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import pandas as pd

from lgp.app.cache import RECORDED_LIBRARIES, ROOT, library_versions
from lgp.app.config import RunConfig
from lgp.app.manifest import TimedCache
from lgp.app.progress import Stopwatch
from lgp.app.replays import replay_cache_paths, replays_to_make, write_replays
from lgp.app.stages import check_targets, effort_tables, risk_tables
from lgp.app.progress import log as _log
from lgp.app.result import Context, RunRecord, RunResult, Section
from lgp.errors import InputError
from lgp.paper import PAPER_SIGMA, TRIAL_IDS

#: Fewest trials the fits of --human-data run on: Eq. 1 has 3 parameters and every
#: held-out fold must leave at least 4 trials to fit them (analysis.crossval.make_folds).
MIN_ANALYSIS_TRIALS = 5
#: The docs the results page links, carried into the output folder.
PAGE_DOCS = ("risk.md",)


def stages() -> list:
    """The feature stages with their renderers, in the order their sections appear in
    the report (a new feature: one stage file, one renderer, one line here)."""
    from lgp.app import build_risk, build_risk_view, participant_sigma, recovery, sensitivity, sigma_from, sigma_from_view

    return [(sensitivity.STAGE, sensitivity.render), (build_risk.STAGE, build_risk_view.render),
            (recovery.STAGE, recovery.render), (sigma_from.STAGE, sigma_from_view.render),
            (participant_sigma.STAGE, participant_sigma.render)]


@dataclass(frozen=True)
class Inputs:
    """The run's checked inputs: its trials and the human responses (None without --human-data)."""

    trials: list
    human: pd.DataFrame | None
    #: sha256 of the human-data file as it was read (None without one)
    human_sha256: str | None = None


def analysis_ids(trials) -> list[str]:
    """The trials the analysis runs on: the paper's 24 when the run holds them all (the
    paper's analysis; other trials stay in the effort and risk tables), else every
    trial of the run, in the run's order."""
    ids = [t.id for t in trials]
    return list(TRIAL_IDS) if set(ids) >= set(TRIAL_IDS) else ids


def check_inputs(config: RunConfig) -> Inputs:
    """The trial files and the human data, read and checked before anything is written or computed."""
    import stimuli

    trials, extra = stimuli.select_trials(config.trials, config.stimuli)
    if extra:
        _log(f"the trial folder also holds {', '.join(extra)} (not among the paper's 24): "
             f"run them with --trials {' '.join(extra)} or --trials all")
    human, digest = None, None
    if config.human_data:
        from analysis import load_human_data
        from lgp.app.manifest import file_sha256
        from analysis.data import using_trials

        # The data must name exactly the analysis's trials: the paper's 24 when the run has them all,
        # else every trial of the run (a --stimuli folder of stimuli.design or stimuli.generate).
        ids = analysis_ids(trials)
        with using_trials(ids):
            human = load_human_data(config.human_data, max_participants=config.max_participants,
                                    allow_simulated=config.allow_simulated)
        digest = file_sha256(config.human_data)
        if len(ids) < MIN_ANALYSIS_TRIALS:
            raise InputError(f"--human-data: the fits of Eq. 1 (3 parameters, held-out folds) need at least "
                             f"{MIN_ANALYSIS_TRIALS} trials; this run has {len(ids)} ({', '.join(ids)})")
    return Inputs(trials, human, digest)


def run(config: RunConfig, workdir: Path, inputs: Inputs | None = None) -> RunResult:
    """Compute the run of `config`: effort, risk, precision, pairs, the analysis and
    every enabled feature stage. Results are cached under ``<config.out>/cache``;
    the files workers make go into `workdir`. `inputs`: check_inputs(config), when
    already checked."""
    t0 = time.perf_counter()
    inputs = check_inputs(config) if inputs is None else inputs
    trials, workdir = inputs.trials, Path(workdir)
    clock = Stopwatch()
    cache = TimedCache(Path(config.out) / "cache", enabled=not config.no_cache)
    _log(f"lgp.reproduce: {len(trials)} trials, M={config.samples}, N={config.n_sims}, {len(config.sigmas)} sigmas, "
         f"jobs={config.jobs}{', scheduler ' + config.scheduler if config.scheduler else ''}; cache {cache.root}")
    enabled = [(s, render) for s, render in stages() if s.enabled(config)]
    ctx = Context(config, trials, None, cache, workdir, _log, core={"human": inputs.human})
    replays, pictures = _compute(ctx, enabled, clock)
    if pictures is None:  # a cluster's workers: the pictures are rendered here
        from lgp.app.pictures import rendered_trial_pictures

        pictures = rendered_trial_pictures(trials, config.seed, workdir / "page", cache, jobs=config.jobs)
        clock.lap("trial pictures")
    _tables(ctx)
    _run_stages(ctx, [(s, r) for s, r in enabled if s.phase == "analysis"])
    clock.lap("analysis")
    core = ctx.core
    result = RunResult(config, trials, core["effort_samples"], core["effort"], core["risk"], core["precision"],
                       core["sigma"], core["pairs"], core.get("over_sigma"), core.get("analysis"),
                       inputs.human is not None, [ctx.sections[s.name] for s, _ in enabled if ctx.sections.get(s.name) is not None],
                       replays, pictures, _docs(), _picture_sizes(pictures), core.get("pair_names", {}))
    result.record = _record(cache, clock, config, time.perf_counter() - t0, inputs)
    if config.verbose:
        _log(f"cache: {cache.summary()}")
    return result


def _compute(ctx: Context, enabled: list, clock: Stopwatch):
    """The stages on the run's one executor: B stands, effort, risk, the compute-phase
    features, the replays and (on local workers) the trial pictures."""
    from lgp import cli
    from lgp.executor import ProcessExecutor, SerialExecutor, executor_for_scheduler

    config, trials, cache = ctx.config, ctx.trials, ctx.cache
    # One executor for the whole run: its workers start now, before this process
    # imports Drake or MuJoCo, and stay warm across trials and stages.
    with executor_for_scheduler(config.scheduler, config.jobs) as executor, cache.stage():
        ctx.executor = executor
        if hasattr(executor, "start"):
            executor.start()
        with cli.deferred_interrupt():  # Drake loads here; a Ctrl-C meanwhile waits until it has
            import models.effort  # noqa: F401
            import models.risk  # noqa: F401
        from models.effort import summarise_effort

        model = config.risk_model
        check_targets(trials, model, cache)  # an unstable B fails now, not after the effort stage
        made: dict = {}  # replays the effort stage records from its own plans of sample 0
        cached = {} if config.no_replays else replay_cache_paths(trials, config.seed, cache, config.effort_spec)
        want = set() if config.no_replays else replays_to_make(trials, cached)
        effort_samples = effort_tables(trials, config.samples, config.seed, executor, cache, verbose=config.verbose,
                                       spec=config.effort_spec, replay_trials=want, replays_out=made)
        clock.lap("effort")
        runs: list = []
        risk = risk_tables(trials, config.sigmas, config.n_sims, config.seed, model, executor, cache, config.risk_chunk,
                           runs_out=runs, verbose=config.verbose)
        clock.lap("risk")
        ctx.core.update(effort_samples=effort_samples, effort=summarise_effort(effort_samples, trials), risk=risk,
                        risk_runs=runs)
        _run_stages(ctx, [(s, r) for s, r in enabled if s.phase == "compute"], clock)
        replays = None
        if not config.no_replays:
            replays = write_replays(trials, config.seed, ctx.workdir / "replays", cache, executor, _log,
                                    spec=config.effort_spec, made=made, cached=cached)
        clock.lap("replays")
        pictures = None
        if isinstance(executor, (ProcessExecutor, SerialExecutor)):  # local, warm workers: render the page's pictures there
            from lgp.app.pictures import rendered_trial_pictures

            pictures = rendered_trial_pictures(trials, config.seed, ctx.workdir / "page", cache, jobs=config.jobs,
                                               executor=executor)
            clock.lap("trial pictures")
    return replays, pictures


def _run_stages(ctx: Context, enabled: list, clock: Stopwatch | None = None) -> None:
    """Run each (stage, renderer) of `enabled`: its data, with the renderer, become ctx.sections[name]."""
    for stage, render in enabled:
        data = stage.run(ctx)
        ctx.sections[stage.name] = None if data is None else Section(stage.name, data, render)
        if clock is not None:
            clock.lap(stage.name.replace("_", " "))


def pairs_sigma(sigmas) -> float:
    """The sigma of the pair table: the paper's when the grid has it, else the grid's middle."""
    return PAPER_SIGMA if any(np.isclose(sigmas, PAPER_SIGMA)) else sigmas[len(sigmas) // 2]


def _tables(ctx: Context) -> None:
    """The required precision, the pair tables and the analysis, into ctx.core."""
    from models.risk.precision import required_precision

    config, core = ctx.config, ctx.core
    core["sigma"] = pairs_sigma(config.sigmas)
    core["precision"] = required_precision(pd.concat(core["risk_runs"], ignore_index=True), n_boot=config.n_boot,
                                           seed=config.seed)
    core["paper"] = {t.id for t in ctx.trials} >= set(TRIAL_IDS)
    if core["paper"]:
        _paper_tables(ctx)
    else:
        _own_trials_tables(ctx)


def _paper_tables(ctx: Context) -> None:
    """On the paper's 24 trials: the pair table, pairs over sigma and the analysis
    (the fits with human data, else the model-only figure). Other trials of the run
    are in the effort and risk tables only."""
    from analysis.pairs import pair_orderings
    from analysis.run import compute_analysis
    from lgp.app import over_sigma

    config, core, human = ctx.config, ctx.core, ctx.core["human"]
    paper = [t for t in ctx.trials if t.id in TRIAL_IDS]
    extra = [t.id for t in ctx.trials if t.id not in TRIAL_IDS]
    if extra:
        _log(f"pair table, figures and fits use the paper's 24 trials; {', '.join(extra)} are in the effort and risk tables only")
    e_samples, e_mean, r = (df[df["trial"].isin(TRIAL_IDS)] for df in (core["effort_samples"], core["effort"], core["risk"]))
    names = {t.pair: t.dimension for t in paper}
    core.update(paper_trials=paper, paper_effort_samples=e_samples, paper_effort=e_mean, paper_risk=r, pair_names=names)
    core["pairs"] = pair_orderings(e_mean, r, core["sigma"], names)
    core["over_sigma"] = over_sigma.OverSigma.of(e_mean, r)
    build = ctx.sections.get("build_risk")
    core["analysis"] = compute_analysis(
        human, e_samples, r, seed=config.seed, n_boot=config.n_boot, jobs=config.jobs,
        sigma=None if human is not None else core["sigma"],
        build_risk=None if human is None or build is None else build.data.measures_of(TRIAL_IDS),
        risk_measure=config.risk_measure, n_perm=config.n_perm, pair_names=names,
        features=_heuristics(paper, config) if human is not None and len(paper) == len(TRIAL_IDS) else None,
        same=_identical(paper))


def _own_trials_tables(ctx: Context) -> None:
    """On another trial set: the pair table of the pairs it declares, and with human
    data the fits on the run's own trials (analysis.data.trialset)."""
    import stimuli
    from analysis.pairs import declared_pair_orderings

    config, core, trials, human = ctx.config, ctx.core, ctx.trials, ctx.core["human"]
    declared = stimuli.declared_pairs(trials)
    core["pairs"] = declared_pair_orderings(core["effort"], core["risk"], core["sigma"],
                                            {t.pair: t.dimension for t in trials}, declared) if declared else None
    core["analysis"] = None
    if human is not None:
        from analysis.run import compute_analysis

        ids = analysis_ids(trials)
        core["analysis"] = analysis = compute_analysis(
            human, core["effort_samples"], core["risk"], seed=config.seed, n_boot=config.n_boot, jobs=config.jobs,
            n_perm=config.n_perm, trials=ids, pair_names={t.pair: t.dimension for t in trials if t.pair is not None},
            same=_identical(trials))
        for _, row in (analysis["skipped"].iterrows() if "skipped" in analysis else ()):
            _log(f"analysis of the {len(ids)} trials: {row['what']} left out: {row['reason']}")
        if config.risk_measure:
            _log(f"--risk-measure {config.risk_measure} works on the paper's 24 trials; the fits of this run use the "
                 "final-state risk table")
    pairs = core["pairs"]
    _log("not all of the paper's 24 trials: "
         + ("fits on the run's own trials (analysis/); " if human is not None
            else "no figures or fits (they need all 24, or --human-data for the run's own trials); ")
         + (f"pair table for the {len(pairs)} pair(s) whose E and H trials are both in the run" if pairs is not None
            else "no pair table (no trial files declare both trials of a pair)"))


def _heuristics(paper, config: RunConfig):
    """The heuristic predictors of the paper's trials (analysis.heuristics), from the
    layouts of A the effort stage planned (its M and seed): the comparison's
    no-physics competitors."""
    from analysis.heuristics import trial_features

    return trial_features(paper, config.samples, config.seed)


def _identical(trials):
    """Sets of the trials whose B is the same structure (folds by structure)."""
    from analysis.heuristics import identical_targets

    return identical_targets(trials)


def _docs() -> dict[str, str]:
    """The text of the docs the page links, from this checkout ({} for an installed copy)."""
    found = {}
    for name in PAGE_DOCS:
        source = ROOT / "docs" / name
        if source.is_file():
            found[name] = source.read_text(encoding="utf-8")
    return found


def _picture_sizes(pictures: dict | None) -> dict[str, tuple[int, int]]:
    """(width, height) of every trial picture, from its PNG header."""
    from lgp.app.pictures import png_size

    return {tid: size for tid, path in (pictures or {}).items() if (size := png_size(path)) is not None}


def _record(cache, clock: Stopwatch, config: RunConfig, elapsed: float, inputs: Inputs) -> RunRecord:
    """The run record: wall times, cache counts, compute time, software, machine, input digests."""
    from lgp.app.stages import risk_key_inputs

    return RunRecord(
        stages=dict(clock.laps), cache_counts=dict(cache.counts), cache_files=dict(cache.files), cache_root=str(cache.root),
        compute=cache.compute_time(),
        software={"libraries": library_versions(), "engine": risk_key_inputs(config.engine)["engine_settings"]},
        recorded_libraries=library_versions(RECORDED_LIBRARIES),
        finished=datetime.datetime.now(datetime.timezone.utc).strftime("%Y-%m-%d %H:%M UTC"),
        machine=f"{platform.node()}, {os.cpu_count()} cores",
        load="load average " + " ".join(f"{x:.2f}" for x in os.getloadavg()),
        elapsed=elapsed,
        inputs={"trial_files": {t.id: t.digest for t in inputs.trials},
                "human_data_sha256": inputs.human_sha256})
