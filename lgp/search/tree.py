"""The search tree and its best-first search: symbolic states (`_Node`), their
children (legal carries and set-asides), the skeleton of a branch, and `search`
with what it takes and returns (`Budget`, `SearchResult`, `SearchError`)."""
from __future__ import annotations

import heapq
import itertools
import time
from dataclasses import dataclass, field
from enum import StrEnum

import numpy as np

from lgp.assignment import assign_blocks
from lgp.planner import Budget, Design, Plan, PlanningError, default_arm, plan_symbolic
from lgp.scene import TABLE, Scene, support_graph, supported_by
from lgp.search.bound import kinetic_energy, skeleton_bound
from lgp.search.problem import Problem
from lgp.search.spots import SPOTS_PER_SET_ASIDE, candidate_spots
from lgp.search.sweep import first_sweep
from lgp.symbolic import (Grasp, Place, PlanState, SymbolicPlan, SymbolicPlanningError, enters_any, nearby_solids,
                          support_memo, apply, symbolic_plan)


class StopReason(StrEnum):
    """Why the search stopped: the gap closed (no open branch can beat the plan
    found), every branch was explored without a plan, or a budget ran out."""

    GAP_CLOSED = "gap closed"
    EXHAUSTED = "exhausted"
    SOLVE_BUDGET = "solve budget"
    TIME_BUDGET = "time budget"
    EXPANSION_BUDGET = "expansion budget"


class NoPlan(StrEnum):
    """Why the search found no plan: every branch explored or pruned and none
    reaches B ("unsolvable"), or the budget ran out first ("budget")."""

    UNSOLVABLE = "unsolvable"
    BUDGET = "budget"


class SearchError(PlanningError):
    """The search found no plan: `reason` a NoPlan; `bound` is the best lower
    bound on effort (J s) reached, inf when no skeleton exists."""

    def __init__(self, message: str, reason: NoPlan, bound: float):
        super().__init__(message)
        self.reason, self.bound = NoPlan(reason), bound


@dataclass
class SearchResult:
    """The least-effort plan found, and the gap to the best bound left open.

    `effort` (J s) is the plan's block kinetic energy (`kinetic_energy`, the same
    integral as models.effort.kinetic_energy); `bound` the lowest lower bound of
    any branch left unexplored (inf when none is left), capped at `effort`; `gap`
    = effort - bound >= 0.

    What is guaranteed (tests/test_search.py checks it): `effort` is never above
    the paper planner's on the same layout (its skeleton is solved first). A
    closed gap (0) says only that no other *set of carries* the search admits
    (assignment, set-asides) has a bound below `effort`. It is not least effort
    over skeletons: carries that differ only in order are one branch, solved in
    the first order found, and the order changes KOMO's effort under an identical
    bound (2H, layout 0: the same four carries in reverse order cost 0.23 % less).
    `paper` is the paper planner's skeleton when it exists and was solved, with
    its effort; `solves`, `expansions`, `seconds` what it cost.
    """

    plan: Plan
    effort: float
    bound: float
    skeleton_bound: float
    solves: int
    expansions: int
    seconds: float
    stopped: StopReason
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


# ----------------------------------------------------------------------------- symbolic states


@dataclass(frozen=True)
class _Node:
    """A symbolic state: where every block of A is (0 = where it started, 1 + j =
    slot j of B, -1 - k = set-aside spot k of `spots`), the carries that led here
    (block, destination), and the bound g so far."""

    where: tuple[int, ...]
    carries: tuple[tuple[int, int], ...]
    g: float
    settled: bool  # no state below can be stuck (Problem.settled), so no set-aside is to come


# ----------------------------------------------------------------------------- the search


def _children(problem: Problem, node: _Node, spots_per_set_aside: int):
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
            if enters_any(moved, [o for o in nearby_solids(moved, (*scene.blocks, *scene.fixed)) if o.name != moved.name]):
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


def _symbolic(problem: Problem, carries) -> SymbolicPlan:
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
    state, support = PlanState(problem.initial), support_memo()
    for action in plan.actions:  # every action legal (lgp.symbolic.apply), or IllegalActionError
        state = apply(action, state, support=support)
    return plan


