"""The nonlinear objectives of a KOMO declaration as Drake constraints.

A "position" or "pose" objective on a plant frame, or on an object held by a
gripper at that slice (X_WB = X_WG X_GB), becomes PositionConstraints (C++
evaluators, with gradients) on the joint vector of that one slice. A pose is
written as three point positions: the frame's origin, and a point a lever arm
along its z and x axes.
"""
from __future__ import annotations

import numpy as np
from pydrake.math import RigidTransform
from pydrake.multibody.inverse_kinematics import PositionConstraint

from lgp.komo.declaration import Declaration, KomoError, Objective

#: Length (m) of the lever arms used to express an orientation as point positions:
#: an orientation error of e rad shows up as a position error of e * LEVER.
LEVER = 0.1


def drake_constraints(komo: Declaration, o: Objective, s: int) -> list[PositionConstraint]:
    """Drake constraints for nonlinear objective o at slice s, on q of that slice."""
    name = o.frames[0]
    if name in komo.objects:
        holder = komo.holder(name, s)
        if holder is None:
            raise KomoError(f"{o.feature} objective on {name} at phase {(s + 1) / komo.slices_per_phase}: {name} is not held then")
        frame, X_GB = komo.frame(holder[0]), holder[1]
    else:
        frame, X_GB = komo.frame(name), RigidTransform()
    plant, context, world = komo.plant, komo.context, komo.plant.world_frame()
    if o.feature == "position":
        scale = np.broadcast_to(np.asarray(o.scale, float), (3,))
        free = scale == 0  # rai-style: a zero scale drops the axis, a negative one flips an ineq
        if o.type == "eq":
            lo, hi = np.where(free, -np.inf, o.target), np.where(free, np.inf, o.target)
        else:
            lo = np.where(scale < 0, o.target, -np.inf)
            hi = np.where(scale > 0, o.target, np.inf)
        if o.points is None and o.X_WA is None:
            return [PositionConstraint(plant, world, lo, hi, frame, X_GB.translation(), context)]
        # Points fixed on the frame (p_FQ), measured in a fixed frame A: p_AQ = X_WA^-1 X_WG X_GF p_FQ.
        points = o.points if o.points is not None else ((0.0, 0.0, 0.0),)
        X_WA = o.X_WA if o.X_WA is not None else RigidTransform()
        return [PositionConstraint(plant, world, X_WA, lo, hi, frame, X_GB.multiply(np.asarray(p, float)), context) for p in points]
    # pose: X_WG = X_target X_GB^-1, written as three point positions (6 equalities):
    X_WT = o.target.multiply(X_GB.inverse())
    inf = np.inf
    return [
        PositionConstraint(plant, world, X_WT.translation(), X_WT.translation(), frame, np.zeros(3), context),
        # G's z axis along T's: the point G + l z_G lies on T's z axis, on the + side.
        PositionConstraint(plant, world, X_WT, np.array([0, 0, 0.0]), np.array([0, 0, inf]), frame, np.array([0, 0, LEVER]), context),
        # G's x axis along T's: the point G + l x_G has no y in T, on the + side.
        PositionConstraint(plant, world, X_WT, np.array([0.0, 0, -inf]), np.array([inf, 0, inf]), frame, np.array([LEVER, 0, 0]), context),
    ]


def violation(komo: Declaration, o: Objective, s: int, q: np.ndarray) -> float:
    """Largest violation of objective o at slice s by the joint vector q (0 if satisfied)."""
    worst = 0.0
    for c in drake_constraints(komo, o, s):
        y = c.Eval(q)
        worst = max(worst, float(np.max(np.maximum(np.maximum(c.lower_bound() - y, y - c.upper_bound()), 0.0))))
    return worst
