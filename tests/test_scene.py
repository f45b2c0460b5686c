"""Scene geometry and the support graph against hand-worked answers."""
import numpy as np
import pytest

import stimuli
from lgp.scene import BLOCK_SIZE as d
from lgp.scene import Block, FixedBox, Scene, footprint_overlap_area, penetration, support_graph, supported_by

h = d / 2


def test_rotated_footprint_overlap_matches_closed_form():
    # A unit square and the same square turned 45 degrees about the same centre
    # share an octagon of area 2(sqrt 2 - 1) s^2.
    a = Block("a", [0, 0, h])
    b = Block("b", [0, 0, 3 * h], yaw=np.pi / 4)
    assert footprint_overlap_area(a, b) == pytest.approx(2 * (np.sqrt(2) - 1) * d * d, rel=1e-9)


def test_offset_blocks_share_the_overlapping_strip():
    a, b = Block("a", [0, 0, h]), Block("b", [0.3 * d, 0.1 * d, 3 * h])
    assert footprint_overlap_area(a, b) == pytest.approx(0.7 * d * 0.9 * d)


def test_penetration_of_side_by_side_blocks():
    a = Block("a", [0, 0, h])
    assert penetration(a, Block("b", [d, 0, h])) == pytest.approx(0.0, abs=1e-12)
    assert penetration(a, Block("b", [0.9 * d, 0, h])) == pytest.approx(0.1 * d)
    assert penetration(a, Block("b", [1.2 * d, 0, h])) < 0


def test_support_graph_of_the_pyramid():
    g = support_graph(stimuli.load_trial("5E").target)
    assert g == {"b1": ["table"], "b2": ["table"], "b3": ["table"], "b4": ["b1", "b2"], "b5": ["b2", "b3"], "b6": ["b4", "b5"]}
    assert supported_by(g)["b2"] == ["b4", "b5"]


def test_support_graph_of_the_bridge_span_rests_on_both_pillars():
    g = support_graph(stimuli.load_trial("5H").target)
    assert sorted(g["b5"]) == ["b2", "b4"] and g["b6"] == ["b5"]


def test_blocks_in_the_bucket_rest_on_the_bucket():
    floor = FixedBox("bucket", [0, 0, 0.0025], [0.1, 0.1, 0.005])
    s = Scene([Block("a", [0, 0, 0.005 + h])], [floor])
    assert support_graph(s) == {"a": ["bucket"]}


def test_block_touching_only_at_an_edge_is_not_supported():
    s = Scene([Block("a", [0, 0, h]), Block("b", [d, 0, 3 * h])])
    assert support_graph(s)["b"] == []


def test_support_graph_after_a_move_is_the_support_graph_of_the_new_scene():
    # The symbolic planner updates the support graph after each place instead of
    # recomputing it; brute force: the full graph, lists in the same order, for
    # random moves onto the table, onto other blocks and (12E, 12H: the trials with
    # fixed boxes) into the bucket, among blocks already resting on its floor.
    from lgp.scene import support_graph_after_move

    rng = np.random.default_rng(6)
    checked = into_bucket = 0
    for tid in ("7H", "3E", "9E", "10H", "4H", "12E", "12H"):
        scene = stimuli.load_trial(tid).target
        graph = support_graph(scene)
        floor = min(scene.fixed, key=lambda f: f.top, default=None)  # the bucket's floor
        for _ in range(25):
            b = scene.blocks[rng.integers(len(scene.blocks))]
            other = scene.blocks[rng.integers(len(scene.blocks))]
            place = rng.integers(4 if floor else 3)
            if place == 0:  # onto the top of another block, partly overlapping
                p = other.p_WB + [rng.uniform(-0.02, 0.02), rng.uniform(-0.02, 0.02), other.size[2]]
            elif place == 1:  # back onto the table
                p = [rng.uniform(0.2, 0.6), rng.uniform(-0.3, 0.3), b.size[2] / 2]
            elif place == 2:  # hovering
                p = [rng.uniform(0.2, 0.6), rng.uniform(-0.3, 0.3), rng.uniform(0.02, 0.1)]
            else:  # onto the bucket's floor
                p = floor.p_WO + [rng.uniform(-0.01, 0.01), rng.uniform(-0.1, 0.1), (floor.size[2] + b.size[2]) / 2]
            moved = b.moved_to(p, rng.uniform(-np.pi, np.pi) if rng.random() < 0.5 else b.yaw)
            new = scene.with_blocks(moved if x.name == b.name else x for x in scene.blocks)
            updated = support_graph_after_move(new, graph, b.name)
            assert updated == support_graph(new)
            scene, graph = new, updated
            checked += sum(map(len, graph.values()))
            into_bucket += floor is not None and floor.name in graph[b.name]
    assert checked > 200 and into_bucket > 5
