"""IK seeding: which quarter turn, elbow swivel and IK branch at every waypoint.

These are discrete choices KOMO cannot make by gradient; they are chosen first,
globally, by dynamic programming (Viterbi) over closed-form IK solutions of every
waypoint, minimising sum |dq|^2 / dt^3 (the cost of rest-to-rest cubics), and the
solutions seed KOMO. `declare` returns the KOMO problem of a symbolic plan with
those seeds and quarter turns.
"""
from __future__ import annotations

import numpy as np

from lgp.arm import Arm
from lgp.planner import skeleton
from lgp.planner.design import APPROACH, APPROACH_TIME, DEFAULT_DESIGN, Design, PlanningError
from lgp.planner.skeleton import Waypoint
from lgp.symbolic import SymbolicPlan

#: Elbow swivel angles tried per waypoint when seeding (and 8 IK branches each).
SWIVELS = 16
#: Joint-limit margin (rad) asked of seeds, so KOMO starts strictly inside.
SEED_MARGIN = 0.02


def declare(symbolic: SymbolicPlan, arm: Arm, rng: np.random.Generator, design: Design = DEFAULT_DESIGN):
    """The KOMO declaration of a symbolic plan, IK seeds {phase: q}, and the quarter turns.

    The seeding swivel grid is shifted by a random fraction of its step drawn from `rng`.
    """
    waypoints = skeleton.waypoints(symbolic, design.approach_height)
    phases = len(symbolic.actions) + 1
    seeds, turns = seed(arm, waypoints, phases, rng.uniform(0, 2 * np.pi / SWIVELS), symbolic.actions, design.approach_height)
    return skeleton.transcribe(symbolic, arm, waypoints, turns, phases, design), seeds, turns


def seed(arm: Arm, waypoints: list[Waypoint], phases: int, offset: float, actions=(), approach_height: float = APPROACH):
    """Quarter turn per action and an IK solution per waypoint, by dynamic programming.

    Candidates per action: closed-form IK solutions of its three waypoints (approach,
    action, retreat) at the same branch, swivel angle (a grid shifted by `offset`
    rad) and quarter turn, all within the joint limits. Path cost, as for
    rest-to-rest cubics: sum over consecutive waypoints of |q_b - q_a|^2 / dt^3, home
    at both ends; Viterbi over the actions. Returns ({phase: q}, {action: turn}).
    Without legs (one waypoint per action) the three are the same waypoint.
    """
    swivels = np.linspace(-np.pi, np.pi, SWIVELS, endpoint=False) + offset
    triples = skeleton.triples(waypoints)
    # One batched closed form for every distinct waypoint pose (approach and retreat share theirs).
    poses: dict[tuple, int] = {}
    for w in (w for triple in triples for w in triple):
        poses.setdefault((np.asarray(w.p_WG, float).tobytes(), float(w.yaw)), len(poses))
    q_all, ok_all = arm.ik_grids_from_above([(np.frombuffer(p), yaw) for p, yaw in poses], swivels, margin=SEED_MARGIN)
    nodes = []  # per action: (pre, at, post) solutions (m, 7) each, quarter turn (m,), internal cost (m,)
    for pre, at, post in triples:
        grids = [(q_all[i], ok_all[i]) for i in (poses[(np.asarray(w.p_WG, float).tobytes(), float(w.yaw))] for w in (pre, at, post))]
        for w, (_, ok) in zip((pre, at, post), grids):
            if not ok.any():
                raise PlanningError(f"{w.what} at phase {w.time:g}: gripper at {np.round(w.p_WG, 4).tolist()} is out of the arm's "
                                    "reach from above", actions[w.action] if actions else None)
        ok = grids[0][1] & grids[1][1] & grids[2][1]
        if not ok.any():
            raise PlanningError(f"{at.what}: no arm posture reaches it and the point {approach_height:g} m above it alike",
                                actions[at.action] if actions else None)
        q_pre, q_at, q_post = (grid[ok] for grid, _ in grids)
        internal = (np.sum((q_at - q_pre) ** 2, axis=1) + np.sum((q_post - q_at) ** 2, axis=1)) / APPROACH_TIME**3
        nodes.append((q_pre, q_at, q_post, np.broadcast_to(np.arange(4)[:, None], ok.shape)[ok], internal))
    cost, prev_q, prev_time, back = np.zeros(1), arm.q_home[None], 0.0, []
    for (pre, _, post), (q_pre, _, q_post, _, internal) in zip(triples, nodes):
        best, value = best_predecessors(prev_q, q_pre, (pre.time - prev_time) ** 3, cost)
        back.append(best)
        cost = value + internal
        prev_q, prev_time = q_post, post.time
    cost = cost + np.sum((prev_q - arm.q_home) ** 2, axis=1) / (phases - prev_time) ** 3
    picks = [int(np.argmin(cost))]
    for k in range(len(nodes) - 1, 0, -1):
        picks.append(back[k][picks[-1]])
    picks.reverse()
    seeds, turns = {}, {}
    for (pre, at, post), (q_pre, q_at, q_post, turn, _), i in zip(triples, nodes, picks):
        seeds.update({pre.time: q_pre[i], at.time: q_at[i], post.time: q_post[i]})
        turns[at.action] = int(turn[i])
    return seeds, turns


