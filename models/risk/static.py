"""Static centre-of-mass criterion for block stacks, independent of any physics
engine: the reference the engines are checked against on small stacks.

A scene stands when, for every block, the centre of mass of the block and of
everything it carries (directly or through other blocks) lies inside the support
polygon of its contact with what is beneath it: the convex hull of the regions
where its bottom face touches its supporters (its own outline on the table). It
is exact for stacks in which every block rests on one block; for bridges and
pyramids, where loads are shared, it is only a sufficient-looking heuristic.
"""
from __future__ import annotations

import numpy as np

from lgp.geometry import clip_convex
from lgp.scene import TABLE, Scene, support_graph, supported_by


def _cross(o, a, b) -> float:
    return (a[0] - o[0]) * (b[1] - o[1]) - (a[1] - o[1]) * (b[0] - o[0])


def _hull(points: np.ndarray) -> np.ndarray:
    """Convex hull, counter-clockwise (monotone chain)."""
    pts = sorted(set(map(tuple, np.round(points, 12))))
    if len(pts) <= 2:
        return np.array(pts)

    def half(seq):
        h = []
        for p in seq:
            while len(h) >= 2 and _cross(h[-2], h[-1], p) <= 0:
                h.pop()
            h.append(p)
        return h

    lower, upper = half(pts), half(pts[::-1])
    return np.array(lower[:-1] + upper[:-1])


def _signed_distance_inside(p: np.ndarray, poly: np.ndarray) -> float:
    """Distance from p to the boundary of convex polygon `poly`, > 0 inside."""
    if len(poly) < 3:
        return -np.inf
    d = np.inf
    for a, b in zip(poly, np.roll(poly, -1, axis=0)):
        e = b - a
        d = min(d, (e[0] * (p[1] - a[1]) - e[1] * (p[0] - a[0])) / np.linalg.norm(e))
    return float(d)


def static_margins(scene: Scene) -> dict[str, float]:
    """For every block: how far (m) the centre of mass of it and its load lies
    inside its support polygon (negative: outside, the block tips)."""
    graph = support_graph(scene)
    above = supported_by(graph)
    blocks = {b.name: b for b in scene.blocks}
    fixed = {f.name: [g for g in scene.fixed if g.name == f.name] for f in scene.fixed}

    def load(name, seen):
        for upper in above.get(name, []):
            if upper not in seen:
                seen.add(upper)
                load(upper, seen)
        return seen

    margins = {}
    for b in scene.blocks:
        group = [blocks[k] for k in load(b.name, {b.name})]
        mass = np.array([np.prod(g.size) for g in group])
        com = (mass[:, None] * np.array([g.p_WB[:2] for g in group])).sum(0) / mass.sum()
        patches = []
        for s in graph[b.name]:
            if s == TABLE:
                patches.append(b.footprint())
            elif s in blocks:
                patches.append(clip_convex(b.footprint(), blocks[s].footprint()))
            else:
                patches += [clip_convex(b.footprint(), f.footprint()) for f in fixed[s]]
        pts = np.vstack([p for p in patches if len(p)]) if patches else np.zeros((0, 2))
        margins[b.name] = _signed_distance_inside(com, _hull(pts)) if len(pts) else -np.inf
    return margins


def static_stable(scene: Scene, margin: float = 0.0) -> bool:
    """True when every block's loaded centre of mass lies more than `margin` (m)
    inside its support polygon."""
    return all(m > margin for m in static_margins(scene).values())
