"""The linear part of a KOMO problem and the elimination of free slices.

Cost. The control cost of order k: sum_s |q^(k)_s|^2 tau with q^(k) the k-th
backward finite difference divided by tau^k -- for k = 2 the integral of the squared
joint acceleration (the paper: "minimizes squared acceleration of the joints").
With `qItself` sos terms it is |W X + w0|^2; `qItself` eq objectives and rests are
the equalities C X = E (X the (N, nq) joint values, one column per joint; W and C
act on slices and are the same for every joint).

Elimination. For fixed keyframes K the other ("free") slices F minimise the
quadratic cost under the linear equalities, so they are an affine function
X_F = M X_K + m of the keyframes, found by one KKT solve; substituting gives the
reduced residual G X_K + g.
"""
from __future__ import annotations

from dataclasses import dataclass
from functools import cached_property
from math import comb

import numpy as np
from scipy import sparse
from scipy.sparse import linalg as splinalg

from lgp.komo.declaration import Declaration, KomoError


def _read_only(*arrays):
    """Mark arrays (dense, or the buffers of a scipy sparse matrix) read-only: the
    structures and eliminations are shared by every Komo of a skeleton in a process."""
    for a in arrays:
        for buffer in (a.data, a.indices, a.indptr) if sparse.issparse(a) else (a,):
            buffer.setflags(write=False)


@dataclass(frozen=True)
class LinearStructure:
    """Cost residual W X + w0 and equalities C X = E over the decision slices.

    W (R, N) and C (n_eq, N) are sparse (a few nonzeros per row); w0 (R, nq) and
    E (n_eq, nq) carry the targets and the fixed prefix at q_home.
    """

    W: sparse.csr_matrix
    w0: np.ndarray
    C: sparse.csr_matrix
    E: np.ndarray

    def __post_init__(self):
        _read_only(self.W, self.w0, self.C, self.E)

    @property
    def N(self) -> int:
        return self.W.shape[1]

    @property
    def nq(self) -> int:
        return self.w0.shape[1]

    def cost(self, X: np.ndarray) -> float:
        """|W X + w0|^2: control cost plus sos terms of the trajectory X (N, nq)."""
        return float(np.sum((self.W @ X + self.w0) ** 2))


@dataclass(frozen=True)
class Elimination:
    """Free slices F as X_F = M X_K + m of the keyframes K, and what remains.

    G X_K + g is the reduced cost residual (G = W_F M + W_K, g = W_F m + w0);
    C_KK X_K = E_KK the equalities that involve keyframes only.
    """

    K: tuple[int, ...]
    F: np.ndarray
    M: np.ndarray
    m: np.ndarray
    G: np.ndarray
    g: np.ndarray
    C_KK: np.ndarray
    E_KK: np.ndarray

    def __post_init__(self):
        _read_only(self.F, self.M, self.m, self.G, self.g, self.C_KK, self.E_KK)

    def trajectory(self, X_K: np.ndarray) -> np.ndarray:
        """The whole (N, nq) trajectory with keyframes X_K and the free slices eliminated."""
        X = np.zeros((len(self.K) + len(self.F), X_K.shape[1]))
        X[list(self.K)], X[self.F] = X_K, self.M @ X_K + self.m
        return X

    @cached_property
    def GtG(self) -> np.ndarray:
        """G'G (|K|, |K|): half the Hessian of the reduced cost, the same for every joint."""
        GtG = self.G.T @ self.G
        _read_only(GtG)
        return GtG

    @cached_property
    def cost_factor(self) -> tuple[np.ndarray, np.ndarray, float]:
        """(L, l, const) with |G X_K + g|^2 = |L X_K + l|^2 + const per joint column,
        L upper triangular (the Cholesky factor of G'G = L'L)."""
        L = np.linalg.cholesky(self.GtG).T
        l = np.linalg.solve(L.T, self.G.T @ self.g)
        _read_only(L, l)
        return L, l, float(np.sum(self.g * self.g) - np.sum(l * l))


def difference_row(komo: Declaration, s: int, order: int) -> np.ndarray:
    """Coefficients over [prefix slices, decision slices] of the order-th difference at s, / tau^order."""
    k = komo.k_order
    row = np.zeros(k + komo.N)
    for i in range(order + 1):
        row[k + s - i] += (-1) ** i * comb(order, i)
    if order > 0 and s - order < -k:
        raise KomoError(f"order-{order} term at slice {s} reaches before the prefix")
    return row / komo.tau**order


