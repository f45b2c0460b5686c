"""The noise rule of the risk model: Gaussian moves of every block of B with no
overlap (paper, "Modeling physical risk"; docs/risk.md, "Noise rule")."""
import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from lgp.scene import BLOCK_SIZE, Block, FixedBox, Scene, penetration
from models.risk import draw_normals, perturb, perturb_from_normals
from models.risk.structures import bridge, grid, harmonic, line, pyramid, staircase, tower, two_block

D = BLOCK_SIZE
#: Numerical slack on "no overlap" (m): pushes end at touching to ~1e-12 m.
SLACK = 1e-9


def bucket_scene() -> Scene:
    """Pair-12-like: an open box of five FixedBoxes holding a 4 x 2 array of blocks."""
    wall, inner = 0.005, np.array([4 * D + 0.002, 2 * D + 0.002])
    cx, cy = 0.4, 0.0
    h = 1.5 * D
    fixed = [
        FixedBox("bucket", [cx, cy, wall / 2], [inner[0] + 2 * wall, inner[1] + 2 * wall, wall]),
        FixedBox("bucket", [cx - (inner[0] + wall) / 2, cy, wall + h / 2], [wall, inner[1] + 2 * wall, h]),
        FixedBox("bucket", [cx + (inner[0] + wall) / 2, cy, wall + h / 2], [wall, inner[1] + 2 * wall, h]),
        FixedBox("bucket", [cx, cy - (inner[1] + wall) / 2, wall + h / 2], [inner[0], wall, h]),
        FixedBox("bucket", [cx, cy + (inner[1] + wall) / 2, wall + h / 2], [inner[0], wall, h]),
    ]
    blocks = [
        Block(f"b{2 * i + j}", [cx + (i - 1.5) * D, cy + (j - 0.5) * D, wall + D / 2])
        for i in range(4)
        for j in range(2)
    ]
    return Scene(blocks, fixed, label="bucket 4x2").validate()


def yawed_pair() -> Scene:
    return Scene(
        [Block("a", [0.3, 0.0, D / 2], yaw=0.3), Block("b", [0.3 + 1.45 * D, 0.01, D / 2], yaw=-0.5),
         Block("c", [0.3, 0.0, 1.5 * D], yaw=0.9)],
        label="yawed",
    ).validate()


SCENES = [tower(10), line(10), two_block(0.45), harmonic(5, 0.9), staircase(4), bridge(), pyramid(),
          grid(3, 5), grid(3, 1, 5), bucket_scene(), yawed_pair()]


def assert_no_overlap(before: Scene, after: Scene):
    for k, (a, a0) in enumerate(zip(after.blocks, before.blocks)):
        assert a.bottom >= min(0.0, a0.bottom) - SLACK, f"{after.label}: {a.name} below the table"
        for b, b0 in zip(after.blocks[k + 1:], before.blocks[k + 1:]):
            allowed = max(0.0, penetration(a0, b0)) + SLACK
            assert penetration(a, b) <= allowed, f"{after.label}: {a.name} overlaps {b.name} by {penetration(a, b)}"
        for f in after.fixed:
            allowed = max(0.0, penetration(a0, f)) + SLACK
            assert penetration(a, f) <= allowed, f"{after.label}: {a.name} overlaps fixed {f.name}"


@pytest.mark.parametrize("scene", [pytest.param(s, marks=pytest.mark.slow) if s.label.startswith("grid") else s
                                   for s in SCENES], ids=lambda s: s.label)  # the 15-block grids in the full suite only
def test_perturbed_blocks_never_overlap_or_sink(scene):
    rng = np.random.default_rng(7)
    for sigma in (0.05, 0.1, 0.3):
        for _ in range(15):
            assert_no_overlap(scene, perturb(scene, sigma, rng))


@settings(max_examples=40, deadline=None)
@given(
    scene_index=st.integers(0, len(SCENES) - 1),
    sigma=st.floats(0.0, 0.5),
    seed=st.integers(0, 2**32 - 1),
)
def test_no_overlap_for_any_noise(scene_index, sigma, seed):
    scene = SCENES[scene_index]
    z = np.random.default_rng(seed).standard_normal((len(scene), 3)) * 2  # heavier tails than N(0, 1)
    assert_no_overlap(scene, perturb_from_normals(scene, sigma, z))


@pytest.mark.parametrize("scene", SCENES, ids=lambda s: s.label)
def test_zero_noise_leaves_every_block_exactly_in_place(scene):
    z = np.random.default_rng(0).standard_normal((len(scene), 3))
    after = perturb_from_normals(scene, 0.0, z)
    assert np.array_equal(after.positions, scene.positions)
    assert [b.yaw for b in after.blocks] == [b.yaw for b in scene.blocks]


