"""Physical risk of a Finish state B (paper, "Modeling physical risk"): the fraction
of N noisy copies of B that fall when simulated for 4 s.

Run r of a scene perturbs B with the standard normals z[r] (drawn once from the
seed, shape (n_blocks, 3)) scaled by sigma, so every sigma value sees the same
random numbers (common random numbers) and a risk curve over sigma is smooth. A
scene's numbers depend only on (scene, sigma, n_sims, seed, engine), never on the other
scenes of a table, on the order of runs, or on the number of worker processes.
"""
from __future__ import annotations

from dataclasses import dataclass
from typing import Callable, Iterable, Sequence

import numpy as np
import pandas as pd

from lgp.executor import borrowed, default_jobs
from lgp.geometry import digest
from lgp.paper import N_SIMS, SIGMA_GRID
from lgp.scene import Scene
from models.risk.engine import ENGINES, FALL_THRESHOLD, Rollout, _smallest_width, get_engine
from models.risk.noise import draw_normals, perturb_from_normals

#: The engine used when none is named: the one that passes the faithfulness suite
#: with the better throughput (docs/risk.md).
DEFAULT_ENGINE = "mujoco"

RUN_COLUMNS = ["trial", "sigma", "run", "fell", "max_displacement", "max_displacement_3d", "sim_time", "engine"]
RISK_COLUMNS = ["trial", "sigma", "risk", "falls", "n", "engine"]


class UnstableSceneError(ValueError):
    """A scene falls in its own right, before any noise (a sigma = 0 run falls)."""


# ----------------------------------------------------------------------------- single runs


def _engine_name(engine: str | None) -> str:
    name = DEFAULT_ENGINE if engine is None else engine
    if name not in ENGINES:
        raise ValueError(f"unknown physics engine {engine!r}; known engines: {', '.join(sorted(ENGINES))}")
    return name


def fall_threshold(scene: Scene) -> float:
    """Distance (m) a block centre must move horizontally for a run to count as a fall."""
    return FALL_THRESHOLD * _smallest_width(scene)


def _row(rollout: Rollout, threshold: float) -> dict:
    h = rollout.horizontal_displacement()
    return {
        "fell": bool(h.max() > threshold) if len(h) else False,
        "max_displacement": float(h.max()) if len(h) else 0.0,
        "max_displacement_3d": float(rollout.displacement_3d().max()) if len(h) else 0.0,
        "sim_time": float(rollout.sim_time),
    }


_STABLE: dict[tuple[str, str], Rollout] = {}


def _scene_key(scene: Scene) -> str:
    """What an unperturbed simulation depends on: the label and every block and box pose and size."""
    return digest(scene.label, *(part for b in scene.blocks for part in (b.name, b.p_WB, b.size, np.float64(b.yaw))),
                  *(part for f in scene.fixed for part in (f.p_WO, f.size)))


def check_stable(scene: Scene, engine: str | None = None) -> Rollout:
    """Simulate the unperturbed scene once (cached per scene and engine) and raise
    UnstableSceneError, naming the scene and the blocks that moved, if it falls."""
    name = _engine_name(engine)
    key = (_scene_key(scene), name)
    if key not in _STABLE:
        scene.validate()
        _STABLE[key] = get_engine(name).simulate(scene)
    rollout = _STABLE[key]
    threshold = fall_threshold(scene)
    moved = rollout.horizontal_displacement()
    if len(moved) and moved.max() > threshold:
        names = [f"{scene.blocks[i].name} moved {moved[i] * 1000:.1f} mm" for i in np.argsort(-moved) if moved[i] > threshold]
        raise UnstableSceneError(
            f"{scene.label}: unstable before any noise (sigma = 0): block {', block '.join(names)} in {rollout.sim_time:.2f} s "
            f"of {name} simulation (a fall is a move of more than {threshold * 1000:.1f} mm)"
        )
    return rollout


def _simulate_runs(scene: Scene, sigma: float, z: np.ndarray, runs: Sequence[int], engine: str) -> list[dict]:
    """Perturb and simulate runs `runs` of the scene (z: their normals, len(runs) x n x 3)."""
    eng = get_engine(engine)
    threshold = fall_threshold(scene)
    rows = []
    for r, z_r in zip(runs, z):
        rollout = eng.simulate(perturb_from_normals(scene, sigma, z_r))
        rows.append({"sigma": sigma, "run": int(r), **_row(rollout, threshold), "engine": engine})
    return rows


# ----------------------------------------------------------------------------- grids


@dataclass(frozen=True)
class _Task:
    scene_index: int
    sigma: float
    start: int
    stop: int


