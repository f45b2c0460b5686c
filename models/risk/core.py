"""Physical risk of a Finish state B (paper, "Modeling physical risk"): the fraction
of N noisy copies of B that fall when simulated for 4 s.

Run r of a scene perturbs B with the standard normals z[r] (drawn once from the
seed, shape (n_blocks, 3)) scaled by sigma, so every sigma value sees the same
random numbers (common random numbers) and a risk curve over sigma is smooth. A
scene's numbers depend only on (scene, sigma, n_sims, seed, engine, fall rule),
never on the other scenes of a table, on the order of runs, or on the number of
worker processes.

The fall rule (docs/risk.md, "Fall rule"): a run falls when some block's centre
ends more than `fall_threshold` * d from where it started, measured in the
horizontal plane (`fall_rule="horizontal"`, the default) or in 3-D (`"3d"`, the
paper's wording). A block lifted by the noise drops back onto its support: that
drop counts under "3d" when it exceeds the threshold, never under "horizontal".
"""
from __future__ import annotations

from dataclasses import dataclass
from typing import Callable, Iterable, Sequence

import numpy as np
import pandas as pd

from lgp.errors import InputError
from lgp.executor import borrowed, default_jobs
from lgp.geometry import digest
from lgp.paper import N_SIMS, SIGMA_GRID
from lgp.scene import Scene
from models.risk.engine import (
    DEFAULT_FALL_RULE,
    FALL_RULES,
    FALL_THRESHOLD,
    Rollout,
    _smallest_width,
    engine_name,
    fall_certain,
    get_engine,
)
from models.risk.noise import DEFAULT_NOISE_RULE, NoiseRule, check_noise_rule, draw_normals

#: The engine used when none is named: the one that passes the faithfulness suite
#: with the better throughput (docs/risk.md).
DEFAULT_ENGINE = "mujoco"

RUN_COLUMNS = ["trial", "sigma", "run", "fell", "max_displacement", "max_displacement_3d", "sim_time", "engine",
               "fall_rule", "fall_threshold", "noise_rule"]
#: risk_low, risk_high: the 95% Wilson score interval of risk = falls / n (Monte Carlo error).
RISK_COLUMNS = ["trial", "sigma", "risk", "falls", "n", "engine", "fall_rule", "fall_threshold", "noise_rule",
                "risk_low", "risk_high"]
#: Two-sided 95% normal quantile of the Wilson intervals.
WILSON_Z = 1.959963984540054


class UnstableSceneError(ValueError):
    """A scene falls in its own right, before any noise (a sigma = 0 run falls)."""


# ----------------------------------------------------------------------------- single runs


def _engine_name(engine: str | None, profile: str | None = None) -> str:
    """The registry name of an engine (None: DEFAULT_ENGINE) with its profile."""
    return engine_name(DEFAULT_ENGINE if engine is None else engine, profile)


def check_fall_rule(fall_rule: str, fall_threshold: float) -> tuple[str, float]:
    """(rule, threshold) checked: ValueError for an unknown rule or a threshold <= 0."""
    if fall_rule not in FALL_RULES:
        raise InputError(f"unknown fall rule {fall_rule!r}; known rules: {', '.join(FALL_RULES)}")
    try:
        threshold = float(fall_threshold)
    except (TypeError, ValueError):
        raise InputError(f"fall threshold must be a number (units of the block size d), got {fall_threshold!r}") from None
    if not threshold > 0 or not np.isfinite(threshold):
        raise InputError(f"fall threshold must be > 0 (units of the block size d), got {fall_threshold!r}")
    return fall_rule, threshold


def check_sigma(sigma) -> float:
    """A noise SD in units of the block size d: a finite number in [0, 1] (0: the
    unperturbed scene; the command lines take (0, 1]). Beyond 1 d the noise moves
    blocks by more than their size and the perturbed positions overflow long
    before sigma = 1e308; inf and nan are no noise level."""
    if isinstance(sigma, bool) or not isinstance(sigma, (int, float, np.integer, np.floating)):
        raise InputError(f"sigma must be a number in [0, 1] (units of the block size d), got {sigma!r}")
    value = float(sigma)
    if not (np.isfinite(value) and 0 <= value <= 1):
        raise InputError(f"sigma must be a finite number in [0, 1] (units of the block size d), got {sigma!r}")
    return value


def check_n_sims(n_sims) -> int:
    """A count of runs: a whole number >= 1 (not 2.5, not the text '4', not True)."""
    if isinstance(n_sims, bool) or not isinstance(n_sims, (int, np.integer)):
        raise InputError(f"n_sims must be a whole number >= 1 (runs per sigma; risk is falls / n_sims), got {n_sims!r}")
    if n_sims < 1:
        raise InputError(f"need n_sims >= 1 runs (risk is falls / n_sims), got {n_sims}")
    return int(n_sims)


