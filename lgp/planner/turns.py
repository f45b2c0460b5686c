"""Quarter-turn re-solves: after KOMO's solution, turn the hand by quarter turns
where a closed-form model predicts a lower cost, and re-solve.

A quarter turn of the hand at an action is a discrete choice (the cube's symmetry)
that the IK seeding (lgp.planner.seeding) makes before KOMO; near-ties between turn
families made different seeds end in different optima. `solve` ranks every turn of
a run of consecutive actions by its predicted cost change and re-solves from the
turned trajectory for the best, up to TURN_RESOLVES times.
"""
from __future__ import annotations

import numpy as np

from lgp.arm import Arm
from lgp.komo import Komo, KomoResult
from lgp.planner import skeleton
from lgp.planner.design import Design
from lgp.planner.seeding import SEED_MARGIN
from lgp.symbolic import SymbolicPlan

#: At most this many KOMO re-solves with re-chosen quarter turns per seed.
TURN_RESOLVES = 3


def solve(symbolic: SymbolicPlan, arm: Arm, komo: Komo, seeds, turns: dict[int, int], formulation: str, solver: str,
          design: Design) -> tuple[Komo, KomoResult, dict[int, int]]:
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
    made different IK seeds end in different optima. Returns (komo, result, turns).
    """
    result = komo.solve(formulation=formulation, solver=solver, seeds=seeds)
    elapsed = result.solve_time
    waypoints = skeleton.waypoints(symbolic, design.approach_height)
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

        d = best_untried_turn(arm, e, X_K, B, slots, -1e-6 * result.cost, lambda d: tuple(sorted(turned(d).items())) not in tried)
        if d is None:
            break
        new_turns = turned(d)
        tried.add(tuple(sorted(new_turns.items())))
        new_komo = skeleton.transcribe(symbolic, arm, waypoints, new_turns, phases, design)
        X_K[:, 6] += B @ d
        candidate = new_komo.solve(formulation=formulation, solver=solver, initial_guess=new_komo.interpolate(dict(zip(K, X_K))))
        elapsed += candidate.solve_time
        if not (candidate.success and candidate.max_violation <= 1e-6 and candidate.cost < result.cost):
            break
        komo, result, turns = new_komo, candidate, new_turns
    result.solve_time = elapsed
    return komo, result, turns


def predicted_turn_changes(arm, G, g, X_K, B, slots, H=None, fast: bool = False):
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
    when A is too ill-conditioned for that bound. `best_untried_turn` decides
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
    D = turn_steps(X_K, B, arm.q_lower[6] + SEED_MARGIN, arm.q_upper[6] - SEED_MARGIN)  # (n_actions, m): column m is one d
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


def turn_steps(X_K, B, lo: float, hi: float) -> np.ndarray:
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


def best_untried_turn(arm, e, X_K, B, slots, threshold: float, untried) -> np.ndarray | None:
    """The first d, in order of predicted change, below `threshold` and `untried(d)`;
    None when there is none. Decided on `predicted_turn_changes(fast=True)` when every
    change it compares (the ones up to the pick, the next one, the threshold) lies
    more than its band apart; else on the exact ranking. Either way the pick is the
    one the exact ranking gives."""
    changes, band, sure = predicted_turn_changes(arm, e.G, e.g, X_K, B, slots, e.GtG, fast=True)
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
    for change, d in predicted_turn_changes(arm, e.G, e.g, X_K, B, slots, e.GtG):
        if change >= threshold:
            return None
        if untried(d):
            return d
    return None
