"""The stages of a reproduce run that compute, each cached per trial by a hash of
its inputs (lgp.app.cache): the check that B stands (`check_targets`), effort
(`effort_tables`) and risk (`risk_tables`), with their cache keys, written here once:
`engine_key_inputs` is what every risk-like result (risk, the stand check, the
build-risk stage, the sensitivity runs) depends on through its physics engine.
"""
from __future__ import annotations

import time
from collections import Counter

import pandas as pd

from lgp.app.cache import LIBRARIES, Cache, files_digest, input_key, library_versions, modules_digest
from lgp.app.progress import Progress
from lgp.app.progress import log as _log


def effort_key_inputs() -> dict:
    """What an effort table depends on besides the trial and the parameters: the
    source of every project module physical_effort can run (stimuli draws the
    layouts of A), the arm's model files, and the numerical libraries (SNOPT is Drake's)."""
    return {"code": modules_digest("models.effort", "stimuli"),
            "data": files_digest("models/*.sdf", "models/*.urdf", "models/*.yaml"),
            "libraries": library_versions(("drake", "numpy", "scipy", "pandas"))}


def effort_key(trial, samples: int, seed: int, spec=None, inputs: dict | None = None) -> str:
    """The cache key of one trial's effort table: the trial file, M, the seed, the
    lgp.planner.EffortSpec (None: the paper's; EffortSpec.key: the design and,
    for the search, the planner and its budget), and `inputs` (None:
    effort_key_inputs(); a caller keying many trials computes it once: hashing the
    code's import closure is most of a key's cost)."""
    from lgp.planner import DEFAULT_EFFORT

    spec = DEFAULT_EFFORT if spec is None else spec
    inputs = effort_key_inputs() if inputs is None else inputs
    return input_key(trial=trial.id, digest=trial.digest, samples=samples, seed=seed, **spec.key(), **inputs)


def effort_tables(trials, samples: int, seed: int, executor, cache: Cache, spec=None, log: bool = True,
                  verbose: bool = True, replay_trials=(), replays_out: dict | None = None) -> pd.DataFrame:
    """Per (trial, sample) effort, one cached file per trial and lgp.planner.EffortSpec
    (None: the paper's pipeline with the default design).

    The layouts of every uncached trial are one stream of work units on the run's
    one executor (warm workers plan across trial boundaries); a trial's file is
    written as soon as its last layout arrives, so an interruption loses at most
    the trials still in flight. For the trials in `replay_trials` whose sample 0 is
    planned here, the worker also records that plan's replay
    (lgp.app.replays.effort_job) into `replays_out` {trial id: page}: the replay
    stage then plans it no second time.
    """
    from lgp.app.replays import effort_job
    from models.effort import effort_table, effort_units

    from lgp.planner import DEFAULT_EFFORT

    spec = DEFAULT_EFFORT if spec is None else spec
    inputs = effort_key_inputs()  # once per stage, not per trial (24 import closures hashed: 1 s of a cached run)
    keys = {t.id: effort_key(t, samples, seed, spec, inputs) for t in trials}
    tables: dict[str, pd.DataFrame] = {}
    for t in trials:
        cached = cache.get("effort", keys[t.id])
        if cached is not None:
            tables[t.id] = cached
    todo = [t for t in trials if t.id not in tables]
    units = [u for t in todo for u in effort_units(t, samples, seed, spec)]
    owner = [u.trial for u in units]
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
                _log(f"[effort {len(tables):2d}/{len(trials)}] {trial.id:>3}: {df['effort'].mean():9.4f} J s over {len(df)} layouts"
                     f"  (planned, {time.perf_counter() - t0:.1f} s into the stage)")

    for t in trials:
        if log and verbose and t.id in tables and t.id not in rows:
            _log(f"[effort {trials.index(t) + 1:2d}/{len(trials)}] {t.id:>3}: {tables[t.id]['effort'].mean():9.4f} J s"
                 f" over {len(tables[t.id])} layouts  (cached)")
    replay = [replays_out is not None and u.sample == 0 and u.trial.id in replay_trials for u in units]
    first = replay.index(True) if any(replay) else -1  # the one unit that also returns the replays' shared library

    def arrived_with_page(k, result):
        row, page = result
        if page is not None:
            replays_out[owner[k].id] = page
        arrived(k, row)

    with bar:
        executor.map(effort_job, [(u, r, k == first) for k, (u, r) in enumerate(zip(units, replay))], arrived_with_page)
    return pd.concat([tables[t.id] for t in trials], ignore_index=True)


def engine_key_inputs(engine: str | None, model: str) -> dict:
    """What a result of the risk model's module `model` (models.risk.core,
    models.risk.build) simulated by `engine` (None: the default) depends on besides
    the trial and the parameters: the source of every project module it can run
    (the engine module is loaded by name, so it is named here), the engine's name
    and settings, and the libraries, the engine's own among them (sapien for PhysX)."""
    from models.risk import DEFAULT_ENGINE, ENGINES, get_engine

    name = DEFAULT_ENGINE if engine is None else engine
    spec = ENGINES[name]
    extra = (spec.requires,) if spec.requires else ()  # e.g. sapien for PhysX
    return {"code": modules_digest(model, spec.target.split(":")[0], "stimuli"),
            "engine": name, "engine_settings": get_engine(name).settings(), "libraries": library_versions(LIBRARIES + extra)}