def check_seed(seed) -> None:
    """A seed: a whole number >= 0 or a numpy Generator. None is refused: numpy
    would seed from the operating system, and the same call would give other
    numbers every time (the project promises same seed, same numbers)."""
    if isinstance(seed, np.random.Generator):
        return
    if seed is None:
        raise InputError("seed=None would draw irreproducible numbers (numpy seeds from the operating system); "
                         "give a whole number >= 0 or a numpy.random.Generator")
    if isinstance(seed, bool) or not isinstance(seed, (int, np.integer)) or seed < 0:
        raise InputError(f"seed must be a whole number >= 0 or a numpy.random.Generator, got {seed!r}")


def fall_threshold(scene: Scene, fall_threshold: float = FALL_THRESHOLD) -> float:
    """Distance (m) a block centre must move for a run to count as a fall
    (`fall_threshold` in units of the block size d)."""
    return fall_threshold * _smallest_width(scene)


def displacement(rollout: Rollout, fall_rule: str = DEFAULT_FALL_RULE) -> np.ndarray:
    """Per-block distance (m) between final and start centre, measured by the rule."""
    return rollout.horizontal_displacement() if fall_rule == "horizontal" else rollout.displacement_3d()


def _row(rollout: Rollout, threshold: float, fall_rule: str) -> dict:
    h = rollout.horizontal_displacement()
    moved = displacement(rollout, fall_rule)
    return {
        "fell": bool(moved.max() > threshold) if len(h) else False,
        "max_displacement": float(h.max()) if len(h) else 0.0,
        "max_displacement_3d": float(rollout.displacement_3d().max()) if len(h) else 0.0,
        "sim_time": float(rollout.sim_time),
    }


def apply_fall_rule(runs: pd.DataFrame, fall_rule: str, fall_threshold: float, d: float) -> pd.DataFrame:
    """The per-run table with `fell` decided again by another rule from its
    displacement columns (`d`: the block size, m). Exact when the runs were
    simulated with a threshold whose early-stop distance (engine.fall_certain)
    equals the new one's, e.g. any two thresholds <= 0.5 d."""
    fall_rule, fall_threshold = check_fall_rule(fall_rule, fall_threshold)
    if "fall_threshold" in runs and (runs["fall_threshold"].map(fall_certain) != fall_certain(fall_threshold)).any():
        raise InputError(f"runs simulated with early stops for another fall threshold cannot be re-judged at {fall_threshold:g} d")
    column = "max_displacement" if fall_rule == "horizontal" else "max_displacement_3d"
    return runs.assign(fell=runs[column] > fall_threshold * d, fall_rule=fall_rule, fall_threshold=fall_threshold)


_STABLE: dict[tuple, Rollout] = {}


def _scene_key(scene: Scene) -> str:
    """What an unperturbed simulation depends on: the label and every block and box pose and size."""
    return digest(scene.label, *(part for b in scene.blocks for part in (b.name, b.p_WB, b.size, np.float64(b.yaw))),
                  *(part for f in scene.fixed for part in (f.p_WO, f.size)))


def geometry_key(scene: Scene) -> str:
    """What a scene's noisy runs depend on besides sigma, n, seed, engine and rules:
    every block's pose and size in order and the fixed boxes -- not the label or
    the block names. Two trials with the same key (the identical 6-towers of 1H,
    9E, 9H, 11E, 11H, for example) have the same runs to the bit, so a grid
    simulates one of them (run_grid, lgp.app.stages.risk_tables)."""
    return digest(*(part for b in scene.blocks for part in (b.p_WB, b.size, np.float64(b.yaw))),
                  *(part for f in scene.fixed for part in (f.p_WO, f.size)))


def check_stable(scene: Scene, engine: str | None = None, *, profile: str | None = None,
                 fall_rule: str = DEFAULT_FALL_RULE, fall_threshold: float = FALL_THRESHOLD) -> Rollout:
    """Simulate the unperturbed scene once (cached per scene, engine and early-stop
    distance) and raise UnstableSceneError, naming the scene and the blocks that
    moved, if it falls by the fall rule."""
    name = _engine_name(engine, profile)
    fall_rule, thr = check_fall_rule(fall_rule, fall_threshold)
    key = (_scene_key(scene), name, fall_certain(thr))
    if key not in _STABLE:
        scene.validate()
        _STABLE[key] = get_engine(name).simulate(scene, fall_threshold=thr)
    rollout = _STABLE[key]
    threshold = thr * _smallest_width(scene)
    moved = displacement(rollout, fall_rule)
    if len(moved) and moved.max() > threshold:
        names = [f"{scene.blocks[i].name} moved {moved[i] * 1000:.1f} mm" for i in np.argsort(-moved) if moved[i] > threshold]
        raise UnstableSceneError(
            f"{scene.label}: unstable before any noise (sigma = 0): block {', block '.join(names)} in {rollout.sim_time:.2f} s "
            f"of {name} simulation (a fall is a {fall_rule} move of more than {threshold * 1000:.1f} mm)"
        )
    return rollout


