"""The cheap screen: risk over a sigma prior by a static centre-of-mass Monte
Carlo, and effort by a distance-based proxy. Both are checked against the
project's faithful values (the MuJoCo risk grid, the planner's efforts) on the
paper's 24 trials and on each designed set's finalists (docs/design.md).

Risk. A run perturbs every block of B horizontally by sigma * d * N(0, 1) per
axis and keeps it resting on what it rested on in B: the analogue of the risk
model's ``noise_rule="settle"`` (models/risk/noise.py), without the side pairs'
separation and without any dynamics. The run falls when some block tips
statically: blocks are visited top-down; each carries its own weight (at its
centre) and the loads handed down by the blocks resting on it; the resultant of
those must lie strictly inside the block's support polygon, the convex hull of
its contact patches (the overlap of its outline with each supporter's, or its
own outline on the table); its total load is then handed to its supporters in
proportion to the patch areas, acting at the point of each patch nearest the
resultant. For a column (every block on one block) this is exactly the static
criterion of models.risk.static (the centre of mass of a block and everything
above it inside its contact with the block beneath); for loads shared between
supports (bridges, walls) it is a heuristic, as there.

Effort. ``effort_proxy``: the total distance (m) the paper's assignment carries
the blocks (lgp.assignment), on one layout of A. Chosen on the paper's 24 against
their efforts (M = 30 layouts, the planner): Spearman 0.986 (Pearson 0.957), better
than the sum of squared path lengths with the approach legs (0.937) or the number of
blocks moved (0.718) (docs/design.md; bench/design.py).
"""
from __future__ import annotations

import numpy as np

from lgp.paper import BLOCK_SIZE as d
from lgp.scene import TABLE, Scene, support_graph

#: The sigma prior of the design (units of d): uniform over this grid.
PRIOR_LO, PRIOR_HI = 0.05, 0.25
#: The sigmas at which the design measures risk (screen and faithful check alike): the
#: paper's 0.065 d, the analysis's 0.10 and 0.15 d, and the ends of the prior; every
#: one a point of the wide grid (lgp.paper.WIDE_SIGMA_GRID), so the faithful check
#: runs through the project's risk stage unchanged.
PRIOR_GRID: tuple[float, ...] = (0.05, 0.065, 0.08, 0.10, 0.12, 0.15, 0.18, 0.20, 0.25)
#: Runs per sigma of the screen (common random numbers across sigma).
SCREEN_RUNS = 100
#: A risk curve "rises within the prior" when risk(0.25 d) - risk(0.05 d) is at least this.
RISE = 0.10
#: The planner's vertical approach leg at every grasp and place (lgp.planner.APPROACH), m.
APPROACH = 0.05


class StackModel:
    """B's blocks with their supporters (B's support graph), ready to be perturbed
    many times at once. Blocks are treated as axis-aligned boxes (every designed
    B has yaw 0; a yawed block of a paper trial is boxed by its own size)."""

    def __init__(self, scene: Scene):
        self.scene = scene
        blocks = list(scene.blocks)
        names = [b.name for b in blocks]
        index = {n: i for i, n in enumerate(names)}
        graph = support_graph(scene)
        self.p = np.array([b.p_WB for b in blocks], float).reshape(-1, 3)
        self.half = np.array([b.size[:2] / 2 for b in blocks], float).reshape(-1, 2)
        self.mass = np.array([float(np.prod(b.size)) for b in blocks]) / d ** 3
        fixed = {}
        for f in scene.fixed:
            fixed.setdefault(f.name, []).append((np.asarray(f.p_WO[:2], float), np.asarray(f.size[:2], float) / 2))
        # supporters per block: ("table",), ("block", j), ("fixed", centre, half)
        self.supports: list[list[tuple]] = []
        for b in blocks:
            sup = []
            for s in graph[b.name]:
                if s == TABLE:
                    sup.append(("table",))
                elif s in index:
                    sup.append(("block", index[s]))
                else:
                    sup += [("fixed", c, h) for c, h in fixed.get(s, [])]
            self.supports.append(sup)
        self.order = sorted(range(len(blocks)), key=lambda i: (-self.p[i, 2], i))  # top-down

    def __len__(self) -> int:
        return len(self.p)

    def falls(self, xy: np.ndarray) -> np.ndarray:
        """(M,) bools: does the scene with block centres `xy` (M, n, 2) tip statically?"""
        M, n = xy.shape[0], len(self)
        W = np.broadcast_to(self.mass, (M, n)).copy()  # load carried by each block
        Q = xy * self.mass[None, :, None]  # moment of that load (weight x point)
        fell = np.zeros(M, bool)
        for i in self.order:
            r = Q[:, i] / W[:, i, None]  # resultant point of block i's load
            lo_i, hi_i = xy[:, i] - self.half[i], xy[:, i] + self.half[i]
            patches = []
            for s in self.supports[i]:
                if s[0] == "table":
                    lo, hi = lo_i, hi_i
                elif s[0] == "block":
                    j = s[1]
                    lo, hi = np.maximum(lo_i, xy[:, j] - self.half[j]), np.minimum(hi_i, xy[:, j] + self.half[j])
                else:
                    lo, hi = np.maximum(lo_i, s[1] - s[2]), np.minimum(hi_i, s[1] + s[2])
                patches.append((s, lo, hi, np.prod(np.clip(hi - lo, 0.0, None), axis=1)))
            if not patches:
                fell[:] = True
                continue
            fell |= ~_inside_hull(r, [(lo, hi, a) for _, lo, hi, a in patches])
            total = sum(a for *_, a in patches)
            safe = np.where(total > 0, total, 1.0)
            for s, lo, hi, a in patches:
                if s[0] != "block":
                    continue
                j, f = s[1], W[:, i] * a / safe
                W[:, j] += f
                Q[:, j] += f[:, None] * np.clip(r, lo, hi)
        return fell

    def stands(self) -> bool:
        """Static verdict without noise (sigma = 0)."""
        return not bool(self.falls(self.p[None, :, :2])[0])

    def risk_curve(self, sigmas, z: np.ndarray) -> np.ndarray:
        """Fraction of runs that tip at each sigma (units of d); `z` (R, n, 2)
        standard normals shared by every sigma (common random numbers)."""
        sig = np.asarray(sigmas, float)
        R = z.shape[0]
        xy = self.p[None, None, :, :2] + sig[:, None, None, None] * d * z[None]
        return self.falls(xy.reshape(len(sig) * R, len(self), 2)).reshape(len(sig), R).mean(axis=1)


