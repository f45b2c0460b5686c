"""Positional noise on a Finish state B (paper, "Modeling physical risk").

Every block of B is moved in 3-D by i.i.d. Gaussian noise with standard deviation
sigma * d per axis, d being the block's size along that axis (axes of the block's
own frame, so a yawed or non-cubic block is perturbed along its edges). The noisy
positions generally interpenetrate; the paper only says it ensured "no overlap
between blocks". Our rule (docs/risk.md, "Noise rule") moves blocks as little as
possible, deterministically, so that the same standard normals scaled by another
sigma give a nearby scene (common random numbers) and sigma = 0 changes nothing:

1. Side pairs -- two solids whose vertical extents overlapped in B (neighbours in
   a line, a floor, a wall, a block and a bucket wall) -- are separated in the
   horizontal plane, each keeping the side it had in B: along the axis that
   separated the pair in B (its shallowest separating axis), an overlapping pair
   is pushed apart, half each, a fixed box not moving; sweeps repeat until no
   side pair overlaps (cyclic projections onto linear constraints, as in
   position-based dynamics; B satisfies them all, so this converges). Blocks
   never swap places. No resampling: a "resample until free" rule ratchets in a
   touching line and breaks common random numbers.
2. Stacked pairs -- one solid above the other in B -- are separated vertically,
   bottom-up in B's height order: a block's centre height is the larger of its
   noisy height and the height at which it rests on the (already placed) solids
   and table beneath its new outline. So a block lifted by its own noise or by a
   lifted support starts above its support and drops when simulated; lifts do
   not add up along a tower (a block's lift is the largest of its own and its
   supports'), but the top of a 10-tower can start a few mm up.

   That is the default noise rule, ``noise_rule="lift"``. The other,
   ``noise_rule="settle"`` (beyond the paper), keeps step 1 and the
   horizontal noise but sets every block's height to the rest height on what lies
   beneath its new outline (or the table), dropping its own vertical noise: no
   block starts in the air and nothing drops when simulated, so what falls is
   what topples.

Overlap already present in B (trial files are rounded to 0.1 mm) is tolerated:
no pair ever overlaps more than it did in B, and no block sits deeper in the
table than in B.
"""
from __future__ import annotations

import numpy as np

from lgp.errors import InputError
from lgp.geometry import rectangle_overlap
from lgp.scene import CONTACT_TOLERANCE, Scene
from models.risk.model import NOISE_RULES, Noise, check_sigma

#: Numerical slack (m) below which an overlap counts as none.
_EPS = 1e-12
#: Projected Gauss-Seidel sweeps allowed for the side pairs (a compressed line of
#: 10 needs ~10; a closed box of blocks a few more).
_MAX_SWEEPS = 500


def check_noise_rule(noise_rule: str) -> Noise:
    """The noise rule checked: ValueError naming the known ones."""
    if noise_rule not in NOISE_RULES:
        raise InputError(f"unknown noise rule {noise_rule!r}; known rules: {', '.join(NOISE_RULES)}")
    return Noise(noise_rule)


def draw_normals(n_runs: int, n_blocks: int, seed=0) -> np.ndarray:
    """Standard normals (n_runs, n_blocks, 3) for `n_runs` perturbations of a scene.

    `seed` is an int or a numpy Generator. Run r of any sigma uses z[r], so risks at
    different sigma values share their random numbers (common random numbers).
    """
    rng = seed if isinstance(seed, np.random.Generator) else np.random.default_rng(seed)
    return rng.standard_normal((n_runs, n_blocks, 3))


def perturb(scene: Scene, sigma: float, rng: np.random.Generator, noise_rule: str = Noise.LIFT) -> Scene:
    """A noisy copy of `scene`: see the module docstring for the rule.

    `sigma` is the noise SD as a fraction of the block size d; `rng` a numpy
    Generator (one (n_blocks, 3) draw of standard normals is taken from it);
    `noise_rule` "lift" (default) or "settle".
    """
    return perturb_from_normals(scene, sigma, rng.standard_normal((len(scene), 3)), noise_rule)


