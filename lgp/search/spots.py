"""Candidate set-aside spots: where on the table a block that stands in the way may
be put down, generated on a grid and ranked by the bound (`candidate_spots`).
Why candidates and not a KOMO-optimised free pose: see lgp.search."""
from __future__ import annotations

import numpy as np

from lgp.scene import Scene
from lgp.search.problem import Problem

#: Candidate set-aside spots: a grid of this pitch (m) over the table region below.
SPOT_PITCH = 0.02
#: The table region (m) set-aside spots are drawn from: the reach of the arm
#: (docs/effort.md, "The arm": x 0.15-0.70, y -0.40-0.40).
SPOT_REGION = ((0.15, 0.70), (-0.40, 0.40))
#: A spot keeps this gap (m) to every block, obstacle and slot of B (footprints).
SPOT_CLEARANCE = 0.01
#: Spots branched on per set-aside, best bound first.
SPOTS_PER_SET_ASIDE = 3


def candidate_spots(problem: Problem, scene: Scene, block: int, free_slots: list[int]) -> list[tuple[float, np.ndarray]]:
    """Table spots where block `block` may be set aside, best first by bound:
    (bound of the carry there plus the cheapest carry on to a free slot of its
    colour, p_WB). A spot is on the grid of SPOT_PITCH over SPOT_REGION, its
    footprint (with SPOT_CLEARANCE) clear of every other block, fixed box and
    slot of B; yaw 0."""
    b = problem.blocks[block]
    (x0, x1), (y0, y1) = SPOT_REGION
    xs = np.arange(x0, x1 + 1e-9, SPOT_PITCH)
    ys = np.arange(y0, y1 + 1e-9, SPOT_PITCH)
    X, Y = np.meshgrid(xs, ys, indexing="ij")
    P = np.column_stack([X.ravel(), Y.ravel(), np.full(X.size, b.size[2] / 2)])
    half = np.linalg.norm(b.size[:2]) / 2 + SPOT_CLEARANCE  # a circle around any yaw of the block
    keep = np.ones(len(P), bool)
    solids = [o for o in scene.blocks if o.name != b.name] + list(problem.slots)
    for o in solids:
        r = np.linalg.norm(o.size[:2]) / 2
        keep &= np.linalg.norm(P[:, :2] - o.p_WB[:2], axis=1) > half + r
    for f in scene.fixed:
        lo, hi = f.p_WO[:2] - f.size[:2] / 2 - half, f.p_WO[:2] + f.size[:2] / 2 + half
        keep &= ~np.all((P[:, :2] > lo) & (P[:, :2] < hi), axis=1)
    P = P[keep]
    if not len(P):
        return []
    here = scene.block(b.name).p_WB
    cost = problem.bound(here, P)
    onward = [j for j in free_slots if problem.slot_colour[j] == b.colour]
    if onward:
        cost = cost + np.min(problem.bound(P[:, None], problem.slot_p[onward][None]), axis=1)
    order = np.argsort(cost, kind="stable")
    return [(float(cost[k]), P[k]) for k in order]
