"""A logic layer that searches: best-first over symbolic states, bounded before solved.

The paper's pipeline (lgp.planner.plan) takes one assignment (Hungarian on
distance) and one order (B's support graph) and optimises that single skeleton.
This module searches over skeletons instead, after Toussaint's LGP as rai
implements it (src/LGP/LGP_tree.cpp: fringes per bound level BD_symbolic ->
BD_pose -> BD_seq -> BD_path; a skeleton reaches the expensive path optimisation
only after the cheap levels accept it). Here the levels are:

1. **symbolic** (no geometry solver): a lower bound on the effort of every
   skeleton below a node, `g + h` (`carry_bound`, `_remaining_bound`);
2. **pose**: every keyframe of the skeleton (grasp, place, and the points above
   them) has a closed-form IK solution (lgp.arm), checked when a carry is added;
3. **path**: the full KOMO program (lgp.planner.plan_symbolic), last.

Actions (one hand; a Grasp is always followed by the Place of the same block, so a
branch is one carry):

- Place(b, slot of B): a clear block of the slot's colour, onto a slot whose
  supports in B are filled, into a free volume (the assignment is part of the
  search: any block of the right colour may fill a slot);
- Place(b, table): a *set-aside* to a spot on the table chosen from generated
  candidates (`candidate_spots`), only when no clear block can go to a slot (the
  state is stuck). Why candidates and not a KOMO-optimised free pose: the bound
  ranks spots in microseconds, a KOMO solve costs ~0.1-1 s per skeleton and the
  mode switch of lgp.komo takes a given X_WB (docs/effort.md, "The search",
  measures how much the spot choice moves effort). Why only when stuck: effort is
  the time integral of kinetic energy with 1 s per action, so an extra action
  always buys time, and a carry split at a midpoint halves its distance-squared
  term; with set-asides allowed anywhere the search would relay every long carry
  (10H's 40 cm carries: the bound drops from 0.146 to 0.092 J s each).

Blocks placed in a slot are final and never move again; a block already at a
slot pose of its colour on final supports is final from the start. So every
block moves at most twice and the search is finite.

`search(initial, target, ...)` returns a `SearchResult`: the least-effort plan
found, its effort, the bound of the best unexplored branch and the gap between
them; it stops when the gap is closed (no open branch can beat the incumbent) or
a `Budget` (KOMO solves, seconds, symbolic expansions) runs out. The paper's
skeleton (Hungarian assignment, the paper's order), when it exists, is the first
branch solved, with the same random generator as lgp.planner.plan: the search
never returns more effort than the paper planner on the same layout.
"""
from __future__ import annotations

import heapq
import itertools
import time
from dataclasses import dataclass, field

import numpy as np
from scipy.optimize import linear_sum_assignment

from lgp.assignment import assign_blocks
from lgp.errors import InputError
from lgp.planner import (APPROACH, APPROACH_TIME, PHASE_DURATION, SEED_MARGIN, SLICES_PER_PHASE, SWIVELS, Plan,
                         PlanningError, Design, default_arm, plan_symbolic)
from lgp.scene import (CONTACT_TOLERANCE, MIN_SUPPORT_AREA, TABLE, Scene, footprint_overlap_area, support_graph,
                       supported_by)
from lgp.symbolic import (Grasp, Place, PlanState, SymbolicPlan, SymbolicPlanningError, _enters_any, _near,
                          _support_memo, apply, same_pose, symbolic_plan)

#: Mass of a unit block (kg) [paper: "a unit mass to a unit block"]; models.effort.BLOCK_MASS.
BLOCK_MASS = 1.0
#: Candidate set-aside spots: a grid of this pitch (m) over the table region below.
SPOT_PITCH = 0.02
#: The table region (m) set-aside spots are drawn from: the reach of the arm
#: (docs/effort.md, "The arm": x 0.15-0.70, y -0.40-0.40).
SPOT_REGION = ((0.15, 0.70), (-0.40, 0.40))
#: A spot keeps this gap (m) to every block, obstacle and slot of B (footprints).
SPOT_CLEARANCE = 0.01
#: Spots branched on per set-aside, best bound first.
SPOTS_PER_SET_ASIDE = 3


