"""The clearance design (approach_height = 0): no approach legs; every carry kept
clear of the table and of every other solid by constraints added where needed.

Starting from the legs design's plan (APPROACH legs), the carried block's corners
are kept above the table top and beyond a face plane of every block or fixed box
it would enter (over its top or beside it, in that solid's frame, the face the
legs plan also clears), added where the solved motion needs them and re-solved
(at most CLEARANCE_ROUNDS times). docs/effort.md, "Modelling choices".
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from pydrake.math import RigidTransform, RotationMatrix

from lgp.arm import Arm
from lgp.komo import Komo, KomoResult
from lgp.planner import skeleton
from lgp.planner import turns as quarter_turns
from lgp.planner.design import APPROACH, Design, PlanningError
from lgp.planner.seeding import declare
from lgp.scene import OVERLAP_TOLERANCE, Scene
from lgp.symbolic import SymbolicPlan

#: approach_height = 0: at most this many re-solves with clearance constraints
#: added where the carried block came too close to the table or entered a solid.
CLEARANCE_ROUNDS = 12
#: approach_height = 0: where a carried block enters a solid (or the table), the
#: rows at which it is within this distance (m) of that solid are constrained too,
#: so that a re-solve does not just move the contact a slice on. Measured (3E / 7E
#: / 2E, side by side): 2 mm 32.8 / 17.5 / 3.9 s, 5 mm 22.1 / 13.3 / 2.1 s, 10 mm
#: 18.9 / 12.7 / 1.4 s per plan (fewer re-solves). A wider margin also fixes the
#: way round more solids early, so the local optimum moves: against 2 mm, efforts
#: of the 24 trials change by -4.9..+2.4 % at 5 mm and -4.9..+4.2 % at 10 mm.
CLEARANCE_MARGIN = 0.005
#: approach_height = 0: a face plane of a solid counts as separating the legs
#: design's carried block from it when the block is at most this far (m) past it:
#: the legs' vertical moves stray up to 1.3 mm from the vertical line.
REFERENCE_SLACK = 0.002
#: approach_height = 0: the solver of the clearance program. Once blocks slide on
#: the table most carried slices hold an active constraint, and SNOPT's reduced
#: Hessian grows with them: 7E (210 keyframes) took 45.6 s with SNOPT and 12.9 s
#: with IPOPT to the same optimum, 3E over 4 minutes with SNOPT and 43 s with IPOPT
#: (docs/effort.md, "Modelling choices").
CLEARANCE_SOLVER = "ipopt"
#: approach_height = 0: IPOPT options of the clearance program (on top of lgp.komo.solve's).
#: IPOPT's linear solver SPRAL by default scales the KKT matrix by a matching
#: (spral_scaling = matching), recomputed with its ordering at every iteration (the
#: symbolic factorisation, about 1/4 of the solve); unscaled, the 24 trials' layout 0
#: planned in 72.4 instead of 108.5 CPU s (3E 37.5 -> 22.4, 7E 18.5 -> 13.3) to the same
#: optimum: every effort within 1.5e-11 relative (bench/clearance.py
#: --options measures both side by side; IPOPT's tol is 1e-9).
#: Its optimality tolerance `tol` 1e-6 (lgp.komo.solve's is 1e-9; constr_viol_tol stays
#: 1e-9, so the clearance constraints hold as tightly): the last digits of an optimum
#: cost IPOPT's limited-memory Hessian many iterations. Side by side, tol 1e-9 against
#: 1e-6 (both unscaled): 3E 21.0 -> 16.0, 7E 13.0 -> 9.6 CPU s, efforts within 8e-9;
#: over the 24 trials every effort within 2.8e-7 relative of lgp.komo's defaults
#: (bench/clearance.py --options --trials all, docs/benchmarks.md).
CLEARANCE_OPTIONS = {"spral_scaling": "none", "tol": 1e-6}
#: approach_height = 0: the carried block's bottom corners stay this far (m) above
#: the table top. With a bound of exactly 0 the block slides on the table right
#: after the grasp's rest and SNOPT stalled 6e-8 m short of it (info 41, 2E); 10 um
#: is far below OVERLAP_TOLERANCE.
CLEARANCE = 1e-5


#: SNOPT's info 41: "current point cannot be improved" (Drake's SnoptSolverDetails.info).
SNOPT_CANNOT_IMPROVE = 41


def usable(result: KomoResult, approach_height: float) -> bool:
    """Solved, every constraint within 1e-6. Without legs SNOPT (if it is the
    CLEARANCE_SOLVER) may also end with info 41 ("cannot be improved") at a feasible
    point: a carried block sliding on the table right after a grasp's rest is a
    degenerate active set (7E); the status stays in the effort table (column status)."""
    if result.max_violation > 1e-6:
        return False
    return result.success or (approach_height == 0 and result.solver == "snopt" and result.solver_info == SNOPT_CANNOT_IMPROVE)


def box_corners(size) -> np.ndarray:
    """The 8 corners (8, 3) of a box of full extents `size`, in its own frame."""
    return _UNIT_CORNERS * np.asarray(size, float) / 2


@dataclass(frozen=True)
class Obstacle:
    """A solid a carried block must stay out of: X_WO (rotation R_WO, centre p_WO), half extents."""

    key: str
    R_WO: np.ndarray
    p_WO: np.ndarray
    half: np.ndarray


def _obstacles(initial: Scene, X_WB: dict[str, np.ndarray], carried: str, i: int) -> list[Obstacle]:
    """Every other block at trajectory row i (poses from X_WB) and every fixed box."""
    out = [Obstacle(b.name, X_WB[b.name][i][:3, :3], X_WB[b.name][i][:3, 3], np.asarray(b.size, float) / 2)
           for b in initial.blocks if b.name != carried]
    out += [Obstacle(f"{f.name} box {j + 1}", np.eye(3), f.p_WO, f.size / 2) for j, f in enumerate(initial.fixed)]
    return out


def _gaps_beyond_faces(P_F: np.ndarray, half: np.ndarray) -> np.ndarray:
    """(n, 6) gap (m) of the point sets P_F (n, k, 3), each in the frame of a box of
    half extents half (n, 3), beyond that box's face planes +x, -x, +y, -y, +z, -z:
    the least distance of a point past the plane (< 0 when some point is not past it)."""
    lo, hi = P_F.min(axis=1) - half, -half - P_F.max(axis=1)
    return np.stack([lo, hi], axis=2).reshape(len(P_F), 6)


def _obstacle_frames(obstacles: list[Obstacle]) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """R_WO (n, 3, 3), p_WO (n, 3) and half extents (n, 3) of the obstacles."""
    return (np.array([o.R_WO for o in obstacles]), np.array([o.p_WO for o in obstacles]),
            np.array([o.half for o in obstacles]))


def face_gaps(p_WC: np.ndarray, obstacles: list[Obstacle]) -> np.ndarray:
    """(n_obstacles, 5) gap (m) of the points p_WC (the carried block's corners) beyond
    each face plane of each obstacle, in the obstacle's frame: +x, -x, +y, -y, +z.
    A gap >= 0 on some face means that face's plane separates the two boxes."""
    if not obstacles:
        return np.zeros((0, 5))
    R, p, e = _obstacle_frames(obstacles)
    C = np.einsum("nji,nkj->nki", R, p_WC[None] - p[:, None])  # corners in each obstacle's frame
    return _gaps_beyond_faces(C, e)[:, :5]


def separation(X_WB: np.ndarray, half: np.ndarray, p_WC: np.ndarray, obstacles: list[Obstacle]) -> np.ndarray:
    """(n_obstacles,) signed separation (m) of the carried block (pose X_WB, half
    extents `half`, corners p_WC) from each obstacle: the largest gap beyond a face
    plane of either box (the obstacle's 6, then the block's 6). For boxes that share
    their vertical axis (yaw only) the face normals are every separating axis, so
    < 0 means they interpenetrate by at least that much (lgp.scene.penetration)."""
    if not obstacles:
        return np.zeros(0)
    R, p, e = _obstacle_frames(obstacles)
    C = np.einsum("nji,nkj->nki", R, p_WC[None] - p[:, None])  # the block's corners in each obstacle's frame
    O_W = p[:, None] + np.einsum("nij,nkj->nki", R, _UNIT_CORNERS[None] * e[:, None])  # obstacles' corners in W
    O_B = (O_W - X_WB[:3, 3]) @ X_WB[:3, :3]  # ... in the block's frame
    beyond_obstacle = _gaps_beyond_faces(C, e).max(axis=1)
    beyond_block = _gaps_beyond_faces(O_B, np.broadcast_to(half, e.shape)).max(axis=1)
    return np.maximum(beyond_obstacle, beyond_block)


#: The 8 corners of the unit cube [-1, 1]^3.
_UNIT_CORNERS = np.array([[x, y, z] for x in (-1, 1) for y in (-1, 1) for z in (-1, 1)], float)


def _separating_face(reference_gaps: np.ndarray, gaps: np.ndarray) -> int:
    """The face plane of a solid to keep a carried block beyond at one row: of the
    faces that separate the reference plan's block from it (gap >= -REFERENCE_SLACK),
    the one the current motion is least far from (smallest move); the reference's
    most separating face if none does."""
    consistent = np.flatnonzero(reference_gaps >= -REFERENCE_SLACK)
    if not len(consistent):
        return int(np.argmax(reference_gaps))
    return int(consistent[np.argmax(gaps[consistent])])


def _addseparation(komo: Komo, name: str, corners: np.ndarray, i: int, obstacle: Obstacle, face: int) -> None:
    """Every corner of the carried block beyond one face plane of the obstacle at row i
    (measured in the obstacle's frame), touching allowed: OVERLAP_TOLERANCE / 2."""
    axis = (0, 0, 1, 1, 2)[face]
    sign = (1.0, -1.0, 1.0, -1.0, 1.0)[face]  # +1: coordinate >= half + ..., -1: <= -half - ...
    scale, target = np.zeros(3), np.zeros(3)
    scale[axis] = -sign
    target[axis] = sign * (obstacle.half[axis] - OVERLAP_TOLERANCE / 2)
    komo.add_objective([i / komo.slices_per_phase], "position", (name,), "ineq", scale=scale, target=target, points=corners,
                       X_WA=RigidTransform(RotationMatrix(obstacle.R_WO), obstacle.p_WO))


def plan_with_clearance(symbolic: SymbolicPlan, arm: Arm, rng, formulation: str, solver: str, slices_per_phase: int):
    """approach_height = 0: the legs design's plan, then its legs dropped and every
    carry kept clear of the table and of every other solid (returns (komo, result)).

    1. The plan with APPROACH legs (quarter turns, swivels and IK branches chosen as
       usual, `solver`) is feasible for the program without legs and clear of every
       solid (within the 1.3 mm its legs stray from vertical): it is the reference
       and the initial guess (`_reference`).
    2. The program without legs (same quarter turns) is solved by CLEARANCE_SOLVER.
       Wherever a carried block's bottom corners come within CLEARANCE / 2 of the
       table top, or no face plane of either box separates it from another block
       or fixed box (`separation`) and they overlap by more than
       OVERLAP_TOLERANCE * 3/4 (`_entered`), a constraint is added at that row, and at the
       rows where the same block is within CLEARANCE_MARGIN of the same solid
       (`_near`, `_constrain`): its bottom corners CLEARANCE
       above the table; its corners beyond one face plane of the solid (over its
       top, or beside one of its four sides; touching allowed): of the faces that
       separate the reference's block from it at that row, the one the solved
       motion is least far past (`_separating_face`). So each constraint holds on
       the reference (the program stays feasible) and the motion keeps the
       reference's way round each solid (beside a neighbour until above it, inside
       the bucket until over its wall) but not its 5 cm detours. Re-solved at most
       CLEARANCE_ROUNDS times, else PlanningError naming the action (`_stuck`).
    """
    reference, turns = _reference(symbolic, arm, rng, formulation, solver, slices_per_phase)
    S = slices_per_phase
    komo = skeleton.transcribe(symbolic, arm, skeleton.waypoints(symbolic, 0.0), turns, len(symbolic.actions) + 1,
                               Design(0.0, S))
    carried = skeleton.carried_slices(symbolic, S)
    blocks = {b.name: _Carried(box_corners(b.size), np.asarray(b.size, float) / 2) for b in symbolic.initial.blocks}
    elapsed = reference.solve_time
    declared: dict[tuple[str, int, str], int] = {}  # (block, row, solid) -> corners constrained
    result = reference
    for round_ in range(CLEARANCE_ROUNDS + 1):
        # Rounds 0 and 1 start from the clear reference: from round 0's solution,
        # which goes through solids, the program took 5x longer (12E, SNOPT: 33.8 s
        # vs 6.7 s); later rounds from the last solution, which misses only the few
        # constraints just added.
        guess = result.q[1:] if round_ >= 2 else reference.q[1:]
        result = komo.solve(formulation=formulation, solver=CLEARANCE_SOLVER, initial_guess=guess, options=_options())
        elapsed += result.solve_time
        if not usable(result, 0.0):
            break
        near = _near(result, symbolic.initial, carried, blocks)
        worst = [w for w in near if _entered(w.solid, w.gap)]
        if not worst:
            break
        added = _constrain(komo, near, worst, declared, reference, blocks, S)
        if round_ == CLEARANCE_ROUNDS or not added:
            raise _stuck(symbolic, worst, S, round_ + 1)
    result.solve_time = elapsed
    return komo, result


def _options() -> dict | None:
    """CLEARANCE_OPTIONS if CLEARANCE_SOLVER is IPOPT (its option names), else none."""
    return dict(CLEARANCE_OPTIONS) if CLEARANCE_SOLVER == "ipopt" else None


def _reference(symbolic: SymbolicPlan, arm: Arm, rng, formulation: str, solver: str, slices_per_phase: int):
    """The legs design's plan (the reference and first guess) and its quarter turns;
    PlanningError naming the action if it is not usable."""
    legs = Design(APPROACH, slices_per_phase)
    komo, seeds, turns = declare(symbolic, arm, rng, legs)
    komo, reference, turns = quarter_turns.solve(symbolic, arm, komo, seeds, turns, formulation, solver, legs)
    if not usable(reference, APPROACH):
        o = reference.worst_objective
        k = int(round(o.time[0])) if o is not None and o.time else None
        action = symbolic.actions[k - 1] if k and 1 <= k <= len(symbolic.actions) else None
        raise PlanningError(f"the reference plan with {APPROACH:g} m legs (the start of the design without legs) failed"
                            f"{f' at action {k} {action}' if action else ''}: {reference.status}, constraint violation "
                            f"{reference.max_violation:.2e}", action)
    return reference, turns


@dataclass(frozen=True)
class _Carried:
    """A block that may be carried: its 8 corners (8, 3) in its frame, half extents."""

    corners: np.ndarray
    half: np.ndarray

    @property
    def bottom(self) -> np.ndarray:
        return self.corners[self.corners[:, 2] < 0]


@dataclass(frozen=True)
class _Near:
    """A carried block `name` at row i within CLEARANCE_MARGIN of a solid (None: the
    table): its gap (height above the table, or `separation`) and corners p_WC in W."""

    name: str
    i: int
    solid: Obstacle | None
    gap: float
    p_WC: np.ndarray

    @property
    def key(self) -> tuple[str, int, str]:
        return (self.name, self.i, "table" if self.solid is None else self.solid.key)

    @property
    def pair(self) -> tuple[str, str | None]:
        return (self.name, None if self.solid is None else self.solid.key)


def _entered(solid: Obstacle | None, gap: float) -> bool:
    """Whether a gap means the block entered the solid (the table: came within CLEARANCE / 2)."""
    return gap < (CLEARANCE / 2 if solid is None else -0.75 * OVERLAP_TOLERANCE)


def _near(result: KomoResult, initial: Scene, carried, blocks: dict[str, _Carried]) -> list[_Near]:
    """Every (carried block, row, solid) of the solved motion within CLEARANCE_MARGIN."""
    near = []
    for name, i in carried:
        b = blocks[name]
        X = result.X_WB[name][i]
        p_WC = b.corners @ X[:3, :3].T + X[:3, 3]
        height = float(np.min(p_WC[:, 2][b.corners[:, 2] < 0]))
        if height < CLEARANCE_MARGIN:
            near.append(_Near(name, i, None, height, p_WC))
        obstacles = _obstacles(initial, result.X_WB, name, i)
        for o, g in zip(obstacles, separation(X, b.half, p_WC, obstacles)):
            if g < CLEARANCE_MARGIN:
                near.append(_Near(name, i, o, float(g), p_WC))
    return near


def _constrain(komo: Komo, near: list[_Near], worst: list[_Near], declared: dict, reference: KomoResult,
               blocks: dict[str, _Carried], S: int) -> int:
    """Constraints at every near row of a (block, solid) pair that `worst` entered;
    `declared` {(block, row, solid): corners constrained} grows. Returns how many added."""
    hit = {w.pair for w in worst}
    added = 0
    for w in near:
        if w.pair not in hit:
            continue
        name, i, o, key = w.name, w.i, w.solid, w.key
        if o is None:
            if key not in declared:
                komo.add_objective([i / S], "position", (name,), "ineq", scale=(0.0, 0.0, -1.0),
                                   target=[0.0, 0.0, CLEARANCE], points=blocks[name].bottom)
                declared[key], added = 4, added + 1
            continue
        if declared.get(key, 0) == 8 or (key in declared and not _entered(o, w.gap)):
            continue
        X = reference.X_WB[name][i]
        p_WC_reference = blocks[name].corners @ X[:3, :3].T + X[:3, 3]
        face = _separating_face(face_gaps(p_WC_reference, [o])[0], face_gaps(w.p_WC, [o])[0])
        # The corners that lead along the face's normal, at the reference and now
        # (4 of 8 each: a near-vertical hand turns the block mostly about z);
        # all 8 if the solid is entered again at this row.
        points = np.arange(8)
        if key not in declared:
            axis, sign = (0, 0, 1, 1, 2)[face], (1.0, -1.0, 1.0, -1.0, 1.0)[face]
            lead = [np.argsort(sign * ((P - o.p_WO) @ o.R_WO)[:, axis])[:4] for P in (p_WC_reference, w.p_WC)]
            points = np.union1d(*lead)
        _addseparation(komo, name, blocks[name].corners[points], i, o, face)
        declared[key] = len(points) if key not in declared else 8
        added += 1
    return added


def _stuck(symbolic: SymbolicPlan, worst: list[_Near], S: int, solves: int) -> PlanningError:
    """The PlanningError of a carry still entering a solid after `solves` solves, naming the action."""
    w = min(worst, key=lambda w: w.gap)
    k = int(np.ceil(w.i / S))
    action = symbolic.actions[k - 1] if 1 <= k <= len(symbolic.actions) else None
    where = (f"comes within {w.gap * 1000:.3f} mm of the table top (less than {CLEARANCE / 2 * 1000:g} mm)"
             if w.solid is None else f"still enters {w.solid.key} by {-w.gap * 1000:.3f} mm")
    return PlanningError(f"action {k} {action}: carried block {w.name} {where} at t = {w.i / S:g} s after {solves} "
                         f"solves without legs", action)
