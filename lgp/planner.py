"""The paper's planner end to end: assignment -> symbolic plan -> KOMO -> Plan.

`plan(initial, target)` runs the three stages of "Modeling physical effort":
`assign_blocks` (Hungarian, colours), `symbolic_plan` (grasp/place order from the
support graphs) and KOMO (lgp.komo) on the arm of models/arm.sdf. The logic layer
meets the geometry only through the skeleton: action k at phase k.

Geometry of one action (Grasp or Place at phase k), with APPROACH = 0.05 m:

- k - 0.2: the gripper straight above the grasp/place pose by APPROACH (same
  orientation), at rest: pre-grasp / pre-place;
- k: the gripper at the grasp pose (G at the block centre, hand vertical, G's x
  axis at the block's yaw modulo 90 deg) or the held block at its target X_WB
  (p_WB exact; yaw up to the cube's quarter-turn symmetry); at rest; the mode
  switch happens here;
- k + 0.2: straight above again, at rest: post-grasp / post-place.

So every block leaves its support and arrives on its target moving vertically (to
within 1 mm, tests/test_komo.py) for the last 5 cm (two block heights), and is
carried 5 cm above both its start and its target; between those waypoints KOMO is
free. Plans start and end at rest at the arm's home posture (phase 0 and phase
n_actions + 1).

Which of the four quarter-turn grasps, which elbow swivel and which IK branch are
discrete choices KOMO cannot make by gradient; they are chosen first, globally, by
dynamic programming over closed-form IK solutions of every waypoint (minimising
sum |dq|^2 / dt^3, the cost of rest-to-rest cubics), and the solutions seed KOMO.

The approach legs are a modelling choice the paper does not make (docs/effort.md):
`plan(..., approach_height=h)` moves the waypoints h m above the poses, and
`approach_height=0` drops them: each carry is then planned with a clearance
constraint instead (`_plan_with_clearance`). Starting from the legs design's
plan, the carried block's corners are kept above the table top and beyond a face
plane of every block or fixed box it would enter (over its top or beside it, in
that solid's frame, the face the legs plan also clears), added where the solved
motion needs them and re-solved (at most CLEARANCE_ROUNDS times).
"""
from __future__ import annotations

import time
from dataclasses import dataclass, field

import numpy as np
from pydrake.math import RigidTransform, RotationMatrix

from lgp.arm import Arm, X_WG_from_above
from lgp.assignment import assign_blocks
from lgp.komo import Komo, KomoResult
from lgp.scene import OVERLAP_TOLERANCE, Scene
from lgp.symbolic import Grasp, SymbolicPlan, symbolic_plan

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
#: Phases between the approach waypoint and the action (and the action and the
#: retreat waypoint): 0.2 s of each 1 s phase.
APPROACH_TIME = 0.2
#: Elbow swivel angles tried per waypoint when seeding (and 8 IK branches each).
SWIVELS = 16
#: At most this many KOMO re-solves with re-chosen quarter turns per seed.
TURN_RESOLVES = 3
#: Joint-limit margin (rad) asked of seeds, so KOMO starts strictly inside.
SEED_MARGIN = 0.02
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
#: approach_height = 0: the carried block's bottom corners stay this far (m) above
#: the table top. With a bound of exactly 0 the block slides on the table right
#: after the grasp's rest and SNOPT stalled 6e-8 m short of it (info 41, 2E); 10 um
#: is far below OVERLAP_TOLERANCE.
CLEARANCE = 1e-5

_ARM: Arm | None = None


def default_arm() -> Arm:
    """The arm of models/arm.sdf + models/arm.yaml, loaded once per process."""
    global _ARM
    if _ARM is None:
        _ARM = Arm()
    return _ARM


class PlanningError(RuntimeError):
    """The geometric planner failed; the message names the scene, the action and why."""

    def __init__(self, message: str, action=None):
        super().__init__(message)
        self.action = action


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



# ----------------------------------------------------------------------------- planning


def check_design(approach_height: float, slices_per_phase: int) -> tuple[float, int]:
    """(approach_height, slices_per_phase) as float and int; ValueError naming the
    rule when the height is not a finite number >= 0 or the slices not an integer >= 1."""
    try:
        h = float(approach_height)
    except (TypeError, ValueError):
        raise ValueError(f"approach_height must be a number of metres >= 0, got {approach_height!r}") from None
    if not np.isfinite(h) or h < 0:
        raise ValueError(f"approach_height must be a finite number of metres >= 0, got {approach_height!r}")
    if isinstance(slices_per_phase, bool) or not float(slices_per_phase).is_integer() or int(slices_per_phase) < 1:
        raise ValueError(f"slices_per_phase must be an integer >= 1, got {slices_per_phase!r}")
    return h, int(slices_per_phase)


