"""Physical effort of a trial (paper: "Measuring physical effort").

"Physical effort is measured by the kinetic energy needed to execute the resulting
full plan" with "a unit mass to a unit block", averaged over M = 30 random initial
layouts. Here, per layout:

    effort = sum over carried blocks of integral 1/2 m |v_WB(t)|^2 dt      [J s]

with m = 1 kg, v_WB the velocity of the block centre along the KOMO trajectory
(lgp.planner.plan), and the integral taken over the whole plan. The time integral,
not a sum over slices, so the number does not change with the slice count (a
per-slice sum would double when the slices do); units are therefore joule-seconds.
Each action takes one phase of 1 s (lgp.planner.PHASE_DURATION). The measure is
`kinetic_energy(plan)` (per block: `kinetic_energy_by_block`, per action:
`kinetic_energy_by_action`), computed here from the Plan's block trajectories
p_WB; the planner only produces trajectories.

Two modelling choices the paper leaves open make the planner's motion design
(lgp.planner.Design): `approach_height` (m; default lgp.planner.APPROACH = 0.05,
the vertical leg at every grasp and place; 0 plans each carry with a clearance
constraint instead) and `slices_per_phase` (default lgp.planner.SLICES_PER_PHASE
= 20). The design and the planner (the paper's pipeline or lgp.search with its
budget) travel together as one lgp.planner.EffortSpec, the `spec` of every
function here. docs/effort.md says how much each moves effort.

The command line (the table of docs/effort.md) is models/effort/__main__.py,
kept out of this module so that the effort cache key (lgp.app.cache.modules_digest of
``models.effort``) does not hash the CLI or its argument helpers::

    python -m models.effort --samples 30 --jobs 2 --out effort_samples.csv
    python -m models.effort 2E 2H --approach-height 0 --slices 40
"""
from __future__ import annotations

from typing import Callable, NamedTuple

import numpy as np
import pandas as pd

from lgp.paper import SAMPLES
from lgp.errors import InputError
from lgp.executor import borrowed
from lgp.planner import DEFAULT_EFFORT, PHASE_DURATION, EffortSpec, PlanningError
from lgp.search import describe_search, plan

COLUMNS = ["trial", "sample", "effort", "n_actions", "solve_time", "solver", "status"]
#: planner="search" adds what the search found: the lower bound of the best
#: unexplored branch (J s), the gap to the plan's effort, set-asides, KOMO solves,
#: and the paper skeleton's effort on the same layout (empty when it has none).
SEARCH_COLUMNS = COLUMNS + ["bound", "gap", "set_asides", "solves", "paper_effort"]
#: Column status of a layout whose plan needs no motion (A is already B).
NOTHING_TO_MOVE = "nothing to move"
#: Column status of a solved plan starts with this: Drake's SolutionResult
#: kSolutionFound by name, as lgp.komo.KomoResult.status writes it.
SOLUTION_FOUND = "kSolutionFound"
#: Mass of a unit block [paper: "a unit mass to a unit block"], kg.
BLOCK_MASS = 1.0


def path_kinetic_energy(p_WB: np.ndarray, tau: float, mass: float = BLOCK_MASS) -> float:
    """Time integral (J s) of 1/2 m |v|^2 along positions p_WB (n, 3) sampled every tau s.

    v is the backward difference (p_s - p_s-1) / tau, so the sum times tau
    approximates the integral and does not grow with the number of slices.
    """
    v = np.diff(np.asarray(p_WB, float), axis=0) / tau
    return float(0.5 * mass * np.sum(v * v) * tau)


def kinetic_energy_by_block(plan, mass: float = BLOCK_MASS) -> dict[str, float]:
    """{block: integral of its kinetic energy, J s} along an lgp.planner.Plan."""
    return {name: path_kinetic_energy(p, plan.tau, mass) for name, p in plan.p_WB.items()}


def kinetic_energy(plan, mass: float = BLOCK_MASS) -> float:
    """Physical effort of one plan: time integral of the blocks' kinetic energy, J s.

    Sum over blocks of integral 1/2 m |v_WB|^2 dt along the Plan's block
    trajectories, v the velocity of the block centre.
    """
    return float(sum(kinetic_energy_by_block(plan, mass).values()))


def kinetic_energy_by_action(plan, mass: float = BLOCK_MASS) -> list[float]:
    """Energy integral of each phase ending at each action (action k: phases k-1 to k)."""
    S = int(round(PHASE_DURATION / plan.tau))
    out = []
    for k in range(1, len(plan.actions) + 1):
        lo, hi = (k - 1) * S, k * S
        out.append(sum(path_kinetic_energy(p[lo:hi + 1], plan.tau, mass) for p in plan.p_WB.values()))
    return out


