"""The design run: screen a pool of candidates, check the finalists faithfully,
choose the set, write it (`design`; the command line is stimuli/design/__main__.py).

1. Screen: candidates 0..C-1 of the seed (grammar.draw) through the screen's
   checks (checks.screen_candidate), spread over the executor; duplicates dropped.
2. Finalists: the objective chooses F (default 1.5 x the set) from the screened
   pool on the screen's numbers; each must stand in the physics engine and plan
   (layout 0); a finalist that fails is discarded (reason counted) and the
   choice is made again without it.
3. Faithful check: the finalists' effort (M layouts, the paper planner) and risk
   (N runs at every sigma of the design grid, the default engine) through the
   project's own cached stages (lgp.app.stages), as lgp.reproduce computes them.
4. The set: the objective chooses k of the finalists on the faithful numbers.
"""
from __future__ import annotations

import time
from collections import Counter
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
import pandas as pd

from lgp.errors import InputError
from stimuli.design import objective
from stimuli.design.checks import Discarded, engine_check, plan_check, screen_candidate
from stimuli.design.grammar import MAX_BLOCKS, draw
from stimuli.design.screen import PRIOR_GRID, PRIOR_HI, PRIOR_LO, RISE, SCREEN_RUNS


@dataclass(frozen=True)
class DesignConfig:
    """Everything a design run depends on (the same config gives the same set)."""

    trials: int = 24
    seed: int = 0
    candidates: int = 10_000
    budget: int = MAX_BLOCKS
    prior: tuple[float, float] = (PRIOR_LO, PRIOR_HI)
    finalists: int | None = None  # default 2 x trials
    samples: int = 5  # M layouts of the faithful effort
    n_sims: int = 30  # N runs per sigma of the faithful risk
    screen_runs: int = SCREEN_RUNS
    engine: str | None = None
    pairs: bool = False

    @property
    def sigmas(self) -> tuple[float, ...]:
        """The design's sigma grid: PRIOR_GRID's points within the prior, its two
        ends, and 0.10 and 0.15 d (the objective's), sorted."""
        lo, hi = self.prior
        pts = {s for s in PRIOR_GRID if lo <= s <= hi} | {round(lo, 4), round(hi, 4), 0.1, 0.15}
        return tuple(sorted(pts))

    @property
    def faithful_sigmas(self) -> tuple[float, ...]:
        """The faithful check's sigmas: the prior's ends, 0.10 and 0.15 d (the
        objective's), the paper's 0.065 d and 0.20 d where inside the prior: the
        simulations cost ~100x the screen's, so fewer points."""
        lo, hi = self.prior
        return tuple(sorted({s for s in (0.065, 0.2) if lo <= s <= hi} | {round(lo, 4), round(hi, 4), 0.1, 0.15}))

    @property
    def n_finalists(self) -> int:
        return self.finalists or (3 * self.trials + 1) // 2


def check_config(cfg: DesignConfig) -> None:
    """ValueError (one line, naming the flag) for a config no run can satisfy."""
    lo, hi = cfg.prior
    if not (0 < lo <= 1 and 0 < hi <= 1 and lo < hi):
        raise InputError(f"--sigma-prior {lo:g} {hi:g}: both ends must lie in (0, 1] (units of d), low < high")
    if cfg.budget < 1:
        raise InputError(f"--budget {cfg.budget}: a trial needs at least 1 block")
    if cfg.trials < 4:
        raise InputError(f"--pairs {cfg.trials // 2}: a design needs at least 2 pairs" if cfg.pairs
                         else f"--trials {cfg.trials}: a design needs at least 4 trials")
    if cfg.trials > cfg.candidates:
        raise InputError(f"--trials {cfg.trials} is more than the {cfg.candidates} candidates (--candidates)")
    if cfg.n_finalists < cfg.trials:
        raise InputError(f"--finalists {cfg.n_finalists} is fewer than --trials {cfg.trials}")
    for name in ("samples", "n_sims", "screen_runs", "candidates"):
        if getattr(cfg, name) < 1:
            raise InputError(f"--{name.replace('_', '-')} must be >= 1, got {getattr(cfg, name)}")


def _screen_unit(unit) -> list:
    """Screen candidates [start, stop) of a seed: rows, or (index, reason) for discards."""
    seed, start, stop, budget, sigmas, runs = unit
    out = []
    for i in range(start, stop):
        c = draw(i, seed, budget)
        try:
            out.append(screen_candidate(c, budget, sigmas, runs, seed))
        except Discarded as e:
            out.append((i, e.reason))
    return out


def _code_key() -> str:
    """The source of the design's screen and checks (and what they import): part of every cache key here."""
    from lgp.app.cache import modules_digest

    return modules_digest("stimuli.design.checks", "stimuli.design.grammar")


def _as_frame(res: list) -> pd.DataFrame:
    rows = [{"candidate": r[0], "discarded": r[1]} if isinstance(r, tuple) else {**r, "discarded": ""} for r in res]
    return pd.DataFrame(rows)


