"""The vectorised noise rule (models.risk.noise.NoiseRule, all runs of a chunk at
once) gives the same block centres, to the bit, as the per-run rule it replaced,
transcribed here (same arithmetic) as an independent reference."""
import numpy as np
import pytest

import stimuli
from conftest import trials_with_copies_slow
from lgp.geometry import rectangle_overlap
from lgp.paper import SIGMA_GRID
from lgp.scene import CONTACT_TOLERANCE
from models.risk.noise import NoiseRule, draw_normals, perturbed_positions
from tests.test_risk_noise import SCENES

_EPS = 1e-12
_MAX_SWEEPS = 500


def reference_positions(scene, sigma, z):
    """The per-run noise rule as it was (numpy per pair and per block)."""
    z = np.asarray(z, float)
    n = len(scene)
    blocks = scene.blocks
    p0 = scene.positions
    if n == 0 or sigma == 0:
        return p0.copy()
    p = perturbed_positions_raw(scene, sigma, z)
    solids = list(blocks) + list(scene.fixed)
    m = len(solids)
    bottom0 = np.array([o.bottom for o in solids])
    top0 = np.array([o.top for o in solids])
    c_xy = np.vstack([p[:, :2], [f.p_WO[:2] for f in scene.fixed]]) if scene.fixed else p[:, :2].copy()
    half = np.array([o.size[:2] / 2 for o in solids])
    yaw = np.array([b.yaw for b in blocks] + [0.0] * len(scene.fixed))
    u = np.stack([np.cos(yaw), np.sin(yaw)], axis=1)
    v = np.stack([-u[:, 1], u[:, 0]], axis=1)
    c0_xy = np.vstack([p0[:, :2], c_xy[n:]])

    def depth_of(cxy, i, j):
        return rectangle_overlap(cxy[i], half[i], u[i], cxy[j], half[j], u[j])

    def r(k, normal):
        return half[k, 0] * np.abs(np.einsum("pk,pk->p", u[k], normal)) + half[k, 1] * np.abs(
            np.einsum("pk,pk->p", v[k], normal))

    ii, jj = np.triu_indices(m, 1)
    keep = ii < n
    ii, jj = ii[keep], jj[keep]
    is_side = np.minimum(top0[ii], top0[jj]) - np.maximum(bottom0[ii], bottom0[jj]) > CONTACT_TOLERANCE
    si, sj = ii[is_side], jj[is_side]
    if len(si):
        depth0, normal = depth_of(c0_xy, si, sj)
        reach = r(si, normal) + r(sj, normal) - np.maximum(0.0, depth0)
        for _ in range(_MAX_SWEEPS):
            slack = np.einsum("pk,pk->p", c_xy[sj] - c_xy[si], normal) - reach
            bad = np.flatnonzero(slack < -_EPS)
            if not len(bad):
                break
            for k in bad:
                i, j, nk = si[k], sj[k], normal[k]
                excess = reach[k] - float(np.dot(c_xy[j] - c_xy[i], nk))
                if excess <= _EPS:
                    continue
                push = nk * (excess + _EPS)
                if j < n:
                    c_xy[i] -= push / 2
                    c_xy[j] += push / 2
                else:
                    c_xy[i] -= push
        else:
            raise RuntimeError("no convergence")
        p[:, :2] = c_xy[:n]
    top = top0.copy()
    for i in sorted(range(n), key=lambda k: (bottom0[k], k)):
        h = blocks[i].size[2] / 2
        z_rest = min(0.0, bottom0[i]) + h
        beneath = np.flatnonzero(top0 <= bottom0[i] + CONTACT_TOLERANCE)
        if len(beneath):
            depth = depth_of(c_xy, np.full(len(beneath), i), beneath)[0]
            under = beneath[depth > _EPS]
            if len(under):
                allowed = np.maximum(0.0, top0[under] - bottom0[i])
                z_rest = max(z_rest, float(np.max(top[under] - allowed)) + h)
        p[i, 2] = max(p[i, 2], z_rest)
        top[i] = p[i, 2] + h
    return p


TRIALS = {t.id: t.target for t in stimuli.load_paper()}


def perturbed_positions_raw(scene, sigma, z):
    """Block centres moved by the noise alone (sigma * size * z in each block's yawed
    frame), before any overlap is undone: (n, 3) for z (n, 3), (runs, n, 3) for z
    (runs, n, 3)."""
    d = sigma * np.asarray(z, float) * np.array([b.size for b in scene.blocks])
    c, s = np.cos([b.yaw for b in scene.blocks]), np.sin([b.yaw for b in scene.blocks])
    return scene.positions + np.stack([c * d[..., 0] - s * d[..., 1], s * d[..., 0] + c * d[..., 1], d[..., 2]], axis=-1)


