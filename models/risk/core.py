"""Physical risk of a Finish state B (paper, "Modeling physical risk"): the fraction
of N noisy copies of B that fall when simulated for 4 s.

Run r of a scene perturbs B with the standard normals z[r] (drawn once from the
seed, shape (n_blocks, 3)) scaled by sigma, so every sigma value sees the same
random numbers (common random numbers) and a risk curve over sigma is smooth. A
scene's numbers depend only on (scene, sigma, n_sims, seed, RiskModel), never
on the other scenes of a table, on the order of runs, or on the number of
worker processes.

The fall rule (docs/risk.md, "Fall rule"; models.risk.model.RiskModel): a run
falls when some block's centre ends more than the fall threshold (units of d)
from where it started, measured in the horizontal plane (FallRule.HORIZONTAL,
the default) or in 3-D (FallRule.THREE_D, the paper's wording). A block lifted by the noise drops back onto its support: that
drop counts under "3d" when it exceeds the threshold, never under "horizontal".
"""
from __future__ import annotations

import hashlib
from dataclasses import dataclass
from typing import Callable, Iterable, Sequence

import numpy as np
import pandas as pd

from lgp.errors import InputError
from lgp.executor import borrowed, default_jobs
from lgp.geometry import digest
from lgp.paper import N_SIMS, SIGMA_GRID
from lgp.scene import Scene
from models.risk.engine import Rollout, get_engine
from models.risk.model import (
    DEFAULT_ENGINE,
    DEFAULT_MODEL,
    MODEL_COLUMNS,
    RiskModel,
    check_n_sims,
    check_seed,
    check_sigma,
)
from models.risk.noise import NoiseRule, draw_normals

__all__ = ["DEFAULT_ENGINE", "RUN_COLUMNS", "RISK_COLUMNS", "UnstableSceneError", "check_stable",
           "geometry_key", "twins", "chunk_size", "SimTask", "simulate_runs", "map_tasks", "simulate_grid",
           "wilson_interval", "summarise", "physical_risk", "risk_curve", "risk_table"]

RUN_COLUMNS = ["trial", "sigma", "run", "fell", "max_displacement", "max_displacement_3d", "sim_time", *MODEL_COLUMNS]
#: risk_low, risk_high: the 95% Wilson score interval of risk = falls / n (Monte Carlo error).
RISK_COLUMNS = ["trial", "sigma", "risk", "falls", "n", *MODEL_COLUMNS, "risk_low", "risk_high"]
#: Two-sided 95% normal quantile of the Wilson intervals.
WILSON_Z = 1.959963984540054


class UnstableSceneError(ValueError):
    """A scene falls in its own right, before any noise (a sigma = 0 run falls)."""


# ----------------------------------------------------------------------------- single runs


def _row(rollout: Rollout, threshold: float, model: RiskModel) -> dict:
    h = rollout.horizontal_displacement()
    moved = model.displacement(rollout)
    return {
        "fell": bool(moved.max() > threshold) if len(h) else False,
        "max_displacement": float(h.max()) if len(h) else 0.0,
        "max_displacement_3d": float(rollout.displacement_3d().max()) if len(h) else 0.0,
        "sim_time": float(rollout.sim_time),
    }


_STABLE: dict[tuple, Rollout] = {}


def _scene_key(scene: Scene) -> str:
    """What an unperturbed simulation depends on: the label and every block and box pose and size."""
    return digest(scene.label, *(part for b in scene.blocks for part in (b.name, b.p_WB, b.size, np.float64(b.yaw))),
                  *(part for f in scene.fixed for part in (f.p_WO, f.size)))


def geometry_key(scene: Scene) -> str:
    """What a scene's noisy runs depend on besides sigma, normals and the model:
    every block's pose and size in order and the fixed boxes -- not the label or
    the block names. The identical 6-towers of 1H, 9E, 9H, 11E, 11H share a key."""
    return digest(*(part for b in scene.blocks for part in (b.p_WB, b.size, np.float64(b.yaw))),
                  *(part for f in scene.fixed for part in (f.p_WO, f.size)))


