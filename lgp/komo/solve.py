"""From a KOMO declaration to a MathematicalProgram, solved; `Komo` = declare + solve.

Two formulations of the same problem (`Komo.solve(formulation=...)`):

- "full": every slice's joint vector is a decision variable (the reference).
- "reduced" (exact): slices that carry a nonlinear objective ("keyframes") are the
  decision variables; every other slice is eliminated (lgp.komo.linear: X_F =
  M X_K + m), which leaves a quadratic cost in the keyframes alone. Joint limits at
  free slices, and objectives declared `lazy`, are imposed where the solution
  violates them: that slice is promoted to a keyframe and the program re-solved, so
  the final point satisfies every constraint of the full program and is stationary
  for it.

Both write the quadratic cost as |a|^2 on auxiliary residual variables tied to the
joint variables by linear equalities (a = W X + w0 for full, a Cholesky factor for
reduced): the same program, but SNOPT's quasi-Newton Hessian is then the identity
instead of a matrix whose condition number grows like N^4 (100x faster, see
docs/benchmarks.md).
"""
from __future__ import annotations

import time as _time
from collections import OrderedDict

import numpy as np
from scipy import sparse
from pydrake.solvers import IpoptSolver, MathematicalProgram, SnoptSolver, SolverOptions

from lgp.komo.constraints import drake_constraints, violation
from lgp.komo.declaration import Declaration, KomoError
from lgp.komo.linear import Elimination, LinearStructure, eliminate, interpolate, linear_structure
from lgp.komo.result import KomoResult, frame_poses, object_poses, worst_violation

#: A free slice may exceed a joint limit by this much (rad) before it is promoted.
LIMIT_TOLERANCE = 1e-9
#: A lazy constraint may be violated by this much before it is imposed.
LAZY_TOLERANCE = 1e-9
FORMULATIONS = ("reduced", "full")
SOLVERS = ("snopt", "ipopt")
#: Linear structures kept per process (least recently used dropped), and eliminations
#: (keyframe sets) kept per structure: a plan needs 2-4, the layouts of a trial share them.
STRUCTURES_KEPT = 4
ELIMINATIONS_KEPT = 8
#: The reduced program's cost |z|^2 is one quadratic cost per keyframe (nq variables
#: each) instead of one over all nK * nq: Drake evaluates a cost's gradient through a
#: dense (variables x variables) derivative matrix, 39 MB for 3E's 2205 residuals at
#: every IPOPT iteration (bench/clearance.py measures both side by side). The solver
#: sees the same gradients, and the same cost but summed in another order: of the 48
#: layout-0 plans of the paper's trials (both designs) 47 came out identical to the
#: bit, 12E's clearance plan within 4.7e-15 rad (effort -7.8e-16 relative). In the
#: default run (M = 30) 4 of 720 efforts differ, by at most 4.9e-12 relative, and no
#: ordering or verdict moves (with False the run's CSVs equal the earlier ones byte for
#: byte, solve_time aside). False only to measure the single cost.
SPLIT_COST = True

# {structure key: (LinearStructure, {keyframes: Elimination})}: the linear part of a
# declaration depends only on its skeleton (slices, rests, qItself objectives, home),
# not on the poses it is asked to reach, so the Komos of a trial's layouts share it.
_STRUCTURES: OrderedDict[tuple, tuple[LinearStructure, OrderedDict[tuple, Elimination]]] = OrderedDict()


def _structure_key(komo: Declaration) -> tuple:
    """Everything lgp.komo.linear.linear_structure reads from a declaration."""
    qitself = tuple((o.slices, o.type, o.order, o.scale, None if o.target is None else np.asarray(o.target, float).tobytes())
                    for o in komo.objectives if o.feature == "qItself")
    return (komo.k_order, komo.N, komo.tau, komo.nq, komo.q_home.tobytes(), tuple(komo.rests), qitself)


