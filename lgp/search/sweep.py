"""The search's check of a solved plan: does a carried block pass through another
solid on the way (`first_sweep`)? The legs design has no collision constraint
between its waypoints, so a skeleton the paper never tried may."""
from __future__ import annotations

import numpy as np

from lgp.planner import Plan


#: A carried block may enter another solid by at most this much (m) along its path
#: (the paper planner's plans keep within it: tests/test_planner.py).
SWEEP_TOLERANCE = 1e-3


def first_sweep(plan: Plan) -> str | None:
    """Where the first carried block enters another block or fixed box by more than
    SWEEP_TOLERANCE along the plan (lgp.scene.penetration at every slice it
    moves), None when none does. The legs design has no collision constraint
    between its waypoints: an order or assignment the paper never tried can carry
    a block through a neighbour (7H), and the search then rejects the plan.
    Every (moving block, slice, solid) pair is screened at once by the
    vectorised separating-axis depth (lgp.geometry.rectangle_overlap); pairs
    not well below the tolerance are decided by the scalar test."""
    from lgp.geometry import rectangle_overlap, yaw_direction
    from lgp.scene import penetration

    initial = plan.initial
    names = initial.names
    P = np.array([plan.p_WB[n] for n in names]).reshape(len(names), len(plan.t), 3)  # (blocks, slices, 3)
    yaw = np.array([np.arctan2(plan.R_WB[n][:, 1, 0], plan.R_WB[n][:, 0, 0]) for n in names]).reshape(len(names), -1)
    half = np.array([np.asarray(b.size, float) / 2 for b in initial.blocks]).reshape(-1, 3)
    k, i = np.nonzero(np.any(np.diff(P, axis=1) != 0, axis=2))  # block k moved into slice i + 1
    i = i + 1
    order = np.lexsort((k, i))  # first in time
    k, i = k[order], i[order]
    if not len(k):
        return None
    nb, nf = len(names), len(initial.fixed)
    # solids per moving entry: every block at that slice (itself masked out), then the fixed boxes
    c_b = np.concatenate([P[:, i, :].transpose(1, 0, 2),
                          np.broadcast_to(np.array([f.p_WO for f in initial.fixed]).reshape(nf, 3), (len(k), nf, 3))], axis=1)
    h_b = np.concatenate([np.broadcast_to(half, (len(k), nb, 3)),
                          np.broadcast_to(np.array([f.size / 2 for f in initial.fixed]).reshape(nf, 3), (len(k), nf, 3))], axis=1)
    y_b = np.concatenate([yaw[:, i].T, np.zeros((len(k), nf))], axis=1)
    n = nb + nf
    c_a = np.repeat(P[k, i][:, None], n, axis=1)
    h_a = np.repeat(half[k][:, None], n, axis=1)
    y_a = np.repeat(yaw[k, i][:, None], n, axis=1)
    flat = lambda x: x.reshape(len(k) * n, *x.shape[2:])  # noqa: E731
    horizontal, _ = rectangle_overlap(flat(c_a)[:, :2], flat(h_a)[:, :2], yaw_direction(flat(y_a)),
                                      flat(c_b)[:, :2], flat(h_b)[:, :2], yaw_direction(flat(y_b)))
    vertical = (np.minimum(flat(c_a)[:, 2] + flat(h_a)[:, 2], flat(c_b)[:, 2] + flat(h_b)[:, 2])
                - np.maximum(flat(c_a)[:, 2] - flat(h_a)[:, 2], flat(c_b)[:, 2] - flat(h_b)[:, 2]))
    maybe = (np.minimum(vertical, horizontal) > SWEEP_TOLERANCE - 1e-7).reshape(len(k), n)
    maybe[np.arange(len(k)), k] = False  # not itself
    for m in np.flatnonzero(maybe.any(axis=1)):
        me = initial.blocks[k[m]].moved_to(P[k[m], i[m]], yaw[k[m], i[m]])
        for j in np.flatnonzero(maybe[m]):
            other = (initial.blocks[j].moved_to(P[j, i[m]], yaw[j, i[m]]) if j < nb else initial.fixed[j - nb])
            depth = penetration(me, other)
            if depth > SWEEP_TOLERANCE:
                return f"carried block {names[k[m]]} enters {other.name} by {depth * 1000:.1f} mm at t = {plan.t[i[m]]:g} s"
    return None
