"""Plane geometry of block outlines, rotations and fingerprints, written once.

Ground floor: imports nothing of the project. Outlines are rectangles seen from
above, given by their centre c (2,), half extents (2,) and unit edge direction
u = (cos yaw, sin yaw) (the other edge is v = (-u_y, u_x)); polygons are (k, 2)
corner arrays, counter-clockwise.

- `rectangle`, `polygon_area`, `clip_convex`: corners, area, Sutherland-Hodgman
  intersection of convex polygons (support polygons, footprint overlap);
- `rectangle_overlap`: separating-axis overlap depth of rectangles, vectorised
  over pairs (block-block penetration, noise separation);
- `quaternion_from_yaw`: (w, x, y, z) of a rotation about world z (engines);
- `digest`: SHA-1 fingerprint of names and arrays (in-process scene caches).
"""
from __future__ import annotations

import hashlib

import numpy as np


def rectangle(center, size, yaw) -> np.ndarray:
    """Corners (4, 2), counter-clockwise, of a rectangle of full `size` (2,) at `center` turned by `yaw`."""
    c, s = np.cos(yaw), np.sin(yaw)
    R = np.array([[c, -s], [s, c]])
    hx, hy = size[0] / 2, size[1] / 2
    local = np.array([[-hx, -hy], [hx, -hy], [hx, hy], [-hx, hy]])
    return local @ R.T + np.asarray(center)[:2]


def polygon_area(P: np.ndarray) -> float:
    """Signed area (shoelace), > 0 for counter-clockwise corners P (k, 2)."""
    x, y = P[:, 0], P[:, 1]
    return 0.5 * float(np.dot(x, np.roll(y, -1)) - np.dot(y, np.roll(x, -1)))


def clip_convex(subject: np.ndarray, clip: np.ndarray) -> np.ndarray:
    """Intersection (k, 2) of convex polygon `subject` with convex `clip` (both CCW), by
    Sutherland-Hodgman; a point within 1e-15 of a clip edge counts as inside."""
    out = list(subject)
    n = len(clip)
    for i in range(n):
        a, b = clip[i], clip[(i + 1) % n]
        edge = b - a
        inp, out = out, []
        if not inp:
            break

        def inside(p):
            return edge[0] * (p[1] - a[1]) - edge[1] * (p[0] - a[0]) >= -1e-15

        def cross(p, q):
            d = q - p
            den = edge[0] * d[1] - edge[1] * d[0]
            t = (edge[1] * (p[0] - a[0]) - edge[0] * (p[1] - a[1])) / den
            return p + t * d

        for j in range(len(inp)):
            p, q = inp[j], inp[(j + 1) % len(inp)]
            if inside(q):
                if not inside(p):
                    out.append(cross(p, q))
                out.append(q)
            elif inside(p):
                out.append(cross(p, q))
    return np.array(out).reshape(-1, 2)


def rectangle_overlap(c_a, half_a, u_a, c_b, half_b, u_b) -> tuple[np.ndarray, np.ndarray]:
    """Overlap depth of rectangles a and b along their shallowest separating axis, and that axis.

    Arguments are arrays over P pairs: centres c (P, 2), half extents (P, 2), unit
    edge directions u (P, 2). Separating-axis theorem on two rectangles: on each of
    the four edge axes the overlap is r_a + r_b - |(c_b - c_a) . axis|, r the
    rectangle's half width on the axis; depth (P,) is the smallest, <= 0 when the
    outlines are apart (its magnitude is the gap only when they are aligned);
    normal (P, 2) the axis of that depth, pointing from a to b.
    """
    c_a, half_a, u_a, c_b, half_b, u_b = (np.asarray(x, float) for x in (c_a, half_a, u_a, c_b, half_b, u_b))
    v_a = np.stack([-u_a[:, 1], u_a[:, 0]], axis=1)
    v_b = np.stack([-u_b[:, 1], u_b[:, 0]], axis=1)
    d = c_b - c_a
    axes = np.stack([u_a, v_a, u_b, v_b], axis=1)  # (P, 4, 2)
    r_a = half_a[:, 0, None] * np.abs(np.einsum("pk,pak->pa", u_a, axes)) + half_a[:, 1, None] * np.abs(
        np.einsum("pk,pak->pa", v_a, axes)
    )
    r_b = half_b[:, 0, None] * np.abs(np.einsum("pk,pak->pa", u_b, axes)) + half_b[:, 1, None] * np.abs(
        np.einsum("pk,pak->pa", v_b, axes)
    )
    proj = np.einsum("pk,pak->pa", d, axes)
    depth = r_a + r_b - np.abs(proj)
    k = np.argmin(depth, axis=1)
    rows = np.arange(len(c_a))
    sign = np.where(proj[rows, k] >= 0, 1.0, -1.0)
    return depth[rows, k], axes[rows, k] * sign[:, None]


def yaw_direction(yaw) -> np.ndarray:
    """Unit edge direction(s) u = (cos yaw, sin yaw), shape (..., 2)."""
    yaw = np.asarray(yaw, float)
    return np.stack([np.cos(yaw), np.sin(yaw)], axis=-1)


def quaternion_from_yaw(yaw) -> np.ndarray:
    """Unit quaternions (n, 4) as (w, x, y, z) of rotations by `yaw` (n,) about world z."""
    yaw = np.asarray(yaw, float)
    return np.stack([np.cos(yaw / 2), 0 * yaw, 0 * yaw, np.sin(yaw / 2)], axis=1)


def digest(*parts) -> str:
    """SHA-1 hex digest of `parts` fed in order: str (UTF-8), bytes, or numpy arrays
    and scalars (their raw bytes, so 0.1 and 0.1 + 1e-17 differ)."""
    h = hashlib.sha1()
    for part in parts:
        if isinstance(part, str):
            part = part.encode()
        elif not isinstance(part, bytes):
            part = np.asarray(part).tobytes()
        h.update(part)
    return h.hexdigest()
