"""Step 1: the assignment equals brute force over all colour-respecting permutations."""
import itertools

import numpy as np
import pytest

from lgp.assignment import assign_blocks, assignment_distance
from lgp.scene import Block, Scene, StimulusError

COLS = ["natural", "green", "yellow"]


def _random_pair(rng, n_a, n_b):
    cols_b = rng.choice(COLS, n_b).tolist()
    cols_a = cols_b + rng.choice(COLS, n_a - n_b).tolist()
    rng.shuffle(cols_a)
    A = Scene([Block(f"a{i}", rng.uniform(-0.3, 0.3, 3), colour=c) for i, c in enumerate(cols_a)], label="A")
    B = Scene([Block(f"b{i}", rng.uniform(-0.3, 0.3, 3), colour=c) for i, c in enumerate(cols_b)], label="B")
    return A, B


def _brute_force(A, B):
    best = np.inf
    for perm in itertools.permutations(range(len(A)), len(B)):
        if all(A.blocks[i].colour == B.blocks[j].colour for j, i in enumerate(perm)):
            best = min(best, sum(np.linalg.norm(A.blocks[i].p_WB - B.blocks[j].p_WB) for j, i in enumerate(perm)))
    return best


@pytest.mark.parametrize("seed", range(25))
def test_assignment_equals_brute_force_with_colours(seed):
    rng = np.random.default_rng(seed)
    n_b = int(rng.integers(1, 6))
    A, B = _random_pair(rng, n_b + int(rng.integers(0, 3)), n_b)
    asg = assign_blocks(A, B)
    assert sorted(asg.values()) == sorted(B.names)
    assert all(A.block(a).colour == B.block(b).colour for a, b in asg.items())
    assert assignment_distance(A, B, asg) == pytest.approx(_brute_force(A, B), rel=1e-12)


def test_missing_colour_is_an_error():
    A = Scene([Block("a", [0, 0, 0])], label="X-A")
    B = Scene([Block("b", [0, 0, 0], colour="red")], label="X-B")
    with pytest.raises(StimulusError, match="X-B: needs 1 red blocks but X-A has 0"):
        assign_blocks(A, B)