def cumulative_effort(plan) -> np.ndarray:
    """Effort (J s) integrated from time 0 to each slice; the last entry is the plan's effort."""
    v = np.stack([np.diff(p, axis=0) for p in plan.p_WB.values()]) / plan.tau  # (blocks, n-1, 3)
    # The same rule as kinetic_energy, one slice interval at a time, so the last
    # value equals kinetic_energy(plan) (checked in tests/test_view.py).
    per_step = 0.5 * BLOCK_MASS * (v ** 2).sum(axis=(0, 2)) * plan.tau
    return np.concatenate([[0.0], np.cumsum(per_step)])


def describe(plan, digits: int | None = None) -> str:
    """The plan's action list (its skeleton) with times and per-action energies, one
    line each, and its effort (4 decimals, or `digits` significant digits); a
    searched plan also its bound and gap."""
    energies = kinetic_energy_by_action(plan) if plan.actions else []
    lines = [f"{k + 1:3d}  t = {k + 1:5.1f} s  {a}   E = {e:.4f} J s" for k, (a, e) in enumerate(zip(plan.actions, energies))]
    effort = f"{kinetic_energy(plan):.4f}" if digits is None else f"{kinetic_energy(plan):.{digits}g}"
    lines.append(f"physical effort: {effort} J s over {len(plan.actions)} actions")
    if describe_search(plan):
        lines.append(describe_search(plan))
    return "\n".join(lines)


def sample_rng(seed: int, sample: int) -> np.random.Generator:
    """The Generator of one sample: the same (seed, sample) gives the same layout anywhere."""
    return np.random.default_rng([seed, sample])


def plan_of_sample(trial, seed: int, sample: int, **planner_options):
    """The Plan behind row (trial, sample) of the effort table.

    One Generator, sample_rng(seed, sample), draws the layout of A and then seeds
    the planner, in that order: this is the only place that order is written, so
    `python -m lgp.show` replays exactly what `physical_effort` computed.
    Raises PlanningError naming the trial, the sample and the failing action.
    """
    rng = sample_rng(seed, sample)
    initial = trial.sample_initial(rng)
    try:
        return plan(initial, trial.target, rng, **planner_options)
    except PlanningError as e:
        raise PlanningError(f"trial {trial.id} sample {sample} (seed {seed}): {e}", e.action) from e


def skeleton_of_sample(trial, seed: int, sample: int):
    """The paper pipeline's symbolic plan (assignment and grasp/place order, no
    motion) of the layout plan_of_sample draws for (trial, sample): what the work
    shares, the plan features and the bound read without KOMO."""
    from lgp.assignment import assign_blocks
    from lgp.symbolic import symbolic_plan

    initial = trial.sample_initial(sample_rng(seed, sample))
    return symbolic_plan(initial, trial.target, assign_blocks(initial, trial.target))


def effort_of_sample(trial, seed: int, sample: int, spec: EffortSpec = DEFAULT_EFFORT) -> dict:
    """One row of the effort table: plan the sample's layout, integrate kinetic energy.

    `spec` (an lgp.planner.EffortSpec) is the motion design and the planner:
    the paper's pipeline (lgp.planner.plan) or the search (lgp.search, within
    its budget). Raises PlanningError naming the trial, the sample and the failing action.
    """
    return effort_row(trial, seed, sample, plan_of_sample(trial, seed, sample, **spec.planner_options()))


def effort_row(trial, seed: int, sample: int, result) -> dict:
    """The effort table's row of the plan `result` of a trial's sample (effort_of_sample,
    and lgp.app.replays, which records the same plan as the sample's replay)."""
    effort = kinetic_energy(result)
    if not np.isfinite(effort):
        raise PlanningError(f"trial {trial.id} sample {sample} (seed {seed}): effort is {effort}")
    komo = result.komo
    searched = result.search
    extra = {} if searched is None else {
        "bound": searched.bound, "gap": searched.gap, "set_asides": searched.set_asides, "solves": searched.solves,
        "paper_effort": searched.paper_effort}
    return extra | {
        "trial": trial.id,
        "sample": sample,
        "effort": effort,
        "n_actions": len(result.actions),
        "solve_time": result.planning_time,  # wall-clock s, assignment to KOMO
        "solver": komo.solver if komo else "none",
        "status": komo.status if komo else NOTHING_TO_MOVE,
    }


def converged(status) -> pd.Series:
    """Per row of an effort table's column status (text, as the table and its CSV
    hold it): whether the layout's plan was solved (KOMO's SolutionResult is
    kSolutionFound) or needed no motion. The in-memory verdict is typed
    (KomoResult.solution_result, .solver_info); this is the one reader of its text."""
    text = pd.Series(status).astype(str)
    return text.str.startswith(SOLUTION_FOUND) | (text == NOTHING_TO_MOVE)


