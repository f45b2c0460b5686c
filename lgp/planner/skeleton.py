"""The skeleton's transcription to KOMO: waypoints of every action, then objectives
and mode switches on the phase clock (as rai's skeleton turns a list of
(phase, action, objects) into KOMO objectives).

Action k of the symbolic plan is at phase k. With approach legs of height h
(Design.approach_height > 0), per action:

- k - APPROACH_TIME: the gripper h straight above the grasp/place pose (same
  orientation), at rest: pre-grasp / pre-place;
- k: the gripper at the grasp pose (G at the block centre, hand vertical, G's x
  axis at the block's yaw plus the chosen quarter turn) or the held block at its
  target X_WB (p_WB exact; yaw up to the cube's quarter-turn symmetry); at rest;
  the mode switch happens here;
- k + APPROACH_TIME: straight above again, at rest: post-grasp / post-place.

Without legs only the action's own waypoint is declared. The plan starts and ends
at rest at the arm's home posture (phases 0 and n_actions + 1).
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from pydrake.math import RigidTransform, RotationMatrix

from lgp.arm import X_WG_from_above
from lgp.komo import Komo
from lgp.planner.design import APPROACH_TIME, PHASE_DURATION, Design
from lgp.symbolic import Grasp, SymbolicPlan


@dataclass(frozen=True)
class Waypoint:
    time: float  # phase
    action: int  # index into actions
    p_WG: np.ndarray  # gripper position
    yaw: float  # block yaw (the gripper yaw is this plus a quarter turn multiple)
    what: str  # e.g. "approach to Place(b1, table)"


def waypoints(symbolic: SymbolicPlan, approach_height: float) -> list[Waypoint]:
    """Per action: approach, action and retreat waypoints; the action's alone when
    approach_height is 0 (no legs)."""
    out = []
    state = symbolic.initial
    for k, (phase, action) in enumerate(symbolic.skeleton()):
        if isinstance(action, Grasp):
            block = state.block(action.block)
            p, yaw = block.p_WB, block.yaw
        else:
            p, yaw = np.asarray(action.p_WB, float), float(action.yaw)
            state = state.with_blocks(b.moved_to(p, yaw) if b.name == action.block else b for b in state.blocks)
        up = np.array([0.0, 0.0, approach_height])
        legs = ((-APPROACH_TIME, up, "approach to"), (0.0, 0.0 * up, "pose of"), (APPROACH_TIME, up, "retreat from"))
        for dt, offset, what in (legs if approach_height > 0 else legs[1:2]):
            out.append(Waypoint(phase + dt, k, p + offset, yaw, f"{what} action {k + 1} {action}"))
    return out


def triples(waypoints: list[Waypoint]) -> list[tuple[Waypoint, Waypoint, Waypoint]]:
    """(approach, action, retreat) waypoints per action; (w, w, w) without legs."""
    by_action: dict[int, list[Waypoint]] = {}
    for w in waypoints:
        by_action.setdefault(w.action, []).append(w)
    return [(ws[0], ws[len(ws) // 2], ws[-1]) for ws in by_action.values()]


def transcribe(symbolic: SymbolicPlan, arm, waypoints: list[Waypoint], turns: dict[int, int], phases: int,
               design: Design) -> Komo:
    """The KOMO problem of the skeleton: poses at the waypoints (hand yaw = block
    yaw + turns[action] quarter turns), rests, grasp and place mode switches, home
    at the end."""
    komo = Komo(arm, phases, design.slices_per_phase, k_order=2, phase_duration=PHASE_DURATION, q_home=arm.q_home,
                objects={b.name: b.X_WB for b in symbolic.initial})
    up = np.array([0.0, 0.0, design.approach_height])
    legs = design.legs
    X_GB = {}
    for (phase, action), (pre, at, post) in zip(symbolic.skeleton(), triples(waypoints)):
        k = at.action
        X_WG = X_WG_from_above(at.p_WG, at.yaw + turns[k] * np.pi / 2)
        X_WG_up = RigidTransform(X_WG.rotation(), X_WG.translation() + up)
        if legs:
            komo.add_objective([pre.time], "pose", ("G",), "eq", target=X_WG_up)
            # The hand stops above (rest at both waypoints): the 5 cm leg is then a
            # rest-to-rest move and stays within 1 mm of the vertical line (passing
            # through the waypoint at speed, it strayed by 5 mm and grazed neighbours).
            komo.add_rest(pre.time)
            komo.add_rest(post.time)
        if isinstance(action, Grasp):
            X_WB = RigidTransform(RotationMatrix.MakeZRotation(at.yaw), at.p_WG)
            X_GB[action.block] = X_WG.inverse().multiply(X_WB)
            komo.add_mode_switch(phase, "grasp", "G", action.block, X_GB=X_GB[action.block])
        else:
            # The block's target pose up to the cube's quarter-turn symmetry: the one
            # that the chosen hand yaw and the grasp give (same p_WB exactly).
            komo.add_mode_switch(phase, "place", "G", action.block, X_WB=X_WG.multiply(X_GB[action.block]))
        komo.add_rest(phase)  # at rest when grasping/placing
        if legs:
            komo.add_objective([post.time], "pose", ("G",), "eq", target=X_WG_up)
    komo.add_objective([float(phases)], "qItself", type="eq", target=arm.q_home)
    komo.add_rest(float(phases), after=False)
    return komo


def carried_slices(symbolic: SymbolicPlan, slices_per_phase: int) -> list[tuple[str, int]]:
    """(block, row) of every trajectory row at which a block is carried, strictly
    between its grasp and its place (row i is time i / slices_per_phase phases)."""
    out, grasped = [], {}
    for phase, action in symbolic.skeleton():
        if isinstance(action, Grasp):
            grasped[action.block] = phase
        else:
            g = grasped.pop(action.block)
            first, last = int(round(g * slices_per_phase)) + 1, int(round(phase * slices_per_phase)) - 1
            out += [(action.block, i) for i in range(first, last + 1)]
    return out
