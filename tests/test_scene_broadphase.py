"""The broad-phase scene checks give the verdicts of the pairwise checks they
replaced (kept here as the reference), and a 500-block trial's exact checks run on
neighbours only."""

import numpy as np
import pytest

from lgp.paper import BLOCK_SIZE as d
from lgp.scene import (CONTACT_TOLERANCE, OVERLAP_TOLERANCE, TABLE, Block, FixedBox, Scene, StimulusError,
                       penetration, rests_on, support_graph, validate_scene)


# ---------------------------------------------------------------- reference: the pairwise checker as it was

def reference_validate(scene):
    label = scene.label
    solids = list(scene.blocks)
    for i, a in enumerate(solids):
        for b in solids[i + 1:]:
            depth = penetration(a, b)
            if depth > OVERLAP_TOLERANCE:
                raise StimulusError(f"{label} block {a.name} overlaps {b.name} by {depth * 1000:.1f} mm")
        for f in scene.fixed:
            depth = penetration(a, f)
            if depth > OVERLAP_TOLERANCE:
                raise StimulusError(f"{label} block {a.name} overlaps fixed {f.name} by {depth * 1000:.1f} mm")
    for b in scene.blocks:
        on_table = abs(b.bottom) <= CONTACT_TOLERANCE
        if not on_table and not any(rests_on(b, o) for o in (*scene.blocks, *scene.fixed) if o is not b):
            raise StimulusError(
                f"{label} block {b.name}: floats (bottom at z = {b.bottom * 1000:.1f} mm rests on neither the table nor another solid)"
            )


def reference_support_graph(scene, tol=CONTACT_TOLERANCE):
    graph = {}
    for b in scene.blocks:
        under = [o.name for o in scene.blocks if o is not b and rests_on(b, o, tol)]
        under += sorted({f.name for f in scene.fixed if rests_on(b, f, tol)})
        if abs(b.bottom) <= tol:
            under.append(TABLE)
        graph[b.name] = under
    return graph


def verdict(check, scene):
    try:
        check(scene)
    except StimulusError as e:
        return str(e)
    return None


def random_scene(rng, n):
    """Blocks on a few levels of a small patch: overlaps, stacks, touching and floating blocks all occur."""
    span = d * np.sqrt(n) * rng.uniform(0.6, 1.6)
    xy = rng.uniform(0, span, size=(n, 2))
    level = rng.integers(0, 3, size=n)
    z = d / 2 + level * d + rng.choice([0.0, 0.0, 0.0, 5e-5, 3e-4], size=n)
    yaw = np.where(rng.random(n) < 0.5, 0.0, rng.uniform(0, np.pi / 2, size=n))
    snap = rng.random(n) < 0.4  # some blocks exactly on a grid: exact touching faces
    xy[snap] = np.round(xy[snap] / d) * d
    blocks = [Block(f"b{i}", [xy[i, 0], xy[i, 1], z[i]], yaw[i]) for i in range(n)]
    fixed = []
    if rng.random() < 0.5:
        fixed = [FixedBox("shelf", [span / 2, span / 2, d], [span / 3, d, 2 * d]),
                 FixedBox("bucket", [span / 4, span, d / 4], [d, d, d / 2])]
    return Scene(blocks, fixed, "random")


@pytest.mark.slow  # many random scenes, pair by pair
def test_broad_phase_gives_the_pairwise_verdicts_on_random_scenes():
    rng = np.random.default_rng(7)
    kinds = set()
    for _ in range(300):
        scene = random_scene(rng, int(rng.integers(1, 14)))
        ours, ref = verdict(validate_scene, scene), verdict(reference_validate, scene)
        assert ours == ref
        kinds.add("valid" if ref is None else ("overlap" if "overlaps" in ref else "floats"))
        assert support_graph(scene) == reference_support_graph(scene)
    assert kinds == {"valid", "overlap", "floats"}  # the random scenes exercised every verdict


@pytest.mark.slow  # every pair of many stacks and rows
def test_broad_phase_verdicts_on_valid_stacks_and_rows():
    rng = np.random.default_rng(3)
    for _ in range(50):
        n = int(rng.integers(2, 30))
        blocks = [Block(f"b{i}", [0.3 + (i % 5) * d, 0.1 * (i // 5 % 2), d / 2 + (i // 10) * d], 0.0) for i in range(n)]
        scene = Scene(blocks, (), "rows")
        assert verdict(validate_scene, scene) == verdict(reference_validate, scene)
        assert support_graph(scene) == reference_support_graph(scene)


def _big_trial_yaml(n_side=10, layers=5):
    lines = ["id: 1E", "pair: 1", "level: E", "target:", "  blocks:"]
    k = 0
    for z in range(layers):
        for i in range(n_side):
            for j in range(n_side):
                k += 1
                lines.append(f"  - {{name: b{k}, p_WB: [{0.25 + i * d:.4f}, {-0.12 + j * d:.4f}, {d / 2 + z * d:.4f}]}}")
    lines += ["initial:", "  scattered:", f"    count: {k}", "    region: {x: [-2.0, 2.0], y: [-2.0, 2.0]}"]
    return "\n".join(lines) + "\n", k


def test_a_500_block_trial_loads_and_its_exact_checks_run_on_neighbours_only(tmp_path):
    """What keeps a 500-block trial's validation fast (its time is not asserted:
    the machines are shared): the broad phase hands the exact checks only the
    pairs of touching neighbours, at most 13 per block in a packed grid of cubes
    (26 neighbours each, every pair counted once), not all n(n - 1)/2 pairs."""
    import stimuli
    from lgp.scene import near_pairs

    text, n = _big_trial_yaml()
    assert n == 500
    path = tmp_path / "1E.yaml"
    path.write_text(text)
    trial = stimuli.load_file(path)
    assert len(trial.target) == 500 and len(trial.initial.scattered) == 500
    blocks = list(trial.target.blocks)
    pairs = near_pairs(blocks)
    assert len(pairs) <= 13 * n < n * (n - 1) // 2
    # and they are exactly the pairs whose axis-aligned boxes touch (brute force, all n^2)
    p = np.array([b.p_WB for b in blocks])
    half = np.array([b.size for b in blocks]) / 2
    lo, hi = p - half, p + half
    touch = ((lo[:, None, :] <= hi[None, :, :]) & (lo[None, :, :] <= hi[:, None, :])).all(axis=2)
    assert {(int(i), int(j)) for i, j in zip(*np.nonzero(touch)) if i < j} == {tuple(sorted(q)) for q in pairs}