def perturb_from_normals(scene: Scene, sigma: float, z: np.ndarray, noise_rule: str = Noise.LIFT) -> Scene:
    """`perturb` with the standard normals `z` (n_blocks, 3) given explicitly."""
    p_WB = perturbed_positions(scene, sigma, z, noise_rule)
    return scene.with_blocks(b.moved_to(p) for b, p in zip(scene.blocks, p_WB))


def perturbed_positions(scene: Scene, sigma: float, z: np.ndarray, noise_rule: str = Noise.LIFT) -> np.ndarray:
    """Block centres p_WB (n, 3) of the noisy scene (the work of `perturb`); with
    normals z of shape (R, n, 3), the centres (R, n, 3) of R noisy scenes."""
    return NoiseRule(scene, noise_rule).positions(sigma, z)


class NoiseRule:
    """The noise rule on one Finish state B, with every part that depends only on
    B (outlines, side pairs with their separating axes, the stacked pairs of the
    lift) computed once, and `positions` vectorised over runs: what a chunk of
    noisy runs of one scene calls instead of `perturbed_positions` per run. Same
    numbers to the bit as one `perturbed_positions` call per run
    (tests/test_risk_noise_reference.py keeps the per-run rule as the reference)."""

    def __init__(self, scene: Scene, noise_rule: str = Noise.LIFT, movable=None):
        """`movable` (n,) bools, default all: blocks marked False get no noise and
        keep their height (a sequential build's settled blocks,
        models/risk/build.py); side pairs still push them apart half each, as a
        hand placing a block nudges its neighbour (pushing the new block alone
        cannot always work: settled neighbours may leave less than a block's
        width between them)."""
        self.scene = scene
        self.noise_rule = check_noise_rule(noise_rule)
        blocks = scene.blocks
        n = self.n = len(scene)
        self.movable = np.ones(n, bool) if movable is None else np.asarray(movable, bool).reshape(n)
        self.p0 = scene.positions
        self.size = np.array([b.size for b in blocks], dtype=float).reshape(n, 3)
        self.cos = np.cos([b.yaw for b in blocks])
        self.sin = np.sin([b.yaw for b in blocks])
        solids = list(blocks) + list(scene.fixed)
        bottom0 = np.array([o.bottom for o in solids])
        top0 = self.top0 = np.array([o.top for o in solids])
        # outlines seen from above: half extents, unit edge directions; fixed boxes' centres
        self.half = np.array([o.size[:2] / 2 for o in solids]).reshape(-1, 2)
        yaw = np.array([b.yaw for b in blocks] + [0.0] * len(scene.fixed))
        self.u = np.stack([np.cos(yaw), np.sin(yaw)], axis=1)
        v = np.stack([-self.u[:, 1], self.u[:, 0]], axis=1)
        self.fixed_xy = np.array([f.p_WO[:2] for f in scene.fixed], dtype=float).reshape(-1, 2)
        m = len(solids)
        c0_xy = np.vstack([self.p0[:, :2], self.fixed_xy])
        outlines = (self.half, self.u, v)

        # 1. side pairs: each keeps the side it had in B, along the axis that separated
        # them in B (orientations are not perturbed, so the axis is fixed)
        ii, jj = np.triu_indices(m, 1)
        keep = ii < n
        ii, jj = ii[keep], jj[keep]
        is_side = np.minimum(top0[ii], top0[jj]) - np.maximum(bottom0[ii], bottom0[jj]) > CONTACT_TOLERANCE
        si, sj = ii[is_side], jj[is_side]
        self.side = None
        if len(si):
            depth0, normal = _depth(c0_xy, outlines, si, sj)
            allowed = np.maximum(0.0, depth0)  # overlap already in B
            reach = _reach(outlines, si, sj, normal) - allowed  # least (c_j - c_i) . normal
            # who moves: 0 half each, 1 i only (j fixed), 2 j only (i fixed); neither: no pair
            mov = np.concatenate([np.ones(n, bool), np.zeros(m - n, bool)])  # blocks are pushed, fixed boxes not
            mode = np.where(mov[si] & mov[sj], 0, np.where(mov[si], 1, 2))
            both = mov[si] | mov[sj]
            side = [(i, j, n0, n1, rk, md) for i, j, n0, n1, rk, md, b in
                    zip(si.tolist(), sj.tolist(), normal[:, 0].tolist(), normal[:, 1].tolist(), reach.tolist(),
                        mode.tolist(), both.tolist()) if b]
            self.side = side or None

        # 2. stacked pairs: the solids beneath each block in B, bottom-up in B's height order
        self.order = sorted(range(n), key=lambda k: (bottom0[k], k))
        self.h = self.size[:, 2] / 2
        self.z_table = np.minimum(0.0, bottom0[:n]) + self.h  # rest on the table
        below_i, below_j, self.beneath = [], [], []
        for i in self.order:
            beneath = np.flatnonzero(top0 <= bottom0[i] + CONTACT_TOLERANCE)  # beneath i in B
            allowed = np.maximum(0.0, top0[beneath] - bottom0[i])  # overlap already in B
            self.beneath.append((i, slice(len(below_i), len(below_i) + len(beneath)), beneath, allowed))
            below_i += [i] * len(beneath)
            below_j += beneath.tolist()
        self.below_i, self.below_j = np.array(below_i, dtype=int), np.array(below_j, dtype=int)

    def positions(self, sigma: float, z: np.ndarray, start: np.ndarray | None = None) -> np.ndarray:
        """Block centres p_WB of the noisy scenes: (n, 3) for normals z (n, 3), or
        (R, n, 3) for z (R, n, 3). `start` (same shape): centres to perturb instead
        of B's (a sequential build's settled state; the pairs, their sides and the
        solids beneath each block are still B's)."""
        scene, n = self.scene, self.n
        z = np.asarray(z, float)
        if z.shape[-2:] != (n, 3) or z.ndim not in (2, 3):
            raise InputError(f"{scene.label}: need standard normals of shape ({n}, 3), got {z.shape}")
        try:
            sigma = check_sigma(sigma)
        except InputError as e:
            raise InputError(f"{scene.label}: {e}") from None
        one = z.ndim == 2
        z = z[None] if one else z
        runs = len(z)
        p = np.broadcast_to(self.p0 if start is None else np.asarray(start, float).reshape(z.shape), z.shape).copy()
        if n == 0 or sigma == 0 or runs == 0:
            return p[0] if one else p
        # noise along each block's own axes, scaled by its size along that axis
        delta_B = sigma * z * self.size
        if not self.movable.all():
            delta_B = delta_B * self.movable[:, None]
        c, s = self.cos, self.sin
        p[:, :, 0] += c * delta_B[:, :, 0] - s * delta_B[:, :, 1]
        p[:, :, 1] += s * delta_B[:, :, 0] + c * delta_B[:, :, 1]
        p[:, :, 2] += delta_B[:, :, 2]

        # -- 1. side pairs: horizontal separation, run by run ------------------------------
        if self.side is not None:
            fixed = self.fixed_xy.tolist()
            for r in range(runs):
                c_xy = p[r, :, :2].tolist() + fixed
                _separate_side_pairs(scene.label, c_xy, self.side, n)
                p[r, :, :2] = c_xy[:n]

        # -- 2. stacked pairs: vertical separation, bottom-up, all runs at once -----------
        L = len(self.below_i)
        if L:
            c_xy = np.concatenate([p[:, :, :2], np.broadcast_to(self.fixed_xy, (runs, *self.fixed_xy.shape))], axis=1)
            a, b = self.below_i, self.below_j
            depth = rectangle_overlap(
                c_xy[:, a].reshape(-1, 2), np.tile(self.half[a], (runs, 1)), np.tile(self.u[a], (runs, 1)),
                c_xy[:, b].reshape(-1, 2), np.tile(self.half[b], (runs, 1)), np.tile(self.u[b], (runs, 1)),
            )[0].reshape(runs, L)
            on = depth > _EPS  # the outlines of i and the solid beneath it overlap
        top = np.broadcast_to(self.top0, (runs, len(self.top0))).copy()
        for i, pairs, beneath, allowed in self.beneath:
            z_rest = np.full(runs, self.z_table[i])
            if len(beneath):
                rests = np.where(on[:, pairs], top[:, beneath] - allowed, -np.inf)
                z_rest = np.maximum(z_rest, rests.max(axis=1) + self.h[i])
            if not self.movable[i]:
                pass  # a settled block keeps its height
            elif self.noise_rule is Noise.SETTLE:
                p[:, i, 2] = z_rest  # rests on what lies beneath its new outline
            else:
                p[:, i, 2] = np.maximum(p[:, i, 2], z_rest)  # lift: never into its support
            top[:, i] = p[:, i, 2] + self.h[i]
        return p[0] if one else p


