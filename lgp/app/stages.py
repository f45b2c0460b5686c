"""The stages of a reproduce run that compute, each cached per trial by a hash of
its inputs (lgp.app.cache): the check that B stands (`check_targets`), risk
(`risk_tables`) and, for effort, its cache key. The keys are written here once:
`engine_key_inputs` is what every risk-like result (risk, the stand check, the
build-risk stage, the sensitivity runs) depends on through its physics engine.
"""
from __future__ import annotations

import time

import pandas as pd

from lgp.app.cache import LIBRARIES, Cache, input_key, library_versions, modules_digest
from lgp.app.progress import Progress
from lgp.app.progress import log as _log


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


def risk_key_inputs(engine: str | None, fall_rule: str | None = None, fall_threshold: float | None = None) -> dict:
    """What a risk table depends on besides the trial and the parameters:
    engine_key_inputs of models.risk.core and the fall rule (None: the model's default)."""
    from models.risk.engine import DEFAULT_FALL_RULE, FALL_THRESHOLD

    return {**engine_key_inputs(engine, "models.risk.core"), "fall_rule": fall_rule or DEFAULT_FALL_RULE,
            "fall_threshold": float(FALL_THRESHOLD if fall_threshold is None else fall_threshold)}


def risk_tables(trials, sigmas, n_sims: int, seed: int, engine: str | None, executor, cache: Cache, chunk: int = 6,
                fall_rule: str | None = None, fall_threshold: float | None = None, verbose: bool = True) -> pd.DataFrame:
    """Per (trial, sigma) risk, one cached file per trial (common random numbers over sigma).

    Uncached trials are simulated a few at a time on the run's one executor, so
    the grid keeps every worker busy and an interruption loses at most one chunk.
    """
    from models.risk import risk_table

    depends = risk_key_inputs(engine, fall_rule, fall_threshold)
    keys = {t.id: input_key(trial=t.id, digest=t.digest, sigmas=list(sigmas), n_sims=n_sims, seed=seed, **depends) for t in trials}
    tables = {t.id: cache.get("risk", keys[t.id]) for t in trials}
    todo = [t for t in trials if tables[t.id] is None]
    if todo:
        _log(f"risk: {len(todo) * len(sigmas) * n_sims} simulations of B ({len(todo)} trial(s) x {len(sigmas)} sigma(s) "
             f"x {n_sims} noisy runs)" + (f"; {len(trials) - len(todo)} trial(s) reused from the cache" if len(todo) < len(trials) else ""))
    bar = Progress("risk", len(todo) * len(sigmas) * n_sims, "runs", what="noisy runs of B")
    for k in range(0, len(todo), chunk):
        group = todo[k:k + chunk]
        t0 = time.perf_counter()
        base = bar.done
        table = risk_table(group, sigmas=list(sigmas), n_sims=n_sims, seed=seed, engine=engine, executor=executor,
                           fall_rule=depends["fall_rule"], fall_threshold=depends["fall_threshold"],
                           progress=lambda done, total: bar.advance(base + done - bar.done))
        for t in group:
            tables[t.id] = cache.put("risk", keys[t.id], table[table["trial"] == t.id].reset_index(drop=True))
        if verbose:
            _log(f"[risk] simulated {', '.join(t.id for t in group)}: {len(group) * len(sigmas) * n_sims} runs in {time.perf_counter() - t0:.1f} s")
    if todo:
        bar.close()
    out = []
    for k, trial in enumerate(trials, 1):
        df = tables[trial.id]
        curve = " ".join(f"{r:.2f}" for r in df.sort_values("sigma")["risk"])
        if verbose:
            _log(f"[risk   {k:2d}/{len(trials)}] {trial.id:>3}: risk over sigma {curve}  ({'cached' if trial not in todo else 'new'})")
        out.append(df)
    return pd.concat(out, ignore_index=True)


def check_targets(trials, engine: str | None, cache: Cache, fall_rule: str | None = None,
                  fall_threshold: float | None = None) -> None:
    """Before the long work: B of every trial must stand unperturbed (the risk
    model's sigma = 0 run), one simulation per trial, cached like the results.
    Raises UnstableSceneError naming every trial whose B falls and its blocks."""
    from models.risk import UnstableSceneError, check_stable

    depends = risk_key_inputs(engine, fall_rule, fall_threshold)
    problems = []
    for t in trials:
        key = input_key(trial=t.id, digest=t.digest, check="B stands unperturbed", **depends)
        df = cache.get("stable", key)
        if df is None:
            try:
                check_stable(t.target, engine, fall_rule=depends["fall_rule"], fall_threshold=depends["fall_threshold"])
                df = pd.DataFrame([{"trial": t.id, "stable": True, "problem": ""}])
            except UnstableSceneError as e:
                df = pd.DataFrame([{"trial": t.id, "stable": False, "problem": str(e)}])
            cache.put("stable", key, df)
        if not bool(df["stable"].iloc[0]):
            problems.append(str(df["problem"].iloc[0]))
    if problems:
        raise UnstableSceneError("; ".join(problems))
