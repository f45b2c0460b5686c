"""State A of a trial: the blocks whose poses the trial fixes, plus blocks scattered
at random anew for each sample (`StartState`, `ScatterRegion`), and the cheap
bound that refuses a region too small for them whatever the draw (`room_check`)."""
from __future__ import annotations

import time
from collections import Counter
from dataclasses import dataclass, replace

import numpy as np

from lgp.paper import BLOCK_SIZE, BUILD_SITE
from lgp.scene import Block, FixedBox, Scene, StimulusError, bounding_boxes, horizontal_penetration

#: Attempts to place one scattered block before the whole layout is redrawn, and
#: redraws before the region is declared too small.
_TRIES_PER_BLOCK = 2000
_LAYOUT_REDRAWS = 50
#: Seconds one layout of scattered blocks may take before the trial is declared
#: too crowded (a machine-independent bound would be a count of tries; this one
#: says in one line how long it searched, instead of searching for minutes).
SCATTER_SECONDS = 30.0
#: Largest |coordinate| (m) a scatter region may have.
MAX_REGION_EXTENT = 1000.0


@dataclass(frozen=True)
class ScatterRegion:
    """Where scattered blocks may lie: a rectangle in x, y, optionally limited to a
    band of distances r_S from the build site S."""

    x: tuple[float, float]
    y: tuple[float, float]
    r_S: tuple[float, float] | None = None

    def contains(self, p, build_site) -> bool:
        inside = self.x[0] <= p[0] <= self.x[1] and self.y[0] <= p[1] <= self.y[1]
        if inside and self.r_S is not None:
            r = float(np.hypot(p[0] - build_site[0], p[1] - build_site[1]))
            inside = self.r_S[0] <= r <= self.r_S[1]
        return inside


