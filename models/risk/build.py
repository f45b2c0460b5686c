"""Risk through the build (beyond the paper; its Discussion names it as future work:
the model "assesses stability only once at the end, without evaluating it in the
intermediate stages throughout the execution of a plan").

A plan is the assignment and symbolic plan of one layout of A, drawn exactly as
the effort row (trial, sample) draws it (`models.effort.sample_rng`, then
`trial.sample_initial`, then `assign_blocks` and `symbolic_plan`, as
`lgp.planner.plan` does); no KOMO is needed. Its **stages** are the states after
each Place. Stage k is simulated with the noise rule and engine of
`physical_risk`, and its risk is the fraction of `n_sims` noisy runs that fall.

Which blocks a stage simulates and perturbs (docs/results.md, "Risk through the
build"): the **structure** -- every block at its B pose (placed so far, or left
in place because it already was) -- plus every block not yet moved that is part
of a stack (rests on or carries another block: a disassembly's remaining tower,
a relocated tower's remainder). All of them are perturbed, as the paper perturbs
every block of B: the noise stands for imprecise positions, not for the last
move only. A block lying alone on the table or on the bucket floor is left out:
nothing can topple it (its risk is 0, tests/test_build_risk.py), and the 15
blocks left in pair 12's bucket would only cost time. So the last stage of a
plan that builds B is B itself, simulated run for run with the same normals as
`physical_risk(trial.target)`: its risk is the paper's R exactly.

Common random numbers: block j of B uses, in run r, the normals z_B[r, j] of
``draw_normals(n_sims, len(B), seed)`` -- the ones `physical_risk` uses -- at
every stage and every sigma; a not-yet-moved stack block i of A uses
z_A[r, i] of ``draw_normals(n_sims, len(A), default_rng([seed, 1]))``. Layouts
that give the same stage scene give the same numbers, so each distinct stage
scene is simulated once (towers: the same k blocks whatever the layout).

Aggregates (per plan, then the mean over the plan's `samples` layouts, as effort
is averaged), with r_k the risk of stage k = 1..K:

    final    = r_K                              (the paper's R when stage K is B)
    max      = max_k r_k
    expected = sum_k r_k                        (expected number of collapses)
    any      = 1 - prod_k (1 - r_k)             (P(at least one collapse) IF the stages were independent)
    care     = sum_k w_k r_k                    (expected fraction of the plan's work undone)
    sequential = P(the sequential build collapses at some stage)  (mode="sequential", below)

`any` treats the stages as independent, which they are not: they share their
random numbers (block j has the same normals at every stage), so a run whose
base is off falls at several stages together and the true P(at least one
collapse) of the shared runs lies between `max` and `any`. It is kept as the
formula it is; `sequential` is a probability computed from the runs.

**Sequential build** (``mode="sequential"``; the Discussion's builder who must
keep an almost finished tower from crashing): B is built in the plan's order and
each stage starts from the state the previous one left. Run r starts from A as
it lies (no noise: nobody placed it); each Place puts its block at its B target
moved by fresh placement noise -- block j of B with the normals z_B[r, j], the
same as the paper's R, so at sigma 0 the build is exact and common random
numbers hold across sigma -- with the noise rule applied to that block alone
(it is pushed clear of its neighbours and set onto, or under "lift" never into,
the settled blocks beneath its new outline; the settled blocks do not move).
The stage is simulated until rest, and its final centres are carried to the
next stage (orientations are not carried: a block that stands keeps its yaw to
a fraction of a degree). A run collapses at the first stage in which a block
moves more than the fall threshold from where that stage started; later
stages are not simulated. The stage table then counts, per stage, the runs that
reached it standing (`reached`) and those that collapsed there (`falls`;
``risk = falls / n_sims``, so the stage risks add up to `sequential`).

w_k is the share of the plan's effort already spent on blocks in the structure
at stage k, so E * care is the effort (J s) a collapse is expected to undo. The
per-block effort share is a documented proxy, not KOMO: a block carried a
distance L = |p_B - p_A| + 2 APPROACH in one phase of fixed duration costs
energy proportional to L^2 (the least kinetic-energy integral of a rest-to-rest
move over a fixed time is proportional to the squared distance), so
w_k = sum over placed blocks of L^2 / sum over all moved blocks of L^2. It is
checked against KOMO's per-block kinetic energies in tests/test_build_risk.py
(a slow test) and docs/results.md.
"""
from __future__ import annotations