class SearchError(PlanningError):
    """The search found no plan: `reason` is "unsolvable" (every branch explored or
    pruned, none reaches B) or "budget" (the budget ran out first); `bound` is the
    best lower bound on effort (J s) reached, inf when no skeleton exists."""

    def __init__(self, message: str, reason: str, bound: float):
        super().__init__(message)
        self.reason, self.bound = reason, bound


@dataclass(frozen=True)
class Budget:
    """When the search stops if the gap is still open: after `solves` KOMO solves,
    `seconds` of wall-clock time, or `expansions` symbolic nodes expanded."""

    solves: int = 3
    seconds: float = 120.0
    expansions: int = 20000

    def __post_init__(self):
        for name in ("solves", "seconds", "expansions"):
            value = getattr(self, name)
            if isinstance(value, bool) or not isinstance(value, (int, float)) or not np.isfinite(value) or value <= 0:
                raise InputError(f"Budget.{name} must be a positive number, got {value!r}")
        if not float(self.solves).is_integer() or not float(self.expansions).is_integer():
            raise InputError(f"Budget.solves and .expansions must be whole numbers, got {self.solves!r}, {self.expansions!r}")


@dataclass
class SearchResult:
    """The least-effort plan found and how far from optimal it may be.

    `effort` (J s) is the plan's block kinetic energy (`kinetic_energy`, the same
    integral as models.effort.kinetic_energy); `bound` the lowest lower bound of
    any branch left unexplored (inf when none is left), capped at `effort`; `gap`
    = effort - bound >= 0 (0: proved least-effort among the skeletons the search
    admits). `paper` is the paper planner's skeleton when it exists and was
    solved, with its effort; `solves`, `expansions`, `seconds` what it cost.
    """

    plan: Plan
    effort: float
    bound: float
    skeleton_bound: float
    solves: int
    expansions: int
    seconds: float
    stopped: str
    paper_effort: float | None = None
    paper_symbolic: SymbolicPlan | None = None
    tried: list = field(default_factory=list)  # (skeleton bound, effort or failure) per KOMO solve
    komo_seconds: float = 0.0  # of `seconds`, the time in lgp.planner.plan_symbolic (IK seeding + KOMO)

    @property
    def gap(self) -> float:
        return max(0.0, self.effort - self.bound)

    @property
    def symbolic(self) -> SymbolicPlan:
        return self.plan.symbolic

    @property
    def set_asides(self) -> int:
        """How many Place actions put a block on a table spot, not in its slot."""
        return sum(isinstance(a, Place) and _is_spot(self.symbolic, a) for a in self.symbolic.actions)

    def __str__(self) -> str:
        lines = [f"{k + 1:3d}  {a}" for k, a in enumerate(self.symbolic.actions)]
        lines.append(f"effort {self.effort:.4f} J s, bound {self.bound:.4f} J s, gap {self.gap:.4f} J s "
                     f"({100 * self.gap / self.effort if self.effort > 0 else 0.0:.1f} %); this skeleton's bound "
                     f"{self.skeleton_bound:.4f}; {self.solves} KOMO solves, {self.expansions} expansions, "
                     f"{self.seconds:.2f} s, stopped: {self.stopped}")
        return "\n".join(lines)


def _is_spot(symbolic: SymbolicPlan, action: Place) -> bool:
    """Whether a Place puts its block somewhere other than its slot in B (a set-aside)."""
    slot = symbolic.assignment.get(action.block)
    return slot is None or not np.allclose(action.p_WB, symbolic.target.block(slot).p_WB, atol=1e-9)


# ----------------------------------------------------------------------------- the bound


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


# ----------------------------------------------------------------------------- symbolic states


