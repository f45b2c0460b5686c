"""Step 2 of the model: the symbolic (logic) layer.

The paper finds "an ordering of blocks by which State B will be constructed from
blocks in State A ... from the ground up, making sure that each block to be placed
has its support already in place", with two primitives, Grasp(Obj) and
Place(Obj1, Obj2). Because pairs 6, 9 and 10 start from structures, the ordering
must also respect the support graph of A: a block can only be grasped when nothing
rests on it. The geometric layer (KOMO) meets this layer only through the skeleton,
a list of (phase, action).
"""
from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from lgp.geometry import rectangle_overlap
from lgp.scene import (OVERLAP_TOLERANCE, TABLE, Block, Scene, may_penetrate, penetration, support_graph, support_graph_after_move,
                       supported_by)


class IllegalActionError(ValueError):
    """An action cannot be applied in the current state; the message names both."""


class SymbolicPlanningError(ValueError):
    """No legal order of grasp/place actions reaches the target."""


@dataclass(frozen=True)
class Grasp:
    """Pick up `block` (a name in A) with the single hand."""

    block: str

    def __str__(self) -> str:
        return f"Grasp({self.block})"


@dataclass(frozen=True)
class Place:
    """Put the held `block` at its target pose (p_WB, yaw), resting on `onto`.

    `onto` names what it rests on once placed: blocks of A (already placed), the
    table, or a fixed obstacle.
    """

    block: str
    onto: tuple[str, ...]
    p_WB: np.ndarray = field(compare=False)
    yaw: float = field(default=0.0, compare=False)

    def __str__(self) -> str:
        return f"Place({self.block}, {'+'.join(self.onto)})"


Action = Grasp | Place


@dataclass(frozen=True)
class PlanState:
    """Block poses (as a Scene of A's block names) and the block in hand, if any."""

    scene: Scene
    held: str | None = None


#: Two poses are the same when centres agree to 0.1 mm and yaw agrees modulo the
#: cube's quarter-turn symmetry to 1 mrad.
POSITION_TOLERANCE = 1e-4
YAW_TOLERANCE = 1e-3


def same_pose(p_a, yaw_a, p_b, yaw_b, size=None) -> bool:
    """Same centre and the same yaw up to the footprint's symmetry: a quarter turn
    for a square footprint (the cubes), a half turn for a rectangle."""
    period = np.pi / 2 if size is None or np.isclose(size[0], size[1]) else np.pi
    d_yaw = (yaw_a - yaw_b + period / 2) % period - period / 2
    return bool(np.linalg.norm(np.asarray(p_a) - np.asarray(p_b)) <= POSITION_TOLERANCE and abs(d_yaw) <= YAW_TOLERANCE)


def apply(action: Action, state: PlanState, *, support=support_graph) -> PlanState:
    """The state after `action`; raises IllegalActionError if it is not allowed.

    Rules: one hand, so Grasp needs an empty hand and Place the block in hand; a
    block can be grasped only when nothing rests on it; a placed block must not
    overlap another block or obstacle and must rest on exactly what `onto` says.
    `support(scene)` gives the support graph (lgp.scene.support_graph, or a
    caller's memo of it).
    """
    scene = state.scene
    if action.block not in scene.names:
        raise IllegalActionError(f"{action} in {scene.label}: no block {action.block!r}")
    if isinstance(action, Grasp):
        if state.held is not None:
            raise IllegalActionError(f"{action} in {scene.label}: the hand already holds {state.held}")
        above = supported_by(support(scene))[action.block]
        if above:
            raise IllegalActionError(f"{action} in {scene.label}: {', '.join(above)} rests on {action.block}")
        return PlanState(scene, held=action.block)
    if isinstance(action, Place):
        if state.held != action.block:
            raise IllegalActionError(f"{action} in {scene.label}: the hand holds {state.held}, not {action.block}")
        moved = scene.block(action.block).moved_to(action.p_WB, action.yaw)
        new = scene.with_blocks(moved if b.name == action.block else b for b in scene.blocks)
        for other in nearby_solids(moved, (*new.blocks, *new.fixed)):
            if other.name == moved.name:
                continue
            depth = penetration(moved, other)
            if depth > OVERLAP_TOLERANCE:
                raise IllegalActionError(f"{action} in {scene.label}: {moved.name} would overlap {other.name} by {depth * 1000:.1f} mm")
        rests = set(support(new)[moved.name])
        if rests != set(action.onto):
            raise IllegalActionError(
                f"{action} in {scene.label}: {moved.name} would rest on {sorted(rests) or 'nothing'}, not {sorted(action.onto)}"
            )
        return PlanState(new, held=None)
    raise IllegalActionError(f"unknown action {action!r}")