import hashlib
from dataclasses import dataclass
from typing import Callable, Iterable, Sequence

import numpy as np
import pandas as pd

from lgp.errors import InputError
from lgp.paper import N_SIMS, SAMPLES
from lgp.scene import Scene, support_graph, supported_by
from models.risk.core import UnstableSceneError, check_stable, chunk_size, map_tasks, resolve_jobs, simulate_grid
from models.risk.engine import get_engine
from models.risk.model import RiskModel, check_n_sims, check_sigma
from models.risk.noise import NoiseRule, draw_normals

#: The stage table, one row per (trial, sample, sigma, stage).
STAGE_COLUMNS = ["trial", "sample", "sigma", "stage", "action_index", "blocks_in_structure",
                 "blocks_simulated", "risk", "falls", "n_sims", "work_share", "engine", "mode", "reached",
                 "noise_rule"]
#: The ways a build's stages are simulated (module docstring): each stage on its
#: own from B's poses ("stages"), or one build carried through ("sequential").
MODES: tuple[str, ...] = ("stages", "sequential")
#: The aggregates of a plan's stage risks (module docstring), in table order;
#: `sequential` comes from a mode="sequential" table.
MEASURES: tuple[str, ...] = ("final", "max", "expected", "any", "care", "sequential")
AGGREGATE_COLUMNS = ["trial", "sigma", *MEASURES, "last_stage", "stages", "samples", "engine"]


class BuildStageError(ValueError):
    """A stage of a plan cannot be simulated (e.g. it falls with no noise); names
    the trial, the sample, the stage and the rule broken."""


@dataclass(frozen=True)
class Stage:
    """The state after the k-th Place of one plan, as simulated.

    `structure` are the B names of blocks at their B pose, in B's order; `stack`
    the A names of not-yet-moved blocks in a stack; `scene` the simulated scene
    (structure blocks first, B's poses and names, then the stack blocks; the
    world's fixed boxes); `key` identifies the scene and its normals.
    """

    trial: str
    sample: int
    stage: int
    action_index: int
    structure: tuple[str, ...]
    stack: tuple[str, ...]
    scene: Scene
    work_share: float
    key: str
    #: the B name of the block this Place put at its B pose
    placed: str = ""


def plan_stages(trial, seed: int = 0, sample: int = 0, approach_height: float | None = None):
    """The stages of the plan of effort row (trial, sample): list of Stage.

    Draws the layout exactly as `models.effort.plan_of_sample` does; only the
    assignment and the symbolic plan are computed (no KOMO). `approach_height`
    (m; None: lgp.planner.APPROACH) is the effort run's, for the work shares.
    """
    from lgp.symbolic import Place
    from models.effort import skeleton_of_sample

    plan = skeleton_of_sample(trial, seed, sample)
    initial, target = plan.initial, plan.target
    if not plan.actions:
        raise BuildStageError(f"trial {trial.id} sample {sample}: the plan has no action, so no stage")
    owner = {b: a for a, b in plan.assignment.items()}  # B name -> A name
    moved = set(plan.moved)
    stays = {a for a in plan.assignment if a not in moved}
    a_index = {name: i for i, name in enumerate(initial.names)}
    weights = _carry_weights(initial, target, plan, approach_height)
    total = sum(weights.values())
    placed: dict[str, None] = {}  # in placement order: the shares add up in that order, whatever the hash seed
    grasped: set[str] = set()
    stages = []
    for k, (action, state) in enumerate(zip(plan.actions, plan.states()), start=1):
        grasped.add(action.block)
        if not isinstance(action, Place):
            continue
        placed[action.block] = None
        scene = state.scene
        structure = tuple(b for b in target.names if owner.get(b) in placed.keys() | stays)
        graph = support_graph(scene)
        above = supported_by(graph)
        blocks = set(scene.names)
        stack = tuple(a for a in scene.names if a not in grasped and a not in stays
                      and (any(s in blocks for s in graph[a]) or any(s in blocks for s in above[a])))
        sim = Scene([target.block(b) for b in structure] + [scene.block(a) for a in stack], scene.fixed,
                    f"{trial.id} sample {sample} stage {len(stages) + 1}")
        key = _stage_key(sim, [("B", target.names.index(b)) for b in structure] + [("A", a_index[a]) for a in stack])
        share = sum(weights[a] for a in placed) / total if total > 0 else 0.0
        stages.append(Stage(trial.id, sample, len(stages) + 1, k, structure, stack, sim, share, key,
                            plan.assignment[action.block]))
    return stages


