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
never returns more effort than the paper planner on the same layout. That is the
guarantee it gives. A closed gap is weaker than least effort: a branch is a *set*
of carries, solved in the first order found, and the order of the same carries
changes KOMO's effort while the bound cannot tell orders apart (tests/test_search.py;
docs/effort.md, "The search").

The package, by idea: `bound` (the effort and its lower bounds), `problem` (the
fixed data of one search and the bound still to come), `spots` (candidate
set-aside spots), `sweep` (a solved plan's carried blocks passing through
solids), `tree` (nodes, children, the best-first `search` and its Budget,
SearchResult, SearchError) and, here, `plan` (planner="paper" | "search").
"""
from __future__ import annotations

from lgp.errors import InputError
from lgp.planner import PLANNERS, Budget, Plan, Planner, check_planner  # noqa: F401
from lgp.scene import Scene
from lgp.search.bound import BLOCK_MASS, carry_bound, kinetic_energy, skeleton_bound  # noqa: F401
from lgp.search.spots import (SPOT_CLEARANCE, SPOT_PITCH, SPOT_REGION, SPOTS_PER_SET_ASIDE,  # noqa: F401
                              candidate_spots)
from lgp.search.sweep import SWEEP_TOLERANCE, first_sweep  # noqa: F401
from lgp.search.tree import NoPlan, SearchError, SearchResult, StopReason, search  # noqa: F401

# ----------------------------------------------------------------------------- planner="paper" | "search"


def plan(initial: Scene, target: Scene, rng_or_seed=0, *, planner: str = "paper", budget: Budget | None = None,
         **options) -> Plan:
    """lgp.plan: the paper's pipeline (planner="paper", lgp.planner.plan) or the
    search (planner="search", `search`; its SearchResult is the plan's `search`
    field: skeleton, effort, bound, gap). `options` are the planner's
    (formulation, solver, slices_per_phase, approach_height, arm)."""
    from lgp import planner as paper

    for name, scene in (("initial (state A)", initial), ("target (state B)", target)):
        if not isinstance(scene, Scene):
            raise InputError(f"lgp.plan: {name} must be an lgp.scene.Scene (e.g. a trial's sample_initial(rng) "
                             f"and .target), got {type(scene).__name__}")
    if check_planner(planner) is Planner.PAPER:
        if budget is not None:
            raise InputError("a budget applies to planner='search' only")
        return paper.plan(initial, target, rng_or_seed, **options)
    return search(initial, target, rng_or_seed, budget=budget, **options).plan


def describe_search(plan: Plan) -> str:
    """'' for a plan of the paper's pipeline; for a searched plan one line: its
    skeleton's bound, the best unexplored bound, the gap and what the search cost."""
    result = plan.search
    if result is None:
        return ""
    gap = 100 * result.gap / result.effort if result.effort > 0 else 0.0
    paper = f", paper's skeleton {result.paper_effort:.4f} J s" if result.paper_effort is not None else ", no paper skeleton"
    return (f"search: bound {result.bound:.4f} J s (best unexplored branch), gap {result.gap:.4f} J s ({gap:.1f} %), "
            f"this skeleton's bound {result.skeleton_bound:.4f} J s, {result.set_asides} set-asides{paper}; "
            f"{result.solves} KOMO solves, {result.expansions} expansions, stopped: {result.stopped}")