def _task_worker(args):
    scene, sigma, z, start, engine = args
    return _simulate_runs(scene, sigma, z, range(start, start + len(z)), engine)


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
) -> pd.DataFrame:
    """Every (scene, sigma, run): a tidy table with columns RUN_COLUMNS, in the
    order of `scenes`, then `sigmas`, then runs.

    Each scene is checked for stability first (UnstableSceneError). The grid is
    spread over `jobs` processes (None: all cores; 1: in this process), with
    numbers identical to a serial run. `progress(done, total)` is called as runs
    finish.
    """
    name = _engine_name(engine)
    sigmas = [float(s) for s in sigmas]
    if n_sims < 1:
        raise ValueError(f"need n_sims >= 1 runs (risk is falls / n_sims), got {n_sims}")
    for s in sigmas:
        if not s >= 0:
            raise ValueError(f"sigma must be >= 0 (a fraction of the block size), got {s}")
    ids = list(trial_ids) if trial_ids is not None else [s.label for s in scenes]
    for scene in scenes:
        check_stable(scene, name)
    normals = [draw_normals(n_sims, len(scene), seed) for scene in scenes]
    jobs = (executor.jobs if executor is not None else default_jobs()) if jobs is None else max(1, int(jobs))
    total = len(scenes) * len(sigmas) * n_sims
    # chunks small enough to balance the load, large enough to amortise the model build
    chunk = max(1, min(n_sims, -(-total // (8 * jobs)))) if total else 1
    tasks = [
        _Task(i, s, a, min(a + chunk, n_sims)) for i in range(len(scenes)) for s in sigmas for a in range(0, n_sims, chunk)
    ]
    args = [(scenes[t.scene_index], t.sigma, normals[t.scene_index][t.start : t.stop], t.start, name) for t in tasks]
    done = 0

    def arrived(k, res):
        nonlocal done
        done += len(res)
        if progress:
            progress(done, total)

    with borrowed(executor, 1 if len(tasks) <= 1 else min(jobs, len(tasks))) as ex:
        results = ex.map(_task_worker, args, arrived)
    rows = []
    for t, res in zip(tasks, results):
        for row in res:
            rows.append({"trial": ids[t.scene_index], **row})
    return pd.DataFrame(rows, columns=RUN_COLUMNS)  # tasks are in (scene, sigma, run) order


def summarise(runs: pd.DataFrame) -> pd.DataFrame:
    """Per (trial, sigma): risk = fraction of runs that fell, with falls, n and engine."""
    g = runs.groupby(["trial", "sigma", "engine"], sort=False)["fell"]
    out = g.agg(falls="sum", n="size").reset_index()
    out["falls"] = out["falls"].astype(int)
    out["risk"] = out["falls"] / out["n"]
    return out[RISK_COLUMNS]


# ----------------------------------------------------------------------------- public API


def physical_risk(
    scene: Scene,
    sigma: float,
    n_sims: int = N_SIMS,
    seed: int = 0,
    engine: str | None = None,
    return_table: bool = False,
    jobs: int | None = 1,
):
    """Physical risk of `scene` (a Finish state B): the fraction of `n_sims` perturbed
    copies (noise SD `sigma` * d per axis) that fall within 4 s of simulation.

    With `return_table`, also the per-run table (columns run, sigma, fell,
    max_displacement, max_displacement_3d [m], sim_time [s], engine).
    Raises UnstableSceneError when the unperturbed scene falls, ValueError for an
    unknown engine.
    """
    runs = run_grid([scene], [sigma], n_sims, seed, engine, jobs)
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
) -> pd.DataFrame:
    """Risk of one scene at each sigma (same random numbers for every sigma):
    columns sigma, risk, falls, n, engine (and the per-run table with `return_table`)."""
    runs = run_grid([scene], sigmas, n_sims, seed, engine, jobs)
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
) -> pd.DataFrame:
    """Risk of many scenes over a grid of sigma values, as a tidy table.

    `trials_or_scenes`: trials (objects with `.id` and `.target`, e.g.
    `stimuli.load_all()`), Scenes (named by their label) or a {trial id: Scene}
    mapping. Returns columns trial, sigma, risk, falls, n, engine, one row per
    (trial, sigma) in input order; with `runs=True` the per-run table instead
    (trial, sigma, run, fell, max_displacement, max_displacement_3d, sim_time,
    engine). Each trial's numbers equal `physical_risk(scene, sigma, n_sims, seed)`.
    """
    ids, scenes = _as_scenes(trials_or_scenes)
    sigmas = list(sigmas)
    table = run_grid(scenes, sigmas, n_sims, seed, engine, jobs, progress, trial_ids=ids, executor=executor)
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
        raise ValueError(f"trial ids must be unique, got {ids}")
    return ids, scenes


def _in_order(table: pd.DataFrame, ids: list[str], then: list[str]) -> pd.DataFrame:
    rank = {t: k for k, t in enumerate(ids)}
    return (
        table.assign(_rank=table["trial"].map(rank))
        .sort_values(["_rank", *then], kind="stable")
        .drop(columns="_rank")
        .reset_index(drop=True)
    )