def plan(initial: Scene, target: Scene, rng_or_seed=0, *, formulation: str = "reduced", solver: str = "snopt",
         slices_per_phase: int = SLICES_PER_PHASE, approach_height: float = APPROACH, arm: Arm | None = None) -> Plan:
    """Plan the construction of `target` from `initial`: assignment, symbolic plan, KOMO.

    `rng_or_seed` (a numpy Generator or seed) jitters the swivel grid of the IK
    seeding only; the optimum does not depend on it (tests/test_planner.py).
    `slices_per_phase` (default SLICES_PER_PHASE = 20) sets the time step, 1 s /
    slices_per_phase; `approach_height` (m, default APPROACH = 0.05) is the
    vertical approach and retreat leg at every grasp and place, and 0 replaces the
    legs by a clearance constraint on every carry (module docstring), planned
    from the legs design's plan (`solver`) by CLEARANCE_SOLVER.
    Raises PlanningError (naming the action) when a waypoint is out of reach or
    KOMO fails to satisfy a constraint; ValueError for a bad height or slice count.
    """
    start = time.perf_counter()
    approach_height, slices_per_phase = check_design(approach_height, slices_per_phase)
    arm = arm or default_arm()
    rng = rng_or_seed if isinstance(rng_or_seed, np.random.Generator) else np.random.default_rng(rng_or_seed)
    assignment = assign_blocks(initial, target)
    symbolic = symbolic_plan(initial, target, assignment)
    result = plan_symbolic(symbolic, rng, formulation=formulation, solver=solver, slices_per_phase=slices_per_phase,
                           approach_height=approach_height, arm=arm)
    result.planning_time = time.perf_counter() - start
    return result


def plan_symbolic(symbolic: SymbolicPlan, rng=0, *, formulation: str = "reduced", solver: str = "snopt",
                  slices_per_phase: int = SLICES_PER_PHASE, approach_height: float = APPROACH, arm: Arm | None = None) -> Plan:
    """KOMO for a given symbolic plan (see `plan`)."""
    start = time.perf_counter()
    approach_height, slices_per_phase = check_design(approach_height, slices_per_phase)
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
        if approach_height > 0:
            komo, seeds, turns = declare(symbolic, arm, rng, slices_per_phase, approach_height)
        else:
            komo, result = _plan_with_clearance(symbolic, arm, rng, formulation, solver, slices_per_phase)
    except PlanningError as e:
        raise PlanningError(f"{initial.label} -> {symbolic.target.label}: {e}", e.action) from None
    if approach_height > 0:
        komo, result, _ = _solve(symbolic, arm, komo, seeds, turns, formulation, solver, slices_per_phase, approach_height)
    if not _usable(result, approach_height):
        o = result.worst_objective
        k = int(round(o.time[0])) if o is not None and o.time else None
        action = symbolic.actions[k - 1] if k and 1 <= k <= len(symbolic.actions) else None
        where = f"action {k} {action}" if action else "joint limits"
        raise PlanningError(
            f"{initial.label} -> {symbolic.target.label}: KOMO ({formulation}, "
            f"{solver if approach_height > 0 else CLEARANCE_SOLVER}) failed at {where}: "
            f"{result.status}, constraint violation {result.max_violation:.2e}", action)
    return Plan(initial, symbolic.target, symbolic, result.t, result.q,
                {n: result.X_WB[n][:, :3, 3].copy() for n in names},
                {n: result.X_WB[n][:, :3, :3].copy() for n in names}, result, arm, time.perf_counter() - start)


@dataclass(frozen=True)
class _Waypoint:
    time: float  # phase
    action: int  # index into actions
    p_WG: np.ndarray  # gripper position
    yaw: float  # block yaw (the gripper yaw is this plus a quarter turn multiple)
    what: str  # e.g. "approach to Place(b1, table)"


def _waypoints(symbolic: SymbolicPlan, approach_height: float = APPROACH) -> list[_Waypoint]:
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
            out.append(_Waypoint(phase + dt, k, p + offset, yaw, f"{what} action {k + 1} {action}"))
    return out


