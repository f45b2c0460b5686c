"""Step 2: every symbolic plan is legal under the state-transition checker and
respects the support graphs of A and B; plan lengths span 4 to 30 actions [paper]."""
import numpy as np
import pytest

import stimuli
from lgp.assignment import assign_blocks
from lgp.paper import TRIAL_IDS as IDS
from lgp.scene import BLOCK_SIZE as d
from lgp.scene import Block, Scene, support_graph, supported_by
from lgp.symbolic import Grasp, IllegalActionError, Place, PlanState, apply, same_pose, symbolic_plan


def _plan(tid, seed=0):
    trial = stimuli.load_trial(tid)
    A = trial.sample_initial(np.random.default_rng(seed))
    return trial, symbolic_plan(A, trial.target, assign_blocks(A, trial.target))


@pytest.mark.parametrize("tid", IDS)
@pytest.mark.parametrize("seed", [0, 1])
def test_plan_is_legal_and_builds_the_target(tid, seed):
    trial, plan = _plan(tid, seed)
    states = plan.states()  # raises IllegalActionError on an illegal step
    final = states[-1].scene
    # the executed assignment (possibly repaired) still gives every B block exactly one A block
    assert sorted(plan.assignment.values()) == sorted(trial.target.names)
    assert len(set(plan.assignment)) == len(plan.assignment)
    assert states[-1].held is None
    for a, b in plan.assignment.items():
        goal = trial.target.block(b)
        assert same_pose(final.block(a).p_WB, final.block(a).yaw, goal.p_WB, goal.yaw)
    # every block is placed only after everything that supports it in B
    placed_at = {act.block: k for k, act in enumerate(plan.actions) if isinstance(act, Place)}
    by_target = {b: a for a, b in plan.assignment.items()}
    for b, under in support_graph(trial.target).items():
        for s in under:
            if s in by_target and by_target[s] in placed_at and by_target[b] in placed_at:
                assert placed_at[by_target[s]] < placed_at[by_target[b]]
    # every grasp happens when nothing rests on the block
    state = PlanState(plan.initial)
    for act in plan.actions:
        if isinstance(act, Grasp):
            assert supported_by(support_graph(state.scene))[act.block] == []
        state = apply(act, state)


def test_plan_lengths_span_4_to_30_actions():
    lengths = {tid: len(_plan(tid)[1]) for tid in IDS}
    assert min(lengths.values()) == 4 and max(lengths.values()) == 30
    assert lengths["9E"] == 4 and lengths["3E"] == lengths["3H"] == 30
    assert lengths["12E"] == lengths["12H"] == 10


def test_disassembly_takes_the_tower_apart_from_the_top():
    _, plan = _plan("6E")
    heights = [plan.initial.block(a).p_WB[2] for a in plan.moved]
    assert heights == sorted(heights, reverse=True)


def test_half_built_tower_moves_only_the_two_loose_blocks():
    _, plan = _plan("9E")
    assert sorted(plan.moved) == ["a5", "a6"]


def test_relocated_tower_is_rebuilt_from_the_top_block_of_A():
    # Minimum distance assigns A's covered bottom block to B's bottom; the logic
    # layer swaps in the clear top block instead of deadlocking.
    _, plan = _plan("10H")
    assert plan.moved == ["a4", "a3", "a2", "a1"]
    assert plan.assignment == {"a4": "b1", "a3": "b2", "a2": "b3", "a1": "b4"}


def test_coloured_tower_respects_colours():
    trial, plan = _plan("11H")
    for a, b in plan.assignment.items():
        assert plan.initial.block(a).colour == trial.target.block(b).colour


# ----------------------------------------------------------------------------- checker rules

h = d / 2
TWO = Scene([Block("x", [0, 0, h]), Block("y", [0, 0, 3 * h]), Block("z", [0.1, 0, h])], label="T")


def test_checker_rejects_grasping_a_covered_block():
    with pytest.raises(IllegalActionError, match=r"Grasp\(x\) in T: y rests on x"):
        apply(Grasp("x"), PlanState(TWO))


def test_checker_rejects_a_second_grasp():
    with pytest.raises(IllegalActionError, match="already holds y"):
        apply(Grasp("z"), PlanState(TWO, held="y"))


