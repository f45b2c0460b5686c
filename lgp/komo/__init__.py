"""KOMO (k-order motion optimisation, Toussaint 2014/2015) on Drake's MathematicalProgram.

The geometric layer of the paper ("Geometric planning"): a motion is *declared* on a
phase clock, rai-style, and then one call turns the declaration into a
MathematicalProgram and solves it::

    komo = Komo(arm, phases=3, slices_per_phase=20, k_order=2, objects={"b1": X_WB})
    komo.add_objective([0.8], "pose", ("G",), "eq", target=X_WG_pregrasp)
    komo.add_mode_switch(1.0, "grasp", "G", "b1", X_GB=X_GB)
    komo.add_rest(1.0)                                             # zero velocity
    komo.add_objective([2.0], "pose", ("b1",), "eq", target=X_WB_goal)
    komo.add_mode_switch(2.0, "place", "G", "b1")
    komo.add_objective([3.0], "qItself", type="eq", target=q_home)
    komo.add_rest(3.0, after=False)
    result = komo.solve()                                          # reduced, SNOPT

Time. Phase p runs over slices; slice s = 0 .. N-1 (N = phases * slices_per_phase)
sits at time (s + 1) * tau, tau = phase_duration / slices_per_phase; a phase time p
maps to slice round(p * slices_per_phase) - 1. Before slice 0 come k_order prefix
slices fixed at `q_home`: the motion starts at rest at home (rai's prefix).

Cost. The control cost of order k: sum_s |q^(k)_s|^2 tau with q^(k) the k-th
backward finite difference divided by tau^k -- for k = 2 the integral of the squared
joint acceleration (the paper: "minimizes squared acceleration of the joints").

Kinematic modes. Objects (blocks) are not bodies of the plant: an object is either
free, at a constant pose, or held by a gripper frame G with a fixed X_GB between a
"grasp" and a "place" mode switch, so that X_WB(q) = X_WG(q) X_GB. A grasp switch
also constrains the gripper to the grasp pose X_WG = X_WB X_GB^-1.

Two formulations of the same problem (`solve(formulation=...)`):

- "full": every slice's joint vector is a decision variable (the reference).
- "reduced" (exact): slices that carry a nonlinear objective ("keyframes") are the
  decision variables; every other slice is eliminated. For fixed keyframes, the
  free slices minimise a quadratic (control cost) subject to linear equalities (rest,
  home), so they are an affine function X_F = M X_K + m of the keyframes, found by
  one KKT solve. Substituting gives a quadratic cost in the keyframes alone. Joint
  limits at free slices, and objectives declared `lazy`, are imposed where the
  solution violates them: that slice is promoted to a keyframe and the program
  re-solved, so the final point satisfies every constraint of the full program and
  is stationary for it.

Both write the quadratic cost as |a|^2 on auxiliary residual variables tied to the
joint variables by linear equalities (a = W X + w0 for full, a Cholesky factor for
reduced): the same program, but SNOPT's quasi-Newton Hessian is then the identity
instead of a matrix whose condition number grows like N^4 (100x faster, see
docs/benchmarks.md).
"""
from __future__ import annotations

import time as _time
from dataclasses import dataclass, field
from math import comb

import numpy as np
from scipy import sparse
from scipy.sparse import linalg as splinalg
from pydrake.math import RigidTransform
from pydrake.multibody.inverse_kinematics import PositionConstraint
from pydrake.solvers import IpoptSolver, MathematicalProgram, SnoptSolver, SolverOptions

#: Features a declared objective may use.
FEATURES = ("qItself", "position", "pose")
#: Objective types, as in rai: equality, inequality (feature - target <= 0), sum of squares.
TYPES = ("eq", "ineq", "sos")
#: Length (m) of the lever arms used to express an orientation as point positions:
#: an orientation error of e rad shows up as a position error of e * _LEVER.
_LEVER = 0.1
#: A free slice may exceed a joint limit by this much (rad) before it is promoted.
_LIMIT_TOLERANCE = 1e-9
#: A lazy constraint may be violated by this much before it is imposed.
_LAZY_TOLERANCE = 1e-9


