"""Every candidate passes the project's trial checks or is discarded with its
reason counted.

The checks, cheapest first (a candidate stops at the first it fails):

| stage | check | reason counted |
|---|---|---|
| screen | B within the block budget | ``over block budget`` |
| screen | the trial file's rules (stimuli/README.md: parse_trial, which also draws one layout of A) | ``trial rules: <rule>`` |
| screen | B stands statically without noise (the screen's own criterion) | ``falls at sigma 0 (static)`` |
| screen | B's geometry and start differ from an earlier candidate's | ``duplicate`` |
| finalist | B stands in the physics engine without noise (models.risk.check_stable) | ``falls at sigma 0 (engine)`` |
| finalist | layout 0 of A plans (the paper planner, models.effort) | ``no plan`` |

The engine and planner checks cost 0.05-10 s each (measured in bench/design.py),
so they run on the finalists only; no trial reaches the designed set without
passing all of them.
"""
from __future__ import annotations

import hashlib
import re

import numpy as np

from lgp.paper import BLOCK_SIZE as d
from lgp.scene import TABLE, StimulusError, support_graph
from stimuli.design.grammar import Candidate
from stimuli.design.screen import PRIOR_GRID, RISE, SCREEN_RUNS, StackModel, effort_proxy, screen_normals
from stimuli.trial import parse_trial


class Discarded(Exception):
    """A candidate that failed a check: `reason` is the counted category."""

    def __init__(self, reason: str, detail: str = ""):
        super().__init__(f"{reason}: {detail}" if detail else reason)
        self.reason, self.detail = reason, detail


def _rule_of(message: str) -> str:
    """A short category of a StimulusError message (the rule broken), for counting."""
    for words, rule in (("overlap", "solids overlap"), ("rests on", "a block does not rest on anything"),
                        ("rest on", "a block does not rest on anything"), ("room", "scatter region too small"),
                        ("cover", "scatter region too small"), ("workspace", "outside the workspace"),
                        ("could not place", "scatter region too small"), ("place", "scatter region too small")):
        if words in message:
            return rule
    return re.sub(r"^[^:]*: ", "", message)[:60]


def geometry_key(trial) -> str:
    """B's geometry (poses to 0.1 mm), the start's kind and A's fixed blocks: equal keys are duplicates."""
    h = hashlib.sha256()
    for scene in (trial.target, ):
        for b in sorted(scene.blocks, key=lambda b: tuple(np.round(b.p_WB, 4))):
            h.update(np.round(b.p_WB, 4).tobytes())
    for b in sorted(trial.initial.blocks, key=lambda b: tuple(np.round(b.p_WB, 4))):
        h.update(np.round(b.p_WB, 4).tobytes())
    s = trial.initial.scattered
    h.update(repr((len(s), trial.initial.region)).encode())
    return "g" + h.hexdigest()[:16]  # a letter first: never read back as a number


def features(trial, sigmas=PRIOR_GRID, runs: int = SCREEN_RUNS, seed: int = 0) -> dict:
    """The screen's numbers of a valid trial: B's size and shape, the effort proxy
    on layout 0 of A (default_rng([seed, 0]), as the effort model's sample 0), and
    the static risk curve over `sigmas` (normals from default_rng([seed, 1]))."""
    B = trial.target
    graph = support_graph(B)
    top = max(b.p_WB[2] + b.size[2] / 2 for b in B.blocks)
    xy = B.positions[:, :2]
    extent = xy.max(axis=0) - xy.min(axis=0) + d
    A = trial.sample_initial(np.random.default_rng([seed, 0]))
    dist, squared, moved = effort_proxy(A, B)
    model = StackModel(B)
    curve = model.risk_curve(sigmas, screen_normals(len(model), runs, np.random.default_rng([seed, 1])))
    row = {"trial": trial.id, "blocks": len(B.blocks), "moved": moved, "height": round(top / d, 3),
           "stacked": sum(1 for b in B.blocks if TABLE not in graph[b.name]),
           "footprint": round(float(extent[0] * extent[1]) / d ** 2, 3), "distance": dist, "effort_proxy": dist, "path_squared": squared,
           "static_stands": model.stands()}
    row.update({f"screen_risk_{s:g}": float(r) for s, r in zip(sigmas, curve)})
    row["screen_risk_prior"] = float(np.mean(curve))
    row["screen_risk_rises"] = bool(curve[-1] - curve[0] >= RISE)
    return row


def screen_candidate(c: Candidate, budget: int, sigmas=PRIOR_GRID, runs: int = SCREEN_RUNS, seed: int = 0) -> dict:
    """The screen's row of candidate `c`, or Discarded with its reason."""
    n = len(c.data["target"]["blocks"])
    if n > budget:
        raise Discarded("over block budget", f"{n} blocks > {budget}")
    try:
        trial = parse_trial(c.data)
    except StimulusError as e:
        raise Discarded(f"trial rules: {_rule_of(str(e))}", str(e)) from None
    if not StackModel(trial.target).stands():
        raise Discarded("falls at sigma 0 (static)")
    row = features(trial, sigmas, runs, seed)
    return {"candidate": c.index, "kind": c.kind, "start": c.start, "key": geometry_key(trial), **row,
            "params": ";".join(f"{k}={v}" for k, v in c.params.items())}


def engine_check(trial, engine: str | None = None) -> None:
    """Discarded("falls at sigma 0 (engine)") unless B stands in the engine without noise."""
    from models.risk import UnstableSceneError, check_stable

    try:
        check_stable(trial.target, engine)
    except UnstableSceneError as e:
        raise Discarded("falls at sigma 0 (engine)", str(e)) from None


def plan_check(trial, seed: int = 0) -> float:
    """The effort (J s) of layout 0 of A by the paper planner; Discarded("no plan") if it cannot plan."""
    from lgp.planner import PlanningError
    from models.effort import effort_of_sample

    try:
        return float(effort_of_sample(trial, seed, 0)["effort"])
    except (PlanningError, StimulusError, ValueError, RuntimeError) as e:
        raise Discarded("no plan", str(e)[:200]) from None
