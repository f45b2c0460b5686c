"""The search's lower bounds (lgp.search's symbolic level): the effort it minimises
(`kinetic_energy`, the block kinetic energy of a plan) and closed-form lower bounds
on it for one carry (`carry_bound`) and for a whole skeleton (`skeleton_bound`),
valid for any motion KOMO can return."""
from __future__ import annotations

import numpy as np

from lgp.planner import APPROACH, APPROACH_TIME, PHASE_DURATION, SLICES_PER_PHASE, Design, Plan
from lgp.symbolic import Place, SymbolicPlan

#: Mass of a unit block (kg) [paper: "a unit mass to a unit block"]; models.effort.BLOCK_MASS.
BLOCK_MASS = 1.0


def kinetic_energy(plan: Plan, mass: float = BLOCK_MASS) -> float:
    """Time integral (J s) of 1/2 m |v_WB|^2 of every block along the plan: the
    effort measure of models.effort.kinetic_energy (backward differences times
    tau), which the search minimises."""
    total = 0.0
    for p in plan.p_WB.values():
        v = np.diff(np.asarray(p, float), axis=0) / plan.tau
        total += 0.5 * mass * float(np.sum(v * v)) * plan.tau
    return total


def _leg_slices(slices_per_phase: int) -> int:
    return int(round(APPROACH_TIME * slices_per_phase))


def carry_bound(p_from, p_to, *, approach_height: float = APPROACH, slices_per_phase: int = SLICES_PER_PHASE,
                mass: float = BLOCK_MASS) -> np.ndarray | float:
    """A lower bound (J s) on the kinetic energy of one carry from centre p_from to
    centre p_to, for any motion KOMO can return (vectorised over leading axes).

    The block is at rest at fixed points at fixed slices: with the legs design
    (approach_height h > 0) at p_from (grasp, phase k), p_from + h z (k + 0.2),
    p_to + h z (k + 0.8) and p_to (k + 1). Between two such slices n slices apart,
    the backward-difference energy sum 1/2 m |dp_i|^2 / tau is at least
    1/2 m |D|^2 / (n tau) (Cauchy-Schwarz: |sum dp_i|^2 <= n sum |dp_i|^2), D the
    displacement: the straight, constant-speed carry. So

        bound = 1/2 m (2 h^2 / T_leg + |p_to - p_from|^2 / T_carry)

    with T_leg = 0.2 s and T_carry = 0.6 s; without legs (h = 0) it is
    1/2 m |p_to - p_from|^2 / T_phase. The legs' h^2 term is what the legs design
    adds for certain. (KOMO's motions are rest to rest and curved; the rest-to-rest
    cubic would be 0.6 m L^2 / T, 1.2 times this.)
    """
    design = Design.of(None, approach_height, slices_per_phase)
    h, S = design.approach_height, design.slices_per_phase
    D2 = np.sum((np.asarray(p_to, float) - np.asarray(p_from, float)) ** 2, axis=-1)
    tau = PHASE_DURATION / S
    if h > 0:
        legs = _leg_slices(S)
        return 0.5 * mass * (2 * h * h / (legs * tau) + D2 / ((S - 2 * legs) * tau))
    return 0.5 * mass * D2 / (S * tau)


def skeleton_bound(symbolic: SymbolicPlan, *, approach_height: float = APPROACH,
                   slices_per_phase: int = SLICES_PER_PHASE, mass: float = BLOCK_MASS) -> float:
    """Sum of `carry_bound` over the carries of a skeleton: a lower bound on the
    effort of any plan KOMO returns for it (tested against KOMO on every trial)."""
    where = {b.name: b.p_WB for b in symbolic.initial.blocks}
    total = 0.0
    for action in symbolic.actions:
        if isinstance(action, Place):
            total += float(carry_bound(where[action.block], action.p_WB, approach_height=approach_height,
                                       slices_per_phase=slices_per_phase, mass=mass))
            where[action.block] = np.asarray(action.p_WB, float)
    return total