@dataclass(frozen=True)
class StartState:
    """State A: blocks of fixed structures, plus blocks scattered at random.

    `blocks` are the blocks whose poses the trial fixes (structures, the bucket's
    contents); `scattered` are (name, colour) of blocks drawn anew for each sample,
    uniformly in `region`, with random yaw, at least `min_gap` (m) from each other
    and at least `clearance` (m) from the target's footprint and fixed structures.
    `recolour` = (count, colour): that many of `blocks`, chosen at random per sample,
    take that colour (pair 12's blue/red blocks in the bucket).
    """

    label: str
    blocks: tuple[Block, ...]
    fixed: tuple[FixedBox, ...]
    scattered: tuple[tuple[str, str], ...] = ()
    region: ScatterRegion | None = None
    min_gap: float = 0.01
    clearance: float = 0.02
    recolour: tuple[int, str] | None = None
    build_site: tuple[float, float] = BUILD_SITE
    keep_clear: tuple = ()

    @property
    def is_random(self) -> bool:
        return bool(self.scattered) or self.recolour is not None

    def colour_counts(self) -> Counter:
        """Most blocks of each colour a sample can hold."""
        counts = Counter(c for _, c in self.scattered) + Counter(b.colour for b in self.blocks)
        if self.recolour:
            n, c = self.recolour
            counts[c] += n
        return counts

    def sample(self, rng: np.random.Generator) -> Scene:
        """A concrete layout of A; the same Generator state gives the same layout."""
        blocks = list(self.blocks)
        if self.scattered:
            blocks += self._scatter(rng)
        if self.recolour:
            n, colour = self.recolour
            chosen = set(rng.choice(len(self.blocks), size=n, replace=False).tolist())
            blocks = [replace(b, colour=colour) if i in chosen else b for i, b in enumerate(blocks)]
        return Scene(blocks, self.fixed, self.label).validate()

    def check_room(self, obstacles: bool = False) -> None:
        """Raise StimulusError at once when the region cannot hold the scattered
        blocks whatever the draw (`room_check`); with `obstacles`, the footprints
        of the fixed blocks, the fixed boxes and the target's blocks (which the
        scattered ones keep `clearance` from) are taken out of the room too."""
        if not self.scattered:
            return
        room_check(self.label, len(self.scattered), self.region, self.min_gap, self.clearance,
                   [*self.blocks, *self.fixed, *self.keep_clear] if obstacles else ())

    def _scatter(self, rng: np.random.Generator) -> list[Block]:
        self.check_room()
        d = BLOCK_SIZE
        obstacles = [*self.blocks, *self.fixed, *self.keep_clear]
        obs_lo, obs_hi = bounding_boxes(obstacles)  # broad phase against the fixed things
        # Spatial hash of the blocks placed so far: a candidate is tested only
        # against blocks in the 3 x 3 cells around it (cells wider than any two
        # inflated outlines can reach), so a layout costs O(n), not O(n^2).
        cell = np.sqrt(2) * (d + 2 * self.min_gap)
        t0, best = time.monotonic(), 0
        for redraw in range(_LAYOUT_REDRAWS):
            placed: list[Block] = []
            grid: dict[tuple[int, int], list[Block]] = {}
            for name, colour in self.scattered:
                if time.monotonic() - t0 > SCATTER_SECONDS:
                    raise StimulusError(
                        f"{self.label}: cannot scatter {len(self.scattered)} blocks in region {self.region}: no layout "
                        f"found in {SCATTER_SECONDS:g} s (at most {max(best, len(placed))} placed, {redraw + 1} "
                        f"draw(s)): the region is too crowded (stimuli.start.SCATTER_SECONDS bounds the search)")
                for _ in range(_TRIES_PER_BLOCK):
                    p = np.array([rng.uniform(*self.region.x), rng.uniform(*self.region.y), d / 2])
                    yaw = rng.uniform(0.0, np.pi / 2)  # a cube looks the same every quarter turn
                    if not self.region.contains(p, self.build_site):
                        continue
                    # Inflate the candidate: gaps are measured between outlines.
                    cand_gap = Block(name, p, yaw, colour, size=np.full(3, d + 2 * self.min_gap))
                    cand_clear = Block(name, p, yaw, colour, size=np.full(3, d + 2 * self.clearance))
                    ci, cj = int(np.floor(p[0] / cell)), int(np.floor(p[1] / cell))
                    near = [o for a in (ci - 1, ci, ci + 1) for b in (cj - 1, cj, cj + 1) for o in grid.get((a, b), ())]
                    if any(horizontal_penetration(cand_gap, o) > 0 for o in near):
                        continue
                    reach = (d / 2 + self.clearance) * (abs(np.cos(yaw)) + abs(np.sin(yaw))) + 1e-12  # half-width of its outline box
                    hits = np.nonzero((obs_lo[:, 0] <= p[0] + reach) & (p[0] - reach <= obs_hi[:, 0])
                                      & (obs_lo[:, 1] <= p[1] + reach) & (p[1] - reach <= obs_hi[:, 1]))[0]
                    if any(horizontal_penetration(cand_clear, obstacles[j]) > 0 for j in hits):
                        continue
                    block = Block(name, p, yaw, colour)
                    placed.append(block)
                    grid.setdefault((ci, cj), []).append(block)
                    break
                else:
                    break
            if len(placed) == len(self.scattered):
                return placed
            best = max(best, len(placed))
        raise StimulusError(f"{self.label}: cannot scatter {len(self.scattered)} blocks in region {self.region} "
                            f"(no layout found in {_LAYOUT_REDRAWS} redraws of {_TRIES_PER_BLOCK} tries per block: too small or too crowded)")