class _Search:
    """One search's state: the incumbent plan, the queue of open branches and what
    the search has cost so far. `solve` tries a complete skeleton with KOMO; `run`
    dives from the best open branch until the gap closes or the budget runs out."""

    def __init__(self, problem: Problem, rng: np.random.Generator, options: dict, budget: Budget,
                 spots_per_set_aside: int, start: float):
        self.problem, self.rng, self.options, self.budget = problem, rng, options, budget
        self.spots_per_set_aside, self.start = spots_per_set_aside, start
        self.best: tuple[float, Plan, float] | None = None  # (effort, plan, skeleton bound)
        self.tried: list = []
        self.solves = self.expansions = 0
        self.komo_seconds = 0.0
        self.counter = itertools.count()
        # Branches that make the same carries in another order are one branch (the
        # bound cannot tell orders apart): the first order found is kept.
        self.seen: set = {frozenset()}
        self.queue: list = []

    def solve(self, symbolic: SymbolicPlan, bound: float) -> None:
        """KOMO on one skeleton; a plan that beats the incumbent becomes it."""
        self.solves += 1
        t0 = time.perf_counter()
        try:
            result = plan_symbolic(symbolic, self.rng, **self.options)
        except PlanningError as e:
            self.tried.append((bound, f"failed: {e}"))
            return
        finally:
            self.komo_seconds += time.perf_counter() - t0
        sweep = first_sweep(result)
        if sweep is not None:
            self.tried.append((bound, f"rejected: {sweep}"))
            return
        effort = kinetic_energy(result)
        self.tried.append((bound, effort))
        if self.best is None or effort < self.best[0]:
            self.best = (effort, result, bound)

    def out_of_budget(self) -> StopReason | None:
        if self.solves >= self.budget.solves:
            return StopReason.SOLVE_BUDGET
        if time.perf_counter() - self.start >= self.budget.seconds:
            return StopReason.TIME_BUDGET
        if self.expansions >= self.budget.expansions:
            return StopReason.EXPANSION_BUDGET
        return None

    def entries(self, node: _Node) -> list:
        """Queue entries of the children of `node` (one expansion), best guide first.

        An entry is (guide g + h_direct rounded, -depth, count, lower bound g + h,
        node): popped in the guide's order (it dives along the bound's best
        assignment; the lower bound alone also counts relays no move takes and goes
        wide); pruned, and reported, by the lower bound."""
        self.expansions += 1
        out = []
        for child in _children(self.problem, node, self.spots_per_set_aside):
            key = frozenset(child.carries)
            if key in self.seen:
                continue
            h, guide = self.problem.remaining_bound(child.where, child.settled)
            f_child = child.g + h
            if not np.isfinite(h) or (self.best is not None and f_child >= self.best[0]):
                continue
            self.seen.add(key)
            out.append((round(child.g + guide, 12), -len(child.carries), next(self.counter), f_child, child))
        return sorted(out)

    def complete(self, node: _Node) -> bool:
        return all((1 + j) in node.where for j in range(len(self.problem.slots)))

    def dive(self, entry, paper_key) -> None:
        """A dive (anytime best-first): from the best open branch down its best child
        to a complete skeleton, the other children queued. Every pop ends in a
        skeleton within a plan's depth of expansions."""
        while entry is not None:
            f, node = entry[3], entry[4]
            if self.best is not None and f >= self.best[0]:
                return  # pruned
            if self.complete(node):
                if frozenset(node.carries) != paper_key:
                    self.solve(_symbolic(self.problem, node.carries), node.g)
                return
            if self.out_of_budget():
                heapq.heappush(self.queue, entry)  # still open
                return
            children = self.entries(node)
            for other in children[1:]:
                heapq.heappush(self.queue, other)
            entry = children[0] if children else None

    def run(self, paper_key) -> StopReason:
        """Dive from the root until no open branch is left or the budget runs out."""
        root = _Node(self.problem.final_from_start(), (), 0.0, False)
        h0, guide0 = self.problem.remaining_bound(root.where, False)
        if np.isfinite(h0):
            self.queue.append((round(guide0, 12), 0, next(self.counter), h0, root))
        while self.queue:
            reason = self.out_of_budget()
            if reason:
                return reason
            self.dive(heapq.heappop(self.queue), paper_key)
        return StopReason.GAP_CLOSED if self.best is not None else StopReason.EXHAUSTED

    def lowest_open(self) -> float:
        """The bound of the best unexplored branch: the lowest lower bound left in the queue."""
        return float(min((e[3] for e in self.queue if self.best is None or e[3] < self.best[0]), default=np.inf))