def linear_structure(komo: Declaration) -> LinearStructure:
    """The cost residual and linear equalities of a declaration (see LinearStructure)."""
    k, N, nq = komo.k_order, komo.N, komo.nq
    prefix = np.tile(komo.q_home, (k, 1))
    cost, eq = [], []
    weight = np.sqrt(komo.tau)  # sum |q^(k)|^2 tau approximates the time integral
    for s in range(N):
        cost.append((weight * difference_row(komo, s, k), np.zeros(nq)))
    for o in komo.objectives:
        if o.feature != "qItself":
            continue
        target = np.zeros(nq) if o.target is None else o.target
        for s in o.slices:
            row = difference_row(komo, s, o.order)
            if o.type == "sos":
                cost.append((o.scale * row, -o.scale * target))
            elif o.type == "eq":
                eq.append((row, target))
            else:
                raise KomoError("ineq objectives on qItself are not supported (use joint limits)")
    for s, after in komo.rests:
        sides = (-1, 1) if after else (-1,)
        for side in sides:
            row = np.zeros(k + N)
            row[k + s], row[k + s + side], row[k + s + 2 * side] = 1.5, -2.0, 0.5
            eq.append((row / komo.tau, np.zeros(nq)))
    W = np.array([r for r, _ in cost])
    w0 = np.array([c for _, c in cost]) + W[:, :k] @ prefix
    if eq:
        C = np.array([r for r, _ in eq])
        E = np.array([c for _, c in eq]) - C[:, :k] @ prefix
    else:
        C, E = np.zeros((0, k + N)), np.zeros((0, nq))
    return LinearStructure(sparse.csr_matrix(W[:, k:]), w0, sparse.csr_matrix(C[:, k:]), E)


def eliminate(linear: LinearStructure, K) -> Elimination:
    """Free slices as X_F = M X_K + m minimising |W X + w0|^2 s.t. C X = E (exact).

    Sparse LU (single-threaded) on the KKT system: it is banded and small.
    """
    K = list(K)
    nq = linear.nq
    F = np.setdiff1d(np.arange(linear.N), K)
    W = sparse.csc_matrix(linear.W)
    C = sparse.csc_matrix(linear.C)
    w0, E = linear.w0, linear.E
    W_F, W_K, C_F, C_K = W[:, F], W[:, K], C[:, F], C[:, K]
    only_K = np.asarray(abs(C_F).sum(axis=1)).ravel() == 0
    Cf, Ck, Ef = C_F[~only_K], C_K[~only_K], E[~only_K]
    nF, nK = len(F), len(K)
    KKT = sparse.bmat([[2 * (W_F.T @ W_F), Cf.T], [Cf, None]], format="csc")
    rhs = np.vstack([np.hstack([-2 * (W_F.T @ W_K).toarray(), -2 * (W_F.T @ w0)]), np.hstack([-Ck.toarray(), Ef])])
    try:
        sol = splinalg.splu(KKT).solve(rhs) if nF + len(Ef) else np.zeros((0, nK + nq))
    except RuntimeError:
        raise KomoError("the linear (qItself) equalities over-determine or contradict each other on free slices") from None
    M, m = sol[:nF, :nK], sol[:nF, nK:]
    G = W_F @ M + W_K.toarray()
    g = W_F @ m + w0
    return Elimination(tuple(K), F, M, m, G, g, C[only_K][:, K].toarray(), E[only_K])


def interpolate(linear: LinearStructure, seeds: dict[int, np.ndarray], elimination=None) -> np.ndarray:
    """Minimum-control-cost trajectory (N, nq) through `seeds` {slice: q} under the linear equalities.

    `elimination(K)` gives the Elimination for keyframes K (default: eliminate afresh;
    lgp.komo.Komo passes its cached one)."""
    K = sorted(seeds)
    X_K = np.array([seeds[s] for s in K]).reshape(len(K), linear.nq)
    e = eliminate(linear, K) if elimination is None else elimination(K)
    return e.trajectory(X_K)
