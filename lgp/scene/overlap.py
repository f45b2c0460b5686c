"""Overlap geometry of solids (lgp.scene.solids): footprint overlap, penetration
depth (separating axes), resting contact, and the broad phase (bounding boxes
compared with array operations) that leaves the exact checks a few pairs."""
from __future__ import annotations

import numpy as np

from lgp.geometry import clip_convex, polygon_area, rectangle_overlap
from lgp.scene.solids import CONTACT_TOLERANCE, MIN_SUPPORT_AREA, OVERLAP_TOLERANCE, Block


def footprint_overlap_area(a, b) -> float:
    """Area (m^2) shared by the outlines seen from above of two blocks/boxes."""
    P = clip_convex(a.footprint(), b.footprint())
    return abs(polygon_area(P)) if len(P) >= 3 else 0.0


def horizontal_penetration(a, b) -> float:
    """Depth (m) by which two outlines seen from above interpenetrate.

    Separating-axis test on the two rectangles (lgp.geometry.rectangle_overlap):
    the shortest push along one of the four edge axes that separates them; <= 0
    means separated (its magnitude is the gap along that axis only when the
    rectangles are aligned). Not the length shared by the two projections: that
    is smaller only when one projection contains the other, and then both exceed
    the smallest block edge, so no verdict against a tolerance below it differs.
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
    return solid_outlines(solids)[1:]


def solid_outlines(solids) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Footprint corners (n, 4, 2) and bounds lo, hi (n, 3) of the solids."""
    solids = list(solids)
    if not solids:
        return np.zeros((0, 4, 2)), np.zeros((0, 3)), np.zeros((0, 3))
    corners = np.array([s.footprint() for s in solids]).reshape(len(solids), 4, 2)
    z = np.array([[s.bottom, s.top] for s in solids]).reshape(len(solids), 2)
    lo = np.column_stack([corners.min(axis=1), z[:, 0]])
    hi = np.column_stack([corners.max(axis=1), z[:, 1]])
    return corners, lo, hi


def box_pairs(lo_a, hi_a, lo_b, hi_b, same: bool, margin: float = 0.0, rows: int = 1024) -> tuple[np.ndarray, np.ndarray]:
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
    _, lo_a, hi_a = solid_outlines(a_solids)
    lo_b, hi_b = (lo_a, hi_a) if same else solid_outlines(b_solids)[1:]
    i, j = box_pairs(lo_a, hi_a, lo_b, hi_b, same, margin, rows)
    return list(zip(i.tolist(), j.tolist()))


def sat_depths(A: np.ndarray, B: np.ndarray) -> np.ndarray:
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


def resting_candidates(blocks: list, fixed: list, tol: float) -> list[list]:
    """Per block, the solids it might rest on (blocks in scene order, then fixed
    boxes): its top is within `tol` (m) of the block's bottom and their outline
    boxes share more than MIN_SUPPORT_AREA (the outlines share at most that).
    A superset of what `rests_on` accepts."""
    out: list[list] = [[] for _ in blocks]
    if not blocks:
        return out
    _, lob, hib = solid_outlines(blocks)
    for others, is_block in ((blocks, True), (fixed, False)):
        if not others:
            continue
        lo, hi = (lob, hib) if is_block else solid_outlines(others)[1:]
        i, j = box_pairs(lob, hib, lo, hi, False, margin=tol)
        shared = np.prod(np.clip(np.minimum(hib[i, :2], hi[j, :2]) - np.maximum(lob[i, :2], lo[j, :2]), 0, None), axis=1)
        keep = (np.abs(lob[i, 2] - hi[j, 2]) <= tol + _SLACK) & (shared > MIN_SUPPORT_AREA - _SLACK * 1e-3)
        if is_block:
            keep &= i != j
        for a, c in zip(i[keep].tolist(), j[keep].tolist()):  # row-major: per block, in the others' order
            out[a].append(others[c])
    return out