def check_stable(scene: Scene, model: RiskModel | str | None = None) -> Rollout:
    """Simulate the unperturbed scene once (cached per scene, engine and early-stop
    distance) and raise UnstableSceneError, naming the scene and the blocks that
    moved, if it falls by the model's fall rule. `model`: a RiskModel, an engine
    name (its default rules) or None (the default model)."""
    model = RiskModel.of(model)
    key = (_scene_key(scene), model.engine, model.stop_distance)
    if key not in _STABLE:
        scene.validate()
        _STABLE[key] = get_engine(model.engine).simulate(scene, stop_distance=model.stop_distance)
    rollout = _STABLE[key]
    threshold = model.fall_distance(scene)
    moved = model.displacement(rollout)
    if len(moved) and moved.max() > threshold:
        names = [f"{scene.blocks[i].name} moved {moved[i] * 1000:.1f} mm" for i in np.argsort(-moved) if moved[i] > threshold]
        raise UnstableSceneError(
            f"{scene.label}: unstable before any noise (sigma = 0): block {', block '.join(names)} in {rollout.sim_time:.2f} s "
            f"of {model.engine} simulation (a fall is a {model.fall_rule} move of more than {threshold * 1000:.1f} mm)"
        )
    return rollout


@dataclass(frozen=True)
class SimTask:
    """A chunk of noisy runs of one scene: runs start .. start + len(z) at noise
    level `sigma`, with their standard normals `z` (runs, blocks, 3)."""

    scene: Scene
    sigma: float
    z: np.ndarray
    start: int
    model: RiskModel


def simulate_runs(task: SimTask) -> list[dict]:
    """Perturb and simulate the runs of `task` (a worker's unit): one row each."""
    model, scene = task.model, task.scene
    eng = get_engine(model.engine)
    threshold = model.fall_distance(scene)
    record = model.record()
    p_WB = NoiseRule(scene, model.noise_rule).positions(task.sigma, task.z)
    rows = []
    for r, p_r in enumerate(p_WB, start=task.start):
        rollout = eng.simulate(scene, stop_distance=model.stop_distance, p_WB=p_r)
        rows.append({"sigma": task.sigma, "run": r, **_row(rollout, threshold, model), **record})
    return rows


# ----------------------------------------------------------------------------- grids


def twins(scenes: Sequence[Scene], normals: Sequence[np.ndarray] | None = None) -> list[int]:
    """For each scene, the index of the first scene with the same geometry
    (geometry_key) and, when `normals` are given per scene, the same normals:
    such scenes have the same runs to the bit, so a grid simulates one of them."""
    first: dict[str, int] = {}
    out = []
    for i, scene in enumerate(scenes):
        key = geometry_key(scene)
        if normals is not None:
            key += hashlib.sha1(np.ascontiguousarray(normals[i], dtype=float).tobytes()).hexdigest()
        out.append(first.setdefault(key, i))
    return out