def _structure(komo: Declaration) -> tuple[LinearStructure, OrderedDict]:
    key = _structure_key(komo)
    entry = _STRUCTURES.get(key)
    if entry is None:
        entry = _STRUCTURES[key] = (linear_structure(komo), OrderedDict())
        while len(_STRUCTURES) > STRUCTURES_KEPT:
            _STRUCTURES.popitem(last=False)
    _STRUCTURES.move_to_end(key)
    return entry


class Komo(Declaration):
    """A KOMO problem: declared on a phase clock (lgp.komo.declaration), then solved.

    The linear structure (lgp.komo.linear) and its eliminations are computed once
    per skeleton in a process and shared by `solve`, `interpolate` and
    `reduced_cost` of every Komo with that skeleton (the layouts of a trial).
    """

    def linear(self) -> LinearStructure:
        """Cost residual and linear equalities of the declaration as it stands now
        (computed once per skeleton in this process and shared)."""
        return _structure(self)[0]

    def elimination(self, keyframes) -> Elimination:
        """The free slices eliminated for these keyframes (lgp.komo.linear.eliminate),
        computed once per (skeleton, keyframes) in this process and shared."""
        linear, eliminations = _structure(self)
        K = tuple(sorted(int(s) for s in keyframes))
        e = eliminations.get(K)
        if e is None:
            e = eliminations[K] = eliminate(linear, K)  # read-only: shared by every Komo of the skeleton
            while len(eliminations) > ELIMINATIONS_KEPT:
                eliminations.popitem(last=False)
        eliminations.move_to_end(K)
        return e

    def interpolate(self, seeds: dict[int, np.ndarray]) -> np.ndarray:
        """Minimum-control-cost trajectory (N, nq) through `seeds` {slice: q} under the linear equalities
        (lgp.komo.linear.interpolate with this skeleton's shared eliminations)."""
        return interpolate(self.linear(), seeds, self.elimination)

    def reduced_cost(self, keyframes) -> tuple[np.ndarray, np.ndarray]:
        """(G, g) with cost = sum_j |G X_K[:, j] + g[:, j]|^2 once the other slices are eliminated."""
        e = self.elimination(keyframes)
        return e.G, e.g

    def frame_poses(self, q: np.ndarray, frame: str) -> np.ndarray:
        """X_WF (n, 4, 4) of a plant frame along a trajectory q (n, nq)."""
        return frame_poses(self, q, frame)

    def object_poses(self, q: np.ndarray) -> dict[str, np.ndarray]:
        """X_WB (n, 4, 4) of every object along q (n = N + 1 rows, time 0 first)."""
        return object_poses(self, q)

    def solve(self, formulation: str = "reduced", solver: str = "snopt", seeds: dict | None = None,
              initial_guess: np.ndarray | None = None, options: dict | None = None, max_promotions: int = 20,
              lifted: bool = True) -> KomoResult:
        """Build the MathematicalProgram of the declaration and solve it.

        `seeds` {phase time: q} are joint vectors at some slices (e.g. IK solutions at
        keyframes); the initial guess is the minimum-control-cost interpolation
        through them. `initial_guess` (N, nq) overrides it. Solvers: "snopt", "ipopt".
        `lifted=False` writes the full formulation's cost on q directly (no residual
        variables), only to measure why it is lifted (bench/komo.py).
        """
        start = _time.perf_counter()
        if formulation not in FORMULATIONS:
            raise KomoError(f"unknown formulation {formulation!r} (known: {', '.join(FORMULATIONS)})")
        linear = self.linear()
        nonlinear = self.nonlinear()
        if initial_guess is None:
            seed_slices = {self.slice_of(t): np.asarray(q, float) for t, q in (seeds or {}).items()}
            initial_guess = self.interpolate(seed_slices)
        X0 = np.asarray(initial_guess, float).reshape(self.N, self.nq)
        backend = _backend(solver, options)
        if formulation == "full":
            X, result, nvar = _solve_full(self, linear, nonlinear, X0, backend, lifted)
            K = tuple(range(self.N))
        else:
            active = [(o, s) for o, s in nonlinear if not o.lazy]
            waiting = [(o, s) for o, s in nonlinear if o.lazy]
            K = sorted({s for _, s in active})
            for _ in range(max_promotions + 1):
                X, result, nvar = _solve_reduced(self, K, active, X0, backend)
                if not result.is_success():
                    break
                # Promote what the solution violates: free slices over a joint limit,
                # and lazy constraints. Exact, not a penalty: the final point obeys all.
                bad = set(np.flatnonzero(np.any((X < self.q_lower - LIMIT_TOLERANCE) | (X > self.q_upper + LIMIT_TOLERANCE), axis=1)).tolist())
                woken = [(o, s) for o, s in waiting if violation(self, o, s, X[s]) > LAZY_TOLERANCE]
                if not bad and not woken:
                    break
                active += woken
                waiting = [w for w in waiting if w not in woken]
                K = sorted(set(K) | bad | {s for _, s in woken})
                X0 = X
            K = tuple(K)
        elapsed = _time.perf_counter() - start
        q = np.vstack([self.q_home, X])
        worst, worst_o = worst_violation(self, X, nonlinear)
        details = result.get_solver_details()
        info = details.info if solver == "snopt" else details.status  # SNOPT's info, IPOPT's ApplicationReturnStatus
        return KomoResult(t=np.arange(self.N + 1) * self.tau, q=q, cost=linear.cost(X), success=bool(result.is_success()),
                          solution_result=result.get_solution_result(), solver_info=int(info), solver=solver, formulation=formulation, solve_time=elapsed, n_variables=int(nvar),
                          keyframes=tuple(K), max_violation=worst, worst_objective=worst_o, X_WB=object_poses(self, q))