def nearby_solids(block, solids) -> list:
    """The solids (in order) that `block` may interpenetrate by more than
    OVERLAP_TOLERANCE: their centres lie within the sum of the half diagonals
    (plus the tolerance). A superset; the exact test decides."""
    if not solids:
        return []
    centres = np.array([s.p_WB if isinstance(s, Block) else s.p_WO for s in solids])
    radius = np.array([np.linalg.norm(s.size) / 2 for s in solids])
    near = np.linalg.norm(centres - block.p_WB, axis=1) <= radius + np.linalg.norm(block.size) / 2 + OVERLAP_TOLERANCE
    return [solids[i] for i in np.flatnonzero(near)]


def enters_any(block: Block, solids: list) -> bool:
    """Whether `block` interpenetrates any of `solids` by more than OVERLAP_TOLERANCE
    (lgp.scene.penetration). The depths of all pairs at once only rule out the pairs
    well below the tolerance; the scalar test decides the rest."""
    if not solids:
        return False
    c, half, u = (np.array(x) for x in zip(*(s.outline() for s in solids)))
    mine = block.outline()
    horizontal, _ = rectangle_overlap(*(np.broadcast_to(x, (len(solids), 2)) for x in mine), c, half, u)
    vertical = np.minimum(block.top, [s.top for s in solids]) - np.maximum(block.bottom, [s.bottom for s in solids])
    maybe = np.flatnonzero(may_penetrate(vertical, horizontal))
    return any(penetration(block, solids[i]) > OVERLAP_TOLERANCE for i in maybe)


def support_memo():
    """support_graph(scene) computed once per Scene object (symbolic_plan asks for
    each state's graph up to three times: clear blocks, grasp, place), and for a
    scene one block away from the last one asked, updated from that one's graph."""
    graphs: dict[int, tuple[Scene, dict]] = {}
    last: list = []

    def support(scene: Scene) -> dict[str, list[str]]:
        hit = graphs.get(id(scene))
        if hit is None or hit[0] is not scene:
            graph = None
            if last:
                before, previous = last[0]
                changed = [a.name for a, b in zip(before.blocks, scene.blocks) if a is not b]
                if (len(changed) == 1 and before.fixed is scene.fixed
                        and [a.name for a in before.blocks] == [b.name for b in scene.blocks]):
                    graph = support_graph_after_move(scene, previous, changed[0])
            hit = graphs[id(scene)] = (scene, graph if graph is not None else support_graph(scene))
        last[:] = [hit]
        return hit[1]

    return support


@dataclass(frozen=True)
class SymbolicPlan:
    """A legal sequence of Grasp/Place actions taking `initial` to `target`."""

    initial: Scene
    target: Scene
    assignment: dict[str, str]
    actions: tuple[Action, ...]

    def __len__(self) -> int:
        return len(self.actions)

    @property
    def moved(self) -> list[str]:
        """Names (in A) of the blocks the plan moves, in the order they move."""
        return [a.block for a in self.actions if isinstance(a, Grasp)]

    def skeleton(self) -> list[tuple[float, Action]]:
        """(phase, action) pairs on KOMO's phase clock: action k at phase k."""
        return [(float(k + 1), a) for k, a in enumerate(self.actions)]

    def states(self) -> list[PlanState]:
        """The state after each action (checked by `apply`)."""
        state, out = PlanState(self.initial), []
        for action in self.actions:
            state = apply(action, state)
            out.append(state)
        return out

    def final_scene(self) -> Scene:
        return self.states()[-1].scene if self.actions else self.initial

    def __str__(self) -> str:
        return " -> ".join(map(str, self.actions))


def _staying(initial: Scene, target_of: dict, support_A: dict, fixed_names: set[str]) -> dict[str, bool]:
    """For every block of A: whether it stays where it is, already at its target pose
    on supports that also stay (pair 9-E moves 2 blocks)."""
    stays: dict[str, bool] = {}

    def stays_put(a: str) -> bool:
        if a not in stays:
            stays[a] = False  # guards against cycles while recursing
            block, goal = initial.block(a), target_of.get(a)
            stays[a] = (
                goal is not None
                and same_pose(block.p_WB, block.yaw, goal.p_WB, goal.yaw, block.size)
                and all(s in fixed_names or stays_put(s) for s in support_A[a])
            )
        return stays[a]

    for a in initial.names:
        stays_put(a)
    return stays