def _carry_weights(initial: Scene, target: Scene, plan, approach_height: float | None = None) -> dict[str, float]:
    """Effort proxy per moved block: L^2, L = |p_B - p_A| + 2 APPROACH (module docstring)."""
    from lgp.planner import APPROACH

    h = APPROACH if approach_height is None else float(approach_height)
    out = {}
    for a in plan.moved:
        d = np.linalg.norm(target.block(plan.assignment[a]).p_WB - initial.block(a).p_WB)
        out[a] = float((d + 2 * h) ** 2)
    return out


def _stage_key(scene: Scene, sources) -> str:
    h = hashlib.sha1(repr(sources).encode())
    for b in scene.blocks:
        h.update(np.round(b.p_WB, 9).tobytes() + np.round(b.size, 9).tobytes() + np.float64(round(b.yaw, 9)).tobytes())
    for f in scene.fixed:
        h.update(f.p_WO.tobytes() + f.size.tobytes())
    return h.hexdigest()


def build_risk(trial, sigma, n_sims: int = N_SIMS, samples: int = SAMPLES, seed: int = 0,
               model: RiskModel | str | None = None, jobs: int | None = 1, executor=None,
               progress: Callable[[int, int], None] | None = None, *, approach_height: float | None = None,
               mode: str = "stages") -> pd.DataFrame:
    """Risk of every stage of the plans of `samples` layouts of `trial`.

    `mode`: "stages" (default: each stage simulated on its own from B's poses)
    or "sequential" (one noisy build carried through the stages, module
    docstring). `model`: the RiskModel of `physical_risk` (engine, rules).

    `trial` is a stimuli.Trial or its id; `sigma` one noise level or several
    (fractions of d; common random numbers across them and across stages).
    Returns the tidy stage table (columns STAGE_COLUMNS): one row per (sample,
    sigma, stage), `stage` 1..K, `action_index` the 1-based index of the Place in
    the plan, `blocks_in_structure` the blocks at their B pose, `blocks_simulated`
    those plus the stack blocks not yet moved, `work_share` the effort-proxy
    share w_k. `approach_height` is that of the effort run (work shares only).
    Raises BuildStageError naming trial, sample and stage when a stage
    falls without noise.
    """
    if isinstance(trial, str):
        import stimuli

        trial = stimuli.load_trial(trial)
    try:
        sigmas = [check_sigma(s) for s in np.atleast_1d(sigma)]
        n_sims = check_n_sims(n_sims)
    except InputError as e:
        raise InputError(f"trial {trial.id}: {e}") from None
    if samples < 1:
        raise InputError(f"trial {trial.id}: need samples >= 1 layouts, got {samples}")
    if mode not in MODES:
        raise InputError(f"trial {trial.id}: unknown build-risk mode {mode!r}; known modes: {', '.join(MODES)}")
    model = RiskModel.of(model)
    drawn = range(samples) if trial.initial.is_random else [0]
    plans = {s: plan_stages(trial, seed, s, approach_height) for s in drawn}
    unique: dict[str, Stage] = {}
    for stages in plans.values():
        for st in stages:
            unique.setdefault(st.key, st)
    target = trial.target
    z_B = draw_normals(n_sims, len(target), seed)
    z_A = draw_normals(n_sims, max(len(trial.initial.blocks), 1), np.random.default_rng([seed, 1]))
    a_index = _stack_index(trial, plans)
    keys = list(unique)
    for key in keys:
        st = unique[key]
        try:
            check_stable(st.scene, model)
        except UnstableSceneError as e:
            raise BuildStageError(f"trial {trial.id} sample {st.sample} stage {st.stage} "
                                  f"(after action {st.action_index}): {e}") from None
    if mode == "sequential":
        return _sequential(trial, plans, sigmas, z_B, a_index, n_sims, samples, model, executor, jobs, progress)
    normals = []
    for key in keys:
        st = unique[key]
        z = z_B[:, [target.names.index(b) for b in st.structure]]
        if st.stack:
            z = np.concatenate([z, z_A[:, [a_index[a] for a in st.stack]]], axis=1)
        normals.append(z)
    runs = simulate_grid([unique[key].scene for key in keys], sigmas, n_sims, seed, model, executor, jobs=jobs,
                         progress=progress, ids=keys, normals=normals)
    falls = runs.groupby(["trial", "sigma"], sort=False)["fell"].sum()
    rows = []
    for sample in range(samples):
        stages = plans[sample if trial.initial.is_random else 0]
        for s in sigmas:
            for st in stages:
                f = int(falls[st.key, s])
                rows.append((trial.id, sample, s, st.stage, st.action_index, len(st.structure),
                             len(st.structure) + len(st.stack), f / n_sims, f, n_sims, st.work_share, model.engine,
                             "stages", n_sims, model.noise_rule.value))
    return pd.DataFrame(rows, columns=STAGE_COLUMNS)


