"""Support graphs: which solids each block of a scene rests on, updated after one
block moves, and inverted (what rests on each solid)."""
from __future__ import annotations

from lgp.scene.overlap import resting_candidates, rests_on
from lgp.scene.solids import CONTACT_TOLERANCE, TABLE, Block


def support_graph(scene: Scene, tol: float = CONTACT_TOLERANCE) -> dict[str, list[str]]:
    """Which solids each block rests on: {block: [supporters]}.

    A supporter is another block, a fixed obstacle's name (e.g. ``bucket``) or
    ``"table"``. Contact means the bottom face is within `tol` (m) of the
    supporter's top face and the outlines share more than MIN_SUPPORT_AREA.
    """
    graph: dict[str, list[str]] = {}
    below = resting_candidates(list(scene.blocks), list(scene.fixed), tol)
    for i, b in enumerate(scene.blocks):
        near = below[i]
        under = [o.name for o in near if isinstance(o, Block) and rests_on(b, o, tol)]
        under += sorted({o.name for o in near if not isinstance(o, Block) and rests_on(b, o, tol)})
        if abs(b.bottom) <= tol:
            under.append(TABLE)
        graph[b.name] = under
    return graph


def support_graph_after_move(scene: Scene, previous: dict[str, list[str]], moved: str,
                             tol: float = CONTACT_TOLERANCE) -> dict[str, list[str]]:
    """support_graph(scene, tol), given `previous`, the graph (same tol) of a scene
    that differs from `scene` only in the pose of block `moved`.

    Whether one solid rests on another depends on that pair alone (the broad phase
    and `rests_on` are pairwise), so only pairs with `moved` are decided again; the
    lists keep support_graph's order (blocks in scene order, fixed names sorted, table).
    """
    blocks = list(scene.blocks)
    below = resting_candidates(blocks, list(scene.fixed), tol)
    block_names = {b.name for b in blocks}
    graph: dict[str, list[str]] = {}
    for i, b in enumerate(blocks):
        near = below[i]
        if b.name == moved:
            under = [o.name for o in near if isinstance(o, Block) and rests_on(b, o, tol)]
            under += sorted({o.name for o in near if not isinstance(o, Block) and rests_on(b, o, tol)})
            if abs(b.bottom) <= tol:
                under.append(TABLE)
        else:
            before = set(previous[b.name])
            under = [o.name for o in near if isinstance(o, Block) and (rests_on(b, o, tol) if o.name == moved else o.name in before)]
            under += [s for s in previous[b.name] if s not in block_names]  # fixed (sorted) and table: unchanged
        graph[b.name] = under
    return graph


def supported_by(graph: dict[str, list[str]]) -> dict[str, list[str]]:
    """Invert a support graph: {solid: [blocks resting on it]}."""
    above: dict[str, list[str]] = {name: [] for name in graph}
    for upper, lowers in graph.items():
        for lower in lowers:
            above.setdefault(lower, []).append(upper)
    return above
