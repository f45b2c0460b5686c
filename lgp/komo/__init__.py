"""KOMO (k-order motion optimisation, Toussaint 2014/2015) on Drake's MathematicalProgram.

The geometric layer of the paper ("Geometric planning"): a motion is *declared* on a
phase clock, rai-style, and then one call turns the declaration into a
MathematicalProgram and solves it::

    komo = Komo(arm, phases=3, slices_per_phase=20, k_order=2, objects={"b1": X_WB})
    komo.add_objective([0.8], "pose", ("G",), "eq", target=X_WG_pregrasp)
    komo.add_mode_switch(1.0, "grasp", "G", "b1", X_GB=X_GB)
    komo.add_rest(1.0)                                             # zero velocity
    komo.add_objective([2.0], "pose", ("b1",), "eq", target=X_WB_goal)
    komo.add_mode_switch(2.0, "place", "G", "b1")
    komo.add_objective([3.0], "qItself", type="eq", target=q_home)
    komo.add_rest(3.0, after=False)
    result = komo.solve()                                          # reduced, SNOPT

One module per idea, each importing only the ones above it in this list:

- `lgp.komo.declaration`: the phase clock, objectives, mode switches, rests (Declaration);
- `lgp.komo.linear`: the quadratic control cost and linear equalities (LinearStructure),
  and the exact elimination of free slices (eliminate, interpolate);
- `lgp.komo.constraints`: nonlinear objectives as Drake constraints (drake_constraints, violation);
- `lgp.komo.result`: KomoResult, frame and object poses along a trajectory;
- `lgp.komo.solve`: `Komo` = Declaration + solve (reduced and full formulations,
  promotion of violated slices).

This module only re-exports their public names.
"""
from lgp.komo.constraints import drake_constraints, violation
from lgp.komo.declaration import FEATURES, TYPES, Declaration, KomoError, ModeSwitch, Objective
from lgp.komo.linear import Elimination, LinearStructure, eliminate, interpolate, linear_structure
from lgp.komo.result import KomoResult, frame_poses, object_poses
from lgp.komo.solve import FORMULATIONS, SOLVERS, Komo

__all__ = ["FEATURES", "FORMULATIONS", "SOLVERS", "TYPES", "Declaration", "Elimination", "Komo", "KomoError", "KomoResult",
           "LinearStructure", "ModeSwitch", "Objective", "drake_constraints", "eliminate", "frame_poses", "interpolate",
           "linear_structure", "object_poses", "violation"]