def test_checker_rejects_placing_a_block_not_in_hand():
    with pytest.raises(IllegalActionError, match="holds None, not z"):
        apply(Place("z", ("y",), np.array([0, 0, 5 * h])), PlanState(TWO))


def test_checker_rejects_placing_into_another_block():
    with pytest.raises(IllegalActionError, match="z would overlap x"):
        apply(Place("z", ("table",), np.array([0.01, 0, h])), PlanState(TWO, held="z"))


def test_checker_rejects_placing_in_mid_air():
    with pytest.raises(IllegalActionError, match=r"would rest on nothing, not \['y'\]"):
        apply(Place("z", ("y",), np.array([0, 0, 6 * h])), PlanState(TWO, held="z"))


def test_rectangular_block_turned_a_quarter_is_not_in_place():
    p = np.zeros(3)
    assert same_pose(p, 0.0, p, np.pi / 2) and same_pose(p, 0.0, p, np.pi / 2, size=[d, d, d])
    assert not same_pose(p, 0.0, p, np.pi / 2, size=[2 * d, d, d])
    assert same_pose(p, 0.0, p, np.pi, size=[2 * d, d, d])


def test_checker_accepts_a_legal_place():
    s = apply(Place("z", ("y",), np.array([0, 0, 5 * h])), PlanState(TWO, held="z"))
    assert s.held is None and support_graph(s.scene)["z"] == ["y"]


def test_bounding_sphere_prefilter_keeps_every_overlap_the_exact_test_finds():
    # apply(Place) runs the exact overlap test only on solids whose bounding spheres
    # meet (lgp.symbolic.nearby_solids); brute force over random blocks and boxes: every
    # solid the exact test flags is among them.
    from lgp.scene import OVERLAP_TOLERANCE, FixedBox, penetration
    from lgp.symbolic import nearby_solids

    rng = np.random.default_rng(2)
    flagged = 0
    for _ in range(200):
        moved = Block("m", [rng.uniform(0, 0.1), rng.uniform(0, 0.1), rng.uniform(0, 0.05)], rng.uniform(-3, 3))
        solids = [Block(f"b{i}", [rng.uniform(0, 0.1), rng.uniform(0, 0.1), rng.uniform(0, 0.05)], rng.uniform(-3, 3))
                  for i in range(8)]
        solids.append(FixedBox("wall", [rng.uniform(0, 0.1), rng.uniform(0, 0.1), 0.02], [0.005, 0.1, 0.04]))
        exact = [s for s in solids if penetration(moved, s) > OVERLAP_TOLERANCE]
        near = nearby_solids(moved, solids)
        assert all(any(s is t for t in near) for s in exact)
        assert [s.name for s in near] == [s.name for s in solids if any(s is t for t in near)]  # order kept
        flagged += len(exact)
    assert flagged > 100


def test_array_overlap_verdict_is_the_scalar_one():
    # The ready-move check rules pairs out with array depths; brute force with the
    # scalar penetration on random, touching and slightly overlapping blocks.
    from lgp.scene import OVERLAP_TOLERANCE, penetration
    from lgp.symbolic import enters_any

    rng = np.random.default_rng(8)
    verdicts = set()
    for _ in range(300):
        block = Block("m", [0.3, 0.0, d / 2], rng.choice([0.0, rng.uniform(-3, 3)]))
        others = []
        for i in range(rng.integers(1, 5)):
            gap = rng.choice([d, d - OVERLAP_TOLERANCE, d - 2 * OVERLAP_TOLERANCE, d + 1e-9, rng.uniform(0, 2 * d)])
            angle = rng.choice([0.0, np.pi / 2, rng.uniform(-np.pi, np.pi)])
            others.append(Block(f"b{i}", [0.3 + gap * np.cos(angle), gap * np.sin(angle), d / 2 + rng.choice([0.0, d / 2, d])],
                                rng.choice([0.0, rng.uniform(-3, 3)])))
        expected = any(penetration(block, o) > OVERLAP_TOLERANCE for o in others)
        assert enters_any(block, others) == expected
        verdicts.add(expected)
    assert verdicts == {True, False}
