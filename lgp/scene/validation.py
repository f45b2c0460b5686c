"""The checks a stimulus state must pass before anything plans or simulates on it
(stimuli/README.md): finite solids in the workspace, known colours, unique names,
no overlap, nothing floating; and the colours a target needs more of than a start has."""
from __future__ import annotations

from collections import Counter

import numpy as np

from lgp.paper import COLOURS
from lgp.scene.overlap import box_pairs, solid_outlines, resting_candidates, sat_depths, may_penetrate, penetration, rests_on
from lgp.scene.solids import CONTACT_TOLERANCE, OVERLAP_TOLERANCE, SOLID_SIZE, WORKSPACE_XY, WORKSPACE_Z, StimulusError


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
    cb, lob, hib = solid_outlines(blocks)
    cf, lof, hif = solid_outlines(fixed)
    # The first overlap in the order of a pairwise scan (block i against blocks
    # j > i, then against fixed boxes), over the pairs the broad phase lets
    # through and a vectorised depth does not rule out; the scalar check decides.
    overlaps = []
    for kind, others, C, lo, hi, same in (("", blocks, cb, lob, hib, True), ("fixed ", fixed, cf, lof, hif, False)):
        i, j = box_pairs(lob, hib, lo, hi, same)
        vertical = np.minimum(hib[i, 2], hi[j, 2]) - np.maximum(lob[i, 2], lo[j, 2])
        keep = may_penetrate(vertical, sat_depths(cb[i], C[j]) if len(i) else vertical)
        overlaps += [((a, int(kind != ""), c), blocks[a], others[c], kind) for a, c in zip(i[keep].tolist(), j[keep].tolist())]
    for _, a, b, kind in sorted(overlaps, key=lambda o: o[0]):
        depth = penetration(a, b)
        if depth > OVERLAP_TOLERANCE:
            raise StimulusError(f"{label} block {a.name} overlaps {kind}{b.name} by {depth * 1000:.1f} mm")
    below = resting_candidates(blocks, fixed, CONTACT_TOLERANCE)
    for i, b in enumerate(blocks):
        on_table = abs(b.bottom) <= CONTACT_TOLERANCE
        if not on_table and not any(rests_on(b, o) for o in below[i]):
            raise StimulusError(
                f"{label} block {b.name}: floats (bottom at z = {b.bottom * 1000:.1f} mm rests on neither the table nor another solid)"
            )


def colour_shortfall(initial: Scene, target: Scene) -> dict[str, tuple[int, int]]:
    """Colours the target needs more of than the start has: {colour: (needed, available)}."""
    have = Counter(b.colour for b in initial.blocks)
    need = Counter(b.colour for b in target.blocks)
    return {c: (n, have[c]) for c, n in need.items() if n > have[c]}