class KomoError(ValueError):
    """A declaration that cannot be turned into a program (bad time, frame, feature)."""


@dataclass(frozen=True)
class Objective:
    """One declared objective: `feature` of `frames` at the decision slices `slices`."""

    slices: tuple[int, ...]
    feature: str
    frames: tuple[str, ...]
    type: str
    scale: float | tuple[float, float, float]
    target: object
    order: int
    time: tuple[float, ...]
    lazy: bool = False


@dataclass(frozen=True)
class ModeSwitch:
    slice: int
    time: float
    mode: str
    gripper: str
    object: str
    X_GB: RigidTransform | None


@dataclass
class KomoResult:
    """A solved KOMO problem: the trajectory (with time 0 first) and how it was found."""

    t: np.ndarray  # (n,) seconds, n = N + 1 (time 0 = the last prefix slice)
    q: np.ndarray  # (n, nq)
    cost: float  # control cost (+ sos terms) of the full trajectory
    success: bool
    status: str
    solver: str
    formulation: str
    solve_time: float  # wall-clock seconds: building, solving, promotions
    n_variables: int
    keyframes: tuple[int, ...]  # decision slices of the reduced program (all for "full")
    max_violation: float  # largest violation of a declared eq/ineq constraint
    worst_objective: Objective | None  # the objective with that violation
    X_WB: dict[str, np.ndarray] = field(default_factory=dict)  # object poses (n, 4, 4)

    def p_WB(self, name: str) -> np.ndarray:
        """Position of object `name` at every slice, (n, 3)."""
        return self.X_WB[name][:, :3, 3]