def _solve_reduced(komo: Komo, K, nonlinear, X0, backend):
    """Keyframes K are the decision variables; free slices are X_F = M X_K + m.

    The reduced cost |G X_K + g|^2 is written as |z|^2 + const on auxiliary
    variables z = L X_K + l (L the Cholesky factor of G'G, a linear equality):
    the same program, but SNOPT's quasi-Newton Hessian is then the identity
    instead of the badly conditioned G'G (9x fewer seconds on a 10-block plan).
    """
    e = komo.elimination(K)
    nK, nq = len(K), komo.nq
    prog = MathematicalProgram()
    x = prog.NewContinuousVariables(nK, nq, "q")
    z = prog.NewContinuousVariables(nK, nq, "z")
    xs, zs = x.reshape(-1), z.reshape(-1)
    L, l, const = e.cost_factor  # G'G = L'L, |G x + g|^2 = |L x + l|^2 + const
    lifted = sparse.hstack([sparse.kron(sparse.csr_matrix(L), sparse.eye(nq)), -sparse.eye(nK * nq)]).tocsc()
    prog.AddLinearEqualityConstraint(lifted, -l.reshape(-1), np.concatenate([xs, zs]))
    _add_squared_norm(prog, z, const)
    if len(e.C_KK):
        prog.AddLinearEqualityConstraint(np.kron(e.C_KK, np.eye(nq)), e.E_KK.reshape(-1), xs)
    for i in range(nK):
        prog.AddBoundingBoxConstraint(komo.q_lower, komo.q_upper, x[i])
    index = {s: i for i, s in enumerate(K)}
    for o, s in nonlinear:
        for c in drake_constraints(komo, o, s):
            prog.AddConstraint(c, x[index[s]])
    prog.SetInitialGuess(x, X0[K])
    prog.SetInitialGuess(z, L @ X0[K] + l)
    result = backend.solve(prog)
    X_K = result.GetSolution(x).reshape(nK, nq)
    return e.trajectory(X_K), result, prog.num_vars()


