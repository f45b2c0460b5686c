"""The paper's planner end to end: assignment -> symbolic plan -> KOMO -> Plan.

`plan(initial, target)` runs the three stages of "Modeling physical effort":
`assign_blocks` (Hungarian, colours), `symbolic_plan` (grasp/place order from the
support graphs) and KOMO (lgp.komo) on the arm of models/arm.sdf. The logic layer
meets the geometry only through the skeleton: action k at phase k. The package,
by idea (as rai keeps KOMO apart from its skeleton and manipulation helpers):

- `design`: the motion `Design` (approach legs, slices per phase) and the
  planner's constants; no Drake, so command lines and cache keys use it freely;
- `skeleton`: the skeleton's transcription to KOMO (waypoints, objectives, mode
  switches on the phase clock);
- `seeding`: quarter turns, elbow swivels and IK branches chosen globally by
  dynamic programming over closed-form IK, seeding KOMO (`declare`);
- `turns`: quarter-turn re-solves after KOMO where a closed form predicts a
  lower cost;
- `clearance`: the design without legs (approach_height = 0), each carry kept
  clear of the table and the other solids by constraints added where needed.

With the default design every block leaves its support and arrives on its target
moving vertically (to within 1 mm, tests/test_komo.py) for the last 5 cm (two
block heights), and is carried 5 cm above both its start and its target; between
those waypoints KOMO is free. Plans start and end at rest at the arm's home
posture. The approach legs are a modelling choice the paper does not make
(docs/effort.md): `plan(..., approach_height=h)` moves the waypoints h m above
the poses, and `approach_height=0` drops them for the clearance design.

Importing this package loads no Drake (the submodules that need it are imported
when planning), so `from lgp.planner import Design, APPROACH` is light.
"""
from __future__ import annotations

import time
from dataclasses import dataclass, field

import numpy as np

from lgp.assignment import assign_blocks
from lgp.planner.design import (  # noqa: F401  (the planner's public names)
    APPROACH, APPROACH_TIME, DEFAULT_DESIGN, DEFAULT_EFFORT, MAX_APPROACH_HEIGHT, PHASE_DURATION, PLANNERS,
    SLICES_PER_PHASE, Budget, Design, DesignError, EffortSpec, Planner, PlanningError, check_approach_height,
    check_planner, check_slices_per_phase)
from lgp.scene import Scene
from lgp.symbolic import SymbolicPlan, symbolic_plan

# Arm (lgp.arm) and KomoResult (lgp.komo) appear in annotations only: both load Drake;
# SearchResult (lgp.search) too: the search imports this module.
_ARM = None


def default_arm() -> "Arm":
    """The arm of models/arm.sdf + models/arm.yaml, loaded once per process."""
    from lgp.arm import Arm

    global _ARM
    if _ARM is None:
        _ARM = Arm()
    return _ARM


@dataclass
class Plan:
    """A solved plan: actions, arm trajectory and every block's world trajectory.

    `t` (n,) s and `q` (n, 7) rad per slice, time 0 first; `p_WB[name]` (n, 3) and
    `R_WB[name]` (n, 3, 3) for every block of the initial scene (by its A name).
    The effort of a plan is measured from these trajectories by the effort model
    (models.effort.kinetic_energy), not here.
    """

    initial: Scene
    target: Scene
    symbolic: SymbolicPlan
    t: np.ndarray
    q: np.ndarray
    p_WB: dict[str, np.ndarray]
    R_WB: dict[str, np.ndarray]
    komo: KomoResult | None = None
    arm: Arm | None = field(default=None, repr=False)
    planning_time: float = 0.0  # wall-clock s: assignment, symbolic plan, seeding, KOMO
    #: what the search found (lgp.search.SearchResult: bound, gap, cost) when the
    #: search made this plan; None for the paper's pipeline
    search: SearchResult | None = field(default=None, repr=False)

    @property
    def actions(self):
        return self.symbolic.actions

    @property
    def tau(self) -> float:
        return float(self.t[1] - self.t[0]) if len(self.t) > 1 else 1.0

    def speed(self, name: str) -> np.ndarray:
        """Speed |v_WB| (m/s) of a block's centre at each slice (0 at time 0)."""
        v = np.diff(self.p_WB[name], axis=0) / self.tau
        return np.concatenate([[0.0], np.linalg.norm(v, axis=1)])

    def __repr__(self) -> str:
        """One line: scene, actions, duration, KOMO status, planning time; the arrays
        stay behind the attributes (t, q, p_WB, R_WB). The effort is the effort
        model's measure of the plan (models.effort.kinetic_energy), not the plan's."""
        actions = self.actions
        shown = " -> ".join(map(str, actions[:2])) + (" -> ..." if len(actions) > 2 else "")
        # not the optimiser's objective ("cost 2124" read as effort): the effort is models.effort.kinetic_energy(plan)
        komo = f", {self.komo.solver} {self.komo.status}" if self.komo is not None else ""
        duration = float(self.t[-1] - self.t[0]) if len(self.t) else 0.0
        return (f"Plan({self.initial.label or 'scene'}: {len(actions)} actions [{shown}], "
                f"{duration:g} s in {len(self.t)} slices{komo}, planned in {self.planning_time:.2f} s)")