def _swap_targets(initial: Scene, target: Scene, covered: str, clear: list[str], target_of: dict,
                  block_of_target: dict) -> str:
    """The clear block of `covered`'s colour that takes its target, the pair that
    adds the least distance swapping targets (in `target_of` and `block_of_target`)."""
    swaps = [c for c in clear if initial.block(c).colour == initial.block(covered).colour]
    if not swaps:
        raise SymbolicPlanningError(
            f"{initial.label} -> {target.label}: {covered} must go to {target_of[covered].name} next but is covered, "
            "and no clear block of its colour can take its place"
        )

    def added(c):
        pc, pa = initial.block(c).p_WB, initial.block(covered).p_WB
        return np.linalg.norm(pc - target_of[covered].p_WB) + np.linalg.norm(pa - target_of[c].p_WB)

    a = min(swaps, key=added)
    target_of[a], target_of[covered] = target_of[covered], target_of[a]
    block_of_target[target_of[a].name], block_of_target[target_of[covered].name] = a, covered
    return a


def symbolic_plan(initial: Scene, target: Scene, assignment: dict[str, str]) -> SymbolicPlan:
    """Order grasp/place actions so B is built from the ground up.

    Greedy over legal moves: a block may move when nothing rests on it (support
    graph of the current state), every block it rests on in B is already in place,
    and its target volume is free. Among legal moves the lowest target goes first,
    ties broken by A's block order. When the distance-minimising assignment admits
    no legal move (relocating a tower, pair 10: the bottom block of A is assigned
    the bottom of B), a clear block of the same colour swaps targets with the
    covered one; the returned plan carries the assignment it executed. Blocks already at their target pose, on
    supports that also stay, are not moved (pair 9-E moves 2 blocks).
    """
    target_of = {a: target.block(b) for a, b in assignment.items()}
    block_of_target = {b: a for a, b in assignment.items()}
    support_A = support_graph(initial)
    support_B = support_graph(target)
    fixed_names = {f.name for f in initial.fixed} | {TABLE}

    stays = _staying(initial, target_of, support_A, fixed_names)
    to_move = [a for a in initial.names if a in target_of and not stays[a]]
    in_place = {a for a in target_of if stays[a]}

    def onto(a: str) -> tuple[str, ...]:
        return tuple(s if s in fixed_names else block_of_target[s] for s in support_B[target_of[a].name])

    state, actions = PlanState(initial), []
    support = support_memo()
    while to_move:
        current = state.scene
        above = supported_by(support(current))
        clear = [a for a in to_move if not above[a]]
        ready = []  # (target height, A order, block assigned to a target that can be built now)
        for order, a in enumerate(to_move):
            goal = target_of[a]
            if not all(s in fixed_names or s in in_place for s in onto(a)):
                continue
            goal_block = current.block(a).moved_to(goal.p_WB, goal.yaw)
            if enters_any(goal_block, [b for b in nearby_solids(goal_block, current.blocks) if b.name != a]):
                continue
            ready.append((goal.p_WB[2], order, a))
        legal = [r for r in ready if r[2] in clear]
        if legal:
            _, _, a = min(legal)
        elif ready:
            # Repair (the paper's footnote: distance and support are handled
            # separately): the block assigned to the lowest ready target is covered,
            # so a clear block of the same colour takes its role, the pair that adds
            # the least distance swapping targets.
            a = _swap_targets(initial, target, min(ready)[2], clear, target_of, block_of_target)
        else:
            raise SymbolicPlanningError(
                f"{initial.label} -> {target.label}: no legal move for blocks {', '.join(to_move)} "
                "(none has its support in B in place with its target volume free)"
            )
        goal = target_of[a]
        for action in (Grasp(a), Place(a, onto(a), goal.p_WB.copy(), goal.yaw)):
            state = apply(action, state, support=support)
            actions.append(action)
        to_move.remove(a)
        in_place.add(a)
    assignment = {a: g.name for a, g in target_of.items()}
    return SymbolicPlan(initial, target, dict(assignment), tuple(actions))