def _simulate_runs(scene: Scene, sigma: float, z: np.ndarray, runs: Sequence[int], engine: str,
                   fall_rule: str = DEFAULT_FALL_RULE, fall_threshold: float = FALL_THRESHOLD,
                   noise_rule: str = DEFAULT_NOISE_RULE) -> list[dict]:
    """Perturb and simulate runs `runs` of the scene (z: their normals, len(runs) x n x 3)."""
    eng = get_engine(engine)
    threshold = fall_threshold * _smallest_width(scene)
    p_WB = NoiseRule(scene, noise_rule).positions(sigma, np.asarray(z, float).reshape(len(runs), len(scene), 3))
    rows = []
    for r, p_r in zip(runs, p_WB):
        rollout = eng.simulate(scene, fall_threshold=fall_threshold, p_WB=p_r)
        rows.append({"sigma": sigma, "run": int(r), **_row(rollout, threshold, fall_rule), "engine": engine,
                     "fall_rule": fall_rule, "fall_threshold": fall_threshold, "noise_rule": noise_rule})
    return rows


# ----------------------------------------------------------------------------- grids


@dataclass(frozen=True)
class _Task:
    scene_index: int
    sigma: float
    start: int
    stop: int


def _task_worker(args):
    """args: (scene, sigma, z, start, engine[, fall_rule, fall_threshold[, noise_rule]])."""
    scene, sigma, z, start, engine, *rule = args
    return _simulate_runs(scene, sigma, z, range(start, start + len(z)), engine, *rule)


def map_runs(args: list, total: int, executor, jobs: int, progress: Callable[[int, int], None] | None) -> list:
    """Simulate chunks of runs (`_task_worker` arguments) on `executor` (or a pool
    of `jobs`), results in input order; `progress(done, total)` counts runs."""
    done = 0

    def arrived(k, res):
        nonlocal done
        done += len(res)
        if progress:
            progress(done, total)

    with borrowed(executor, 1 if len(args) <= 1 else min(jobs, len(args))) as ex:
        return ex.map(_task_worker, args, arrived)