def _stack_index(trial, plans: dict) -> dict[str, int]:
    """Each stack block's index among A's fixed blocks: the row of its normals in
    z_A. Stack blocks are blocks A fixes (scattered blocks lie alone), so the
    index is the same in every layout."""
    fixed_A = [b.name for b in trial.initial.blocks]
    index = {}
    for stages in plans.values():
        for st in stages:
            for a in st.stack:
                if a not in fixed_A:
                    raise BuildStageError(f"trial {trial.id} sample {st.sample} stage {st.stage}: block {a} "
                                          "is in a stack but is not one of A's fixed blocks")
                index[a] = fixed_A.index(a)
    return index


def _sources(st: Stage, target: Scene, a_index: dict[str, int]) -> list[tuple[str, int]]:
    """Where each block of a stage scene comes from: ("B", index in B) for the
    structure, ("A", index among A's fixed blocks) for the stack."""
    return [("B", target.names.index(b)) for b in st.structure] + [("A", a_index[a]) for a in st.stack]


@dataclass(frozen=True)
class BuildTask:
    """A chunk of runs of one sequential build: the plan as (stage scene, block
    sources, index of the block the Place put or None) per stage, the noise
    level, the normals of B's blocks (runs, blocks of B, 3) and the model."""

    plan: tuple
    sigma: float
    z_B: np.ndarray
    model: RiskModel