def _depth(c_xy, outlines, i, j):
    """Overlap depth of the outlines of solids i and j (arrays of indices) along their
    shallowest separating axis, and that axis (pointing from i to j); depth <= 0
    means the outlines are apart (lgp.geometry.rectangle_overlap)."""
    half, u, _ = outlines
    return rectangle_overlap(c_xy[i], half[i], u[i], c_xy[j], half[j], u[j])


def _reach(outlines, i, j, normal):
    """Half-widths of outlines i plus j projected on `normal` (P, 2)."""
    half, u, v = outlines
    r = lambda k: half[k, 0] * np.abs(np.einsum("pk,pk->p", u[k], normal)) + half[k, 1] * np.abs(  # noqa: E731
        np.einsum("pk,pk->p", v[k], normal)
    )
    return r(i) + r(j)


def _separate_side_pairs(label, c_xy, pairs, n) -> None:
    """Cyclic projections (Gauss-Seidel, as in position-based dynamics) onto the
    half-planes (c_j - c_i) . normal >= reach: an offending pair is pushed apart
    along its normal, half each, a fixed box not moving. The constraints are linear
    and B satisfies all of them, so the sweeps converge.

    c_xy: outline centres as a list of [x, y] lists, moved in place; pairs:
    (i, j, normal x, normal y, reach, mode) tuples, mode 0 (half each), 1 (only
    i moves: j is a fixed box or a settled block) or 2 (only j moves). Plain floats, not numpy: a scene
    has tens of pairs, and each push must see the previous ones (measured: numpy
    over all runs of a chunk in lockstep is no faster at 100 runs a chunk, and
    slower at 10 or 20, because a line of 10 takes ~400 sweeps)."""
    for _ in range(_MAX_SWEEPS):
        bad = []
        for pair in pairs:
            i, j, n0, n1, rk, _ = pair
            ci, cj = c_xy[i], c_xy[j]
            if ((cj[0] - ci[0]) * n0 + (cj[1] - ci[1]) * n1) - rk < -_EPS:
                bad.append(pair)
        if not bad:
            return
        for i, j, n0, n1, rk, mode in bad:  # sequential, so each push sees the previous ones
            ci, cj = c_xy[i], c_xy[j]
            excess = rk - ((cj[0] - ci[0]) * n0 + (cj[1] - ci[1]) * n1)
            if excess <= _EPS:
                continue
            step = excess + _EPS
            px, py = n0 * step, n1 * step
            if mode == 0:
                ci[0] -= px / 2
                ci[1] -= py / 2
                cj[0] += px / 2
                cj[1] += py / 2
            elif mode == 1:  # a fixed box (or settled block) does not move
                ci[0] -= px
                ci[1] -= py
            else:
                cj[0] += px
                cj[1] += py
    raise RuntimeError(f"{label}: could not separate overlapping neighbours after {_MAX_SWEEPS} sweeps")