def chunk_size(total: int, n_sims: int, jobs: int) -> int:
    """Runs per task: small enough to balance the load over `jobs` workers (about
    8 tasks each), large enough to amortise the engine's model build."""
    return max(1, min(n_sims, -(-total // (8 * jobs)))) if total else 1


def resolve_jobs(executor, jobs: int | None) -> int:
    """Worker count of a grid: `jobs`, else the executor's, else every core."""
    return (executor.jobs if executor is not None else default_jobs()) if jobs is None else max(1, int(jobs))


def map_tasks(worker, tasks: list, total: int, executor, jobs: int, progress: Callable[[int, int], None] | None,
              size=len) -> list:
    """`worker` over `tasks` on `executor` (or a pool of `jobs`), results in input
    order; `progress(done, total)` counts runs (`size(result)` each)."""
    done = 0

    def arrived(k, res):
        nonlocal done
        done += size(res)
        if progress:
            progress(done, total)

    with borrowed(executor, 1 if len(tasks) <= 1 else min(jobs, len(tasks))) as ex:
        return ex.map(worker, tasks, arrived)


def simulate_grid(
    scenes: Sequence[Scene],
    sigmas: Iterable[float],
    n_sims: int = N_SIMS,
    seed: int = 0,
    model: RiskModel = DEFAULT_MODEL,
    executor=None,
    *,
    jobs: int | None = None,
    progress: Callable[[int, int], None] | None = None,
    ids: Sequence[str] | None = None,
    normals: Sequence[np.ndarray] | None = None,
) -> pd.DataFrame:
    """Every (scene, sigma, run): a tidy table with columns RUN_COLUMNS, in the
    order of `scenes`, then `sigmas`, then runs; `trial` from `ids` (default:
    the scenes' labels).

    Common random numbers: run r of a scene uses the normals z[r] at every
    sigma, ``draw_normals(n_sims, len(scene), seed)`` unless `normals` gives
    them per scene (arrays (n_sims, blocks, 3)). A scene with the geometry and
    normals of an earlier one (`twins`) is simulated once. Each scene is
    checked for stability first (UnstableSceneError). The grid is spread over
    `jobs` processes (None: the executor's or all cores; 1: in this process),
    numbers identical to a serial run. `progress(done, total)` counts runs.
    """
    model = RiskModel.of(model)
    sigmas = [check_sigma(s) for s in sigmas]
    n_sims = check_n_sims(n_sims)
    check_seed(seed)
    ids = list(ids) if ids is not None else [s.label for s in scenes]
    for scene in scenes:
        check_stable(scene, model)
    twin = twins(scenes, normals)
    unique = [i for i in range(len(scenes)) if twin[i] == i]
    if normals is None:
        z = {i: draw_normals(n_sims, len(scenes[i]), seed) for i in unique}
    else:
        z = {i: np.asarray(normals[i], dtype=float).reshape(n_sims, len(scenes[i]), 3) for i in unique}
    jobs = resolve_jobs(executor, jobs)
    total = len(unique) * len(sigmas) * n_sims
    chunk = chunk_size(total, n_sims, jobs)
    tasks = [SimTask(scenes[i], s, z[i][a:a + chunk], a, model) for i in unique for s in sigmas for a in range(0, n_sims, chunk)]
    results = map_tasks(simulate_runs, tasks, total, executor, jobs, progress)
    by_scene: dict[int, list[dict]] = {}
    for i, res in zip((i for i in unique for s in sigmas for a in range(0, n_sims, chunk)), results):
        by_scene.setdefault(i, []).extend(res)
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
    """Per (trial, sigma): risk = fraction of runs that fell, with falls, n, the
    model's columns and the 95% Wilson interval (risk_low, risk_high)."""
    if "noise_rule" not in runs:
        runs = runs.assign(noise_rule=DEFAULT_MODEL.noise_rule.value)
    g = runs.groupby(["trial", "sigma", *MODEL_COLUMNS], sort=False)["fell"]
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


def physical_risk(scene: Scene, sigma: float, n_sims: int = N_SIMS, seed: int = 0,
                  model: RiskModel | str | None = None, return_table: bool = False, jobs: int | None = 1):
    """Physical risk of `scene` (a Finish state B): the fraction of `n_sims` perturbed
    copies (noise SD `sigma` * d per axis) that fall within 4 s of simulation.

    `model`: the RiskModel (engine and profile, fall rule and threshold, noise
    rule; an engine name stands for that engine with the default rules; None:
    the default model). With `return_table`, also the per-run table (columns
    run, sigma, fell, max_displacement, max_displacement_3d [m], sim_time [s],
    and the model's MODEL_COLUMNS). Raises UnstableSceneError
    when the unperturbed scene falls; ValueError for a sigma that is not a
    finite number in [0, 1], an `n_sims` that is not a whole number >= 1 (2.5,
    '4' and True are refused), and a `seed` that is not a whole number >= 0 or
    a Generator (None is refused: it would give other numbers on every call).
    """
    runs = simulate_grid([scene], [sigma], n_sims, seed, model, jobs=jobs)
    risk = float(runs["fell"].mean())
    if return_table:
        return risk, runs.drop(columns="trial")
    return risk


def risk_curve(scene: Scene, sigmas: Iterable[float] = SIGMA_GRID, n_sims: int = N_SIMS, seed: int = 0,
               model: RiskModel | str | None = None, jobs: int | None = None, return_table: bool = False) -> pd.DataFrame:
    """Risk of one scene at each sigma (same random numbers for every sigma):
    columns sigma, risk, falls, n, the model's columns and the Wilson interval
    (and the per-run table with `return_table`)."""
    runs = simulate_grid([scene], sigmas, n_sims, seed, model, jobs=jobs)
    curve = summarise(runs).drop(columns="trial")
    return (curve, runs.drop(columns="trial")) if return_table else curve


def risk_table(trials_or_scenes, sigmas: Iterable[float] = SIGMA_GRID, n_sims: int = N_SIMS, seed: int = 0,
               model: RiskModel | str | None = None, jobs: int | None = None,
               progress: Callable[[int, int], None] | None = None, runs: bool = False, executor=None) -> pd.DataFrame:
    """Risk of many scenes over a grid of sigma values, as a tidy table.

    `trials_or_scenes`: trials (objects with `.id` and `.target`, e.g.
    `stimuli.load_all()`), Scenes (named by their label) or a {trial id: Scene}
    mapping. Returns RISK_COLUMNS (trial, sigma, risk, falls, n, the model's
    MODEL_COLUMNS, risk_low, risk_high: the 95% Wilson interval), one row per (trial, sigma) in input order; with `runs=True` the
    per-run table instead (RUN_COLUMNS). `model` as in `physical_risk`. Each
    trial's numbers equal `physical_risk(scene, sigma, n_sims, seed, model)`.
    """
    ids, scenes = _as_scenes(trials_or_scenes)
    table = simulate_grid(scenes, list(sigmas), n_sims, seed, model, executor, jobs=jobs, progress=progress, ids=ids)
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