class Komo:
    """A KOMO problem declared on a phase clock over a Drake MultibodyPlant.

    `arm` is an `lgp.arm.Arm` or anything with `plant` (finalized MultibodyPlant),
    `q_home`, `q_lower`, `q_upper`; or a bare MultibodyPlant (then `q_home` must be
    given). `objects` maps object names to their initial world pose X_WB.
    """

    def __init__(self, arm, phases: int, slices_per_phase: int, k_order: int = 2, *, phase_duration: float = 1.0,
                 q_home=None, objects: dict[str, RigidTransform] | None = None):
        plant = getattr(arm, "plant", arm)
        self.plant = plant
        self.context = plant.CreateDefaultContext()
        self.nq = plant.num_positions()
        home = q_home if q_home is not None else getattr(arm, "q_home", None)
        if home is None:
            raise KomoError("Komo needs q_home (the rest configuration at time 0)")
        self.q_home = np.asarray(home, float).reshape(self.nq)
        self.q_lower = np.asarray(getattr(arm, "q_lower", plant.GetPositionLowerLimits()), float)
        self.q_upper = np.asarray(getattr(arm, "q_upper", plant.GetPositionUpperLimits()), float)
        if phases < 1 or slices_per_phase < 1 or k_order < 1:
            raise KomoError(f"Komo needs phases, slices_per_phase, k_order >= 1, got {phases}, {slices_per_phase}, {k_order}")
        self.phases, self.slices_per_phase, self.k_order = int(phases), int(slices_per_phase), int(k_order)
        self.phase_duration = float(phase_duration)
        self.tau = self.phase_duration / self.slices_per_phase
        self.N = self.phases * self.slices_per_phase
        self.objects = {name: RigidTransform(X) for name, X in (objects or {}).items()}
        self.objectives: list[Objective] = []
        self.switches: list[ModeSwitch] = []
        self.rests: list[tuple[int, bool]] = []  # (slice, also after it)

    # ------------------------------------------------------------------ declaration

    def slice_of(self, time: float) -> int:
        s = int(round(time * self.slices_per_phase)) - 1
        if not 0 <= s < self.N or abs((s + 1) - time * self.slices_per_phase) > 1e-9:
            raise KomoError(f"time {time} (phases) is not a slice of 0 < t <= {self.phases} at {self.slices_per_phase} slices per phase")
        return s

    def _slices(self, times) -> tuple[int, ...]:
        if times is None or len(times) == 0:
            return tuple(range(self.N))
        if len(times) == 1:
            return (self.slice_of(times[0]),)
        if len(times) == 2:
            return tuple(range(self.slice_of(times[0]), self.slice_of(times[1]) + 1))
        raise KomoError(f"times must be [], [t] or [t_start, t_end], got {times}")

    def add_objective(self, times, feature: str, frames=(), type: str = "sos", scale=1.0, target=None, order: int = 0,
                      lazy: bool = False):
        """Declare `feature` of `frames` at `times` ([t], [t0, t1] or [] for all).

        Features: "qItself" (the joint vector, or its order-th time derivative;
        linear), "position" (p_WF of a plant frame or object, target a 3-vector;
        a 3-vector `scale` with zeros leaves those axes free),
        "pose" (X_WF, target a RigidTransform). Types: "eq", "ineq" (feature - target
        <= 0, componentwise; position only; a negative scale flips an axis to >=, as
        in rai) and "sos" (scale^2 |feature - target|^2 added to the cost; qItself
        only, so the cost stays quadratic). A `lazy` constraint is only imposed by the
        reduced formulation once the solution violates it (its slice is then promoted
        to a keyframe and the program re-solved), which keeps it exact but cheap when
        it is mostly inactive; the full formulation imposes it everywhere from the start.
        Time derivatives are backward differences, as in rai.
        """
        if feature not in FEATURES:
            raise KomoError(f"unknown feature {feature!r} (known: {', '.join(FEATURES)})")
        if type not in TYPES:
            raise KomoError(f"unknown objective type {type!r} (known: {', '.join(TYPES)})")
        frames = (frames,) if isinstance(frames, str) else tuple(frames)
        if feature != "qItself":
            if order != 0:
                raise KomoError(f"feature {feature} supports order 0 only")
            if type == "sos":
                raise KomoError(f"sos objectives on {feature} are not supported (the reduced formulation needs a quadratic cost)")
            if type == "ineq" and feature == "pose":
                raise KomoError("ineq objectives on pose are not supported")
            if len(frames) != 1:
                raise KomoError(f"feature {feature} takes one frame, got {frames}")
            if frames[0] not in self.objects:
                self._frame(frames[0])  # raises if unknown
        elif order > self.k_order and type != "sos":
            raise KomoError(f"qItself of order {order} needs k_order >= {order}")
        if feature == "position":
            target = np.asarray(target, float).reshape(3)
        elif feature == "pose":
            target = RigidTransform(target)
        elif target is not None:
            target = np.broadcast_to(np.asarray(target, float), (self.nq,)).copy()
        times = tuple(float(t) for t in (times or ()))
        scale = float(scale) if np.ndim(scale) == 0 else tuple(float(v) for v in np.reshape(scale, 3))
        if lazy and (feature == "qItself" or type == "sos"):
            raise KomoError("only nonlinear eq/ineq objectives can be lazy")
        self.objectives.append(Objective(self._slices(times), feature, frames, type, scale, target, int(order), times, bool(lazy)))
        return self

    def add_mode_switch(self, time: float, mode: str, gripper: str, obj: str, X_GB: RigidTransform | None = None, X_WB=None):
        """Declare a kinematic mode switch of object `obj` at phase `time`.

        "grasp": from this slice on `obj` moves with `gripper` as X_WB = X_WG X_GB;
        the gripper is constrained to X_WG = X_WB X_GB^-1 at this slice (X_GB
        required). "place": after this slice `obj` stays where it is; with X_WB
        given, also declares the eq objective "pose of obj = X_WB" at this slice.
        """
        if mode not in ("grasp", "place"):
            raise KomoError(f"unknown mode {mode!r} (known: grasp, place)")
        if obj not in self.objects:
            raise KomoError(f"mode switch on unknown object {obj!r} (declare it in objects=)")
        self._frame(gripper)
        if mode == "grasp" and X_GB is None:
            raise KomoError(f"grasp of {obj} at phase {time} needs X_GB (the object's pose in the gripper)")
        s = self.slice_of(time)
        self.switches.append(ModeSwitch(s, float(time), mode, gripper, obj, None if X_GB is None else RigidTransform(X_GB)))
        self.switches.sort(key=lambda m: (m.slice, m.mode != "place"))
        if mode == "place" and X_WB is not None:
            self.add_objective([time], "pose", (obj,), "eq", target=X_WB)
        return self

    def add_rest(self, time: float, after: bool = True):
        """Zero velocity at phase `time`, to second order, without standing still a slice.

        Imposes (3 q[s] - 4 q[s-1] + q[s-2]) / (2 tau) = 0 and, with `after`, the same
        one-sided difference forward: the motion comes to rest at s and leaves it
        tangentially. (rai's order-1 feature, (q[s] - q[s-1]) / tau = 0, makes the
        arm stand still for a whole slice, which shortens the neighbouring moves by
        tau each and biased a 20-slice-per-phase plan's effort by 4 %.)
        """
        s = self.slice_of(time)
        if s < 1 or (after and s > self.N - 3):
            raise KomoError(f"a rest at phase {time} needs two slices on each side it constrains")
        self.rests.append((s, bool(after)))
        return self

    def _frame(self, name: str):
        if not self.plant.HasFrameNamed(name):
            raise KomoError(f"no frame or object named {name!r} in the plant or objects")
        return self.plant.GetFrameByName(name)

    def _holder(self, obj: str, s: int):
        """(gripper frame name, X_GB) if `obj` is held at slice s, else None."""
        held = None
        for m in self.switches:
            if m.object != obj or m.slice > s:
                continue
            if m.mode == "grasp":
                held = (m.gripper, m.X_GB)
            elif m.slice < s:
                held = None
        return held

    # ------------------------------------------------------------------ linear structure

    def _row(self, s: int, order: int) -> np.ndarray:
        """Coefficients over [prefix slices, decision slices] of the order-th difference at s, / tau^order."""
        k = self.k_order
        row = np.zeros(k + self.N)
        for i in range(order + 1):
            row[k + s - i] += (-1) ** i * comb(order, i)
        if order > 0 and s - order < -k:
            raise KomoError(f"order-{order} term at slice {s} reaches before the prefix")
        return row / self.tau**order

    def _linear_rows(self):
        """Cost residual W X + w0 and equalities C X = E over decision slices (per joint).

        W and C are sparse (a few nonzeros per row); X is (N, nq), one column per joint.
        """
        k, prefix = self.k_order, np.tile(self.q_home, (self.k_order, 1))
        cost, eq = [], []
        weight = np.sqrt(self.tau)  # sum |q^(k)|^2 tau approximates the time integral
        for s in range(self.N):
            cost.append((weight * self._row(s, k), np.zeros(self.nq)))
        for o in self.objectives:
            if o.feature != "qItself":
                continue
            target = np.zeros(self.nq) if o.target is None else o.target
            for s in o.slices:
                row = self._row(s, o.order)
                if o.type == "sos":
                    cost.append((o.scale * row, -o.scale * target))
                elif o.type == "eq":
                    eq.append((row, target))
                else:
                    raise KomoError("ineq objectives on qItself are not supported (use joint limits)")
        for s, after in self.rests:
            sides = (-1, 1) if after else (-1,)
            for side in sides:
                row = np.zeros(k + self.N)
                row[k + s], row[k + s + side], row[k + s + 2 * side] = 1.5, -2.0, 0.5
                eq.append((row / self.tau, np.zeros(self.nq)))
        W = np.array([r for r, _ in cost])
        w0 = np.array([c for _, c in cost]) + W[:, :k] @ prefix
        if eq:
            C = np.array([r for r, _ in eq])
            E = np.array([c for _, c in eq]) - C[:, :k] @ prefix
        else:
            C, E = np.zeros((0, k + self.N)), np.zeros((0, self.nq))
        return sparse.csr_matrix(W[:, k:]), w0, sparse.csr_matrix(C[:, k:]), E

    def _eliminate(self, K: list[int], W, w0, C, E):
        """Free slices as X_F = M X_K + m minimising |W X + w0|^2 s.t. C X = E (exact).

        Returns F, M, m, and the reduced residual G X_K + g (G = W_F M + W_K, g =
        W_F m + w0), plus the equalities that involve keyframes only. Sparse LU
        (single-threaded) on the KKT system: it is banded and small.
        """
        F = np.setdiff1d(np.arange(self.N), K)
        W = sparse.csc_matrix(W)
        C = sparse.csc_matrix(C)
        W_F, W_K, C_F, C_K = W[:, F], W[:, K], C[:, F], C[:, K]
        only_K = np.asarray(abs(C_F).sum(axis=1)).ravel() == 0
        Cf, Ck, Ef = C_F[~only_K], C_K[~only_K], E[~only_K]
        nF, nK = len(F), len(K)
        KKT = sparse.bmat([[2 * (W_F.T @ W_F), Cf.T], [Cf, None]], format="csc")
        rhs = np.vstack([np.hstack([-2 * (W_F.T @ W_K).toarray(), -2 * (W_F.T @ w0)]), np.hstack([-Ck.toarray(), Ef])])
        try:
            sol = splinalg.splu(KKT).solve(rhs) if nF + len(Ef) else np.zeros((0, nK + self.nq))
        except RuntimeError:
            raise KomoError("the linear (qItself) equalities over-determine or contradict each other on free slices") from None
        M, m = sol[:nF, :nK], sol[:nF, nK:]
        G = W_F @ M + W_K.toarray()
        g = W_F @ m + w0
        return F, M, m, G, g, C[only_K][:, K].toarray(), E[only_K]

    def reduced_cost(self, keyframes) -> tuple[np.ndarray, np.ndarray]:
        """(G, g) with cost = sum_j |G X_K[:, j] + g[:, j]|^2 once the other slices are eliminated."""
        W, w0, C, E = self._linear_rows()
        _, _, _, G, g, _, _ = self._eliminate(sorted(keyframes), W, w0, C, E)
        return G, g

    def interpolate(self, seeds: dict[int, np.ndarray]) -> np.ndarray:
        """Minimum-control-cost trajectory (N, nq) through `seeds` {slice: q} under the linear equalities."""
        W, w0, C, E = self._linear_rows()
        K = sorted(seeds)
        X = np.zeros((self.N, self.nq))
        X_K = np.array([seeds[s] for s in K]).reshape(len(K), self.nq)
        X[K] = X_K
        F, M, m, *_ = self._eliminate(K, W, w0, C, E)
        X[F] = M @ X_K + m
        return X

    # ------------------------------------------------------------------ nonlinear constraints

    def _constraints(self, o: Objective, s: int):
        """Drake constraints (C++ evaluators) for nonlinear objective o at slice s."""
        name = o.frames[0]
        if name in self.objects:
            holder = self._holder(name, s)
            if holder is None:
                raise KomoError(f"{o.feature} objective on {name} at phase {(s + 1) / self.slices_per_phase}: {name} is not held then")
            frame, X_GB = self._frame(holder[0]), holder[1]
        else:
            frame, X_GB = self._frame(name), RigidTransform()
        world = self.plant.world_frame()
        if o.feature == "position":
            p_GQ = X_GB.translation()
            scale = np.broadcast_to(np.asarray(o.scale, float), (3,))
            free = scale == 0  # rai-style: a zero scale drops the axis, a negative one flips an ineq
            if o.type == "eq":
                lo, hi = np.where(free, -np.inf, o.target), np.where(free, np.inf, o.target)
            else:
                lo = np.where(scale < 0, o.target, -np.inf)
                hi = np.where(scale > 0, o.target, np.inf)
            return [PositionConstraint(self.plant, world, lo, hi, frame, p_GQ, self.context)]
        # pose: X_WG = X_target X_GB^-1, written as three point positions (6 equalities):
        X_WT = o.target.multiply(X_GB.inverse())
        inf = np.inf
        return [
            PositionConstraint(self.plant, world, X_WT.translation(), X_WT.translation(), frame, np.zeros(3), self.context),
            # G's z axis along T's: the point G + l z_G lies on T's z axis, on the + side.
            PositionConstraint(self.plant, world, X_WT, np.array([0, 0, 0.0]), np.array([0, 0, inf]), frame, np.array([0, 0, _LEVER]), self.context),
            # G's x axis along T's: the point G + l x_G has no y in T, on the + side.
            PositionConstraint(self.plant, world, X_WT, np.array([0.0, 0, -inf]), np.array([inf, 0, inf]), frame, np.array([_LEVER, 0, 0]), self.context),
        ]

    def _grasp_objectives(self) -> list[Objective]:
        """The gripper-at-grasp-pose objective implied by each grasp switch."""
        out = []
        for m in self.switches:
            if m.mode == "grasp":
                X_WB = self._free_pose(m.object, m.slice)
                out.append(Objective((m.slice,), "pose", (m.gripper,), "eq", 1.0, X_WB.multiply(m.X_GB.inverse()), 0, (m.time,)))
        return out

    def _free_pose(self, obj: str, s: int) -> RigidTransform:
        """Pose of `obj` when grasped at slice s: initial, or the target of its last place."""
        X = self.objects[obj]
        for m in self.switches:
            if m.object == obj and m.mode == "place" and m.slice < s:
                X = next((o.target for o in self.objectives if o.feature == "pose" and o.frames == (obj,) and m.slice in o.slices), None)
                if X is None:
                    raise KomoError(f"{obj} is grasped at slice {s} after a place without a declared pose target")
        return X

    def _nonlinear(self) -> list[tuple[Objective, int]]:
        return [(o, s) for o in (*self.objectives, *self._grasp_objectives()) if o.feature != "qItself" for s in o.slices]

    # ------------------------------------------------------------------ solving

    def solve(self, formulation: str = "reduced", solver: str = "snopt", seeds: dict | None = None,
              initial_guess: np.ndarray | None = None, options: dict | None = None, max_promotions: int = 20) -> KomoResult:
        """Build the MathematicalProgram of the declaration and solve it.

        `seeds` {phase time: q} are joint vectors at some slices (e.g. IK solutions at
        keyframes); the initial guess is the minimum-control-cost interpolation
        through them. `initial_guess` (N, nq) overrides it. Solvers: "snopt", "ipopt".
        """
        start = _time.perf_counter()
        if formulation not in ("reduced", "full"):
            raise KomoError(f"unknown formulation {formulation!r} (known: reduced, full)")
        W, w0, C, E = self._linear_rows()
        nonlinear = self._nonlinear()
        if initial_guess is None:
            seed_slices = {self.slice_of(t): np.asarray(q, float) for t, q in (seeds or {}).items()}
            initial_guess = self.interpolate(seed_slices)
        X0 = np.asarray(initial_guess, float).reshape(self.N, self.nq)
        backend = _solver(solver, options)
        if formulation == "full":
            X, result, nvar = self._solve_full(W, w0, C, E, nonlinear, X0, backend)
            K = tuple(range(self.N))
        else:
            active = [(o, s) for o, s in nonlinear if not o.lazy]
            waiting = [(o, s) for o, s in nonlinear if o.lazy]
            K = sorted({s for _, s in active})
            for _ in range(max_promotions + 1):
                X, result, nvar = self._solve_reduced(K, W, w0, C, E, active, X0, backend)
                if not result.is_success():
                    break
                # Promote what the solution violates: free slices over a joint limit,
                # and lazy constraints. Exact, not a penalty: the final point obeys all.
                bad = set(np.flatnonzero(np.any((X < self.q_lower - _LIMIT_TOLERANCE) | (X > self.q_upper + _LIMIT_TOLERANCE), axis=1)).tolist())
                woken = [(o, s) for o, s in waiting if self._violation(o, s, X[s]) > _LAZY_TOLERANCE]
                if not bad and not woken:
                    break
                active += woken
                waiting = [w for w in waiting if w not in woken]
                K = sorted(set(K) | bad | {s for _, s in woken})
                X0 = X
            K = tuple(K)
        elapsed = _time.perf_counter() - start
        return self._result(X, result, solver, formulation, elapsed, nvar, K, nonlinear, W, w0)

    def _solve_reduced(self, K, W, w0, C, E, nonlinear, X0, backend):
        """Keyframes K are the decision variables; free slices are X_F = M X_K + m.

        The reduced cost |G X_K + g|^2 is written as |z|^2 + const on auxiliary
        variables z = L X_K + l (L the Cholesky factor of G'G, a linear equality):
        the same program, but SNOPT's quasi-Newton Hessian is then the identity
        instead of the badly conditioned G'G (9x fewer seconds on a 10-block plan).
        """
        F, M, m, G, g, C_KK, E_KK = self._eliminate(K, W, w0, C, E)
        nK = len(K)
        prog = MathematicalProgram()
        x = prog.NewContinuousVariables(nK, self.nq, "q")
        z = prog.NewContinuousVariables(nK, self.nq, "z")
        xs, zs = x.reshape(-1), z.reshape(-1)
        L = np.linalg.cholesky(G.T @ G).T  # G'G = L'L
        l = np.linalg.solve(L.T, G.T @ g)  # |G x + g|^2 = |L x + l|^2 + const
        const = float(np.sum(g * g) - np.sum(l * l))
        lifted = sparse.hstack([sparse.kron(sparse.csr_matrix(L), sparse.eye(self.nq)), -sparse.eye(nK * self.nq)]).tocsc()
        prog.AddLinearEqualityConstraint(lifted, -l.reshape(-1), np.concatenate([xs, zs]))
        prog.AddQuadraticCost(2 * np.eye(nK * self.nq), np.zeros(nK * self.nq), const, zs, is_convex=True)
        if len(C_KK):
            prog.AddLinearEqualityConstraint(np.kron(C_KK, np.eye(self.nq)), E_KK.reshape(-1), xs)
        for i in range(nK):
            prog.AddBoundingBoxConstraint(self.q_lower, self.q_upper, x[i])
        index = {s: i for i, s in enumerate(K)}
        for o, s in nonlinear:
            for c in self._constraints(o, s):
                prog.AddConstraint(c, x[index[s]])
        prog.SetInitialGuess(x, X0[K])
        prog.SetInitialGuess(z, L @ X0[K] + l)
        result = backend.solve(prog)
        X_K = result.GetSolution(x).reshape(nK, self.nq)
        X = np.zeros((self.N, self.nq))
        X[K], X[F] = X_K, M @ X_K + m
        return X, result, prog.num_vars()

    def _solve_full(self, W, w0, C, E, nonlinear, X0, backend):
        """Every slice's joint vector is a decision variable (the reference program).

        The control cost is put on auxiliary residual variables a = W X + w0 (tied by
        sparse linear equalities) with cost |a|^2: the same program, but SNOPT's
        quasi-Newton Hessian no longer has to learn the badly conditioned W'W
        (condition number ~ N^4); with the cost written on X directly, a 2-block plan
        took 170 s instead of 0.6 s (docs/benchmarks.md).
        """
        prog = MathematicalProgram()
        x = prog.NewContinuousVariables(self.N, self.nq, "q")
        R = W.shape[0]
        a = prog.NewContinuousVariables(R, self.nq, "a")
        xs, as_ = x.reshape(-1), a.reshape(-1)
        eye = sparse.eye(self.nq)
        lifted = sparse.hstack([sparse.kron(W, eye), -sparse.eye(R * self.nq)]).tocsc()
        prog.AddLinearEqualityConstraint(lifted, -w0.reshape(-1), np.concatenate([xs, as_]))
        prog.AddQuadraticCost(2 * np.eye(R * self.nq), np.zeros(R * self.nq), 0.0, as_, is_convex=True)
        if C.shape[0]:
            prog.AddLinearEqualityConstraint(sparse.kron(C, eye).tocsc(), E.reshape(-1), xs)
        prog.AddBoundingBoxConstraint(np.tile(self.q_lower, self.N), np.tile(self.q_upper, self.N), xs)
        for o, s in nonlinear:
            for c in self._constraints(o, s):
                prog.AddConstraint(c, x[s])
        prog.SetInitialGuess(x, X0)
        prog.SetInitialGuess(a, W @ X0 + w0)
        result = backend.solve(prog)
        return result.GetSolution(x).reshape(self.N, self.nq), result, prog.num_vars()

    def _violation(self, o: Objective, s: int, q: np.ndarray) -> float:
        worst = 0.0
        for c in self._constraints(o, s):
            y = c.Eval(q)
            worst = max(worst, float(np.max(np.maximum(np.maximum(c.lower_bound() - y, y - c.upper_bound()), 0.0))))
        return worst

    def _result(self, X, result, solver, formulation, elapsed, nvar, K, nonlinear, W, w0) -> KomoResult:
        q = np.vstack([self.q_home, X])
        t = np.arange(self.N + 1) * self.tau
        cost = float(np.sum((W @ X + w0) ** 2))  # W sparse
        worst, worst_o = 0.0, None
        for o, s in nonlinear:
            v = self._violation(o, s, X[s])
            if v > worst:
                worst, worst_o = v, o
        limits = float(np.max(np.maximum(np.maximum(self.q_lower - X, X - self.q_upper), 0.0)))
        if limits > worst:
            worst, worst_o = limits, None
        status = str(result.get_solution_result()).split(".")[-1]
        if solver == "snopt":
            status += f" (snopt info {result.get_solver_details().info})"
        return KomoResult(t=t, q=q, cost=cost, success=bool(result.is_success()), status=status, solver=solver,
                          formulation=formulation, solve_time=elapsed, n_variables=int(nvar), keyframes=tuple(K),
                          max_violation=worst, worst_objective=worst_o, X_WB=self.object_poses(q))

    # ------------------------------------------------------------------ evaluation

    def frame_poses(self, q: np.ndarray, frame: str) -> np.ndarray:
        """X_WF (n, 4, 4) of a plant frame along a trajectory q (n, nq)."""
        F = self._frame(frame)
        out = np.empty((len(q), 4, 4))
        for i, qi in enumerate(q):
            self.plant.SetPositions(self.context, qi)
            out[i] = self.plant.CalcRelativeTransform(self.context, self.plant.world_frame(), F).GetAsMatrix4()
        return out

    def object_poses(self, q: np.ndarray) -> dict[str, np.ndarray]:
        """X_WB (n, 4, 4) of every object along q (n = N + 1 rows, time 0 first)."""
        poses = {}
        cache: dict[str, np.ndarray] = {}
        for name, X0 in self.objects.items():
            X = np.empty((len(q), 4, 4))
            current = X0.GetAsMatrix4()
            for i in range(len(q)):
                holder = self._holder(name, i - 1) if i > 0 else None
                if holder is not None:
                    gripper, X_GB = holder
                    if gripper not in cache:
                        cache[gripper] = self.frame_poses(q, gripper)
                    current = cache[gripper][i] @ X_GB.GetAsMatrix4()
                X[i] = current
            poses[name] = X
        return poses


