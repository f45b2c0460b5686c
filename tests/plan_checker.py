"""An independent checker of solved plans, written apart from the planner and the
scene module (its own box geometry): one hand, no interpenetration along the
block paths, every resting block supported (centre of mass over its contact
area), and B built with the right colours. `check_plan` returns the list of
broken rules, empty for a good plan.
"""
from __future__ import annotations

import numpy as np

#: Interpenetration allowed between two solids (m): touching faces solved to 1e-6 plus slack.
DEPTH_TOLERANCE = 1e-3
#: A block's bottom within this of a top (or of the table at z = 0) rests on it (m).
CONTACT = 1e-3
#: A final block within this of its slot's centre (m) fills it.
AT_SLOT = 1e-3


def _axes(R):
    return [R[:, k] for k in range(3)]


def box_depth(p_a, R_a, half_a, p_b, R_b, half_b) -> float:
    """Interpenetration depth (m) of two oriented boxes by the separating axis theorem
    (15 axes): the least overlap of their projections, <= 0 when they are apart."""
    d = p_b - p_a
    axes = _axes(R_a) + _axes(R_b)
    for u in _axes(R_a):
        for v in _axes(R_b):
            c = np.cross(u, v)
            n = np.linalg.norm(c)
            if n > 1e-9:
                axes.append(c / n)
    depth = np.inf
    for axis in axes:
        ra = sum(h * abs(axis @ R_a[:, k]) for k, h in enumerate(half_a))
        rb = sum(h * abs(axis @ R_b[:, k]) for k, h in enumerate(half_b))
        depth = min(depth, ra + rb - abs(axis @ d))
        if depth <= 0:
            return depth
    return depth


def _footprint(p, R, half):
    """Corners (4, 2) counter-clockwise of a box's outline seen from above (R about z)."""
    u, v = R[:2, 0] * half[0], R[:2, 1] * half[1]
    c = p[:2]
    return np.array([c - u - v, c + u - v, c + u + v, c - u + v])


def _clip(subject, clipper):
    """Sutherland-Hodgman: the part of convex polygon `subject` inside convex `clipper` (both ccw)."""
    out = list(subject)
    for k in range(len(clipper)):
        a, b = clipper[k], clipper[(k + 1) % len(clipper)]
        inside = lambda p: (b[0] - a[0]) * (p[1] - a[1]) - (b[1] - a[1]) * (p[0] - a[0]) >= -1e-12  # noqa: E731
        src, out = out, []
        for i in range(len(src)):
            p, q = src[i], src[(i + 1) % len(src)]
            if inside(q):
                if not inside(p):
                    out.append(_intersect(p, q, a, b))
                out.append(q)
            elif inside(p):
                out.append(_intersect(p, q, a, b))
        if not out:
            return []
    return out


def _intersect(p, q, a, b):
    r, s = q - p, b - a
    t = ((a[0] - p[0]) * s[1] - (a[1] - p[1]) * s[0]) / (r[0] * s[1] - r[1] * s[0])
    return p + t * r


def _area(poly) -> float:
    if len(poly) < 3:
        return 0.0
    x, y = np.array(poly).T
    return 0.5 * float(np.dot(x, np.roll(y, -1)) - np.dot(y, np.roll(x, -1)))


def _inside_hull(point, points) -> bool:
    """Whether `point` lies in the convex hull of `points` (2-D), to 1e-9."""
    from scipy.spatial import ConvexHull, QhullError

    pts = np.asarray(points)
    try:
        hull = ConvexHull(pts)
    except (QhullError, ValueError):
        return False
    return bool(np.all(hull.equations[:, :2] @ point + hull.equations[:, 2] <= 1e-9))


def _solids(plan, i):
    """(name, p, R, half) of every block at slice i and every fixed box."""
    out = [(b.name, plan.p_WB[b.name][i], plan.R_WB[b.name][i], np.asarray(b.size) / 2) for b in plan.initial.blocks]
    out += [(f"{f.name}#{k}", np.asarray(f.p_WO), np.eye(3), np.asarray(f.size) / 2) for k, f in enumerate(plan.initial.fixed)]
    return out