def _seed(arm: Arm, waypoints: list[_Waypoint], phases: int, offset: float, actions=(), approach_height: float = APPROACH):
    """Quarter turn per action and an IK solution per waypoint, by dynamic programming.

    Candidates per action: closed-form IK solutions of its three waypoints (approach,
    action, retreat) at the same branch, swivel angle (a grid shifted by `offset`
    rad) and quarter turn, all within the joint limits. Path cost, as for
    rest-to-rest cubics: sum over consecutive waypoints of |q_b - q_a|^2 / dt^3, home
    at both ends; Viterbi over the actions. Returns ({phase: q}, {action: turn}).
    Without legs (one waypoint per action) the three are the same waypoint.
    """
    swivels = np.linspace(-np.pi, np.pi, SWIVELS, endpoint=False) + offset
    triples = _triples(waypoints)
    # One batched closed form for every distinct waypoint pose (approach and retreat share theirs).
    poses: dict[tuple, int] = {}
    for w in (w for triple in triples for w in triple):
        poses.setdefault((np.asarray(w.p_WG, float).tobytes(), float(w.yaw)), len(poses))
    q_all, ok_all = arm.ik_grids_from_above([(np.frombuffer(p), yaw) for p, yaw in poses], swivels, margin=SEED_MARGIN)
    nodes = []  # per action: (pre, at, post) solutions (m, 7) each, quarter turn (m,), internal cost (m,)
    for pre, at, post in triples:
        grids = [(q_all[i], ok_all[i]) for i in (poses[(np.asarray(w.p_WG, float).tobytes(), float(w.yaw))] for w in (pre, at, post))]
        for w, (_, ok) in zip((pre, at, post), grids):
            if not ok.any():
                raise PlanningError(f"{w.what} at phase {w.time:g}: gripper at {np.round(w.p_WG, 4).tolist()} is out of the arm's "
                                    "reach from above", actions[w.action] if actions else None)
        ok = grids[0][1] & grids[1][1] & grids[2][1]
        if not ok.any():
            raise PlanningError(f"{at.what}: no arm posture reaches it and the point {approach_height:g} m above it alike",
                                actions[at.action] if actions else None)
        q_pre, q_at, q_post = (grid[ok] for grid, _ in grids)
        internal = (np.sum((q_at - q_pre) ** 2, axis=1) + np.sum((q_post - q_at) ** 2, axis=1)) / APPROACH_TIME**3
        nodes.append((q_pre, q_at, q_post, np.broadcast_to(np.arange(4)[:, None], ok.shape)[ok], internal))
    cost, prev_q, prev_time, back = np.zeros(1), arm.q_home[None], 0.0, []
    for (pre, _, post), (q_pre, _, q_post, _, internal) in zip(triples, nodes):
        best, value = _best_predecessors(prev_q, q_pre, (pre.time - prev_time) ** 3, cost)
        back.append(best)
        cost = value + internal
        prev_q, prev_time = q_post, post.time
    cost = cost + np.sum((prev_q - arm.q_home) ** 2, axis=1) / (phases - prev_time) ** 3
    picks = [int(np.argmin(cost))]
    for k in range(len(nodes) - 1, 0, -1):
        picks.append(back[k][picks[-1]])
    picks.reverse()
    seeds, turns = {}, {}
    for (pre, at, post), (q_pre, q_at, q_post, turn, _), i in zip(triples, nodes, picks):
        seeds.update({pre.time: q_pre[i], at.time: q_at[i], post.time: q_post[i]})
        turns[at.action] = int(turn[i])
    return seeds, turns


#: Relative width of the band of predecessors whose Viterbi cost `_best_predecessors`
#: re-evaluates exactly: far above the ~1e-15 by which two roundings of it can differ.
_VITERBI_BAND = 1e-11


