"""Scenes of 1-inch cubes on a table: blocks, fixed obstacles, and the checks a
stimulus must pass before anything plans or simulates on it.

Frames follow Drake's monogram notation: W is the world frame on the table top
(z = 0 is the table surface, x away from the agent, y to its left); B is a block's
body frame at its centre; `p_WB` is the block centre in W and `yaw` its rotation
about z, so X_WB = RigidTransform(RotationMatrix.MakeZRotation(yaw), p_WB).
"""
from __future__ import annotations

from collections import Counter
from dataclasses import dataclass, field, replace
from typing import Iterable

import numpy as np

from lgp.geometry import clip_convex, polygon_area, rectangle, rectangle_overlap, yaw_direction
from lgp.paper import BLOCK_SIZE, COLOURS

#: Two solids may interpenetrate by at most this much (m) and still count as
#: touching: trial files are written to 0.1 mm, and a touching pair computed in
#: floating point overlaps by ~1e-17 m.
OVERLAP_TOLERANCE = 1e-4
#: A block rests on a surface when its bottom face is within this distance (m) of
#: that surface's top face (and their footprints overlap by more than
#: MIN_SUPPORT_AREA).
CONTACT_TOLERANCE = 1e-4
#: Smallest footprint overlap (m^2) that counts as support: 1 mm x 1 mm.
MIN_SUPPORT_AREA = 1e-6
#: Name of the table in support graphs.
TABLE = "table"

#: The workspace of a table-top task, which every solid (block or fixed box) of a
#: scene must lie in: centre within |x|, |y| <= WORKSPACE_XY and WORKSPACE_Z[0] <=
#: z <= WORKSPACE_Z[1] (m), every edge longer than SOLID_SIZE[0] and at most
#: SOLID_SIZE[1] (m), yaw within one turn (|yaw| <= 2 pi). Not the paper's numbers:
#: bounds well beyond the arm's reach and the 1-inch blocks, there to refuse absurd
#: input (a size of 1e300 hangs a physics engine) before anything plans or simulates.
WORKSPACE_XY = 2.0
WORKSPACE_Z: tuple[float, float] = (0.0, 2.0)
SOLID_SIZE: tuple[float, float] = (1e-3, 0.5)


class StimulusError(ValueError):
    """A trial, state or block breaks a rule of the stimulus format.

    The message names the trial and state (e.g. ``7H-B``), the block and the rule.
    """


@dataclass(frozen=True)
class Block:
    """A cuboid block: name, centre `p_WB`, yaw about world z, colour, size (m)."""

    name: str
    p_WB: np.ndarray
    yaw: float = 0.0
    colour: str = "natural"
    size: np.ndarray = field(default_factory=lambda: np.full(3, BLOCK_SIZE))

    def __post_init__(self):
        object.__setattr__(self, "p_WB", np.asarray(self.p_WB, dtype=float).reshape(3))
        object.__setattr__(self, "size", np.asarray(self.size, dtype=float).reshape(3))
        object.__setattr__(self, "yaw", float(self.yaw))

    @property
    def X_WB(self):
        """Pose of the block frame in the world, as a Drake RigidTransform."""
        from pydrake.math import RigidTransform, RotationMatrix

        return RigidTransform(RotationMatrix.MakeZRotation(self.yaw), self.p_WB)

    @property
    def bottom(self) -> float:
        return float(self.p_WB[2] - self.size[2] / 2)

    @property
    def top(self) -> float:
        return float(self.p_WB[2] + self.size[2] / 2)

    def footprint(self) -> np.ndarray:
        """Corners (4, 2) of the block's outline seen from above, counter-clockwise."""
        return rectangle(self.p_WB[:2], self.size[:2], self.yaw)

    def outline(self) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """(centre, half extents, unit edge direction), each (2,), of the outline seen from above."""
        return self.p_WB[:2], self.size[:2] / 2, yaw_direction(self.yaw)

    def moved_to(self, p_WB, yaw: float | None = None) -> "Block":
        return replace(self, p_WB=np.asarray(p_WB, float), yaw=self.yaw if yaw is None else yaw)


@dataclass(frozen=True)
class FixedBox:
    """An axis-aligned box that never moves (a wall or the floor of the bucket).

    `name` is the obstacle it belongs to (several boxes may share it, e.g. the five
    boxes of the bucket); `p_WO` is the box centre and `size` its full extents.
    """

    name: str
    p_WO: np.ndarray
    size: np.ndarray

    def __post_init__(self):
        object.__setattr__(self, "p_WO", np.asarray(self.p_WO, dtype=float).reshape(3))
        object.__setattr__(self, "size", np.asarray(self.size, dtype=float).reshape(3))

    @property
    def bottom(self) -> float:
        return float(self.p_WO[2] - self.size[2] / 2)

    @property
    def top(self) -> float:
        return float(self.p_WO[2] + self.size[2] / 2)

    def footprint(self) -> np.ndarray:
        return rectangle(self.p_WO[:2], self.size[:2], 0.0)

    def outline(self) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """(centre, half extents, unit edge direction), each (2,), of the outline seen from above."""
        return self.p_WO[:2], self.size[:2] / 2, yaw_direction(0.0)