def _inside_hull(r: np.ndarray, patches) -> np.ndarray:
    """(M,) bools: is point r (M, 2) strictly inside the convex hull of the patches
    (axis-aligned rectangles lo, hi (M, 2) with areas a (M,); empty ones ignored)?

    One patch: the rectangle test. Several: r is outside (or on the boundary)
    exactly when some direction u has u . (q - r) <= 0 for every corner q; such a
    u can be taken perpendicular to some (q_k - r), so those 2K directions are
    tried against the K corners."""
    if len(patches) == 1:
        lo, hi, a = patches[0]
        return (a > 0) & np.all((r > lo) & (r < hi), axis=1)
    corners, valid = [], []
    for lo, hi, a in patches:
        for cx, cy in ((lo[:, 0], lo[:, 1]), (hi[:, 0], lo[:, 1]), (hi[:, 0], hi[:, 1]), (lo[:, 0], hi[:, 1])):
            corners.append(np.stack([cx, cy], axis=1))
            valid.append(a > 0)
    q = np.stack(corners, axis=1) - r[:, None, :]  # (M, K, 2)
    ok = np.stack(valid, axis=1)  # (M, K)
    perp = np.stack([-q[..., 1], q[..., 0]], axis=-1)  # (M, K, 2)
    u = np.concatenate([perp, -perp], axis=1)  # (M, 2K, 2)
    dots = u[:, :, None, 0] * q[:, None, :, 0] + u[:, :, None, 1] * q[:, None, :, 1]  # (M, 2K, K)
    dots = np.where(ok[:, None, :], dots, -np.inf)
    best = dots.max(axis=2)  # per direction: the corner furthest along it
    best = np.where(np.concatenate([ok, ok], axis=1), best, np.inf)  # directions from empty patches: not tried
    return ok.any(axis=1) & (best.min(axis=1) > 0)


def screen_normals(n_blocks: int, runs: int = SCREEN_RUNS, seed=0) -> np.ndarray:
    """Standard normals (runs, n_blocks, 2) of one scene's screen."""
    rng = seed if isinstance(seed, np.random.Generator) else np.random.default_rng(seed)
    return rng.standard_normal((runs, n_blocks, 2))


def screen_risk(scene: Scene, sigmas=PRIOR_GRID, runs: int = SCREEN_RUNS, seed=0) -> np.ndarray:
    """The screen's risk curve of B over `sigmas` (units of d), `runs` runs each."""
    model = StackModel(scene)
    return model.risk_curve(sigmas, screen_normals(len(model), runs, seed))


def effort_proxy(initial: Scene, target: Scene) -> tuple[float, float, int]:
    """(proxy, sum of squared paths, blocks moved) of one layout: the paper's
    assignment (lgp.assignment); the proxy is the total distance (m) of the
    moved blocks' centres; the second number sums, per moved block,
    (horizontal distance + 2 x APPROACH + |height change|)^2 (the rejected
    alternative, kept for the check)."""
    from lgp.assignment import assign_blocks

    pairs = assign_blocks(initial, target)
    A = {b.name: b.p_WB for b in initial.blocks}
    B = {b.name: b.p_WB for b in target.blocks}
    proxy = dist = 0.0
    moved = 0
    for a, b in pairs.items():
        delta = np.asarray(B[b]) - np.asarray(A[a])
        h = float(np.hypot(delta[0], delta[1]))
        if h < 1e-4 and abs(delta[2]) < 1e-4:
            continue  # already in place
        moved += 1
        dist += float(np.linalg.norm(delta))
        proxy += (h + 2 * APPROACH + abs(float(delta[2]))) ** 2
    return dist, proxy, moved
