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

Overlap already present in B (trial files are rounded to 0.1 mm) is tolerated:
no pair ever overlaps more than it did in B, and no block sits deeper in the
table than in B.
"""
from __future__ import annotations

import numpy as np

from lgp.geometry import rectangle_overlap
from lgp.scene import CONTACT_TOLERANCE, Scene

#: Numerical slack (m) below which an overlap counts as none.
_EPS = 1e-12
#: Projected Gauss-Seidel sweeps allowed for the side pairs (a compressed line of
#: 10 needs ~10; a closed box of blocks a few more).
_MAX_SWEEPS = 500


def draw_normals(n_runs: int, n_blocks: int, seed=0) -> np.ndarray:
    """Standard normals (n_runs, n_blocks, 3) for `n_runs` perturbations of a scene.

    `seed` is an int or a numpy Generator. Run r of any sigma uses z[r], so risks at
    different sigma values share their random numbers (common random numbers).
    """
    rng = seed if isinstance(seed, np.random.Generator) else np.random.default_rng(seed)
    return rng.standard_normal((n_runs, n_blocks, 3))


def perturb(scene: Scene, sigma: float, rng: np.random.Generator) -> Scene:
    """A noisy copy of `scene`: see the module docstring for the rule.

    `sigma` is the noise SD as a fraction of the block size d; `rng` a numpy
    Generator (one (n_blocks, 3) draw of standard normals is taken from it).
    """
    return perturb_from_normals(scene, sigma, rng.standard_normal((len(scene), 3)))


def perturb_from_normals(scene: Scene, sigma: float, z: np.ndarray) -> Scene:
    """`perturb` with the standard normals `z` (n_blocks, 3) given explicitly."""
    p_WB = perturbed_positions(scene, sigma, z)
    return scene.with_blocks(b.moved_to(p) for b, p in zip(scene.blocks, p_WB))


def perturbed_positions(scene: Scene, sigma: float, z: np.ndarray) -> np.ndarray:
    """Block centres p_WB (n, 3) of the noisy scene (the work of `perturb`)."""
    z = np.asarray(z, float)
    n = len(scene)
    if z.shape != (n, 3):
        raise ValueError(f"{scene.label}: need standard normals of shape ({n}, 3), got {z.shape}")
    if not sigma >= 0:
        raise ValueError(f"{scene.label}: sigma must be >= 0 (a fraction of the block size), got {sigma}")
    blocks = scene.blocks
    p0 = scene.positions
    if n == 0 or sigma == 0:
        return p0.copy()
    # noise along each block's own axes, scaled by its size along that axis
    delta_B = sigma * z * np.array([b.size for b in blocks])
    c, s = np.cos([b.yaw for b in blocks]), np.sin([b.yaw for b in blocks])
    p = p0.copy()
    p[:, 0] += c * delta_B[:, 0] - s * delta_B[:, 1]
    p[:, 1] += s * delta_B[:, 0] + c * delta_B[:, 1]
    p[:, 2] += delta_B[:, 2]

    solids = list(blocks) + list(scene.fixed)
    m = len(solids)
    bottom0 = np.array([o.bottom for o in solids])
    top0 = np.array([o.top for o in solids])
    # outlines seen from above: centre, half extents, unit edge directions
    c_xy = np.vstack([p[:, :2], [f.p_WO[:2] for f in scene.fixed]]) if scene.fixed else p[:, :2].copy()
    half = np.array([o.size[:2] / 2 for o in solids])
    yaw = np.array([b.yaw for b in blocks] + [0.0] * len(scene.fixed))
    u = np.stack([np.cos(yaw), np.sin(yaw)], axis=1)
    v = np.stack([-u[:, 1], u[:, 0]], axis=1)
    outlines = (half, u, v)
    c0_xy = np.vstack([p0[:, :2], c_xy[n:]])

    # -- 1. side pairs: horizontal separation ------------------------------------------
    ii, jj = np.triu_indices(m, 1)
    keep = ii < n
    ii, jj = ii[keep], jj[keep]
    is_side = np.minimum(top0[ii], top0[jj]) - np.maximum(bottom0[ii], bottom0[jj]) > CONTACT_TOLERANCE
    si, sj = ii[is_side], jj[is_side]
    if len(si):
        # each pair keeps the side it had in B: j stays beyond i along the axis that
        # separated them in B (orientations are not perturbed, so the axis is fixed)
        depth0, normal = _depth(c0_xy, outlines, si, sj)
        allowed = np.maximum(0.0, depth0)  # overlap already in B
        reach = _reach(outlines, si, sj, normal) - allowed  # least (c_j - c_i) . normal
        _separate_side_pairs(scene.label, c_xy, si, sj, normal, reach, n)
        p[:, :2] = c_xy[:n]

    # -- 2. stacked pairs: vertical separation, bottom-up ------------------------------
    top = top0.copy()
    for i in sorted(range(n), key=lambda k: (bottom0[k], k)):
        h = blocks[i].size[2] / 2
        z_rest = min(0.0, bottom0[i]) + h  # the table
        beneath = np.flatnonzero(top0 <= bottom0[i] + CONTACT_TOLERANCE)  # beneath i in B
        if len(beneath):
            depth = _depth(c_xy, outlines, np.full(len(beneath), i), beneath)[0]
            under = beneath[depth > _EPS]
            if len(under):
                allowed = np.maximum(0.0, top0[under] - bottom0[i])  # overlap already in B
                z_rest = max(z_rest, float(np.max(top[under] - allowed)) + h)
        p[i, 2] = max(p[i, 2], z_rest)
        top[i] = p[i, 2] + h
    return p


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


def _separate_side_pairs(label, c_xy, si, sj, normal, reach, n) -> None:
    """Cyclic projections (Gauss-Seidel, as in position-based dynamics) onto the
    half-planes (c_j - c_i) . normal >= reach: an offending pair is pushed apart
    along its normal, half each, a fixed box not moving. The constraints are linear
    and B satisfies all of them, so the sweeps converge."""
    for _ in range(_MAX_SWEEPS):
        slack = np.einsum("pk,pk->p", c_xy[sj] - c_xy[si], normal) - reach
        bad = np.flatnonzero(slack < -_EPS)
        if not len(bad):
            return
        for k in bad:  # sequential, so each push sees the previous ones
            i, j, nk = si[k], sj[k], normal[k]
            excess = reach[k] - float(np.dot(c_xy[j] - c_xy[i], nk))
            if excess <= _EPS:
                continue
            push = nk * (excess + _EPS)
            if j < n:
                c_xy[i] -= push / 2
                c_xy[j] += push / 2
            else:  # a fixed box does not move
                c_xy[i] -= push
    raise RuntimeError(f"{label}: could not separate overlapping neighbours after {_MAX_SWEEPS} sweeps")