@dataclass(frozen=True)
class _Node:
    """A symbolic state: where every block of A is (0 = where it started, 1 + j =
    slot j of B, -1 - k = set-aside spot k of `spots`), the carries that led here
    (block, destination), and the bound g so far."""

    where: tuple[int, ...]
    carries: tuple[tuple[int, int], ...]
    g: float
    settled: bool  # no state below can be stuck (_Problem.settled), so no set-aside is to come


class _Problem:
    """The fixed data of one search: blocks of A, slots of B and their supports,
    the spots created so far, and memoised geometry."""

    def __init__(self, initial: Scene, target: Scene, approach_height: float, slices_per_phase: int, arm):
        self.initial, self.target = initial, target
        self.h, self.S, self.arm = approach_height, slices_per_phase, arm
        self.blocks = list(initial.blocks)
        self.slots = list(target.blocks)
        self.colour = [b.colour for b in self.blocks]
        self.slot_colour = [s.colour for s in self.slots]
        graph_B = support_graph(target)
        index_B = {s.name: j for j, s in enumerate(self.slots)}
        self.fixed_names = {f.name for f in initial.fixed} | {TABLE}
        # per slot: the slots it rests on in B, and the fixed solids / table it rests on
        self.slot_below = [[index_B[n] for n in graph_B[s.name] if n in index_B] for s in self.slots]
        self.slot_ground = [[n for n in graph_B[s.name] if n not in index_B] for s in self.slots]
        self.spots: list[tuple[np.ndarray, float]] = []  # (p_WB, yaw)
        self._spot_index: dict[tuple, int] = {}
        self._reach: dict[tuple, bool] = {}
        self.slot_p = np.array([s.p_WB for s in self.slots]).reshape(-1, 3)
        # A block of A with a fixed box resting on it can never be grasped.
        self.pinned = [any(abs(f.bottom - b.top) <= CONTACT_TOLERANCE and footprint_overlap_area(b, f) > MIN_SUPPORT_AREA
                           for f in initial.fixed) for b in self.blocks]
        self.start_p = initial.positions

    # -- positions and scenes
    def pose(self, i: int, w: int) -> tuple[np.ndarray, float]:
        if w == 0:
            return self.blocks[i].p_WB, self.blocks[i].yaw
        if w > 0:
            return self.slots[w - 1].p_WB, self.slots[w - 1].yaw
        return self.spots[-1 - w]

    def scene(self, where) -> Scene:
        return self.initial.with_blocks(b if w == 0 else b.moved_to(*self.pose(i, w)) for i, (b, w) in enumerate(zip(self.blocks, where)))

    def spot(self, p_WB, yaw: float) -> int:
        key = (round(float(p_WB[0]), 6), round(float(p_WB[1]), 6), round(float(yaw), 6))
        if key not in self._spot_index:
            self._spot_index[key] = len(self.spots)
            self.spots.append((np.asarray(p_WB, float), float(yaw)))
        return -1 - self._spot_index[key]

    def bound(self, p_from, p_to):
        return carry_bound(p_from, p_to, approach_height=self.h, slices_per_phase=self.S)

    # -- the pose level: closed-form IK of a carry's keyframes
    def reachable(self, p_WB, yaw: float) -> bool:
        """Whether the arm reaches the pose from above and the point approach_height
        above it at the same quarter turn, branch and swivel (as the planner seeds)."""
        key = (round(float(p_WB[0]), 6), round(float(p_WB[1]), 6), round(float(p_WB[2]), 6), round(float(yaw), 6))
        if key not in self._reach:
            swivels = np.linspace(-np.pi, np.pi, SWIVELS, endpoint=False)
            up = np.array([0.0, 0.0, self.h])
            poses = [(np.asarray(p_WB, float), float(yaw))] + ([(np.asarray(p_WB, float) + up, float(yaw))] if self.h > 0 else [])
            _, ok = self.arm.ik_grids_from_above(poses, swivels, margin=SEED_MARGIN)
            self._reach[key] = bool(np.all(ok, axis=0).any())
        return self._reach[key]

    # -- which blocks are final, clear, in the way
    def final_from_start(self) -> tuple[int, ...]:
        """Blocks of A already at a slot pose of their colour, on supports that are
        themselves final (or fixed): where (1 + j) for those, 0 for the rest."""
        where = [0] * len(self.blocks)
        graph_A = support_graph(self.initial)
        index_A = {b.name: i for i, b in enumerate(self.blocks)}
        taken = set()

        def final(i, seen=()):
            if where[i] > 0:
                return True
            if i in seen:
                return False
            b = self.blocks[i]
            for j, s in enumerate(self.slots):
                if j in taken or s.colour != b.colour or not same_pose(b.p_WB, b.yaw, s.p_WB, s.yaw, b.size):
                    continue
                if all(n in self.fixed_names or final(index_A[n], seen + (i,)) for n in graph_A[b.name]):
                    where[i] = 1 + j
                    taken.add(j)
                    return True
            return False

        for i in range(len(self.blocks)):
            final(i)
        return tuple(where)

    def settled(self, where, scene: Scene, above: dict) -> bool:
        """Whether no state reachable from this one is stuck: no block outside the
        slots has a block on it or stands in an unfilled slot's volume. Then every
        ready slot's volume stays free and its colour has a clear block (the
        colour count is checked by the bound), and nothing ever covers such a
        block again: a placed block rests only on slots. So set-asides never
        happen below, and direct carries bound the rest."""
        movers = [i for i, w in enumerate(where) if w <= 0]
        if any(above[self.blocks[i].name] for i in movers):
            return False
        unfilled = [s for j, s in enumerate(self.slots) if (1 + j) not in where]
        if not unfilled:
            return True
        return not any(_enters_any(scene.blocks[i], _near(scene.blocks[i], unfilled)) for i in movers)

    def remaining_bound(self, where, settled: bool = False) -> tuple[float, float]:
        """Two estimates of the effort still to come, by minimum-cost assignment of
        a distinct block of its colour, not in a slot, to every unfilled slot:

        - a lower bound: each carried from where it is now, directly or (a block
          still at its start, which may yet be set aside) via one set-aside, the
          better of one carry and two through the midpoint;
        - the guide: direct carries only (what the best-first order follows; it is
          the bound whenever no set-aside is to come, as on every paper trial).

        The two agree when the state is `settled`. (inf, inf) when the colours
        cannot fill the slots."""
        free = [j for j in range(len(self.slots)) if (1 + j) not in where]
        if not free:
            return 0.0, 0.0
        movers = [i for i, w in enumerate(where) if w <= 0]
        if len(movers) < len(free):
            return np.inf, np.inf
        ok = np.array([[self.colour[i] == self.slot_colour[j] for j in free] for i in movers])
        if not ok.any(axis=0).all():
            return np.inf, np.inf
        p_from = np.array([self.pose(i, where[i])[0] for i in movers])
        p_to = self.slot_p[free]
        direct = self.bound(p_from[:, None], p_to[None])
        relay = 2 * self.bound(p_from[:, None], (p_from[:, None] + p_to[None]) / 2)
        at_start = np.array([where[i] == 0 for i in movers])
        out = []
        lower = direct if settled else np.where(at_start[:, None], np.minimum(direct, relay), direct)
        for cost in (lower, direct):
            big = 1e6 + cost.max()
            rows, cols = linear_sum_assignment(np.where(ok, cost, big))
            if not ok[rows, cols].all() or len(cols) < len(free):
                return np.inf, np.inf
            out.append(float(cost[rows, cols].sum()))
        return out[0], out[1]