@dataclass(frozen=True)
class Scene:
    """Blocks plus fixed obstacles; `label` says where it came from (``7H-B``)."""

    blocks: tuple[Block, ...]
    fixed: tuple[FixedBox, ...] = ()
    label: str = "scene"

    def __post_init__(self):
        object.__setattr__(self, "blocks", tuple(self.blocks))
        object.__setattr__(self, "fixed", tuple(self.fixed))

    def __len__(self) -> int:
        return len(self.blocks)

    def __iter__(self):
        return iter(self.blocks)

    @property
    def names(self) -> list[str]:
        return [b.name for b in self.blocks]

    def block(self, name: str) -> Block:
        for b in self.blocks:
            if b.name == name:
                return b
        raise KeyError(f"{self.label}: no block named {name!r}")

    def with_blocks(self, blocks: Iterable[Block]) -> "Scene":
        return replace(self, blocks=tuple(blocks))

    @property
    def positions(self) -> np.ndarray:
        """Block centres p_WB, shape (n, 3), in block order."""
        return np.array([b.p_WB for b in self.blocks]).reshape(-1, 3)

    def validate(self) -> "Scene":
        """Raise StimulusError on the first broken rule; return self when valid."""
        validate_scene(self)
        return self


# ----------------------------------------------------------------------------- geometry


def footprint_overlap_area(a, b) -> float:
    """Area (m^2) shared by the outlines seen from above of two blocks/boxes."""
    P = clip_convex(a.footprint(), b.footprint())
    return abs(polygon_area(P)) if len(P) >= 3 else 0.0


def horizontal_penetration(a, b) -> float:
    """Depth (m) by which two outlines seen from above interpenetrate.

    Separating-axis test on the two rectangles (lgp.geometry.rectangle_overlap):
    the shortest push along one of the four edge axes that separates them; <= 0
    means separated (its magnitude is the gap along that axis only when the
    rectangles are aligned). (Until issue 9 this was the length shared by the two
    projections, which is smaller only when one projection contains the other;
    both then exceed the smallest block edge, so no verdict against a tolerance
    below it changes.)
    """
    (c_a, half_a, u_a), (c_b, half_b, u_b) = a.outline(), b.outline()
    depth, _ = rectangle_overlap(c_a[None], half_a[None], u_a[None], c_b[None], half_b[None], u_b[None])
    return float(depth[0])


def penetration(a, b) -> float:
    """Depth (m) by which two solids interpenetrate; <= 0 when they are apart."""
    vertical = min(a.top, b.top) - max(a.bottom, b.bottom)
    return min(vertical, horizontal_penetration(a, b))


def bounding_boxes(solids) -> tuple[np.ndarray, np.ndarray]:
    """Axis-aligned bounds (lo, hi), each (n, 3), of the solids' footprints x heights."""
    return _outlines(solids)[1:]


