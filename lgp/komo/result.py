"""What a solved KOMO problem gives: the trajectory, object poses along it, and checks."""
from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
from pydrake.solvers import SolutionResult

from lgp.komo.constraints import violation
from lgp.komo.declaration import Declaration, Objective


@dataclass
class KomoResult:
    """A solved KOMO problem: the trajectory (with time 0 first) and how it was found."""

    t: np.ndarray  # (n,) seconds, n = N + 1 (time 0 = the last prefix slice)
    q: np.ndarray  # (n, nq)
    cost: float  # control cost (+ sos terms) of the full trajectory
    success: bool
    solution_result: SolutionResult  # Drake's verdict (kSolutionFound, kIterationLimit, ...)
    solver_info: int | None  # the solver's own code: SNOPT's info (1 optimal, 41 cannot be improved), IPOPT's status
    solver: str
    formulation: str
    solve_time: float  # wall-clock seconds: building, solving, promotions
    n_variables: int
    keyframes: tuple[int, ...]  # decision slices of the reduced program (all for "full")
    max_violation: float  # largest violation of a declared eq/ineq constraint
    worst_objective: Objective | None  # the objective with that violation
    X_WB: dict[str, np.ndarray] = field(default_factory=dict)  # object poses (n, 4, 4)

    @property
    def status(self) -> str:
        """The verdict as text, for tables and messages: ``kSolutionFound (snopt info 1)``
        (SNOPT's info appended), ``kSolutionFound`` (IPOPT, whose code stays in
        `solver_info`): the text effort tables have always held (column status)."""
        text = self.solution_result.name
        return f"{text} (snopt info {self.solver_info})" if self.solver == "snopt" else text

    def p_WB(self, name: str) -> np.ndarray:
        """Position of object `name` at every slice, (n, 3)."""
        return self.X_WB[name][:, :3, 3]


def frame_poses(komo: Declaration, q: np.ndarray, frame: str) -> np.ndarray:
    """X_WF (n, 4, 4) of a plant frame along a trajectory q (n, nq)."""
    F = komo.frame(frame)
    plant, context = komo.plant, komo.context
    out = np.empty((len(q), 4, 4))
    for i, qi in enumerate(q):
        plant.SetPositions(context, qi)
        out[i] = plant.CalcRelativeTransform(context, plant.world_frame(), F).GetAsMatrix4()
    return out


def object_poses(komo: Declaration, q: np.ndarray) -> dict[str, np.ndarray]:
    """X_WB (n, 4, 4) of every object along q (n = N + 1 rows, time 0 first).

    Row i is slice i - 1. An object's holder changes only at its mode switches
    (at a switch's slice or the one after), so it is looked up there and the held
    stretches are filled at once: X_WG X_GB per row, the same products as row by row.
    """
    poses = {}
    cache: dict[str, np.ndarray] = {}
    n = len(q)
    for name, X0 in komo.objects.items():
        X = np.empty((n, 4, 4))
        current = X0.GetAsMatrix4()
        changes = sorted({1, n} | {i for m in komo.switches if m.object == name for i in (m.slice + 1, m.slice + 2) if 1 <= i < n})
        X[0] = current
        for lo, hi in zip(changes[:-1], changes[1:]):  # rows lo..hi-1 share the holder of slice lo - 1
            holder = komo.holder(name, lo - 1)
            if holder is not None:
                gripper, X_GB = holder
                if gripper not in cache:
                    cache[gripper] = frame_poses(komo, q, gripper)
                X[lo:hi] = cache[gripper][lo:hi] @ X_GB.GetAsMatrix4()
                current = X[hi - 1]
            else:
                X[lo:hi] = current
        poses[name] = X
    return poses


def worst_violation(komo: Declaration, X: np.ndarray, nonlinear) -> tuple[float, Objective | None]:
    """(largest violation, its objective) over the nonlinear objectives and the joint limits (None)."""
    worst, worst_o = 0.0, None
    for o, s in nonlinear:
        v = violation(komo, o, s, X[s])
        if v > worst:
            worst, worst_o = v, o
    limits = float(np.max(np.maximum(np.maximum(komo.q_lower - X, X - komo.q_upper), 0.0)))
    if limits > worst:
        worst, worst_o = limits, None
    return worst, worst_o