def candidate_spots(problem: _Problem, scene: Scene, block: int, free_slots: list[int]) -> list[tuple[float, np.ndarray]]:
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


# ----------------------------------------------------------------------------- the search


def _children(problem: _Problem, node: _Node, spots_per_set_aside: int):
    """(child node, its g) for every legal carry from `node`: clear blocks into
    ready slots of their colour; set-asides only when no such carry exists."""
    where = node.where
    scene = problem.scene(where)
    above = supported_by(support_graph(scene))
    settled = node.settled or problem.settled(where, scene, above)
    names = [b.name for b in problem.blocks]
    filled = {w - 1 for w in where if w > 0}
    clear = [i for i, w in enumerate(where) if w <= 0 and not above[names[i]] and not (w == 0 and problem.pinned[i])]
    out = []
    ready = [j for j in range(len(problem.slots)) if j not in filled and all(k in filled for k in problem.slot_below[j])]
    for j in ready:
        slot = problem.slots[j]
        for i in clear:
            if problem.colour[i] != slot.colour:
                continue
            moved = scene.blocks[i].moved_to(slot.p_WB, slot.yaw)
            if _enters_any(moved, [o for o in _near(moved, (*scene.blocks, *scene.fixed)) if o.name != moved.name]):
                continue
            if not problem.reachable(slot.p_WB, slot.yaw):
                continue
            out.append((i, 1 + j))
    if not out:
        free = [j for j in range(len(problem.slots)) if j not in filled]
        for i in clear:
            if where[i] != 0:
                continue  # set aside at most once
            taken = 0
            for _, p in candidate_spots(problem, scene, i, free):
                if taken == spots_per_set_aside:
                    break
                if problem.reachable(p, 0.0):
                    out.append((i, problem.spot(p, 0.0)))
                    taken += 1
    children = []
    for i, w in out:
        p_from, _ = problem.pose(i, where[i])
        p_to, _ = problem.pose(i, w)
        new = list(where)
        new[i] = w
        g = node.g + float(problem.bound(p_from, p_to))
        children.append(_Node(tuple(new), node.carries + ((i, w),), g, settled))
    return children


