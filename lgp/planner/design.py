"""The motion design of the planner and its constants: no Drake here.

Two modelling choices the paper leaves open (docs/effort.md, "Modelling choices")
make a `Design`: `approach_height`, the vertical approach/retreat leg (m) at every
grasp and place (0: no legs, each carry planned with a clearance constraint
instead), and `slices_per_phase`, KOMO's time step 1 s / slices_per_phase. A
Design is checked once, when it is made; the planner, the effort units, the
command lines (through `check_approach_height`) and the effort cache key all use
it, so the rule is written only here.

This module imports neither Drake nor the rest of the planner: a command line can
refuse a bad design, and a cache key be computed, before Drake loads.
"""
from __future__ import annotations

import math
from dataclasses import dataclass
from enum import StrEnum

from lgp.errors import InputError

#: Duration of one phase (one action) in seconds: a reach-and-place of a block in
#: about a second is human-like, and every phase has the same length, as in KOMO.
PHASE_DURATION = 1.0
#: Slices per phase: 20, i.e. 50 ms. Not converged for short carries: a layout's
#: effort at 20 is +4.75 % (2E), +3.27 % (10E), typically +0.5..2 % above 80 slices;
#: 40 is within 0.7 % of 80 for every trial (docs/effort.md, "Time discretisation").
#: A parameter of `plan` and of `python -m lgp.reproduce --slices`.
SLICES_PER_PHASE = 20
#: Vertical approach/retreat distance (m) above every grasp and place pose: the
#: default `approach_height` of `plan` (0 plans with a clearance constraint instead).
APPROACH = 0.05
#: Approach heights are below this (m): a leg of half a metre above a block on the
#: table leaves the arm's reach from above (models/arm.sdf), so a larger one could
#: only fail later, inside the planner, and less clearly.
MAX_APPROACH_HEIGHT = 0.5
#: Phases between the approach waypoint and the action (and the action and the
#: retreat waypoint): 0.2 s of each 1 s phase.
APPROACH_TIME = 0.2


class PlanningError(RuntimeError):
    """The geometric planner failed; the message names the scene, the action and why."""

    def __init__(self, message: str, action=None):
        super().__init__(message)
        self.action = action


class DesignError(ValueError):
    """A motion design the planner does not take (the message names the rule)."""


def check_approach_height(value) -> float:
    """`value` (a number or its text) as a float in [0, MAX_APPROACH_HEIGHT) m, else DesignError."""
    try:
        h = float(value)
    except (TypeError, ValueError):
        h = math.nan
    if isinstance(value, bool) or not (math.isfinite(h) and 0 <= h < MAX_APPROACH_HEIGHT):
        raise DesignError(f"an approach height (approach_height) must be a number of metres in "
                          f"[0, {MAX_APPROACH_HEIGHT:g}), got {value!r}")
    return h


def check_slices_per_phase(value) -> int:
    """`value` as an int >= 1, else DesignError."""
    try:
        ok = not isinstance(value, bool) and float(value).is_integer() and int(value) >= 1
    except (TypeError, ValueError, OverflowError):
        ok = False
    if not ok:
        raise DesignError(f"slices_per_phase must be an integer >= 1, got {value!r}")
    return int(value)


@dataclass(frozen=True)
class Design:
    """The planner's motion design: `approach_height` (m, in [0, MAX_APPROACH_HEIGHT);
    0 = no legs, a clearance constraint instead) and `slices_per_phase` (>= 1).
    Checked when made (DesignError naming the rule); frozen, so it stays checked."""

    approach_height: float = APPROACH
    slices_per_phase: int = SLICES_PER_PHASE

    def __post_init__(self):
        object.__setattr__(self, "approach_height", check_approach_height(self.approach_height))
        object.__setattr__(self, "slices_per_phase", check_slices_per_phase(self.slices_per_phase))

    @property
    def legs(self) -> bool:
        """Whether every grasp and place has its vertical approach and retreat legs."""
        return self.approach_height > 0

    @classmethod
    def of(cls, design: "Design | None" = None, approach_height: float | None = None,
           slices_per_phase: int | None = None) -> "Design":
        """`design` itself when given (already checked), else a Design of the two
        values, each None meaning its default; both forms at once is a TypeError."""
        if design is not None:
            if approach_height is not None or slices_per_phase is not None:
                raise TypeError("give a Design or approach_height / slices_per_phase, not both")
            if not isinstance(design, Design):
                raise TypeError(f"design must be an lgp.planner.Design, got {design!r}")
            return design
        return cls(APPROACH if approach_height is None else approach_height,
                   SLICES_PER_PHASE if slices_per_phase is None else slices_per_phase)


#: The paper-run default: 5 cm legs, 20 slices per phase.
DEFAULT_DESIGN = Design()


class Planner(StrEnum):
    """Which logic layer plans a layout: the paper's pipeline (one assignment, one
    order; the default, it reproduces the paper) or the search over skeletons
    (lgp.search)."""

    PAPER = "paper"
    SEARCH = "search"


#: The planners by name, the paper's first.
PLANNERS: tuple[str, ...] = tuple(p.value for p in Planner)


def check_planner(planner) -> Planner:
    """`planner` as a Planner, else InputError naming the known ones."""
    try:
        return Planner(planner)
    except ValueError:
        raise InputError(f"planner must be one of {', '.join(PLANNERS)}, got {planner!r}") from None


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
            if isinstance(value, bool) or not isinstance(value, (int, float)) or not math.isfinite(value) or value <= 0:
                raise InputError(f"Budget.{name} must be a positive number, got {value!r}")
        if not float(self.solves).is_integer() or not float(self.expansions).is_integer():
            raise InputError(f"Budget.solves and .expansions must be whole numbers, got {self.solves!r}, {self.expansions!r}")


@dataclass(frozen=True)
class EffortSpec:
    """How a layout's effort is planned: the motion `design`, the `planner` and,
    for the search, its `budget` (None: Budget(); refused with the paper's
    pipeline, which has none). Checked when made; what the effort units carry to
    the workers and what the effort cache key is derived from."""

    design: Design = DEFAULT_DESIGN
    planner: Planner = Planner.PAPER
    budget: Budget | None = None

    def __post_init__(self):
        if not isinstance(self.design, Design):
            raise TypeError(f"design must be an lgp.planner.Design, got {self.design!r}")
        planner = check_planner(self.planner)
        object.__setattr__(self, "planner", planner)
        if planner is Planner.PAPER and self.budget is not None:
            raise InputError("a budget applies to planner='search' only")
        if planner is Planner.SEARCH:
            budget = Budget() if self.budget is None else self.budget
            if not isinstance(budget, Budget):
                raise TypeError(f"budget must be an lgp.search.Budget, got {budget!r}")
            object.__setattr__(self, "budget", budget)

    @property
    def searched(self) -> bool:
        return self.planner is Planner.SEARCH

    def planner_options(self) -> dict:
        """The keywords of lgp.plan (lgp.search.plan) for this spec."""
        searched = {"planner": self.planner.value, "budget": self.budget} if self.searched else {}
        return {"design": self.design, **searched}

    def key(self) -> dict:
        """What an effort result depends on of the spec, for the cache key: the
        design's two values and, for the search only, the planner and its budget."""
        searched = {"planner": self.planner.value, "budget": repr(self.budget)} if self.searched else {}
        return {"approach_height": self.design.approach_height, "slices_per_phase": self.design.slices_per_phase,
                **searched}


#: The paper's effort: its pipeline with the default design.
DEFAULT_EFFORT = EffortSpec()