def plan(initial: Scene, target: Scene, rng_or_seed=0, *, formulation: str = "reduced", solver: str = "snopt",
         slices_per_phase: int | None = None, approach_height: float | None = None, design: Design | None = None,
         arm: "Arm | None" = None) -> Plan:
    """Plan the construction of `target` from `initial`: assignment, symbolic plan, KOMO.

    `rng_or_seed` (a numpy Generator or seed) jitters the swivel grid of the IK
    seeding only; the optimum does not depend on it (tests/test_planner.py).
    The motion design is `design` (a `Design`) or, the same, `approach_height`
    (m, default APPROACH = 0.05: the vertical approach and retreat leg at every
    grasp and place; 0 replaces the legs by a clearance constraint on every
    carry, planned from the legs design's plan (`solver`) by CLEARANCE_SOLVER)
    and `slices_per_phase` (default SLICES_PER_PHASE = 20: the time step is
    1 s / slices_per_phase).
    Raises PlanningError (naming the action) when a waypoint is out of reach or
    KOMO fails to satisfy a constraint; DesignError (a ValueError) for a bad
    height or slice count.
    """
    start = time.perf_counter()
    design = Design.of(design, approach_height, slices_per_phase)
    rng = rng_or_seed if isinstance(rng_or_seed, np.random.Generator) else np.random.default_rng(rng_or_seed)
    assignment = assign_blocks(initial, target)
    symbolic = symbolic_plan(initial, target, assignment)
    result = plan_symbolic(symbolic, rng, formulation=formulation, solver=solver, design=design, arm=arm or default_arm())
    result.planning_time = time.perf_counter() - start
    return result


def plan_symbolic(symbolic: SymbolicPlan, rng=0, *, formulation: str = "reduced", solver: str = "snopt",
                  slices_per_phase: int | None = None, approach_height: float | None = None,
                  design: Design | None = None, arm: "Arm | None" = None) -> Plan:
    """KOMO for a given symbolic plan (see `plan`)."""
    from lgp.planner import clearance, seeding, turns

    start = time.perf_counter()
    design = Design.of(design, approach_height, slices_per_phase)
    arm = arm or default_arm()
    rng = rng if isinstance(rng, np.random.Generator) else np.random.default_rng(rng)
    initial = symbolic.initial
    names = initial.names
    if not symbolic.actions:
        n = len(names)
        return Plan(initial, symbolic.target, symbolic, np.zeros(1), arm.q_home[None].copy(),
                    {b.name: b.p_WB[None].copy() for b in initial}, {b.name: b.X_WB.rotation().matrix()[None] for b in initial} if n else {},
                    None, arm)
    try:
        if design.legs:
            komo, seeds, quarter_turns = seeding.declare(symbolic, arm, rng, design)
        else:
            komo, result = clearance.plan_with_clearance(symbolic, arm, rng, formulation, solver, design.slices_per_phase)
    except PlanningError as e:
        raise PlanningError(f"{initial.label} -> {symbolic.target.label}: {e}", e.action) from None
    if design.legs:
        komo, result, _ = turns.solve(symbolic, arm, komo, seeds, quarter_turns, formulation, solver, design)
    if not clearance.usable(result, design.approach_height):
        o = result.worst_objective
        k = int(round(o.time[0])) if o is not None and o.time else None
        action = symbolic.actions[k - 1] if k and 1 <= k <= len(symbolic.actions) else None
        where = f"action {k} {action}" if action else "joint limits"
        raise PlanningError(
            f"{initial.label} -> {symbolic.target.label}: KOMO ({formulation}, "
            f"{solver if design.legs else clearance.CLEARANCE_SOLVER}) failed at {where}: "
            f"{result.status}, constraint violation {result.max_violation:.2e}", action)
    return Plan(initial, symbolic.target, symbolic, result.t, result.q,
                {n: result.X_WB[n][:, :3, 3].copy() for n in names},
                {n: result.X_WB[n][:, :3, :3].copy() for n in names}, result, arm, time.perf_counter() - start)


#: Names of the Drake-using submodules, re-exported here on first use.
_LAZY = {"seeding": ("declare", "SWIVELS", "SEED_MARGIN"), "skeleton": ("carried_slices",), "turns": ("TURN_RESOLVES",),
         "clearance": ("CLEARANCE_ROUNDS", "CLEARANCE_MARGIN", "REFERENCE_SLACK", "CLEARANCE_SOLVER", "CLEARANCE")}


def __getattr__(name: str):
    if any(name in names for names in _LAZY.values()):
        from lgp.planner import clearance, seeding, skeleton, turns

        modules = {"seeding": seeding, "skeleton": skeleton, "turns": turns, "clearance": clearance}
        return next(getattr(modules[m], name) for m, names in _LAZY.items() if name in names)
    raise AttributeError(f"module 'lgp.planner' has no attribute {name!r}")