def run_grid(
    scenes: Sequence[Scene],
    sigmas: Iterable[float],
    n_sims: int = N_SIMS,
    seed: int = 0,
    engine: str | None = None,
    jobs: int | None = None,
    progress: Callable[[int, int], None] | None = None,
    trial_ids: Sequence[str] | None = None,
    executor=None,
    *,
    profile: str | None = None,
    fall_rule: str = DEFAULT_FALL_RULE,
    fall_threshold: float = FALL_THRESHOLD,
    noise_rule: str = DEFAULT_NOISE_RULE,
) -> pd.DataFrame:
    """Every (scene, sigma, run): a tidy table with columns RUN_COLUMNS, in the
    order of `scenes`, then `sigmas`, then runs.

    Each scene is checked for stability first (UnstableSceneError). The grid is
    spread over `jobs` processes (None: all cores; 1: in this process), with
    numbers identical to a serial run. `progress(done, total)` is called as runs
    finish.
    """
    name = _engine_name(engine, profile)
    fall_rule, fall_threshold = check_fall_rule(fall_rule, fall_threshold)
    noise_rule = check_noise_rule(noise_rule)
    sigmas = [check_sigma(s) for s in sigmas]
    n_sims = check_n_sims(n_sims)
    check_seed(seed)
    ids = list(trial_ids) if trial_ids is not None else [s.label for s in scenes]
    for scene in scenes:
        check_stable(scene, name, fall_rule=fall_rule, fall_threshold=fall_threshold)
    # a scene identical to an earlier one (geometry_key) has the same runs: simulated once
    first: dict[str, int] = {}
    twin = [first.setdefault(geometry_key(scene), i) for i, scene in enumerate(scenes)]
    unique = [i for i in range(len(scenes)) if twin[i] == i]
    normals = {i: draw_normals(n_sims, len(scenes[i]), seed) for i in unique}
    jobs = (executor.jobs if executor is not None else default_jobs()) if jobs is None else max(1, int(jobs))
    total = len(unique) * len(sigmas) * n_sims
    # chunks small enough to balance the load, large enough to amortise the model build
    chunk = max(1, min(n_sims, -(-total // (8 * jobs)))) if total else 1
    tasks = [
        _Task(i, s, a, min(a + chunk, n_sims)) for i in unique for s in sigmas for a in range(0, n_sims, chunk)
    ]
    args = [(scenes[t.scene_index], t.sigma, normals[t.scene_index][t.start : t.stop], t.start, name, fall_rule, fall_threshold,
             noise_rule) for t in tasks]
    results = map_runs(args, total, executor, jobs, progress)
    by_scene: dict[int, list[dict]] = {}
    for t, res in zip(tasks, results):
        by_scene.setdefault(t.scene_index, []).extend(res)
    rows = []
    for i in range(len(scenes)):  # in (scene, sigma, run) order
        rows += [{"trial": ids[i], **row} for row in by_scene.get(twin[i], [])]
    return pd.DataFrame(rows, columns=RUN_COLUMNS)


def wilson_interval(falls, n, z: float = WILSON_Z):
    """The Wilson score interval (95% by default) of a binomial proportion falls / n:
    (low, high), arrays like `falls`. Unlike the normal approximation it is not
    empty at 0 of 100 (0 to 0.037) and stays inside [0, 1]."""
    k = np.asarray(falls, dtype=float)
    n = np.asarray(n, dtype=float)
    p = k / n
    denom = 1 + z * z / n
    centre = (p + z * z / (2 * n)) / denom
    half = z * np.sqrt(p * (1 - p) / n + z * z / (4 * n * n)) / denom
    low = np.where(k == 0, 0.0, np.clip(centre - half, 0.0, 1.0))  # exact ends: no 1e-18 rounding at 0 falls
    high = np.where(k == n, 1.0, np.clip(centre + half, 0.0, 1.0))
    return (low, high) if low.ndim else (float(low), float(high))


def summarise(runs: pd.DataFrame) -> pd.DataFrame:
    """Per (trial, sigma): risk = fraction of runs that fell, with falls, n, engine,
    the rules and the 95% Wilson interval (risk_low, risk_high)."""
    if "noise_rule" not in runs:
        runs = runs.assign(noise_rule=DEFAULT_NOISE_RULE)
    g = runs.groupby(["trial", "sigma", "engine", "fall_rule", "fall_threshold", "noise_rule"], sort=False)["fell"]
    out = g.agg(falls="sum", n="size").reset_index()
    out["falls"] = out["falls"].astype(int)
    out["risk"] = out["falls"] / out["n"]
    out["risk_low"], out["risk_high"] = wilson_interval(out["falls"], out["n"])
    return out[RISK_COLUMNS]


def contrast_holds(risk_e: pd.Series | dict, risk_h: pd.Series | dict) -> bool:
    """H riskier than E beyond Monte Carlo noise: H's Wilson interval lies wholly
    above E's (rows with risk_low, risk_high). A stricter test than a difference
    of two fractions: intervals that overlap can still differ at the 5% level."""
    return bool(risk_h["risk_low"] > risk_e["risk_high"])


# ----------------------------------------------------------------------------- public API


def physical_risk(
    scene: Scene,
    sigma: float,
    n_sims: int = N_SIMS,
    seed: int = 0,
    engine: str | None = None,
    return_table: bool = False,
    jobs: int | None = 1,
    *,
    profile: str | None = None,
    fall_rule: str = DEFAULT_FALL_RULE,
    fall_threshold: float = FALL_THRESHOLD,
    noise_rule: str = DEFAULT_NOISE_RULE,
):
    """Physical risk of `scene` (a Finish state B): the fraction of `n_sims` perturbed
    copies (noise SD `sigma` * d per axis) that fall within 4 s of simulation.

    `engine`: "mujoco" (default), "drake", "physx" (optional extra); `profile`:
    the engine's profile ("faithful", or for physx "game-defaults", unfaithful;
    the same as engine="physx:game-defaults"). A run falls when a block centre
    moves more than `fall_threshold` * d, measured by `fall_rule`
    ("horizontal" or "3d"). With `return_table`, also the per-run table (columns
    run, sigma, fell, max_displacement, max_displacement_3d [m], sim_time [s],
    engine, fall_rule, fall_threshold). Raises UnstableSceneError when the
    unperturbed scene falls, ValueError for an unknown engine, profile or rule, a
    threshold <= 0, or a missing optional engine (saying how to install it);
    ValueError too for a sigma that is not a finite number in [0, 1], an `n_sims`
    that is not a whole number >= 1 (2.5, '4' and True are refused), and a
    `seed` that is not a whole number >= 0 or a Generator (None is refused: it
    would give other numbers on every call).
    `noise_rule`: "lift" (default, the paper's reading) or "settle" (every block
    set to rest on what lies beneath its new outline; models/risk/noise.py).
    """
    runs = run_grid([scene], [sigma], n_sims, seed, engine, jobs, profile=profile, fall_rule=fall_rule,
                    fall_threshold=fall_threshold, noise_rule=noise_rule)
    risk = float(runs["fell"].mean())
    if return_table:
        return risk, runs.drop(columns="trial")
    return risk


def risk_curve(
    scene: Scene,
    sigmas: Iterable[float] = SIGMA_GRID,
    n_sims: int = N_SIMS,
    seed: int = 0,
    engine: str | None = None,
    jobs: int | None = None,
    return_table: bool = False,
    *,
    profile: str | None = None,
    fall_rule: str = DEFAULT_FALL_RULE,
    fall_threshold: float = FALL_THRESHOLD,
    noise_rule: str = DEFAULT_NOISE_RULE,
) -> pd.DataFrame:
    """Risk of one scene at each sigma (same random numbers for every sigma):
    columns sigma, risk, falls, n, engine, fall_rule, fall_threshold (and the
    per-run table with `return_table`)."""
    runs = run_grid([scene], sigmas, n_sims, seed, engine, jobs, profile=profile, fall_rule=fall_rule,
                    fall_threshold=fall_threshold, noise_rule=noise_rule)
    curve = summarise(runs).drop(columns="trial")
    return (curve, runs.drop(columns="trial")) if return_table else curve


def risk_table(
    trials_or_scenes,
    sigmas: Iterable[float] = SIGMA_GRID,
    n_sims: int = N_SIMS,
    seed: int = 0,
    engine: str | None = None,
    jobs: int | None = None,
    progress: Callable[[int, int], None] | None = None,
    runs: bool = False,
    executor=None,
    *,
    profile: str | None = None,
    fall_rule: str = DEFAULT_FALL_RULE,
    fall_threshold: float = FALL_THRESHOLD,
    noise_rule: str = DEFAULT_NOISE_RULE,
) -> pd.DataFrame:
    """Risk of many scenes over a grid of sigma values, as a tidy table.

    `trials_or_scenes`: trials (objects with `.id` and `.target`, e.g.
    `stimuli.load_all()`), Scenes (named by their label) or a {trial id: Scene}
    mapping. Returns columns trial, sigma, risk, falls, n, engine, fall_rule,
    fall_threshold, noise_rule, risk_low, risk_high (95% Wilson interval), one
    row per (trial, sigma) in input order; with `runs=True`
    the per-run table instead (trial, sigma, run, fell, max_displacement,
    max_displacement_3d, sim_time, engine, fall_rule, fall_threshold). `engine`,
    `profile`, `fall_rule`, `fall_threshold`: as in `physical_risk`. Each trial's
    numbers equal `physical_risk(scene, sigma, n_sims, seed, ...)`.
    """
    ids, scenes = _as_scenes(trials_or_scenes)
    sigmas = list(sigmas)
    table = run_grid(scenes, sigmas, n_sims, seed, engine, jobs, progress, trial_ids=ids, executor=executor,
                     profile=profile, fall_rule=fall_rule, fall_threshold=fall_threshold, noise_rule=noise_rule)
    if runs:
        return _in_order(table, ids, ["sigma", "run"])
    return _in_order(summarise(table), ids, ["sigma"])


def _as_scenes(items) -> tuple[list[str], list[Scene]]:
    if isinstance(items, Scene):
        items = [items]
    if isinstance(items, dict):
        ids, scenes = list(items.keys()), list(items.values())
    else:
        ids, scenes = [], []
        for it in items:
            if isinstance(it, Scene):
                ids.append(it.label)
                scenes.append(it)
            else:
                ids.append(str(it.id))
                scenes.append(it.target)
    if len(set(ids)) != len(ids):
        raise InputError(f"trial ids must be unique, got {ids}")
    return ids, scenes


def _in_order(table: pd.DataFrame, ids: list[str], then: list[str]) -> pd.DataFrame:
    rank = {t: k for k, t in enumerate(ids)}
    return (
        table.assign(_rank=table["trial"].map(rank))
        .sort_values(["_rank", *then], kind="stable")
        .drop(columns="_rank")
        .reset_index(drop=True)
    )