def _sequential(trial, plans, sigmas, z_B, a_index, n_sims, samples, model: RiskModel, executor, jobs,
                progress) -> pd.DataFrame:
    """mode="sequential" of `build_risk` (module docstring): one task per distinct
    plan (its sequence of stage scenes), sigma and chunk of runs."""
    target = trial.target
    sequences: dict[tuple, list[Stage]] = {}
    of_sample = {}
    for sample, stages in plans.items():
        key = tuple(st.key for st in stages)
        sequences.setdefault(key, stages)
        of_sample[sample] = key
    keys = list(sequences)
    jobs = resolve_jobs(executor, jobs)
    total = len(keys) * len(sigmas) * n_sims
    chunk = chunk_size(total, n_sims, jobs)
    tasks, args = [], []
    for key in keys:
        plan = []
        for st in sequences[key]:
            sources = _sources(st, target, a_index)
            placed = ("B", target.names.index(st.placed))
            plan.append((st.scene, sources, sources.index(placed) if placed in sources else None))
        for s in sigmas:
            for a in range(0, n_sims, chunk):
                tasks.append((key, s))
                args.append(BuildTask(tuple(plan), s, z_B[a:a + chunk], model))
    results = map_tasks(collapse_stages, args, total, executor, jobs, progress, size=lambda res: res.shape[0])
    collapsed: dict[tuple, list[np.ndarray]] = {}
    for task, res in zip(tasks, results):
        collapsed.setdefault(task, []).append(res)
    rows = []
    for sample in range(samples):
        key = of_sample[sample if trial.initial.is_random else 0]
        stages = sequences[key]
        for s in sigmas:
            at = np.concatenate(collapsed[key, s])  # stage (1-based) at which each run collapsed, 0: stood
            reached = n_sims
            for st in stages:
                f = int((at == st.stage).sum())
                rows.append((trial.id, sample, s, st.stage, st.action_index, len(st.structure),
                             len(st.structure) + len(st.stack), f / n_sims, f, n_sims, st.work_share, model.engine,
                             "sequential", reached, model.noise_rule.value))
                reached -= f
    return pd.DataFrame(rows, columns=STAGE_COLUMNS)


def collapse_stages(task: BuildTask) -> np.ndarray:
    """Runs of one sequential build: for each run (rows of z_B), the stage at which
    it collapsed (1-based), 0 when it stood to the end."""
    model, z_B = task.model, task.z_B
    eng = get_engine(model.engine)
    runs = len(z_B)
    at = np.zeros(runs, dtype=int)
    settled: dict[tuple[str, int], np.ndarray] = {}  # source -> (runs, 3) centres after the last stage
    for k, (scene, sources, placed) in enumerate(task.plan, start=1):
        n = len(scene)
        start = np.broadcast_to(scene.positions, (runs, n, 3)).copy()
        for q, src in enumerate(sources):
            if src in settled:
                start[:, q] = settled[src]
        z = np.zeros((runs, n, 3))
        movable = np.zeros(n, bool)
        if placed is not None:  # the block this Place put: fresh placement noise
            movable[placed] = True
            z[:, placed] = z_B[:, sources[placed][1]]
        p_WB = NoiseRule(scene, model.noise_rule, movable).positions(task.sigma, z, start) if movable.any() else start
        threshold = model.fall_distance(scene)
        for r in np.flatnonzero(at == 0):
            rollout = eng.simulate(scene, stop_distance=model.stop_distance, p_WB=p_WB[r])
            moved = model.displacement(rollout)
            if len(moved) and moved.max() > threshold:
                at[r] = k
            else:
                for q, src in enumerate(sources):
                    settled.setdefault(src, np.zeros((runs, 3)))[r] = rollout.p_WB_final[q]
    return at


def aggregate_plan(risks: Sequence[float], shares: Sequence[float]) -> dict[str, float]:
    """The five aggregates of one plan's stage risks r_1..r_K (module docstring)."""
    r = np.asarray(risks, dtype=float)
    w = np.asarray(shares, dtype=float)
    if r.size == 0:
        raise InputError("a plan with no stage has no build risk")
    if r.shape != w.shape:
        raise InputError(f"{r.size} stage risks but {w.size} work shares")
    if np.any((r < 0) | (r > 1)) or not np.all(np.isfinite(r)):
        raise InputError(f"stage risks must be probabilities in [0, 1], got {r.tolist()}")
    return {"final": float(r[-1]), "max": float(r.max()), "expected": float(r.sum()),
            "any": float(1 - np.prod(1 - r)), "care": float(np.dot(w, r))}