def _paper_key(problem: Problem, paper_symbolic: SymbolicPlan) -> frozenset:
    """The carries (block index, 1 + slot index) of the paper's skeleton: the search does not solve them again."""
    index = {b.name: i for i, b in enumerate(problem.blocks)}
    slot = {s.name: j for j, s in enumerate(problem.slots)}
    return frozenset((index[a.block], 1 + slot[paper_symbolic.assignment[a.block]])
                     for a in paper_symbolic.actions if isinstance(a, Place))


def search(initial: Scene, target: Scene, rng_or_seed=0, *, budget: Budget | None = None,
           approach_height: float | None = None, slices_per_phase: int | None = None, design: Design | None = None,
           formulation: str = "reduced", solver: str = "snopt", arm=None,
           spots_per_set_aside: int = SPOTS_PER_SET_ASIDE, paper_first: bool = True) -> SearchResult:
    """The least-effort plan the search finds for building `target` from `initial`.

    Best-first (A*) over symbolic states, ordered by the lower bound g + h (ties:
    deeper first). A complete skeleton popped with a bound below the incumbent's
    effort is solved by KOMO (lgp.planner.plan_symbolic; all solves draw from one
    Generator). With `paper_first`, the paper's skeleton (assign_blocks +
    symbolic_plan) is solved before the search starts, with the Generator in the
    state lgp.planner.plan would use: the result's effort is then never above
    the paper planner's. Stops when no open branch's bound is below the
    incumbent (gap closed: no other set of carries can beat it; other orders of
    the same carries are not tried, see SearchResult) or the budget runs out; raises SearchError (a
    PlanningError) when no plan is found, saying whether the task has none or
    the budget ran out, with the best bound reached. The motion design is
    `design` or its two values (None: the default), as for lgp.planner.plan.
    """
    start = time.perf_counter()
    budget = budget or Budget()
    design = Design.of(design, approach_height, slices_per_phase)
    approach_height, slices_per_phase = design.approach_height, design.slices_per_phase
    arm = arm or default_arm()
    rng = rng_or_seed if isinstance(rng_or_seed, np.random.Generator) else np.random.default_rng(rng_or_seed)
    label = f"{initial.label} -> {target.label}"
    problem = Problem(initial, target, approach_height, slices_per_phase, arm)
    options = dict(formulation=formulation, solver=solver, slices_per_phase=slices_per_phase,
                   approach_height=approach_height, arm=arm)
    state = _Search(problem, rng, options, budget, spots_per_set_aside, start)
    paper_effort, paper_symbolic = None, None
    if paper_first:
        try:
            paper_symbolic = symbolic_plan(initial, target, assign_blocks(initial, target))
        except SymbolicPlanningError:
            paper_symbolic = None
        if paper_symbolic is not None:
            state.solve(paper_symbolic, skeleton_bound(paper_symbolic, approach_height=approach_height,
                                                       slices_per_phase=slices_per_phase))
            if state.best is not None:
                paper_effort = state.best[0]
    stopped = state.run(None if paper_symbolic is None else _paper_key(problem, paper_symbolic))
    lowest_open = state.lowest_open()
    seconds = time.perf_counter() - start
    if state.best is None:
        raise _no_plan(label, stopped, state, seconds, lowest_open)
    effort, result, bound = state.best
    result.planning_time = seconds
    found = SearchResult(result, effort, min(lowest_open, effort), bound, state.solves, state.expansions, seconds,
                         stopped, paper_effort, paper_symbolic, state.tried, state.komo_seconds)
    result.search = found  # the plan carries what the search found (Plan.search)
    return found


def _no_plan(label: str, stopped: StopReason, state: _Search, seconds: float, lowest_open: float) -> SearchError:
    """The SearchError of a search that found no plan: unsolvable when every
    branch was explored, else the budget that ran out (with why each solve failed)."""
    if stopped in (StopReason.EXHAUSTED, StopReason.GAP_CLOSED):
        why = "; ".join(str(t[1]) for t in state.tried) or "no sequence of carries reaches B"
        return SearchError(f"{label}: no plan: every branch of the search explored ({state.expansions} expansions), "
                          f"{why}", NoPlan.UNSOLVABLE, lowest_open)
    solved = "".join(f"; {t[1]}" for t in state.tried)  # why each solve gave no plan (failed, or rejected by the sweep check)
    return SearchError(f"{label}: {stopped} ran out before any plan was found ({state.solves} KOMO solves, "
                      f"{state.expansions} expansions, {seconds:.1f} s{solved}); best lower bound {lowest_open:.4f} J s",
                      NoPlan.BUDGET, lowest_open)