def room_check(label: str, n: int, region: ScatterRegion, min_gap: float, clearance: float, obstacles=()) -> None:
    """Raise StimulusError when `n` blocks cannot be scattered in `region` whatever
    the draw; cheap, so it runs before anything of size `n` is built.

    The blocks' outlines, each grown by g/2 (g = min_gap), are disjoint and lie in
    the region's rectangle grown by d/sqrt(2) + g/2 (centres lie in the
    rectangle), so their total area cannot exceed that grown rectangle's (nor,
    with r_S, the grown annulus'). With `obstacles` (things the blocks keep
    `clearance` c from): the outlines grown by h = min(g/2, c) are disjoint from
    each other and from every obstacle's footprint, so they fit in the grown
    rectangle minus the area the obstacles cover there (a lower bound of that
    area: footprints of pairwise disjoint bounding boxes, clipped to it)."""
    r, d, g = region, BLOCK_SIZE, min_gap
    bounds = [*r.x, *r.y, *(r.r_S or ())]
    if not all(np.isfinite(bounds)) or not np.isfinite(r.x[1] - r.x[0]) or not np.isfinite(r.y[1] - r.y[0]):
        raise StimulusError(f"{label} scattered region: bounds must be finite numbers (x {r.x}, y {r.y}, r_S {r.r_S})")
    if max(abs(v) for v in bounds) > MAX_REGION_EXTENT:
        raise StimulusError(f"{label} scattered region: bounds beyond {MAX_REGION_EXTENT:g} m from the origin "
                            f"(x {r.x}, y {r.y}, r_S {r.r_S}): a table top is not that large, and block outlines "
                            "lose their millimetre precision there")
    if r.x[0] > r.x[1] or r.y[0] > r.y[1] or (r.r_S is not None and not 0 <= r.r_S[0] <= r.r_S[1]):
        raise StimulusError(f"{label} scattered region: each range must be [min, max] with min <= max (x {r.x}, y {r.y}, r_S {r.r_S})")
    if not (np.isfinite(g) and g >= 0 and np.isfinite(clearance) and clearance >= 0):
        raise StimulusError(f"{label} scattered: min_gap and clearance must be finite and >= 0 (got {g}, {clearance})")
    grow = d / np.sqrt(2) + g / 2
    rect = (r.x[1] - r.x[0] + 2 * grow) * (r.y[1] - r.y[0] + 2 * grow)
    room = rect
    if r.r_S is not None:
        room = min(room, np.pi * ((r.r_S[1] + grow) ** 2 - max(0.0, r.r_S[0] - grow) ** 2))
    need = n * (d * d + 2 * d * g + np.pi * g * g / 4)
    if need > room:
        raise StimulusError(f"{label}: cannot scatter {n} blocks in region {r}: they need at least "
                            f"{need:.4g} m^2 with min_gap {g:g} m, the region offers at most {room:.4g} m^2 (too small)")
    if len(obstacles):
        h = min(g / 2, clearance)
        grow_h = d / np.sqrt(2) + h
        box = np.array([[r.x[0] - grow_h, r.y[0] - grow_h], [r.x[1] + grow_h, r.y[0] - grow_h],
                        [r.x[1] + grow_h, r.y[1] + grow_h], [r.x[0] - grow_h, r.y[1] + grow_h]])
        taken = _covered_area(obstacles, box)
        free = (r.x[1] - r.x[0] + 2 * grow_h) * (r.y[1] - r.y[0] + 2 * grow_h) - taken
        need_h = n * (d * d + 4 * d * h + np.pi * h * h)
        if need_h > free:
            raise StimulusError(f"{label}: cannot scatter {n} blocks in region {r}: they need at least {need_h:.4g} m^2 "
                                f"(clearance {clearance:g} m, min_gap {g:g} m), the region offers at most {free:.4g} m^2 "
                                f"once the {taken:.4g} m^2 covered by the target's blocks and the fixed things are taken "
                                "out (too small)")


def _covered_area(solids, box: np.ndarray) -> float:
    """A lower bound of the area of `box` (a CCW rectangle, (4, 2)) the solids'
    footprints cover: the footprints of a greedy set of solids whose bounding
    boxes (seen from above) do not overlap, each clipped to `box`."""
    from lgp.geometry import clip_convex, polygon_area
    from lgp.scene import box_pairs

    solids = list(solids)
    if not solids:
        return 0.0
    lo, hi = bounding_boxes(solids)
    lo, hi = lo[:, :2], hi[:, :2]
    blo, bhi = box.min(axis=0), box.max(axis=0)
    inside = np.flatnonzero(np.all((lo < bhi) & (blo < hi), axis=1))
    if not len(inside):
        return 0.0
    i, j = box_pairs(lo[inside], hi[inside], lo[inside], hi[inside], True, margin=-1e-9)
    neighbours: dict[int, list[int]] = {}
    for a, b in zip(i.tolist(), j.tolist()):
        neighbours.setdefault(b, []).append(a)  # a < b
    chosen = np.zeros(len(inside), bool)
    area = 0.0
    for k in range(len(inside)):
        if any(chosen[a] for a in neighbours.get(k, ())):
            continue
        chosen[k] = True
        P = clip_convex(solids[inside[k]].footprint(), box)
        area += abs(polygon_area(P)) if len(P) >= 3 else 0.0
    return area