def _supported(name, solids) -> str | None:
    """None when block `name` rests stably (on the table or on solids), else why not."""
    me = next(s for s in solids if s[0] == name)
    _, p, R, half = me
    bottom = p[2] - abs(R[2, :]) @ half
    if abs(bottom) <= CONTACT:
        return None
    mine = _footprint(p, R, half)
    contact = []
    for other, q, Q, h in solids:
        if other == name:
            continue
        top = q[2] + abs(Q[2, :]) @ h
        if abs(top - bottom) <= CONTACT:
            poly = _clip(mine, _footprint(q, Q, h))
            if _area(poly) > 1e-8:
                contact += poly
    if not contact:
        return f"{name} floats (bottom at {bottom * 1000:.1f} mm, nothing under it)"
    if not _inside_hull(p[:2], contact):
        return f"{name}'s centre of mass is outside its contact area"
    return None


def check_plan(plan, target) -> list[str]:
    """Every broken rule of a solved plan (lgp Plan: t, p_WB, R_WB, actions, initial), [] if none."""
    problems = []
    names = plan.initial.names
    n = len(plan.t)
    # one hand: at most one block moves between two slices
    moves = np.array([[np.linalg.norm(plan.p_WB[b][i + 1] - plan.p_WB[b][i]) > 1e-7 for b in names] for i in range(n - 1)])
    if len(moves) and moves.sum(axis=1).max() > 1:
        i = int(np.argmax(moves.sum(axis=1)))
        problems.append(f"two blocks move at once at slice {i}: {[b for b, m in zip(names, moves[i]) if m]}")
    # blocks move only when the plan's actions say so: between a Grasp and the Place of the same block
    S = int(round(1.0 / plan.tau))
    held = np.zeros((n, len(names)), bool)
    grasped = {}
    for k, action in enumerate(plan.actions, start=1):
        kind = type(action).__name__
        if kind == "Grasp":
            if grasped:
                problems.append(f"action {k} {action}: the hand already holds {list(grasped)}")
            grasped[action.block] = k
        else:
            g = grasped.pop(action.block, None)
            if g is None:
                problems.append(f"action {k} {action}: {action.block} is not in the hand")
                continue
            held[g * S:k * S + 1, names.index(action.block)] = True
    for i in range(n - 1):
        for j, b in enumerate(names):
            if moves[i, j] and not (held[i, j] and held[i + 1, j]):
                problems.append(f"{b} moves at slice {i} without being held")
                break
    # no interpenetration at any slice; every block not in the hand supported
    moving_at = np.zeros((n, len(names)), bool)
    if len(moves):
        moving_at[1:] |= moves
        moving_at[:-1] |= moves
    for i in range(n):
        solids = _solids(plan, i)
        everyone = i % S == 0 or i == n - 1  # every pair at the actions' times, else the pairs with a moving block
        for a in range(len(solids)):
            for b in range(a + 1, len(solids)):
                if a >= len(names) and b >= len(names):
                    continue  # two fixed boxes
                if not everyone and not moving_at[i, a] and not (b < len(names) and moving_at[i, b]):
                    continue
                name_a, p_a, R_a, h_a = solids[a]
                name_b, p_b, R_b, h_b = solids[b]
                if np.linalg.norm(p_a - p_b) > np.linalg.norm(h_a) + np.linalg.norm(h_b):
                    continue
                depth = box_depth(p_a, R_a, h_a, p_b, R_b, h_b)
                if depth > DEPTH_TOLERANCE:
                    problems.append(f"slice {i}: {name_a} and {name_b} interpenetrate by {depth * 1000:.2f} mm")
        if everyone:
            for j, b in enumerate(names):
                if not held[i, j] or i == n - 1:
                    why = _supported(b, solids)
                    if why:
                        problems.append(f"slice {i}: {why}")
    # B built: every slot filled by a distinct block of its colour at its centre
    final = {b.name: plan.p_WB[b.name][-1] for b in plan.initial.blocks}
    colour = {b.name: b.colour for b in plan.initial.blocks}
    used = set()
    for slot in target.blocks:
        hits = [b for b, p in final.items() if np.linalg.norm(p - slot.p_WB) <= AT_SLOT and b not in used]
        if not hits:
            problems.append(f"slot {slot.name} of {target.label} is empty")
        elif colour[hits[0]] != slot.colour:
            problems.append(f"slot {slot.name} holds {hits[0]} ({colour[hits[0]]}), needs {slot.colour}")
        else:
            used.add(hits[0])
    return problems