def assert_same_as_reference(trial, seeds, runs, sigmas):
    scene = TRIALS[trial]
    rule = NoiseRule(scene)
    for seed in seeds:
        z = draw_normals(runs, len(scene), seed)
        for sigma in sigmas:
            batch = rule.positions(sigma, z)
            for r in range(len(z)):
                ref = reference_positions(scene, sigma, z[r])
                assert np.array_equal(batch[r], ref), f"{trial} sigma {sigma} seed {seed} run {r}"
            assert np.array_equal(perturbed_positions(scene, sigma, z[-1]), batch[-1])


@pytest.mark.parametrize("trial", trials_with_copies_slow(list(TRIALS)))
def test_vectorised_noise_rule_equals_the_per_run_rule_on_every_trial(trial):
    """All 24 trials, 8 runs at four noise levels: every block centre equal to the
    bit, in one batched call and run by run (a B that copies an earlier one's
    blocks: in the full suite only)."""
    assert_same_as_reference(trial, [3], 8, [0.05, 0.065, 0.1, 0.4])


def noise_inputs(scene) -> tuple:
    """All the noise rule reads of a scene (NoiseRule and reference_positions alike):
    block centres, sizes and yaws in block order, and the fixed boxes."""
    return (scene.positions.tobytes(), np.array([b.size for b in scene.blocks]).tobytes(),
            tuple(float(b.yaw) for b in scene.blocks), tuple((tuple(f.p_WO), tuple(f.size)) for f in scene.fixed))


#: Each trial -> the first trial whose B gives the noise rule the same inputs (the
#: same blocks at the same places in the same order: 2H copies 2E; 9E, 9H, 11E and
#: 11H copy 1H). Same inputs, same arithmetic: one check stands for the copies.
_first: dict = {}
FIRST_SAME_INPUTS = {tid: _first.setdefault(noise_inputs(scene), tid) for tid, scene in TRIALS.items()}


def test_a_copied_b_gives_the_noise_rule_the_numbers_of_the_b_it_copies():
    copies = {tid: first for tid, first in FIRST_SAME_INPUTS.items() if tid != first}
    assert copies == {"2H": "2E", "9E": "1H", "9H": "1H", "11E": "1H", "11H": "1H"}
    for tid, first in copies.items():
        z = draw_normals(40, len(TRIALS[tid]), 0)
        assert np.array_equal(NoiseRule(TRIALS[tid]).positions(0.4, z), NoiseRule(TRIALS[first]).positions(0.4, z)), tid


@pytest.mark.slow
@pytest.mark.parametrize("trial", [tid for tid, first in FIRST_SAME_INPUTS.items() if tid == first])
def test_vectorised_noise_rule_equals_the_per_run_rule_over_the_paper_grid(trial):
    """All 24 trials, the paper's sigma grid plus heavier noise, 40 runs (a trial
    whose B copies an earlier one's blocks in order, 2H, 9E, 9H, 11E, 11H, through
    that one: test_a_copied_b_gives_the_noise_rule_the_numbers_of_the_b_it_copies).
    One seed's 520 runs per structure exercise the rule as three seeds' 1,560 did
    (measured: side pushes in the same 10 of the 19 structures, 5H's fewest, 17
    runs of 520; lifts in all 19, in nearly every run), so two more seeds only
    repeated it (30 CPU-s). The check is not vacuous: the rule moves some block
    beyond its noise in most runs (asserted)."""
    assert_same_as_reference(trial, [0], 40, [*SIGMA_GRID, 0.2, 0.4])
    scene, z = TRIALS[trial], draw_normals(40, len(TRIALS[trial]), 0)
    moved = [not np.array_equal(NoiseRule(scene).positions(s, z), perturbed_positions_raw(scene, s, z)) for s in SIGMA_GRID]
    assert all(moved), f"{trial}: at some sigma the rule moved no block beyond the noise in 40 runs"


@pytest.mark.parametrize("scene", [pytest.param(s, marks=pytest.mark.slow) if s.label.startswith(("bucket", "line")) else s
                                   for s in SCENES], ids=lambda s: s.label)  # the two costliest in the full suite only
def test_vectorised_noise_rule_equals_the_per_run_rule_on_yawed_boxed_and_fixed_scenes(scene):
    """Textbook structures, a bucket of fixed boxes and yawed blocks, heavy-tailed
    normals (the pushes and lifts work hardest)."""
    rule = NoiseRule(scene)
    for seed in range(3):
        z = 2 * draw_normals(15, len(scene), seed)
        for sigma in (0.0, 0.05, 0.1, 0.3):
            batch = rule.positions(sigma, z)
            for r in range(len(z)):
                assert np.array_equal(batch[r], reference_positions(scene, sigma, z[r])), f"{scene.label} {sigma} {seed} {r}"