def _symbolic(problem: _Problem, carries) -> SymbolicPlan:
    """The skeleton (Grasp, Place) of a sequence of carries, checked by lgp.symbolic.apply."""
    where = list(problem.final_from_start())
    names = [b.name for b in problem.blocks]
    slot_of = {i: w - 1 for i, w in enumerate(where) if w > 0}
    actions = []
    for i, w in carries:
        p, yaw = problem.pose(i, w)
        if w > 0:
            j = w - 1
            slot_of[i] = j
            block_in = {s: names[k] for k, s in slot_of.items()}
            onto = tuple(problem.slot_ground[j]) + tuple(block_in[k] for k in problem.slot_below[j])
        else:
            onto = (TABLE,)
        actions += [Grasp(names[i]), Place(names[i], onto, np.array(p, float), float(yaw))]
        where[i] = w
    assignment = {names[i]: problem.slots[j].name for i, j in slot_of.items()}
    plan = SymbolicPlan(problem.initial, problem.target, assignment, tuple(actions))
    state, support = PlanState(problem.initial), _support_memo()
    for action in plan.actions:  # every action legal (lgp.symbolic.apply), or IllegalActionError
        state = apply(action, state, support=support)
    return plan


def search(initial: Scene, target: Scene, rng_or_seed=0, *, budget: Budget | None = None,
           approach_height: float = APPROACH, slices_per_phase: int = SLICES_PER_PHASE, formulation: str = "reduced",
           solver: str = "snopt", arm=None, spots_per_set_aside: int = SPOTS_PER_SET_ASIDE,
           paper_first: bool = True) -> SearchResult:
    """The least-effort plan the search finds for building `target` from `initial`.

    Best-first (A*) over symbolic states, ordered by the lower bound g + h (ties:
    deeper first). A complete skeleton popped with a bound below the incumbent's
    effort is solved by KOMO (lgp.planner.plan_symbolic; all solves draw from one
    Generator). With `paper_first`, the paper's skeleton (assign_blocks +
    symbolic_plan) is solved before the search starts, with the Generator in the
    state lgp.planner.plan would use: the result's effort is then never above
    the paper planner's. Stops when no open branch's bound is below the
    incumbent (gap closed) or the budget runs out; raises SearchError (a
    PlanningError) when no plan is found, saying whether the task has none or
    the budget ran out, with the best bound reached.
    """
    start = time.perf_counter()
    budget = budget or Budget()
    design = Design.of(None, approach_height, slices_per_phase)
    approach_height, slices_per_phase = design.approach_height, design.slices_per_phase
    arm = arm or default_arm()
    rng = rng_or_seed if isinstance(rng_or_seed, np.random.Generator) else np.random.default_rng(rng_or_seed)
    label = f"{initial.label} -> {target.label}"
    problem = _Problem(initial, target, approach_height, slices_per_phase, arm)
    options = dict(formulation=formulation, solver=solver, slices_per_phase=slices_per_phase,
                   approach_height=approach_height, arm=arm)
    best: tuple[float, Plan, float] | None = None  # (effort, plan, skeleton bound)
    tried: list = []
    solves = 0
    paper_effort, paper_symbolic = None, None

    komo_seconds = 0.0

    def solve(symbolic: SymbolicPlan, bound: float) -> None:
        nonlocal best, solves, komo_seconds
        solves += 1
        t0 = time.perf_counter()
        try:
            result = plan_symbolic(symbolic, rng, **options)
        except PlanningError as e:
            tried.append((bound, f"failed: {e}"))
            return
        finally:
            komo_seconds += time.perf_counter() - t0
        sweep = first_sweep(result)
        if sweep is not None:
            tried.append((bound, f"rejected: {sweep}"))
            return
        effort = kinetic_energy(result)
        tried.append((bound, effort))
        if best is None or effort < best[0]:
            best = (effort, result, bound)

    if paper_first:
        try:
            paper_symbolic = symbolic_plan(initial, target, assign_blocks(initial, target))
        except SymbolicPlanningError:
            paper_symbolic = None
        if paper_symbolic is not None:
            solve(paper_symbolic, skeleton_bound(paper_symbolic, approach_height=approach_height,
                                                 slices_per_phase=slices_per_phase))
            if best is not None:
                paper_effort = best[0]

    root = _Node(problem.final_from_start(), (), 0.0, False)
    h0, guide0 = problem.remaining_bound(root.where, False)
    paper_key = None
    if paper_symbolic is not None:
        index = {b.name: i for i, b in enumerate(problem.blocks)}
        slot = {s.name: j for j, s in enumerate(problem.slots)}
        paper_key = frozenset((index[a.block], 1 + slot[paper_symbolic.assignment[a.block]])
                              for a in paper_symbolic.actions if isinstance(a, Place))
    counter = itertools.count()
    # Entries (guide g + h_direct rounded, -depth, count, lower bound g + h, node): popped
    # in the guide's order (it dives along the bound's best assignment; the lower
    # bound alone also counts relays no move takes and goes wide); pruned, and
    # reported, by the lower bound.
    queue = [] if not np.isfinite(h0) else [(round(guide0, 12), 0, next(counter), h0, root)]
    # Branches that make the same carries in another order are one branch (the
    # bound cannot tell orders apart): the first order found is kept.
    seen: set = {frozenset()}
    expansions = 0
    stopped = "gap closed"

    def out_of_budget():
        if solves >= budget.solves:
            return "solve budget"
        if time.perf_counter() - start >= budget.seconds:
            return "time budget"
        if expansions >= budget.expansions:
            return "expansion budget"
        return None

    def entries(node):
        """Queue entries of the children of `node` (one expansion), best guide first."""
        nonlocal expansions
        expansions += 1
        out = []
        for child in _children(problem, node, spots_per_set_aside):
            key = frozenset(child.carries)
            if key in seen:
                continue
            h, guide = problem.remaining_bound(child.where, child.settled)
            f_child = child.g + h
            if not np.isfinite(h) or (best is not None and f_child >= best[0]):
                continue
            seen.add(key)
            out.append((round(child.g + guide, 12), -len(child.carries), next(counter), f_child, child))
        return sorted(out)

    complete = lambda node: all((1 + j) in node.where for j in range(len(problem.slots)))  # noqa: E731
    while queue:
        reason = out_of_budget()
        if reason:
            stopped = reason
            break
        entry = heapq.heappop(queue)
        # A dive (anytime best-first): from the best open branch down its best child
        # to a complete skeleton, the other children queued. Every pop ends in a
        # skeleton within a plan's depth of expansions.
        while entry is not None:
            f, node = entry[3], entry[4]
            if best is not None and f >= best[0]:
                break  # pruned
            if complete(node):
                if frozenset(node.carries) != paper_key:
                    solve(_symbolic(problem, node.carries), node.g)
                break
            if out_of_budget():
                heapq.heappush(queue, entry)  # still open
                break
            children = entries(node)
            for other in children[1:]:
                heapq.heappush(queue, other)
            entry = children[0] if children else None
    else:
        stopped = "gap closed" if best is not None else "exhausted"
    # The bound of the best unexplored branch: the lowest lower bound left in the queue.
    open_bounds = [entry[3] for entry in queue if best is None or entry[3] < best[0]]
    lowest_open = min(open_bounds, default=np.inf)

    seconds = time.perf_counter() - start
    if best is None:
        if stopped in ("exhausted", "gap closed"):
            why = "; ".join(str(t[1]) for t in tried) or "no sequence of carries reaches B"
            raise SearchError(f"{label}: no plan: every branch of the search explored ({expansions} expansions), "
                              f"{why}", "unsolvable", float(lowest_open))
        raise SearchError(f"{label}: {stopped} ran out before any plan was found ({solves} KOMO solves, "
                          f"{expansions} expansions, {seconds:.1f} s); best lower bound {lowest_open:.4f} J s",
                          "budget", float(lowest_open))
    effort, result, bound = best
    result.planning_time = seconds
    return SearchResult(result, effort, min(float(lowest_open), effort), bound, solves, expansions, seconds, stopped,
                        paper_effort, paper_symbolic, tried, komo_seconds)