def test_small_noise_moves_blocks_by_sigma_times_block_size():
    """Away from neighbours, a block moves by exactly sigma * d * z along the axes."""
    scene = line(3, gap=0.05)
    z = np.array([[0.3, -0.2, 0.5], [1.0, 0.4, 0.1], [-0.7, 0.0, 2.0]])
    after = perturb_from_normals(scene, 0.1, z)
    np.testing.assert_allclose(after.positions - scene.positions, 0.1 * D * z, atol=1e-15)


def test_noise_is_gaussian_with_sd_sigma_d_for_a_free_block():
    scene = Scene([Block("b0", [0.3, 0.0, 0.2])], label="in the air")  # nothing to collide with
    rng = np.random.default_rng(3)
    moves = np.array([perturb(scene, 0.08, rng).positions[0] - scene.positions[0] for _ in range(4000)])
    np.testing.assert_allclose(moves.std(axis=0), 0.08 * D, rtol=0.05)
    np.testing.assert_allclose(moves.mean(axis=0), 0.0, atol=0.08 * D * 0.1)


def test_yawed_block_is_perturbed_along_its_own_edges():
    scene = Scene([Block("b0", [0.3, 0.0, 0.2], yaw=np.pi / 2, size=[0.05, 0.02, 0.02])], label="yawed plank")
    after = perturb_from_normals(scene, 0.1, np.array([[1.0, 0.0, 0.0]]))
    # its own x axis points along world y, and its size along it is 0.05 m
    np.testing.assert_allclose(after.positions[0] - scene.positions[0], [0.0, 0.005, 0.0], atol=1e-15)


def test_lowered_block_is_lifted_onto_its_support_not_pushed_sideways():
    scene = tower(2)
    after = perturb_from_normals(scene, 0.1, np.array([[0.0, 0.0, 0.0], [0.0, 0.0, -2.0]]))
    np.testing.assert_allclose(after.positions, scene.positions, atol=1e-15)


def test_lifts_do_not_add_up_along_a_tower():
    """A block's start height above rest is the largest lift below it, not the sum."""
    scene = tower(10)
    z = np.zeros((10, 3))
    z[:, 2] = 1.0  # every block 0.1 d up
    after = perturb_from_normals(scene, 0.1, z)
    np.testing.assert_allclose(after.positions[:, 2] - scene.positions[:, 2], 0.1 * D, atol=1e-15)


def test_touching_line_is_pushed_apart_along_the_line_without_ratcheting():
    scene = line(10)
    z = np.zeros((10, 3))
    z[:, 1] = np.linspace(1, -1, 10)  # every pair squeezed together
    after = perturb_from_normals(scene, 0.1, z)
    y = after.positions[:, 1]
    np.testing.assert_allclose(np.diff(y), D, atol=1e-9)  # ends touching
    assert abs(y.mean() - scene.positions[:, 1].mean()) < 1e-9  # pushed symmetrically, no drift
    np.testing.assert_array_equal(after.positions[:, 0], scene.positions[:, 0])


def test_same_normals_give_same_scene_and_sigma_scales_them():
    scene = staircase(4)
    z = draw_normals(5, len(scene), seed=11)
    assert np.array_equal(z, draw_normals(5, len(scene), seed=11))
    a = perturb_from_normals(scene, 0.07, z[0])
    b = perturb_from_normals(scene, 0.07, z[0])
    assert np.array_equal(a.positions, b.positions)
    assert np.array_equal(perturb_from_normals(scene, 0.0, z[0]).positions, scene.positions)

    # Blocks far apart on the table never touch: each moves sigma * d * z in x and y,
    # and up by sigma * d * z (down is the table), so doubling sigma doubles every move.
    free = line(4, gap=2 * D)
    for zr in draw_normals(5, len(free), seed=11):
        moves = {s: perturb_from_normals(free, s, zr).positions - free.positions for s in (0.07, 0.14)}
        expected = 0.07 * D * zr
        expected[:, 2] = np.maximum(expected[:, 2], 0.0)
        np.testing.assert_allclose(moves[0.07], expected, rtol=0, atol=1e-15)
        np.testing.assert_allclose(moves[0.14], 2 * expected, rtol=0, atol=1e-15)


def test_bad_normals_shape_is_refused():
    with pytest.raises(ValueError, match="shape"):
        perturb_from_normals(tower(3), 0.1, np.zeros((2, 3)))
    with pytest.raises(ValueError, match="sigma"):
        perturb_from_normals(tower(3), -0.1, np.zeros((3, 3)))