def _add_squared_norm(prog: MathematicalProgram, z, const: float) -> None:
    """The cost |z|^2 + const on the variables z (nK, nq): one cost per row (SPLIT_COST)."""
    if not SPLIT_COST:
        prog.AddQuadraticCost(2 * np.eye(z.size), np.zeros(z.size), const, z.reshape(-1), is_convex=True)
        return
    n = z.shape[1]
    for i, row in enumerate(z):
        prog.AddQuadraticCost(2 * np.eye(n), np.zeros(n), const if i == 0 else 0.0, row, is_convex=True)


def _solve_full(komo: Komo, linear: LinearStructure, nonlinear, X0, backend, lifted: bool = True):
    """Every slice's joint vector is a decision variable (the reference program).

    The control cost is put on auxiliary residual variables a = W X + w0 (tied by
    sparse linear equalities) with cost |a|^2: the same program, but SNOPT's
    quasi-Newton Hessian no longer has to learn the badly conditioned W'W
    (condition number ~ N^4); with the cost written on X directly (`lifted=False`),
    a 2-block plan took 170 s instead of 0.6 s (docs/benchmarks.md).
    """
    W, w0, C, E = linear.W, linear.w0, linear.C, linear.E
    N, nq = komo.N, komo.nq
    prog = MathematicalProgram()
    x = prog.NewContinuousVariables(N, nq, "q")
    xs = x.reshape(-1)
    eye = sparse.eye(nq)
    if lifted:
        R = W.shape[0]
        a = prog.NewContinuousVariables(R, nq, "a")
        as_ = a.reshape(-1)
        lifting = sparse.hstack([sparse.kron(W, eye), -sparse.eye(R * nq)]).tocsc()
        prog.AddLinearEqualityConstraint(lifting, -w0.reshape(-1), np.concatenate([xs, as_]))
        prog.AddQuadraticCost(2 * np.eye(R * nq), np.zeros(R * nq), 0.0, as_, is_convex=True)
    else:
        prog.AddQuadraticCost(sparse.kron(2 * (W.T @ W), eye).toarray(), 2 * (W.T @ w0).reshape(-1), float(np.sum(w0 * w0)), xs,
                              is_convex=True)
    if C.shape[0]:
        prog.AddLinearEqualityConstraint(sparse.kron(C, eye).tocsc(), E.reshape(-1), xs)
    prog.AddBoundingBoxConstraint(np.tile(komo.q_lower, N), np.tile(komo.q_upper, N), xs)
    for o, s in nonlinear:
        for c in drake_constraints(komo, o, s):
            prog.AddConstraint(c, x[s])
    prog.SetInitialGuess(x, X0)
    if lifted:
        prog.SetInitialGuess(a, W @ X0 + w0)
    result = backend.solve(prog)
    return result.GetSolution(x).reshape(N, nq), result, prog.num_vars()


class _Backend:
    def __init__(self, solver, options):
        self.solver, self.options = solver, options

    def solve(self, prog):
        return self.solver.Solve(prog, None, self.options)


def _backend(name: str, extra: dict | None) -> _Backend:
    options = SolverOptions()
    if name == "snopt":
        solver = SnoptSolver()
        defaults = {"Major feasibility tolerance": 1e-9, "Major optimality tolerance": 1e-7, "Major iterations limit": 3000,
                    "Iterations limit": 200000}
    elif name == "ipopt":
        solver = IpoptSolver()
        defaults = {"tol": 1e-9, "constr_viol_tol": 1e-9, "max_iter": 3000, "print_level": 0}
    else:
        raise KomoError(f"unknown solver {name!r} (known: {', '.join(SOLVERS)})")
    if not solver.available() or not solver.enabled():
        raise KomoError(f"solver {name} is not available in this Drake build")
    for key, value in {**defaults, **(extra or {})}.items():
        options.SetOption(solver.solver_id(), key, value)
    return _Backend(solver, options)