#: Relative width of the band of predecessors whose Viterbi cost `best_predecessors`
#: re-evaluates exactly: far above the ~1e-15 by which two roundings of it can differ.
VITERBI_BAND = 1e-11


def best_predecessors(a: np.ndarray, b: np.ndarray, dt3: float, cost: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """For every b_j: the first i minimising d_ij = |a_i - b_j|^2 / dt3 + cost_i, and d_ij.

    The same picks and values, to the bit, as `argmin` down the columns of
    `squared_distances(a, b) / dt3 + cost[:, None]`: a BLAS product (in row
    blocks small enough for one thread) ranks the predecessors, and only those
    within a relative VITERBI_BAND of each column's best are evaluated as
    `squared_distances` rounds them (the einsum of a pair does not depend on
    its neighbours), ties going to the first.
    """
    aa, bb = np.einsum("ik,ik->i", a, a), np.einsum("jk,jk->j", b, b)
    m, n = len(a), len(b)
    # Rank by d_ij - bb_j / dt3 = c_i - 2 a_i.b_j / dt3 (a column constant does not
    # change the ranking): row j of rank = [b_j, 1] . [a_i (-2 / dt3), c_i] over i.
    lhs = np.column_stack([b, np.ones(n)])
    rhs = np.ascontiguousarray(np.column_stack([a * (-2.0 / dt3), aa / dt3 + cost]).T)
    rank = np.empty((n, m))
    rows = max(1, 200_000 // (8 * max(m, 1)))  # OpenBLAS stays on one thread below 262144 multiply-adds
    for s in range(0, n, rows):
        np.matmul(lhs[s:s + rows], rhs, out=rank[s:s + rows])
    band = VITERBI_BAND * ((aa.max() + bb) / dt3 + np.abs(cost).max())
    columns = np.arange(n)
    first = rank.argmin(axis=1)
    limit = rank[columns, first] + band
    rank[columns, first] = np.inf
    close = np.flatnonzero(rank.min(axis=1) <= limit)  # columns with another candidate in the band
    J, I = [columns], [first]
    if len(close):
        j, i = np.nonzero(rank[close] <= limit[close, None])
        J.append(close[j])
        I.append(i)
    I, J = np.concatenate(I), np.concatenate(J)
    sq = np.maximum(aa[I] + bb[J] - 2 * np.einsum("pk,pk->p", a[I], b[J]), 0.0)
    d = sq / dt3 + cost[I]
    order = np.lexsort((I, d, J))  # per column: smallest d, then first row
    keep = order[np.r_[True, J[order][1:] != J[order][:-1]]]
    best = np.empty(n, int)
    value = np.empty(n)
    best[J[keep]], value[J[keep]] = I[keep], d[keep]
    return best, value


def squared_distances(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """|a_i - b_j|^2 for all pairs; einsum, not BLAS, whose threads stall on a busy machine."""
    sq = np.einsum("ik,ik->i", a, a)[:, None] + np.einsum("jk,jk->j", b, b)[None, :] - 2 * np.einsum("ik,jk->ij", a, b)
    return np.maximum(sq, 0.0)
