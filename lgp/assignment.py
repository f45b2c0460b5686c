"""Step 1 of the model: which block of A goes to which block of B.

The paper chooses "a one-to-one assignment of blocks in State A to blocks in State B
that minimizes the total Euclidean distance between the initial and final positions
of all blocks while taking into account the blocks' colors", solved with the
Hungarian algorithm (here scipy's linear_sum_assignment).
"""
from __future__ import annotations


import numpy as np
from scipy.optimize import linear_sum_assignment

from lgp.scene import Scene, StimulusError, colour_shortfall  # noqa: F401  (re-exported)

#: Cost of pairing blocks of different colours: large enough that no feasible
#: assignment uses one, finite so the solver stays well-posed.
_FORBIDDEN = 1e6


def assign_blocks(initial: Scene, target: Scene) -> dict[str, str]:
    """Minimum total Euclidean distance assignment {A block name: B block name}.

    Every block of B receives exactly one block of A of the same colour; blocks of A
    that B does not need are left out (they stay where they are).
    """
    short = colour_shortfall(initial, target)
    if short:
        colour, (n, have) = next(iter(short.items()))
        raise StimulusError(f"{target.label}: needs {n} {colour} blocks but {initial.label} has {have}")
    p_A, p_B = initial.positions, target.positions
    distance = np.linalg.norm(p_A[:, None, :] - p_B[None, :, :], axis=-1)
    same_colour = np.array([[a.colour == b.colour for b in target.blocks] for a in initial.blocks], dtype=bool)
    cost = np.where(same_colour, distance, _FORBIDDEN)
    rows, cols = linear_sum_assignment(cost)
    return {initial.blocks[i].name: target.blocks[j].name for i, j in zip(rows, cols)}


def assignment_distance(initial: Scene, target: Scene, assignment: dict[str, str]) -> float:
    """Total Euclidean distance (m) between assigned block centres."""
    return float(sum(np.linalg.norm(initial.block(a).p_WB - target.block(b).p_WB) for a, b in assignment.items()))