def build_risk_aggregates(stages: pd.DataFrame) -> pd.DataFrame:
    """Per (trial, sigma): each aggregate of `aggregate_plan` averaged over the
    plan's samples (layouts), with the number of stages (mean over samples) and
    samples. Columns AGGREGATE_COLUMNS. A table with mode="sequential" rows (one
    or both modes, concatenated) gives `sequential`, P(the sequential build
    collapses), and `last_stage`, P(its last stage collapses | it got there),
    the sequential counterpart of `final`; measures of a mode not in the table
    are NaN."""
    if "mode" not in stages:
        stages = stages.assign(mode="stages")
    rows = []
    for (trial, sigma, engine), g in stages.groupby(["trial", "sigma", "engine"], sort=False):
        out = {m: np.nan for m in MEASURES}
        out["last_stage"] = np.nan
        independent, sequential = g[g["mode"] == "stages"], g[g["mode"] == "sequential"]
        counted = independent if len(independent) else sequential
        if len(independent):
            per = [aggregate_plan(p.sort_values("stage")["risk"], p.sort_values("stage")["work_share"])
                   for _, p in independent.groupby("sample", sort=True)]
            out.update({m: float(np.mean([a[m] for a in per])) for m in MEASURES if m != "sequential"})
        if len(sequential):
            plans = [p.sort_values("stage") for _, p in sequential.groupby("sample", sort=True)]
            out["sequential"] = float(np.mean([p["falls"].sum() / p["n_sims"].iloc[0] for p in plans]))
            out["last_stage"] = float(np.mean([p["falls"].iloc[-1] / p["reached"].iloc[-1] if p["reached"].iloc[-1] else np.nan
                                               for p in plans]))
        rows.append({"trial": trial, "sigma": sigma, **out,
                     "stages": float(counted.groupby("sample").size().mean()),
                     "samples": counted["sample"].nunique(), "engine": engine})
    return pd.DataFrame(rows, columns=AGGREGATE_COLUMNS)


def measure_table(aggregates: pd.DataFrame) -> pd.DataFrame:
    """The aggregates in long form (trial, sigma, measure, risk), the input of
    ``analysis`` with ``risk_measure``."""
    return aggregates.melt(id_vars=["trial", "sigma"], value_vars=list(MEASURES), var_name="measure",
                           value_name="risk")[["trial", "sigma", "measure", "risk"]]


def stage_curve(stages: pd.DataFrame, sigma: float | None = None) -> pd.DataFrame:
    """Mean risk per stage over samples (and its spread), for printing and figures:
    columns trial, sigma, stage, blocks_in_structure (mean), risk (mean), risk_min,
    risk_max, samples."""
    g = stages if sigma is None else stages[np.isclose(stages["sigma"], sigma)]
    if "mode" in g:
        g = g[g["mode"] == "stages"] if (g["mode"] == "stages").any() else g
    out = (g.groupby(["trial", "sigma", "stage"], sort=False)
           .agg(blocks_in_structure=("blocks_in_structure", "mean"), risk=("risk", "mean"),
                risk_min=("risk", "min"), risk_max=("risk", "max"), samples=("sample", "nunique"))
           .reset_index())
    return out


def build_risk_table(trials: Iterable, sigmas, n_sims: int = N_SIMS, samples: int = SAMPLES, seed: int = 0,
                     model: RiskModel | str | None = None, jobs: int | None = 1, executor=None) -> pd.DataFrame:
    """`build_risk` of several trials, concatenated in input order."""
    return pd.concat([build_risk(t, sigmas, n_sims, samples, seed, model, jobs, executor) for t in trials],
                     ignore_index=True)


__all__ = ["MEASURES", "MODES", "STAGE_COLUMNS", "AGGREGATE_COLUMNS", "BuildStageError", "Stage", "plan_stages",
           "build_risk", "build_risk_table", "aggregate_plan", "build_risk_aggregates", "measure_table",
           "stage_curve"]