def _outlines(solids) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Footprint corners (n, 4, 2) and bounds lo, hi (n, 3) of the solids."""
    solids = list(solids)
    if not solids:
        return np.zeros((0, 4, 2)), np.zeros((0, 3)), np.zeros((0, 3))
    corners = np.array([s.footprint() for s in solids]).reshape(len(solids), 4, 2)
    z = np.array([[s.bottom, s.top] for s in solids]).reshape(len(solids), 2)
    lo = np.column_stack([corners.min(axis=1), z[:, 0]])
    hi = np.column_stack([corners.max(axis=1), z[:, 1]])
    return corners, lo, hi


def _box_pairs(lo_a, hi_a, lo_b, hi_b, same: bool, margin: float = 0.0, rows: int = 1024) -> tuple[np.ndarray, np.ndarray]:
    """Index arrays (i, j) of the boxes that touch or overlap when grown by `margin`
    (i < j when `same`), in row-major order; memory O(rows x n)."""
    I, J = [], []
    for start in range(0, len(lo_a), rows):
        la, ha = lo_a[start:start + rows, None, :], hi_a[start:start + rows, None, :]
        hit = np.all((la <= hi_b[None] + margin) & (lo_b[None] <= ha + margin), axis=2)
        if same:
            hit &= np.arange(len(lo_b))[None, :] > np.arange(start, start + len(la))[:, None]
        i, j = np.nonzero(hit)
        I.append(i + start)
        J.append(j)
    if not I:
        return np.zeros(0, int), np.zeros(0, int)
    return np.concatenate(I), np.concatenate(J)


def near_pairs(a_solids, b_solids=None, margin: float = 0.0, rows: int = 1024) -> list[tuple[int, int]]:
    """Broad phase: index pairs (i, j) whose bounding boxes, grown by `margin` (m),
    touch or overlap; with one list, pairs i < j of that list.

    A superset of the pairs that can penetrate or touch, found with array
    operations; the exact checks then run on these pairs only, which keeps the
    verdicts of the pairwise checks while a 500-block trial validates in well
    under a second.
    """
    same = b_solids is None
    _, lo_a, hi_a = _outlines(a_solids)
    lo_b, hi_b = (lo_a, hi_a) if same else _outlines(b_solids)[1:]
    i, j = _box_pairs(lo_a, hi_a, lo_b, hi_b, same, margin, rows)
    return list(zip(i.tolist(), j.tolist()))


def _sat_depths(A: np.ndarray, B: np.ndarray) -> np.ndarray:
    """horizontal_penetration for many pairs of outlines at once, A and B (P, 4, 2).

    Used only to discard pairs far from a threshold: a pair near it is decided by
    the scalar function, so rounding here cannot change a verdict.
    """
    edges = np.concatenate([A[:, 1:3] - A[:, 0:2], B[:, 1:3] - B[:, 0:2]], axis=1)  # (P, 4 axes, 2)
    axes = edges / np.linalg.norm(edges, axis=2, keepdims=True)
    pa = np.einsum("pcd,pkd->pkc", A, axes)  # (P, axis, corner)
    pb = np.einsum("pcd,pkd->pkc", B, axes)
    depth = np.minimum(pa.max(axis=2), pb.max(axis=2)) - np.maximum(pa.min(axis=2), pb.min(axis=2))
    return depth.min(axis=1)


#: Slack (m, m^2) by which the vectorised filters keep pairs near a threshold for the exact scalar check.
_SLACK = 1e-7


def may_penetrate(vertical: np.ndarray, horizontal: np.ndarray) -> np.ndarray:
    """Which pairs the vectorised depths (m; vertical extent overlap, horizontal SAT
    depth) leave to the scalar `penetration` test: those not well below
    OVERLAP_TOLERANCE. The slack is far above the ~1e-17 m by which array and scalar
    depths can round apart, so this filter cannot change a verdict."""
    return np.minimum(vertical, horizontal) > OVERLAP_TOLERANCE - _SLACK


def rests_on(upper: Block, lower, tol: float = CONTACT_TOLERANCE) -> bool:
    """True when `upper`'s bottom face lies on `lower`'s top face over a real area."""
    return abs(upper.bottom - lower.top) <= tol and footprint_overlap_area(upper, lower) > MIN_SUPPORT_AREA


# ----------------------------------------------------------------------------- validation


def check_solid(label: str, kind: str, name: str, p, size, yaw: float = 0.0) -> None:
    """Raise StimulusError unless a solid's centre `p` (m), edges `size` (m) and `yaw`
    (rad) are finite and inside the workspace (WORKSPACE_XY, WORKSPACE_Z, SOLID_SIZE).
    `kind` is ``block`` or ``fixed``; the message names label, solid and rule."""
    where = f"{label} {kind} {name}"
    p, size = np.asarray(p, dtype=float), np.asarray(size, dtype=float)
    if not (np.all(np.isfinite(p)) and np.all(np.isfinite(size)) and np.isfinite(yaw)):
        raise StimulusError(f"{where}: pose or size is not finite (position {p}, size {size}, yaw {yaw})")
    lo, hi = SOLID_SIZE
    if np.any(size <= lo) or np.any(size > hi):
        raise StimulusError(f"{where}: size {size} m breaks the workspace rule: every edge longer than "
                            f"{lo * 1000:g} mm and at most {hi:g} m")
    if np.any(np.abs(p[:2]) > WORKSPACE_XY) or not WORKSPACE_Z[0] <= p[2] <= WORKSPACE_Z[1]:
        raise StimulusError(f"{where}: centre {p} m lies outside the workspace |x|, |y| <= {WORKSPACE_XY:g} m, "
                            f"{WORKSPACE_Z[0]:g} <= z <= {WORKSPACE_Z[1]:g} m")
    if abs(yaw) > 2 * np.pi:
        raise StimulusError(f"{where}: yaw {yaw} rad is more than one turn (|yaw| <= 2 pi)")


def validate_scene(scene: Scene) -> None:
    """Check the rules every stimulus state obeys (see stimuli/README.md)."""
    label = scene.label
    for f in scene.fixed:  # first: a NaN box would otherwise surface as an overlap
        check_solid(label, "fixed", f.name, f.p_WO, f.size)
        if f.bottom < -CONTACT_TOLERANCE:
            raise StimulusError(f"{label} fixed {f.name}: lies under the table (bottom at z = {f.bottom * 1000:.1f} mm)")
    seen: set[str] = set()
    for b in scene.blocks:
        if b.name in seen:
            raise StimulusError(f"{label}: duplicate block name {b.name!r}")
        seen.add(b.name)
        check_solid(label, "block", b.name, b.p_WB, b.size, b.yaw)
        if b.colour not in COLOURS:
            raise StimulusError(f"{label} block {b.name}: unknown colour {b.colour!r} (known: {', '.join(COLOURS)})")
        if b.bottom < -CONTACT_TOLERANCE:
            raise StimulusError(f"{label} block {b.name}: lies under the table (bottom at z = {b.bottom * 1000:.1f} mm)")
    blocks, fixed = list(scene.blocks), list(scene.fixed)
    cb, lob, hib = _outlines(blocks)
    cf, lof, hif = _outlines(fixed)
    # The first overlap in the order of a pairwise scan (block i against blocks
    # j > i, then against fixed boxes), over the pairs the broad phase lets
    # through and a vectorised depth does not rule out; the scalar check decides.
    overlaps = []
    for kind, others, C, lo, hi, same in (("", blocks, cb, lob, hib, True), ("fixed ", fixed, cf, lof, hif, False)):
        i, j = _box_pairs(lob, hib, lo, hi, same)
        vertical = np.minimum(hib[i, 2], hi[j, 2]) - np.maximum(lob[i, 2], lo[j, 2])
        keep = may_penetrate(vertical, _sat_depths(cb[i], C[j]) if len(i) else vertical)
        overlaps += [((a, int(kind != ""), c), blocks[a], others[c], kind) for a, c in zip(i[keep].tolist(), j[keep].tolist())]
    for _, a, b, kind in sorted(overlaps, key=lambda o: o[0]):
        depth = penetration(a, b)
        if depth > OVERLAP_TOLERANCE:
            raise StimulusError(f"{label} block {a.name} overlaps {kind}{b.name} by {depth * 1000:.1f} mm")
    below = _resting_candidates(blocks, fixed, CONTACT_TOLERANCE)
    for i, b in enumerate(blocks):
        on_table = abs(b.bottom) <= CONTACT_TOLERANCE
        if not on_table and not any(rests_on(b, o) for o in below[i]):
            raise StimulusError(
                f"{label} block {b.name}: floats (bottom at z = {b.bottom * 1000:.1f} mm rests on neither the table nor another solid)"
            )


def _resting_candidates(blocks: list, fixed: list, tol: float) -> list[list]:
    """Per block, the solids it might rest on (blocks in scene order, then fixed
    boxes): its top is within `tol` (m) of the block's bottom and their outline
    boxes share more than MIN_SUPPORT_AREA (the outlines share at most that).
    A superset of what `rests_on` accepts."""
    out: list[list] = [[] for _ in blocks]
    if not blocks:
        return out
    _, lob, hib = _outlines(blocks)
    for others, is_block in ((blocks, True), (fixed, False)):
        if not others:
            continue
        lo, hi = (lob, hib) if is_block else _outlines(others)[1:]
        i, j = _box_pairs(lob, hib, lo, hi, False, margin=tol)
        shared = np.prod(np.clip(np.minimum(hib[i, :2], hi[j, :2]) - np.maximum(lob[i, :2], lo[j, :2]), 0, None), axis=1)
        keep = (np.abs(lob[i, 2] - hi[j, 2]) <= tol + _SLACK) & (shared > MIN_SUPPORT_AREA - _SLACK * 1e-3)
        if is_block:
            keep &= i != j
        for a, c in zip(i[keep].tolist(), j[keep].tolist()):  # row-major: per block, in the others' order
            out[a].append(others[c])
    return out


def colour_shortfall(initial: Scene, target: Scene) -> dict[str, tuple[int, int]]:
    """Colours the target needs more of than the start has: {colour: (needed, available)}."""
    have = Counter(b.colour for b in initial.blocks)
    need = Counter(b.colour for b in target.blocks)
    return {c: (n, have[c]) for c, n in need.items() if n > have[c]}


# ----------------------------------------------------------------------------- support graph


def support_graph(scene: Scene, tol: float = CONTACT_TOLERANCE) -> dict[str, list[str]]:
    """Which solids each block rests on: {block: [supporters]}.

    A supporter is another block, a fixed obstacle's name (e.g. ``bucket``) or
    ``"table"``. Contact means the bottom face is within `tol` (m) of the
    supporter's top face and the outlines share more than MIN_SUPPORT_AREA.
    """
    graph: dict[str, list[str]] = {}
    below = _resting_candidates(list(scene.blocks), list(scene.fixed), tol)
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
    below = _resting_candidates(blocks, list(scene.fixed), tol)
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