# ----------------------------------------------------------------------------- planner="paper" | "search"

#: The planners `plan` dispatches to: the paper's pipeline (the default; it
#: reproduces the paper) and this search.
PLANNERS = ("paper", "search")


def check_planner(planner: str) -> str:
    """`planner` if it is one of PLANNERS, else InputError naming them."""
    if planner not in PLANNERS:
        raise InputError(f"planner must be one of {', '.join(PLANNERS)}, got {planner!r}")
    return planner


def plan(initial: Scene, target: Scene, rng_or_seed=0, *, planner: str = "paper", budget: Budget | None = None,
         **options) -> Plan:
    """lgp.plan: the paper's pipeline (planner="paper", lgp.planner.plan) or the
    search (planner="search", `search`; its SearchResult is the plan's `search`
    attribute: skeleton, effort, bound, gap). `options` are the planner's
    (formulation, solver, slices_per_phase, approach_height, arm)."""
    from lgp import planner as paper

    if check_planner(planner) == "paper":
        if budget is not None:
            raise InputError("a budget applies to planner='search' only")
        return paper.plan(initial, target, rng_or_seed, **options)
    result = search(initial, target, rng_or_seed, budget=budget, **options)
    result.plan.search = result
    return result.plan


def describe_search(plan: Plan) -> str:
    """'' for a plan of the paper's pipeline; for a searched plan one line: its
    skeleton's bound, the best unexplored bound, the gap and what the search cost."""
    result = getattr(plan, "search", None)
    if result is None:
        return ""
    gap = 100 * result.gap / result.effort if result.effort > 0 else 0.0
    paper = f", paper's skeleton {result.paper_effort:.4f} J s" if result.paper_effort is not None else ", no paper skeleton"
    return (f"search: bound {result.bound:.4f} J s (best unexplored branch), gap {result.gap:.4f} J s ({gap:.1f} %), "
            f"this skeleton's bound {result.skeleton_bound:.4f} J s, {result.set_asides} set-asides{paper}; "
            f"{result.solves} KOMO solves, {result.expansions} expansions, stopped: {result.stopped}")