def screen(cfg: DesignConfig, executor, log=print, cache=None) -> tuple[pd.DataFrame, Counter]:
    """The screened pool (one row per candidate that passed, duplicates dropped)
    and the discards counted by reason. Each chunk of 100 candidates is cached
    (`cache`, lgp.app.cache.Cache, kind "screen") by the seed, its range, the
    screen's settings and the code: an interrupted run resumes."""
    from lgp.app.cache import input_key

    chunk = 100
    units = [(cfg.seed, a, min(a + chunk, cfg.candidates), cfg.budget, cfg.sigmas, cfg.screen_runs)
             for a in range(0, cfg.candidates, chunk)]
    code = _code_key()
    keys = [input_key(unit=list(u[:4]), sigmas=list(u[4]), runs=u[5], code=code) for u in units]
    frames = {k: cache.get("screen", keys[k]) if cache is not None else None for k in range(len(units))}
    todo = [k for k in range(len(units)) if frames[k] is None]
    t0 = time.perf_counter()
    done = [sum(u[2] - u[1] for k, u in enumerate(units) if frames[k] is not None)]
    if done[0]:
        log(f"screen: {done[0]} candidates from the cache")

    def arrived(j, res):
        k = todo[j]
        frames[k] = _as_frame(res)
        if cache is not None:
            cache.put("screen", keys[k], frames[k])
        done[0] += len(res)
        if done[0] % 1000 < chunk or done[0] == cfg.candidates:
            log(f"screen: {done[0]}/{cfg.candidates} candidates ({time.perf_counter() - t0:.0f} s)")

    executor.map(_screen_unit, [units[k] for k in todo], arrived)
    table = pd.concat([frames[k] for k in range(len(units))], ignore_index=True)
    gone = table["discarded"].fillna("").astype(str) != ""
    reasons = Counter(table.loc[gone, "discarded"].astype(str))
    pool = table[~gone].drop(columns="discarded").reset_index(drop=True)
    for col in [c for c in pool.columns if c.endswith("_rises") or c == "static_stands"]:
        pool[col] = pool[col].astype(str).str.lower().eq("true")
    if len(pool):
        dup = pool.duplicated("key")
        reasons["duplicate"] += int(dup.sum())
        pool = pool[~dup].reset_index(drop=True)
    return pool, reasons


def _finalist_unit(unit):
    data, engine, seed = unit
    from stimuli.trial import parse_trial

    trial = parse_trial(data)
    try:
        engine_check(trial, engine)
        return ("ok", plan_check(trial, seed))
    except Discarded as e:
        return (e.reason, e.detail)


def pick_finalists(cfg: DesignConfig, pool: pd.DataFrame, executor, reasons: Counter, log=print, cache=None) -> pd.DataFrame:
    """F finalists chosen by the objective on the screen's numbers, each standing
    in the engine and planning; failures are discarded (counted) and the choice
    made again (at most 6 rounds)."""
    rng = np.random.default_rng([cfg.seed, 2])
    failed: set[int] = set()
    checked: dict[int, float] = {}
    F = min(cfg.n_finalists, len(pool))
    for rnd in range(6):
        live = pool[~pool["candidate"].isin(failed)].reset_index(drop=True)
        if len(live) < cfg.trials:
            raise InputError(f"only {len(live)} candidates pass every check; --trials {cfg.trials} needs more (--candidates)")
        idx, terms = objective.choose(live, min(F, len(live)), rng)
        chosen = live.iloc[idx]
        todo = [int(c) for c in chosen["candidate"] if int(c) not in checked]
        log(f"finalists, round {rnd + 1}: {len(chosen)} chosen (screen |r| max {terms['max_abs_r']:.2f}, "
            f"rising {terms['rising']:.0%}); {len(todo)} to check in the engine and the planner")
        from lgp.app.cache import input_key
        from lgp.app.stages import effort_key_inputs, engine_key_inputs

        depends = {"code": _code_key(), "engine": engine_key_inputs(cfg.engine, "models.risk.core"),
                   "effort": effort_key_inputs()}
        units = [(draw(c, cfg.seed, cfg.budget).data, cfg.engine, cfg.seed) for c in todo]
        fkeys = [input_key(data=repr(u[0]), engine_name=u[1], seed=u[2], **depends) for u in units]
        got = {j: cache.get("finalist", fkeys[j]) if cache is not None else None for j in range(len(units))}
        need = [j for j in range(len(units)) if got[j] is None]

        def checked_one(i, res):
            j = need[i]
            got[j] = pd.DataFrame([{"status": res[0], "value": str(res[1])}])
            if cache is not None:
                cache.put("finalist", fkeys[j], got[j])

        executor.map(_finalist_unit, [units[j] for j in need], checked_one)
        results = [(str(got[j]["status"].iloc[0]), got[j]["value"].iloc[0]) for j in range(len(units))]
        for c, (status, value) in zip(todo, results):
            value = float(value) if status == "ok" else value
            if status == "ok":
                checked[c] = value
            else:
                failed.add(c)
                reasons[status] += 1
        if not (set(int(c) for c in chosen["candidate"]) & failed):
            return chosen.assign(effort_layout0=[checked[int(c)] for c in chosen["candidate"]]).reset_index(drop=True)
    raise InputError("finalists: still failing checks after 6 rounds")


