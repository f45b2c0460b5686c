"""Heuristic predictors of difficulty a reviewer would propose instead of physics:
simple counts and sizes read from a trial's files and its symbolic plan, no
physics engine and no motion planner.

Per trial (FEATURES, each one sentence in FEATURE_MEANING):

* ``height``: B's height in block levels, the top of B's highest block over the
  block edge d (lgp.paper.BLOCK_SIZE), rounded to 0.001;
* ``blocks``: the number of blocks in B;
* ``stacked``: the number of B's blocks that rest on another block (not only on
  the table or a fixed box), from B's support graph;
* ``distance``: the total transport distance of the assignment (m): the sum of
  Euclidean distances between assigned block centres of A and B (the paper's
  Hungarian assignment, lgp.assignment; the one the symbolic plan executes),
  averaged over the same random layouts of A the effort stage plans
  (models.effort.sample_rng(seed, sample));
* ``actions``: the number of grasp and place actions of the symbolic plan,
  averaged over the same layouts (the effort table's n_actions, without KOMO);
* ``depth``: support-graph depth of B: the longest chain of blocks each resting
  on the one below (a block on the table or a fixed box has depth 1).

`trial_features(trials, samples, seed)` returns a tidy table, one row per trial.
Values, not physics: the whole table for the paper's 24 trials at M = 30 takes
about a second.
"""
from __future__ import annotations

import functools
from typing import Sequence

import numpy as np
import pandas as pd

from analysis.spec import FEATURE_MEANING, FEATURES  # noqa: E402,F401  (one home: analysis.spec)


def target_features(target, block_edge: float | None = None) -> dict[str, float]:
    """height, blocks, stacked, depth of one target Scene (see the module docstring)."""
    from lgp.paper import BLOCK_SIZE
    from lgp.scene.support import support_graph

    d = BLOCK_SIZE if block_edge is None else block_edge
    blocks = list(target.blocks)
    graph = support_graph(target)
    names = {b.name for b in blocks}
    depth: dict[str, int] = {}

    def depth_of(name: str, seen: frozenset = frozenset()) -> int:
        if name not in depth:
            below = [s for s in graph.get(name, []) if s in names and s not in seen]
            depth[name] = 1 + max((depth_of(s, seen | {name}) for s in below), default=0)
        return depth[name]

    top = max((b.top for b in blocks), default=0.0)
    return {"height": round(float(top) / d, 3), "blocks": float(len(blocks)),
            "stacked": float(sum(any(s in names for s in graph[b.name]) for b in blocks)),
            "depth": float(max((depth_of(b.name) for b in blocks), default=0))}


def plan_features(trial, samples: int, seed: int) -> dict[str, float]:
    """distance and actions of one trial, averaged over its layouts of A (one
    layout when A is not random), each layout drawn as the effort stage draws it."""
    from lgp.assignment import assignment_distance
    from models.effort import skeleton_of_sample

    dist, actions = [], []
    for i in (range(samples) if trial.initial.is_random else [0]):
        plan = skeleton_of_sample(trial, seed, i)
        dist.append(assignment_distance(plan.initial, trial.target, plan.assignment))
        actions.append(len(plan.actions))
    return {"distance": float(np.mean(dist)), "actions": float(np.mean(actions))}


def trial_features(trials: Sequence, samples: int = 30, seed: int = 0) -> pd.DataFrame:
    """One row per trial (stimuli.Trial objects or ids of the paper's trial files):
    trial, then FEATURES. `samples` and `seed` as the effort stage's M and seed."""
    import stimuli

    rows = []
    for t in trials:
        trial = stimuli.load_trial(t) if isinstance(t, str) else t
        rows.append({"trial": trial.id, **target_features(trial.target), **plan_features(trial, samples, seed)})
    return pd.DataFrame(rows, columns=["trial", *FEATURES])


def paper_features(samples: int = 30, seed: int = 0) -> pd.DataFrame:
    """`trial_features` of the paper's 24 trials (stimuli.load_paper())."""
    import stimuli

    return trial_features(stimuli.load_paper(), samples, seed)


def target_key(target, decimals: int = 6) -> tuple:
    """An order-free key of a target scene: its blocks' positions (m, relative to
    the blocks' mean x and y: the same structure built elsewhere on the table is
    the same structure), sizes and yaw (mod a quarter turn, cubes look the same)
    rounded to `decimals`, sorted; with the fixed boxes a block rests on (same
    frame; a bucket off to the side is not part of the structure). Colour is not
    part of it. Two trials with the same key build the same B."""
    from lgp.scene.support import support_graph
    origin = np.zeros(3)
    if len(target.blocks):
        origin[:2] = np.mean([b.p_WB[:2] for b in target.blocks], axis=0)
    blocks = sorted(tuple(np.round(np.concatenate([b.p_WB - origin, b.size, [np.mod(b.yaw, np.pi / 2)]]), decimals))
                    for b in target.blocks)
    under = {s for supporters in support_graph(target).values() for s in supporters}
    fixed = sorted(tuple(np.round(np.concatenate([f.p_WO - origin, f.size]), decimals))
                   for f in target.fixed if f.name in under)
    return tuple(blocks), tuple(fixed)


@functools.lru_cache(maxsize=4)
def paper_identical_targets() -> tuple[tuple[str, ...], ...]:
    """`identical_targets` of the paper's 24 trial files (read once per process)."""
    import stimuli

    return tuple(tuple(g) for g in identical_targets(stimuli.load_paper()))


def identical_targets(trials: Sequence) -> list[list[str]]:
    """Sets (of two or more trial ids) whose B is the same structure (`target_key`),
    in order of first appearance: what folds by structure hold out together."""
    import stimuli

    groups: dict[tuple, list[str]] = {}
    for t in trials:
        trial = stimuli.load_trial(t) if isinstance(t, str) else t
        groups.setdefault(target_key(trial.target), []).append(trial.id)
    return [ids for ids in groups.values() if len(ids) > 1]