class EffortResult(NamedTuple):
    """What `physical_effort` returns: ``.mean`` the mean effort over the layouts
    (J s) and ``.table`` one row per layout (columns COLUMNS). A named tuple, so
    ``mean, table = physical_effort(...)`` works too."""

    mean: float
    table: pd.DataFrame

    def __repr__(self) -> str:
        return f"EffortResult(mean={self.mean:.6g} J s over {len(self.table)} layouts)"


class EffortUnit(NamedTuple):
    """One layout to plan (what an executor's worker receives): trial, seed,
    sample and the EffortSpec it is planned with."""

    trial: object
    seed: int
    sample: int
    spec: EffortSpec = DEFAULT_EFFORT


def effort_units(trial, samples: int, seed: int, spec: EffortSpec = DEFAULT_EFFORT) -> list[EffortUnit]:
    """The work units of a trial's effort, one per layout that needs planning:
    every sample, or only sample 0 when A is not random; each carries `spec` so
    an executor's workers plan with the same choices."""
    if not isinstance(spec, EffortSpec):
        raise TypeError(f"spec must be an lgp.planner.EffortSpec, got {spec!r}")
    return [EffortUnit(trial, seed, i, spec) for i in (range(samples) if trial.initial.is_random else [0])]


def effort_of_unit(unit: EffortUnit) -> dict:
    """effort_of_sample for one unit of `effort_units` (what executors map)."""
    return effort_of_sample(unit.trial, unit.seed, unit.sample, unit.spec)


def effort_table(trial, samples: int, rows: list[dict]) -> pd.DataFrame:
    """The tidy (trial, sample) table from the rows of a trial's units (any order);
    a trial whose A is not random has its one row repeated for every sample.
    Columns COLUMNS, or SEARCH_COLUMNS for rows of planner="search"."""
    if not trial.initial.is_random:
        rows = [{**rows[0], "sample": i} for i in range(samples)]
    columns = SEARCH_COLUMNS if rows and "bound" in rows[0] else COLUMNS
    return pd.DataFrame(rows, columns=columns).sort_values("sample").reset_index(drop=True)


def physical_effort(trial, samples: int = SAMPLES, seed: int = 0, jobs: int = 1,
                    progress: Callable[[int, int], None] | None = None, executor=None, *,
                    spec: EffortSpec = DEFAULT_EFFORT) -> EffortResult:
    """Physical effort of `trial` over `samples` random layouts: an `EffortResult`
    with ``.mean`` (J s) and ``.table`` (one row per layout: trial, sample, effort,
    n_actions, solve_time, solver, status).

    `trial` is a stimuli.Trial or its id ("7H"). Sample i draws its layout with
    numpy.random.default_rng([seed, i]); `jobs` > 1 spreads samples over that many
    processes with identical numbers (or pass an `executor`, lgp.executor, to reuse
    warm workers across trials). `progress(done, total)` is called after each
    sample. A trial whose layout is not random (a fixed structure in A) is planned
    once and its row repeated: every sample would draw the same layout.
    `spec` (lgp.planner.EffortSpec) is the motion design (a Design: approach
    height, 0.05 m default, 0 = clearance constraint instead of the legs; slices
    per phase, 20 default; docs/effort.md, "Modelling choices") and the planner:
    Planner.PAPER (the paper's pipeline, default) or Planner.SEARCH (lgp.search
    within its budget; the table then has SEARCH_COLUMNS: bound, gap,
    set-asides, solves, paper_effort).
    """
    if isinstance(trial, str):
        import stimuli

        trial = stimuli.load_trial(trial)
    if samples < 1:
        raise InputError(f"physical_effort needs samples >= 1, got {samples}")
    units = effort_units(trial, samples, seed, spec)
    done = 0

    def record(_, row):
        nonlocal done
        done += 1 if trial.initial.is_random else samples
        if progress is not None:
            progress(done, samples)

    with borrowed(executor, jobs if len(units) > 1 else 1) as ex:
        rows = ex.map(effort_of_unit, units, record)
    table = effort_table(trial, samples, rows)
    return EffortResult(float(table["effort"].mean()), table)


def summarise_effort(samples: pd.DataFrame, trials) -> pd.DataFrame:
    """One row per trial (in the order of `trials`) from the tidy (trial, sample)
    table: trial, pair, level, effort (the mean over layouts, J s), effort_sd
    (ddof 1) and samples. `pair` is empty for a trial of no pair."""
    order = {t.id: i for i, t in enumerate(trials)}
    g = samples.groupby("trial")["effort"]
    df = pd.DataFrame({"effort": g.mean(), "effort_sd": g.std(ddof=1), "samples": g.size()}).reset_index()
    df["pair"] = df["trial"].map({t.id: t.pair for t in trials}).astype("Int64")  # empty for a trial of no pair
    df["level"] = df["trial"].map({t.id: t.level for t in trials})
    return df.sort_values("trial", key=lambda s: s.map(order)).reset_index(drop=True)[["trial", "pair", "level", "effort", "effort_sd", "samples"]]