def risk_key_inputs(model=None) -> dict:
    """What a risk table depends on besides the trial and the parameters:
    engine_key_inputs of models.risk.core and the risk model as the tables record
    it (a models.risk.RiskModel, an engine name or None: RiskModel.of)."""
    from models.risk import RiskModel

    model = RiskModel.of(model)
    return {**engine_key_inputs(model.engine, "models.risk.core"), **model.record()}


def _run_cache_columns() -> list[str]:
    """The per-run columns a run caches: what the risk table and the required
    precision's bootstrap over runs are computed from."""
    from models.risk import MODEL_COLUMNS

    return ["trial", "sigma", "run", "fell", *MODEL_COLUMNS]


def risk_tables(trials, sigmas, n_sims: int, seed: int, model, executor, cache: Cache, chunk: int = 6,
                runs_out: list | None = None, verbose: bool = True) -> pd.DataFrame:
    """Per (trial, sigma) risk of the RiskModel `model`, one cached file per trial
    (common random numbers over sigma).

    Each trial's cached file holds its runs' verdicts (the run columns); the
    risk table (with its Wilson intervals) is summarised from them, and
    `runs_out`, when given, receives the per-run tables (for the required precision).
    Uncached trials are simulated a few at a time on the run's one executor, so
    the grid keeps every worker busy and an interruption loses at most one chunk.
    """
    from models.risk import RiskModel, risk_table, summarise
    from models.risk.core import twins

    model = RiskModel.of(model)
    columns = _run_cache_columns()
    depends = risk_key_inputs(model)
    keys = {t.id: input_key(trial=t.id, digest=t.digest, sigmas=list(sigmas), n_sims=n_sims, seed=seed, **depends) for t in trials}
    tables = {t.id: cache.get("riskruns", keys[t.id], rows=len(sigmas) * n_sims) for t in trials}
    todo = [t for t in trials if tables[t.id] is None]
    # a trial whose B is identical to another's has the same runs: the grid simulates
    # one of each, so a chunk takes each distinct B with all its twins
    first = twins([t.target for t in todo])
    simulate = [t for k, t in enumerate(todo) if first[k] == k]
    with_twins = {t.id: [todo[j] for j in range(len(todo)) if todo[first[j]] is t] for t in simulate}
    if todo:
        _log(f"risk: {len(simulate) * len(sigmas) * n_sims} simulations of B ({len(simulate)} trial(s) x {len(sigmas)} sigma(s) "
             f"x {n_sims} noisy runs" + (f"; {len(todo) - len(simulate)} trial(s) with an identical B reuse their runs"
                                         if len(simulate) < len(todo) else "") + ")"
             + (f"; {len(trials) - len(todo)} trial(s) reused from the cache" if len(todo) < len(trials) else ""))
    bar = Progress("risk", len(simulate) * len(sigmas) * n_sims, "runs", what="noisy runs of B")
    for k in range(0, len(simulate), chunk):
        group = simulate[k:k + chunk]
        members = [same for t in group for same in with_twins[t.id]]
        t0 = time.perf_counter()
        base = bar.done
        table = risk_table(members, sigmas=list(sigmas), n_sims=n_sims, seed=seed, model=model, executor=executor,
                           runs=True, progress=lambda done, total: bar.advance(base + done - bar.done))[columns]
        for same in members:
            tables[same.id] = cache.put("riskruns", keys[same.id], table[table["trial"] == same.id].reset_index(drop=True))
        if verbose:
            _log(f"[risk] simulated {', '.join(t.id for t in group)}: {len(group) * len(sigmas) * n_sims} runs in {time.perf_counter() - t0:.1f} s")
    if todo:
        bar.close()
    out = []
    for k, trial in enumerate(trials, 1):
        if runs_out is not None:
            runs_out.append(tables[trial.id])
        df = summarise(tables[trial.id].assign(trial=tables[trial.id]["trial"].astype(str)))
        curve = " ".join(f"{r:.2f}" for r in df.sort_values("sigma")["risk"])
        if verbose:
            _log(f"[risk   {k:2d}/{len(trials)}] {trial.id:>3}: risk over sigma {curve}  ({'cached' if trial not in todo else 'new'})")
        out.append(df)
    return pd.concat(out, ignore_index=True)


def check_targets(trials, model, cache: Cache) -> None:
    """Before the long work: B of every trial must stand unperturbed under the
    RiskModel `model` (its sigma = 0 run), one simulation per trial, cached like
    the results. Raises UnstableSceneError naming every trial whose B falls and its blocks."""
    from models.risk import RiskModel, UnstableSceneError, check_stable

    model = RiskModel.of(model)
    depends = risk_key_inputs(model)
    problems = []
    for t in trials:
        key = input_key(trial=t.id, digest=t.digest, check="B stands unperturbed", **depends)
        df = cache.get("stable", key)
        if df is None:
            try:
                check_stable(t.target, model)
                df = pd.DataFrame([{"trial": t.id, "stable": True, "problem": ""}])
            except UnstableSceneError as e:
                df = pd.DataFrame([{"trial": t.id, "stable": False, "problem": str(e)}])
            cache.put("stable", key, df)
        if not bool(df["stable"].iloc[0]):
            problems.append(str(df["problem"].iloc[0]))
    if problems:
        raise UnstableSceneError("; ".join(problems))