def kinetic_energy(p: np.ndarray, tau: float, mass: float = 1.0) -> float:
    """Time integral (J s) of 1/2 m |v|^2 along positions p (n, 3) sampled every tau s.

    v is the backward difference (p_s - p_s-1) / tau, so the sum times tau
    approximates the integral and does not grow with the number of slices.
    """
    v = np.diff(np.asarray(p, float), axis=0) / tau
    return float(0.5 * mass * np.sum(v * v) * tau)


class _Backend:
    def __init__(self, solver, options):
        self.solver, self.options = solver, options

    def solve(self, prog):
        return self.solver.Solve(prog, None, self.options)


def _solver(name: str, extra: dict | None) -> _Backend:
    options = SolverOptions()
    if name == "snopt":
        solver = SnoptSolver()
        defaults = {"Major feasibility tolerance": 1e-9, "Major optimality tolerance": 1e-7, "Major iterations limit": 3000,
                    "Iterations limit": 200000}
    elif name == "ipopt":
        solver = IpoptSolver()
        defaults = {"tol": 1e-9, "constr_viol_tol": 1e-9, "max_iter": 3000, "print_level": 0}
    else:
        raise KomoError(f"unknown solver {name!r} (known: snopt, ipopt)")
    if not solver.available() or not solver.enabled():
        raise KomoError(f"solver {name} is not available in this Drake build")
    for key, value in {**defaults, **(extra or {})}.items():
        options.SetOption(solver.solver_id(), key, value)
    return _Backend(solver, options)