def _best_predecessors(a: np.ndarray, b: np.ndarray, dt3: float, cost: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """For every b_j: the first i minimising d_ij = |a_i - b_j|^2 / dt3 + cost_i, and d_ij.

    The same picks and values, to the bit, as `argmin` down the columns of
    `_squared_distances(a, b) / dt3 + cost[:, None]`: a BLAS product (in row
    blocks small enough for one thread) ranks the predecessors, and only those
    within a relative _VITERBI_BAND of each column's best are evaluated as
    `_squared_distances` rounds them (the einsum of a pair does not depend on
    its neighbours), ties going to the first.
    """
    aa, bb = np.einsum("ik,ik->i", a, a), np.einsum("jk,jk->j", b, b)
    m, n = len(a), len(b)
    # Rank by d_ij - bb_j / dt3 = c_i - 2 a_i.b_j / dt3 (a column constant does not
    # change the ranking): row j of rank = [b_j, 1] . [a_i (-2 / dt3), c_i] over i.
    lhs = np.column_stack([b, np.ones(n)])
    rhs = np.ascontiguousarray(np.column_stack([a * (-2.0 / dt3), aa / dt3 + cost]).T)
    rank = np.empty((n, m))
    rows = max(1, 200_000 // (8 * max(m, 1)))  # OpenBLAS stays on one thread below 262144 multiply-adds
    for s in range(0, n, rows):
        np.matmul(lhs[s:s + rows], rhs, out=rank[s:s + rows])
    band = _VITERBI_BAND * ((aa.max() + bb) / dt3 + np.abs(cost).max())
    columns = np.arange(n)
    first = rank.argmin(axis=1)
    limit = rank[columns, first] + band
    rank[columns, first] = np.inf
    close = np.flatnonzero(rank.min(axis=1) <= limit)  # columns with another candidate in the band
    J, I = [columns], [first]
    if len(close):
        j, i = np.nonzero(rank[close] <= limit[close, None])
        J.append(close[j])
        I.append(i)
    I, J = np.concatenate(I), np.concatenate(J)
    sq = np.maximum(aa[I] + bb[J] - 2 * np.einsum("pk,pk->p", a[I], b[J]), 0.0)
    d = sq / dt3 + cost[I]
    order = np.lexsort((I, d, J))  # per column: smallest d, then first row
    keep = order[np.r_[True, J[order][1:] != J[order][:-1]]]
    best = np.empty(n, int)
    value = np.empty(n)
    best[J[keep]], value[J[keep]] = I[keep], d[keep]
    return best, value


def _squared_distances(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """|a_i - b_j|^2 for all pairs; einsum, not BLAS, whose threads stall on a busy machine."""
    sq = np.einsum("ik,ik->i", a, a)[:, None] + np.einsum("jk,jk->j", b, b)[None, :] - 2 * np.einsum("ik,jk->ij", a, b)
    return np.maximum(sq, 0.0)


def declare(symbolic: SymbolicPlan, arm: Arm, rng: np.random.Generator, slices_per_phase: int = SLICES_PER_PHASE,
            approach_height: float = APPROACH):
    """The KOMO declaration of a symbolic plan, IK seeds {phase: q}, and the quarter turns.

    The seeding swivel grid is shifted by a random fraction of its step drawn from `rng`.
    """
    waypoints = _waypoints(symbolic, approach_height)
    phases = len(symbolic.actions) + 1
    seeds, turns = _seed(arm, waypoints, phases, rng.uniform(0, 2 * np.pi / SWIVELS), symbolic.actions, approach_height)
    return _declare(symbolic, arm, waypoints, turns, phases, slices_per_phase, approach_height), seeds, turns


def _solve(symbolic, arm, komo, seeds, turns, formulation, solver, slices_per_phase, approach_height=APPROACH):
    """Solve, then change quarter turns while a closed-form model predicts a lower cost.

    A quarter turn of the hand at an action changes joint 7 by 90 deg at that
    action's waypoints (its axis is vertical there) and nothing else; the control
    cost is a sum of independent quadratics per joint. For d = a turn of a run of
    consecutive actions, the cost after re-optimising is predicted by the quadratic
    cost (exact) plus one step along each waypoint's swivel direction (the null
    space of its pose constraint, linearised at the solution). Every run and d in
    {+-90, 180 deg} is ranked this way; KOMO re-solves from the turned (feasible)
    trajectory for the best one predicted to lower the cost, up to TURN_RESOLVES
    times, keeping it when it does. Near-ties between such turn families were what
    made different IK seeds end in different optima. Returns (komo, result).
    """
    result = komo.solve(formulation=formulation, solver=solver, seeds=seeds)
    elapsed = result.solve_time
    waypoints = _waypoints(symbolic, approach_height)
    phases = len(symbolic.actions) + 1
    tried = {tuple(sorted(turns.items()))}
    for _ in range(TURN_RESOLVES):
        if not result.success:
            break
        K = list(result.keyframes)
        slots = [K.index(komo.slice_of(w.time)) for w in waypoints]
        B = np.zeros((len(K), len(symbolic.actions)))  # which keyframes each action's turn moves
        B[slots, [w.action for w in waypoints]] = 1.0
        e = komo.elimination(K)
        X_K = result.q[1:][K]

        def turned(d, turns=turns):
            # Joint 7 turns about G's z axis, which points down: +d on joint 7 is -d of hand yaw.
            return {k: (t - int(round(d[k] / (np.pi / 2)))) % 4 for k, t in turns.items()}

        d = _best_untried_turn(arm, e, X_K, B, slots, -1e-6 * result.cost, lambda d: tuple(sorted(turned(d).items())) not in tried)
        if d is None:
            break
        new_turns = turned(d)
        tried.add(tuple(sorted(new_turns.items())))
        new_komo = _declare(symbolic, arm, waypoints, new_turns, phases, slices_per_phase, approach_height)
        X_K[:, 6] += B @ d
        candidate = new_komo.solve(formulation=formulation, solver=solver, initial_guess=new_komo.interpolate(dict(zip(K, X_K))))
        elapsed += candidate.solve_time
        if not (candidate.success and candidate.max_violation <= 1e-6 and candidate.cost < result.cost):
            break
        komo, result, turns = new_komo, candidate, new_turns
    result.solve_time = elapsed
    return komo, result, turns


def _predicted_turn_changes(arm, G, g, X_K, B, slots, H=None, fast: bool = False):
    """(predicted cost change, d) for joint-7 turns d over runs of actions, best first.

    Cost c(X_K) = sum_j |G X_K[:, j] + g[:, j]|^2 over joints j (X_K: (|K|, 7)
    keyframes); with H = G'G and the half gradient grad = G'(G X_K + g), a step
    dX changes it by exactly 2 <grad, dX> + sum_j dX[:, j]' H dX[:, j].

    The step: joint 7 turns by B d (B (|K|, n_actions) marks each action's
    keyframes; d the turn per action), and each waypoint r (keyframe slots[r])
    moves by alpha_r along its swivel direction n_r (a null vector of the gripper
    Jacobian, which joint 7 does not change: G lies on its axis). Then

        change(d, alpha) = d' B'HB d + 2 grad_7' B d                  (turn_cost)
                         + 2 alpha' (b0 + P d) + alpha' A alpha
        A  = (n_r . n_s) H[slots_r, slots_s]                          (swivel_hessian)
        b0 = n_r . grad[slots_r]                                      (swivel_gradient)
        P  = n_r[7] (H B)[slots_r]                                    (swivel_turn_coupling)

    and the best alpha gives change(d) = turn_cost - (b_d' A^-1 b_d - b0' A^-1 b0),
    b_d = b0 + P d, measured against the best swivel step without a turn (zero at
    an exact optimum). Turns that take joint 7 within SEED_MARGIN of a limit are
    left out. `H` is G'G when the caller has it (lgp.komo.Elimination.GtG).

    `fast=True` does the two large products (P D and A^-1 b_d) in blocks small
    enough for one BLAS thread (a 2-thread product of these sizes stalls when the
    other core is busy: 25 ms instead of 0.2 ms) and returns (list, band, sure):
    its changes are within `band` of this function's own, and `sure` is False
    when A is too ill-conditioned for that bound. `_best_untried_turn` decides
    with them only when no decision is within `band` of another.
    """
    from pydrake.multibody.tree import JacobianWrtVariable

    plant, context = arm.plant, arm.context
    swivel = np.zeros((len(slots), arm.nq))  # row r: n_r, unit null vector of the gripper Jacobian
    for r, i in enumerate(slots):
        plant.SetPositions(context, X_K[i])
        J = plant.CalcJacobianSpatialVelocity(context, JacobianWrtVariable.kQDot, arm.G, np.zeros(3), plant.world_frame(), plant.world_frame())
        swivel[r] = np.linalg.svd(J)[2][-1]
    H = G.T @ G if H is None else H  # half the Hessian of the cost, per joint, (|K|, |K|)
    grad = G.T @ (G @ X_K + g)  # half the gradient, (|K|, 7)
    swivel_hessian = (swivel @ swivel.T) * H[np.ix_(slots, slots)]  # A
    swivel_gradient = np.einsum("rj,rj->r", swivel, grad[slots])  # b0
    swivel_turn_coupling = swivel[:, 6][:, None] * (H @ B)[slots]  # P, (waypoints, n_actions)
    turn_hessian = B.T @ H @ B  # B'HB, (n_actions, n_actions)
    turn_gradient = grad[:, 6] @ B  # grad_7' B, (n_actions,)
    D = _turn_steps(X_K, B, arm.q_lower[6] + SEED_MARGIN, arm.q_upper[6] - SEED_MARGIN)  # (n_actions, m): column m is one d
    if D.shape[1] == 0:
        return ([], 0.0, True) if fast else []
    turn_cost = np.einsum("km,kl,lm->m", D, turn_hessian, D) + 2 * turn_gradient @ D  # joints 1-6 held
    if not fast:
        b_d = swivel_gradient[:, None] + swivel_turn_coupling @ D
        Ainv_b_d = np.linalg.solve(swivel_hessian, b_d)
        swivel_gain = np.einsum("rm,rm->m", b_d, Ainv_b_d) - swivel_gradient @ np.linalg.solve(swivel_hessian, swivel_gradient)
        change = turn_cost - swivel_gain
        order = np.argsort(change)
        return [(float(change[m]), D[:, m]) for m in order]
    r, m = swivel_turn_coupling.shape[0], D.shape[1]
    # A^-1 b_d = A^-1 b0 + (A^-1 P) d: one solve with 1 + n_actions right-hand sides.
    # (numpy's LAPACK: scipy's lu_solve took 12 ms here on a busy machine, its BLAS threads waiting.)
    solved = np.linalg.solve(swivel_hessian, np.column_stack([swivel_gradient, swivel_turn_coupling]))
    Ainv_b0, Ainv_P = solved[:, 0], solved[:, 1:]
    b_d, Ainv_b_d = np.empty((r, m)), np.empty((r, m))
    cols = max(1, 200_000 // (r * swivel_turn_coupling.shape[1]))  # one BLAS thread below 262144 multiply-adds
    for s in range(0, m, cols):
        b_d[:, s:s + cols] = swivel_gradient[:, None] + swivel_turn_coupling @ D[:, s:s + cols]
        Ainv_b_d[:, s:s + cols] = Ainv_b0[:, None] + Ainv_P @ D[:, s:s + cols]
    swivel_gain = np.einsum("rm,rm->m", b_d, Ainv_b_d) - swivel_gradient @ Ainv_b0
    change = turn_cost - swivel_gain
    # The two ways round differently by ~ r cond(A) 1e-16 times |b_d| (|A^-1 b0| + |A^-1 P| |d|)
    # (backward-stable solves, no cancellation assumed): with cond(A) <= 1e4 the band
    # below is >= 1e3 times that; a worse A is left to the exact way.
    cond = np.linalg.cond(swivel_hessian, 1)
    x_size = np.linalg.norm(Ainv_b0) + np.linalg.norm(Ainv_P) * np.linalg.norm(D, axis=0)
    scale = np.linalg.norm(b_d, axis=0) * x_size + np.linalg.norm(swivel_gradient) * np.linalg.norm(Ainv_b0)
    band = 1e-6 * float(scale.max() + np.abs(turn_cost).max())
    order = np.argsort(change)
    return [(float(change[m]), D[:, m]) for m in order], band, bool(cond < 1e4)


def _turn_steps(X_K, B, lo: float, hi: float) -> np.ndarray:
    """Candidate joint-7 turns d (n_actions, m): for each step in (+90, -90, +180, -180
    deg) and each run i..j of consecutive actions whose keyframes all stay within
    [lo, hi] when turned, d = step on actions i..j; in that order (step, i, j)."""
    n = B.shape[1]
    x7 = [X_K[B[:, k] > 0, 6] for k in range(n)]
    columns = []
    k = np.arange(n)
    for step in (np.pi / 2, -np.pi / 2, np.pi, -np.pi):
        ok = np.array([bool(np.all(x + step >= lo) and np.all(x + step <= hi)) for x in x7])
        # The run from i may extend up to the first action j >= i that is not ok.
        stop = np.minimum.accumulate(np.where(ok, n, k)[::-1])[::-1] if n else np.zeros(0, int)
        i = np.repeat(k, np.maximum(stop - k, 0))
        j = np.concatenate([np.arange(a, b) for a, b in zip(k, stop) if b > a]) if np.any(stop > k) else np.zeros(0, int)
        block = np.where((k[None, :] >= i[:, None]) & (k[None, :] <= j[:, None]), step, 0.0)
        columns.append(block)
    return np.concatenate(columns).T if columns else np.zeros((n, 0))


def _best_untried_turn(arm, e, X_K, B, slots, threshold: float, untried) -> np.ndarray | None:
    """The first d, in order of predicted change, below `threshold` and `untried(d)`;
    None when there is none. Decided on `_predicted_turn_changes(fast=True)` when every
    change it compares (the ones up to the pick, the next one, the threshold) lies
    more than its band apart; else on the exact ranking. Either way the pick is the
    one the exact ranking gives."""
    changes, band, sure = _predicted_turn_changes(arm, e.G, e.g, X_K, B, slots, e.GtG, fast=True)
    pick, last = None, len(changes) - 1  # last: the index up to which the ranking must be certain
    for index, (change, d) in enumerate(changes):
        if change >= threshold:
            last = index
            break
        if untried(d):
            pick, last = d, index + 1
            break
    values = np.array([c for c, _ in changes[:last + 1]] + [np.inf])
    certain = sure and bool(np.all(np.diff(values) > 2 * band)) and bool(np.all(np.abs(values[:-1] - threshold) > band))
    if certain:
        return pick
    for change, d in _predicted_turn_changes(arm, e.G, e.g, X_K, B, slots, e.GtG):
        if change >= threshold:
            return None
        if untried(d):
            return d
    return None


def _declare(symbolic, arm, waypoints, turns, phases, slices_per_phase, approach_height=APPROACH) -> Komo:
    komo = Komo(arm, phases, slices_per_phase, k_order=2, phase_duration=PHASE_DURATION, q_home=arm.q_home,
                objects={b.name: b.X_WB for b in symbolic.initial})
    up = np.array([0.0, 0.0, approach_height])
    legs = approach_height > 0
    X_GB = {}
    for (phase, action), (pre, at, post) in zip(symbolic.skeleton(), _triples(waypoints)):
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


def _triples(waypoints):
    """(approach, action, retreat) waypoints per action; (w, w, w) without legs."""
    by_action: dict[int, list[_Waypoint]] = {}
    for w in waypoints:
        by_action.setdefault(w.action, []).append(w)
    return [(ws[0], ws[len(ws) // 2], ws[-1]) for ws in by_action.values()]


# ----------------------------------------------------------------------------- clearance (approach_height = 0)


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


def _usable(result: KomoResult, approach_height: float) -> bool:
    """Solved, every constraint within 1e-6. Without legs SNOPT (if it is the
    CLEARANCE_SOLVER) may also end with info 41 ("cannot be improved") at a feasible
    point: a carried block sliding on the table right after a grasp's rest is a
    degenerate active set (7E); the status stays in the effort table (column status)."""
    if result.max_violation > 1e-6:
        return False
    return result.success or (approach_height == 0 and CLEARANCE_SOLVER == "snopt" and "snopt info 41" in result.status)


def _box_corners(size) -> np.ndarray:
    """The 8 corners (8, 3) of a box of full extents `size`, in its own frame."""
    return _UNIT_CORNERS * np.asarray(size, float) / 2


@dataclass(frozen=True)
class _Obstacle:
    """A solid a carried block must stay out of: X_WO (rotation R_WO, centre p_WO), half extents."""

    key: str
    R_WO: np.ndarray
    p_WO: np.ndarray
    half: np.ndarray


def _obstacles(initial: Scene, X_WB: dict[str, np.ndarray], carried: str, i: int) -> list[_Obstacle]:
    """Every other block at trajectory row i (poses from X_WB) and every fixed box."""
    out = [_Obstacle(b.name, X_WB[b.name][i][:3, :3], X_WB[b.name][i][:3, 3], np.asarray(b.size, float) / 2)
           for b in initial.blocks if b.name != carried]
    out += [_Obstacle(f"{f.name} box {j + 1}", np.eye(3), f.p_WO, f.size / 2) for j, f in enumerate(initial.fixed)]
    return out


def _gaps_beyond_faces(P_F: np.ndarray, half: np.ndarray) -> np.ndarray:
    """(n, 6) gap (m) of the point sets P_F (n, k, 3), each in the frame of a box of
    half extents half (n, 3), beyond that box's face planes +x, -x, +y, -y, +z, -z:
    the least distance of a point past the plane (< 0 when some point is not past it)."""
    lo, hi = P_F.min(axis=1) - half, -half - P_F.max(axis=1)
    return np.stack([lo, hi], axis=2).reshape(len(P_F), 6)


def _obstacle_frames(obstacles: list[_Obstacle]) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """R_WO (n, 3, 3), p_WO (n, 3) and half extents (n, 3) of the obstacles."""
    return (np.array([o.R_WO for o in obstacles]), np.array([o.p_WO for o in obstacles]),
            np.array([o.half for o in obstacles]))


def _face_gaps(p_WC: np.ndarray, obstacles: list[_Obstacle]) -> np.ndarray:
    """(n_obstacles, 5) gap (m) of the points p_WC (the carried block's corners) beyond
    each face plane of each obstacle, in the obstacle's frame: +x, -x, +y, -y, +z.
    A gap >= 0 on some face means that face's plane separates the two boxes."""
    if not obstacles:
        return np.zeros((0, 5))
    R, p, e = _obstacle_frames(obstacles)
    C = np.einsum("nji,nkj->nki", R, p_WC[None] - p[:, None])  # corners in each obstacle's frame
    return _gaps_beyond_faces(C, e)[:, :5]


def _separation(X_WB: np.ndarray, half: np.ndarray, p_WC: np.ndarray, obstacles: list[_Obstacle]) -> np.ndarray:
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


def _add_separation(komo: Komo, name: str, corners: np.ndarray, i: int, obstacle: _Obstacle, face: int) -> None:
    """Every corner of the carried block beyond one face plane of the obstacle at row i
    (measured in the obstacle's frame), touching allowed: OVERLAP_TOLERANCE / 2."""
    axis = (0, 0, 1, 1, 2)[face]
    sign = (1.0, -1.0, 1.0, -1.0, 1.0)[face]  # +1: coordinate >= half + ..., -1: <= -half - ...
    scale, target = np.zeros(3), np.zeros(3)
    scale[axis] = -sign
    target[axis] = sign * (obstacle.half[axis] - OVERLAP_TOLERANCE / 2)
    komo.add_objective([i / komo.slices_per_phase], "position", (name,), "ineq", scale=scale, target=target, points=corners,
                       X_WA=RigidTransform(RotationMatrix(obstacle.R_WO), obstacle.p_WO))


def _plan_with_clearance(symbolic: SymbolicPlan, arm: Arm, rng, formulation: str, solver: str, slices_per_phase: int):
    """approach_height = 0: the legs design's plan, then its legs dropped and every
    carry kept clear of the table and of every other solid (returns (komo, result)).

    1. The plan with APPROACH legs (quarter turns, swivels and IK branches chosen as
       usual, `solver`) is feasible for the program without legs and clear of every
       solid (within the 1.3 mm its legs stray from vertical): it is the reference
       and the initial guess.
    2. The program without legs (same quarter turns) is solved by CLEARANCE_SOLVER.
       Wherever a carried block's bottom corners come within CLEARANCE / 2 of the
       table top, or no face plane of either box separates it from another block
       or fixed box (`_separation`) and they overlap by more than
       OVERLAP_TOLERANCE * 3/4, a constraint is added at that row, and at the rows where the same block
       is within CLEARANCE_MARGIN of the same solid: its bottom corners CLEARANCE
       above the table; its corners beyond one face plane of the solid (over its
       top, or beside one of its four sides; touching allowed): of the faces that
       separate the reference's block from it at that row, the one the solved
       motion is least far past (`_separating_face`). So each constraint holds on
       the reference (the program stays feasible) and the motion keeps the
       reference's way round each solid (beside a neighbour until above it, inside
       the bucket until over its wall) but not its 5 cm detours. Re-solved at most
       CLEARANCE_ROUNDS times, else PlanningError naming the action.
    """
    komo, seeds, turns = declare(symbolic, arm, rng, slices_per_phase, APPROACH)
    komo, reference, turns = _solve(symbolic, arm, komo, seeds, turns, formulation, solver, slices_per_phase, APPROACH)
    if not _usable(reference, APPROACH):
        o = reference.worst_objective
        k = int(round(o.time[0])) if o is not None and o.time else None
        action = symbolic.actions[k - 1] if k and 1 <= k <= len(symbolic.actions) else None
        raise PlanningError(f"the reference plan with {APPROACH:g} m legs (the start of the design without legs) failed"
                            f"{f' at action {k} {action}' if action else ''}: {reference.status}, constraint violation "
                            f"{reference.max_violation:.2e}", action)
    initial = symbolic.initial
    S = slices_per_phase
    komo = _declare(symbolic, arm, _waypoints(symbolic, 0.0), turns, len(symbolic.actions) + 1, S, 0.0)
    carried = carried_slices(symbolic, S)
    corners = {b.name: _box_corners(b.size) for b in initial.blocks}
    bottom = {n: c[c[:, 2] < 0] for n, c in corners.items()}
    half = {b.name: np.asarray(b.size, float) / 2 for b in initial.blocks}
    elapsed = reference.solve_time
    declared: dict[tuple[str, int, str], int] = {}  # (block, row, solid) -> corners constrained
    result = reference
    for round_ in range(CLEARANCE_ROUNDS + 1):
        # Rounds 0 and 1 start from the clear reference: from round 0's solution,
        # which goes through solids, the program took 5x longer (12E, SNOPT: 33.8 s
        # vs 6.7 s); later rounds from the last solution, which misses only the few
        # constraints just added.
        guess = result.q[1:] if round_ >= 2 else reference.q[1:]
        result = komo.solve(formulation=formulation, solver=CLEARANCE_SOLVER, initial_guess=guess)
        elapsed += result.solve_time
        if not _usable(result, 0.0):
            break
        near = []  # (block, row, solid or None for the table, gap or height, corners in W)
        for name, i in carried:
            X = result.X_WB[name][i]
            p_WC = corners[name] @ X[:3, :3].T + X[:3, 3]
            height = float(np.min(p_WC[:, 2][corners[name][:, 2] < 0]))
            if height < CLEARANCE_MARGIN:
                near.append((name, i, None, height, p_WC))
            obstacles = _obstacles(initial, result.X_WB, name, i)
            for o, g in zip(obstacles, _separation(X, half[name], p_WC, obstacles)):
                if g < CLEARANCE_MARGIN:
                    near.append((name, i, o, float(g), p_WC))

        def entered(o, g):
            return g < (CLEARANCE / 2 if o is None else -0.75 * OVERLAP_TOLERANCE)

        worst = [w for w in near if entered(w[2], w[3])]
        if not worst:
            break
        hit = {(n, None if o is None else o.key) for n, _, o, _, _ in worst}
        added = 0
        for name, i, o, g, p_WC in near:
            if (name, None if o is None else o.key) not in hit:
                continue
            key = (name, i, "table" if o is None else o.key)
            if o is None:
                if key not in declared:
                    komo.add_objective([i / S], "position", (name,), "ineq", scale=(0.0, 0.0, -1.0),
                                       target=[0.0, 0.0, CLEARANCE], points=bottom[name])
                    declared[key], added = 4, added + 1
                continue
            if declared.get(key, 0) == 8 or (key in declared and not entered(o, g)):
                continue
            X = reference.X_WB[name][i]
            p_WC_reference = corners[name] @ X[:3, :3].T + X[:3, 3]
            face = _separating_face(_face_gaps(p_WC_reference, [o])[0], _face_gaps(p_WC, [o])[0])
            # The corners that lead along the face's normal, at the reference and now
            # (4 of 8 each: a near-vertical hand turns the block mostly about z);
            # all 8 if the solid is entered again at this row.
            points = np.arange(8)
            if key not in declared:
                axis, sign = (0, 0, 1, 1, 2)[face], (1.0, -1.0, 1.0, -1.0, 1.0)[face]
                lead = [np.argsort(sign * ((P - o.p_WO) @ o.R_WO)[:, axis])[:4] for P in (p_WC_reference, p_WC)]
                points = np.union1d(*lead)
            _add_separation(komo, name, corners[name][points], i, o, face)
            declared[key] = len(points) if key not in declared else 8
            added += 1
        if round_ == CLEARANCE_ROUNDS or not added:
            name, i, o, g, _ = min(worst, key=lambda w: w[3])
            k = int(np.ceil(i / S))
            action = symbolic.actions[k - 1] if 1 <= k <= len(symbolic.actions) else None
            where = (f"comes within {g * 1000:.3f} mm of the table top (less than {CLEARANCE / 2 * 1000:g} mm)" if o is None
                     else f"still enters {o.key} by {-g * 1000:.3f} mm")
            raise PlanningError(f"action {k} {action}: carried block {name} {where} at t = {i / S:g} s after {round_ + 1} "
                                f"solves without legs", action)
    result.solve_time = elapsed
    return komo, result