def faithful(trials, cfg: DesignConfig, executor, cache) -> tuple[pd.DataFrame, pd.DataFrame]:
    """Effort (M layouts) and risk (N runs, the design's sigmas) of `trials`
    through the project's cached stages: (effort per trial, risk table)."""
    from lgp.app.stages import effort_tables, risk_tables
    from models.effort import summarise_effort

    samples = effort_tables(trials, cfg.samples, cfg.seed, executor, cache, verbose=False)
    risk = risk_tables(trials, list(cfg.faithful_sigmas), cfg.n_sims, cfg.seed, cfg.engine, executor, cache, verbose=False)
    return summarise_effort(samples, trials), risk


def wide(risk: pd.DataFrame, prefix: str = "risk") -> pd.DataFrame:
    """The risk table as one row per trial: `prefix`_<sigma> columns, the prior's
    mean, and whether the curve rises within the prior (screen.RISE)."""
    w = risk.pivot(index="trial", columns="sigma", values="risk")
    out = pd.DataFrame({f"{prefix}_{s:g}": w[s] for s in w.columns})
    out[f"{prefix}_prior"] = w.mean(axis=1)
    out[f"{prefix}_rises"] = (w[w.columns.max()] - w[w.columns.min()]) >= RISE
    return out


@dataclass
class Design:
    """What a design run found: the pool, the discards, the finalists with their
    screen and faithful numbers, the chosen rows and the objective's terms."""

    config: DesignConfig
    pool: pd.DataFrame
    reasons: Counter
    finalists: pd.DataFrame
    chosen: pd.DataFrame
    terms: dict
    timings: dict = field(default_factory=dict)
    effort: pd.DataFrame | None = None  # faithful effort per finalist (trial, effort, effort_sd, ...)
    risk: pd.DataFrame | None = None  # faithful risk table of the finalists (trial, sigma, risk, ...)


def paper_features(cfg: DesignConfig) -> pd.DataFrame:
    """The screen's numbers of the paper's 24 (for the correlation matrix and the screen's check)."""
    import stimuli
    from stimuli.design.checks import features

    return pd.DataFrame([features(t, cfg.sigmas, cfg.screen_runs, cfg.seed) for t in stimuli.load_paper()])


def write_trial_file(data: dict, path: Path, header: str) -> Path:
    import yaml

    from lgp.atomic import write_text_atomic

    write_text_atomic(header + yaml.safe_dump(data, sort_keys=False, default_flow_style=None), path)
    return path


def run_design(cfg: DesignConfig, out: Path, executor, cache, log=print) -> Design:
    """Steps 1-4 of the module docstring; writes the finalists' trial files under
    `out`/finalists (the faithful stages key their caches by the file's bytes)."""
    import stimuli

    check_config(cfg)
    timings = {}
    t0 = time.perf_counter()
    pool, reasons = screen(cfg, executor, log, cache)
    timings["screen"] = time.perf_counter() - t0
    log(f"screen: {len(pool)} of {cfg.candidates} candidates pass ({', '.join(f'{n} {r}' for r, n in reasons.most_common())})")
    if len(pool) < cfg.trials:
        raise InputError(f"only {len(pool)} of {cfg.candidates} candidates pass the screen; --trials {cfg.trials} needs more")
    t1 = time.perf_counter()
    fin = pick_finalists(cfg, pool, executor, reasons, log, cache)
    timings["finalists"] = time.perf_counter() - t1
    folder = out / "finalists"
    folder.mkdir(parents=True, exist_ok=True)
    trials = []
    for c in fin["candidate"]:
        cand = draw(int(c), cfg.seed, cfg.budget)
        path = write_trial_file(cand.data, folder / f"{cand.id}.yaml", f"# Design finalist {cand.id}: {cand.data['description']}\n")
        trials.append(stimuli.load_file(path))
    t2 = time.perf_counter()
    log(f"faithful check: {len(trials)} finalists, M = {cfg.samples} layouts, N = {cfg.n_sims} runs x {len(cfg.faithful_sigmas)} sigmas")
    effort, risk = faithful(trials, cfg, executor, cache)
    timings["faithful"] = time.perf_counter() - t2
    fin = fin.merge(effort[["trial", "effort", "effort_sd"]], on="trial").merge(wide(risk), left_on="trial", right_index=True)
    rng = np.random.default_rng([cfg.seed, 3])
    idx, terms = objective.choose(fin, cfg.trials, rng, effort="effort", risk="risk")
    chosen = fin.iloc[idx].sort_values(["risk_prior", "candidate"]).reset_index(drop=True)
    timings["total"] = time.perf_counter() - t0
    return Design(cfg, pool, reasons, fin, chosen, terms, timings, effort, risk)
