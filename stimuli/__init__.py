"""The 24 construction trials of the paper (Figure 1) as data files, and their loader.

Each trial is a YAML file in ``stimuli/trials/`` (format: ``stimuli/README.md``).
``load_trial("7H")`` returns a validated :class:`Trial`; ``load_paper()`` the paper's
24 trials (lgp.paper.TRIAL_IDS) in order 1E, 1H, ..., 12H; ``load_all()`` those plus
any extra trial file a user drops in (sorted after). Every loader takes a
``directory`` (default ``stimuli/trials``) to read another set of trial files.
"""
from __future__ import annotations

import hashlib
import os
from collections import Counter
import re
import time
from dataclasses import dataclass, field, replace
from pathlib import Path

import numpy as np
import yaml

from lgp.paper import BLOCK_SIZE, BUILD_SITE, TRIAL_IDS, canonical_trial_id
from lgp.scene import (SOLID_SIZE, WORKSPACE_XY, Block, FixedBox, Scene, StimulusError, bounding_boxes, colour_shortfall,
                       horizontal_penetration)

TRIAL_DIR = Path(__file__).parent / "trials"
TRIAL_ID = re.compile(r"^(\d+)([EH])$")
#: Id of a trial that belongs to no pair (a user's or generated stimulus, e.g. G0001).
FREE_ID = re.compile(r"^[A-Z][A-Z0-9_-]{0,63}$")

#: Attempts to place one scattered block before the whole layout is redrawn, and
#: redraws before the region is declared too small.
_TRIES_PER_BLOCK = 2000
_LAYOUT_REDRAWS = 50
#: Seconds one layout of scattered blocks may take before the trial is declared
#: too crowded (a machine-independent bound would be a count of tries; this one
#: says in one line how long it searched, instead of searching for minutes).
SCATTER_SECONDS = 30.0
#: Largest trial file read (bytes): a 10,000-block trial is about 0.6 MB.
MAX_TRIAL_BYTES = 2_000_000
#: Largest |coordinate| (m) a scatter region may have.
MAX_REGION_EXTENT = 1000.0

_TRIAL_KEYS = {"id", "pair", "level", "dimension", "description", "build_site", "provenance", "fixed", "initial", "target"}
_INITIAL_KEYS = {"blocks", "scattered", "recolour"}
_SCATTER_KEYS = {"count", "colour", "colours", "region", "min_gap", "clearance", "prefix"}
_BLOCK_KEYS = {"name", "p_WB", "yaw", "colour", "size"}


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
                        f"draw(s)): the region is too crowded (stimuli.SCATTER_SECONDS bounds the search)")
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
    from lgp.scene import _box_pairs

    solids = list(solids)
    if not solids:
        return 0.0
    lo, hi = bounding_boxes(solids)
    lo, hi = lo[:, :2], hi[:, :2]
    blo, bhi = box.min(axis=0), box.max(axis=0)
    inside = np.flatnonzero(np.all((lo < bhi) & (blo < hi), axis=1))
    if not len(inside):
        return 0.0
    i, j = _box_pairs(lo[inside], hi[inside], lo[inside], hi[inside], True, margin=-1e-9)
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


@dataclass(frozen=True)
class Trial:
    """One construction task: start state A, target state B, and where facts come from."""

    id: str
    pair: int | None  # None: the trial belongs to no easy/hard pair
    level: str | None
    dimension: str
    description: str
    initial: StartState
    target: Scene
    provenance: dict = field(default_factory=dict)
    path: Path | None = None
    sha256: str = ""  # of the file's bytes as read and parsed (load_file)

    def sample_initial(self, rng: np.random.Generator) -> Scene:
        """Draw a concrete A (scattered blocks at random), validated."""
        return self.initial.sample(rng)

    @property
    def digest(self) -> str:
        """Hash of the trial file's bytes: keys caches of results computed from it."""
        if self.sha256:
            return self.sha256[:16]
        return hashlib.sha256(read_trial_bytes(self.path)).hexdigest()[:16] if self.path else ""

    def __repr__(self) -> str:
        return f"Trial({self.id}: {self.description})"


# ----------------------------------------------------------------------------- parsing


def _check_keys(where: str, data: dict, allowed: set[str]) -> None:
    if not isinstance(data, dict):
        raise StimulusError(f"{where}: expected a mapping, got {type(data).__name__}")
    unknown = set(data) - allowed
    if unknown:
        raise StimulusError(f"{where}: unknown field(s) {', '.join(sorted(unknown))} (allowed: {', '.join(sorted(allowed))})")


def _vector(where: str, value, n: int) -> np.ndarray:
    if not isinstance(value, (list, tuple)) or len(value) != n:
        raise StimulusError(f"{where}: expected {n} numbers, got {value!r}")
    return np.array([_number(where, v) for v in value], dtype=float)


def _number(where: str, value) -> float:
    """A real number from a YAML field, or a StimulusError naming the field.

    Text that reads as a number is accepted: YAML 1.1 (PyYAML) reads ``1e-3``
    without a dot as a string."""
    if isinstance(value, str):
        try:
            value = float(value)
        except ValueError:
            raise StimulusError(f"{where}: expected a number, got {value!r}") from None
    if isinstance(value, bool) or not isinstance(value, (int, float)):
        raise StimulusError(f"{where}: expected a number, got {value!r}")
    return float(value)  # finiteness is a rule of the scene or region it belongs to, checked there


def _integer(where: str, value, minimum: int | None = None) -> int:
    """A whole number from a YAML field (no strings, no fractions), at least `minimum`."""
    if isinstance(value, bool) or not isinstance(value, int):
        raise StimulusError(f"{where}: expected a whole number, got {value!r}")
    if minimum is not None and value < minimum:
        raise StimulusError(f"{where}: must be >= {minimum}, got {value}")
    return int(value)


def _text(where: str, value) -> str:
    if not isinstance(value, (str, int, float)) or isinstance(value, bool):
        raise StimulusError(f"{where}: expected text, got {value!r}")
    return str(value)


def _range(where: str, value) -> tuple[float, float]:
    if not isinstance(value, (list, tuple)) or len(value) != 2:
        raise StimulusError(f"{where}: expected [min, max], got {value!r}")
    return (_number(where, value[0]), _number(where, value[1]))


def _block(where: str, data: dict) -> Block:
    _check_keys(where, data, _BLOCK_KEYS)
    if "name" not in data or "p_WB" not in data:
        raise StimulusError(f"{where}: a block needs a name and p_WB")
    name = _text(f"{where} block name", data["name"])
    where = f"{where} block {name}"
    size = _vector(where + " size", data.get("size", [BLOCK_SIZE] * 3), 3)
    return Block(name, _vector(where + " p_WB", data["p_WB"], 3), _number(where + " yaw", data.get("yaw", 0.0)),
                 _text(where + " colour", data.get("colour", "natural")), size)


def _fixed(where: str, data: list) -> tuple[FixedBox, ...]:
    boxes = []
    if data is not None and not isinstance(data, list):
        raise StimulusError(f"{where}: expected a list of obstacles, got {data!r}")
    for obstacle in data or []:
        _check_keys(where, obstacle, {"name", "boxes"})
        if "name" not in obstacle or not isinstance(obstacle.get("boxes"), list):
            raise StimulusError(f"{where}: an obstacle needs a name and a list of boxes")
        name = _text(f"{where} name", obstacle["name"])
        for k, box in enumerate(obstacle["boxes"]):
            at = f"{where} {name} box {k + 1}"
            _check_keys(at, box, {"p_WO", "size"})
            if "p_WO" not in box or "size" not in box:
                raise StimulusError(f"{at}: a box needs p_WO and size")
            boxes.append(FixedBox(name, _vector(at + " p_WO", box["p_WO"], 3), _vector(at + " size", box["size"], 3)))
    return tuple(boxes)


def parse_trial(data: dict, path: Path | None = None) -> Trial:
    """Build and validate a Trial from the mapping in a trial file."""
    where = str(data.get("id", path)) if isinstance(data, dict) else str(path)
    _check_keys(where, data, _TRIAL_KEYS)
    tid = str(data.get("id", ""))
    m = TRIAL_ID.match(tid)
    if m:
        if _integer(f"{tid} pair", data.get("pair", -1)) != int(m.group(1)) or data.get("level") != m.group(2):
            raise StimulusError(f"{tid}: pair/level fields disagree with the id")
        pair, level = int(m.group(1)), m.group(2)
    elif FREE_ID.match(tid):
        if "pair" in data or "level" in data:
            raise StimulusError(f"{tid}: pair and level need an id of the form <pair><E|H> (e.g. 7H); {tid!r} is a trial of no pair")
        pair, level = None, None
    else:
        raise StimulusError(f"{path}: trial id {tid!r} is neither of the form <pair><E|H> (e.g. 7H) nor a name of "
                            "capital letters, digits, _ and - starting with a letter (e.g. G0001; ids are upper case)")
    fixed = _fixed(f"{tid} fixed", data.get("fixed"))
    build_site = tuple(_vector(f"{tid} build_site", data.get("build_site", list(BUILD_SITE)), 2))
    if not (np.all(np.isfinite(build_site)) and np.all(np.abs(build_site) <= WORKSPACE_XY)):
        raise StimulusError(f"{tid} build_site: {[float(v) for v in build_site]} must lie inside the workspace |x|, |y| <= {WORKSPACE_XY:g} m")

    target_data = data.get("target") or {}
    _check_keys(f"{tid}-B", target_data, {"blocks"})
    target = Scene([_block(f"{tid}-B", b) for b in _list(f"{tid}-B blocks", target_data.get("blocks", []))], fixed, f"{tid}-B").validate()
    if not target.blocks:
        raise StimulusError(f"{tid}-B: the target has no blocks")

    init = data.get("initial") or {}
    _check_keys(f"{tid}-A", init, _INITIAL_KEYS)
    fixed_blocks = tuple(_block(f"{tid}-A", b) for b in _list(f"{tid}-A blocks", init.get("blocks", [])))
    Scene(fixed_blocks, fixed, f"{tid}-A").validate()
    scattered, region, kw = (), None, {}
    if "scattered" in init:
        s = init["scattered"]
        _check_keys(f"{tid}-A scattered", s, _SCATTER_KEYS)
        where = f"{tid}-A scattered"
        r = s.get("region") or {}
        _check_keys(f"{where} region", r, {"x", "y", "r_S"})
        if "x" not in r or "y" not in r:
            raise StimulusError(f"{where} region: needs x: [min, max] and y: [min, max]")
        region = ScatterRegion(_range(f"{where} region x", r["x"]), _range(f"{where} region y", r["y"]),
                               _range(f"{where} region r_S", r["r_S"]) if "r_S" in r else None)
        kw = {k: _number(f"{where} {k}", s[k]) for k in ("min_gap", "clearance") if k in s}
        for k, v in kw.items():
            if not 0.0 <= v <= SOLID_SIZE[1]:
                raise StimulusError(f"{tid}-A scattered {k}: {v} m must lie in [0, {SOLID_SIZE[1]:g}] m")
        bounds = [*region.x, *region.y, *(region.r_S or ())]
        if not (np.all(np.isfinite(bounds)) and np.all(np.abs(bounds[:4]) <= WORKSPACE_XY)
                and region.x[0] <= region.x[1] and region.y[0] <= region.y[1]):
            raise StimulusError(f"{tid}-A scattered region: x {region.x}, y {region.y} must be finite ranges "
                                f"[min, max] inside the workspace |x|, |y| <= {WORKSPACE_XY:g} m")
        if "colours" in s:
            colours = [_text(f"{where} colours", c) for c in _list(f"{where} colours", s["colours"])]
        else:
            count = _integer(f"{where} count", s.get("count", 0), 0)
            # the room first: a count of 10**12 must not become a list of 10**12 colours
            room_check(f"{tid}-A", count, region, kw.get("min_gap", StartState.min_gap),
                       kw.get("clearance", StartState.clearance))
            colours = [_text(f"{where} colour", s.get("colour", "natural"))] * count
        prefix = _text(f"{where} prefix", s.get("prefix", "s"))
        scattered = tuple((f"{prefix}{i + 1}", c) for i, c in enumerate(colours))
    recolour = None
    if "recolour" in init:
        rc = init["recolour"]
        _check_keys(f"{tid}-A recolour", rc, {"count", "colour"})
        if "count" not in rc or "colour" not in rc:
            raise StimulusError(f"{tid}-A recolour: needs count and colour")
        recolour = (_integer(f"{tid}-A recolour count", rc["count"], 0), _text(f"{tid}-A recolour colour", rc["colour"]))
        if recolour[0] > len(fixed_blocks):
            raise StimulusError(f"{tid}-A recolour: {recolour[0]} blocks asked, only {len(fixed_blocks)} listed")
    names = [b.name for b in fixed_blocks] + [n for n, _ in scattered]
    dup = {n for n in names if names.count(n) > 1}
    if dup:
        raise StimulusError(f"{tid}-A: duplicate block name {sorted(dup)[0]!r}")
    start = StartState(f"{tid}-A", fixed_blocks, fixed, scattered, region, recolour=recolour, build_site=build_site, keep_clear=target.blocks, **kw)
    start.check_room(obstacles=True)  # the target's footprint and the fixed things take room too

    have = start.colour_counts()
    for colour, need in Counter(b.colour for b in target.blocks).items():
        if need > have.get(colour, 0):
            raise StimulusError(f"{tid}-B: needs {need} {colour} blocks but {tid}-A has {have.get(colour, 0)}")
    trial = Trial(tid, pair, level, str(data.get("dimension", "")), str(data.get("description", "")), start, target, data.get("provenance") or {}, path)
    # One draw proves the region can hold the scattered blocks and A is valid.
    sample = trial.sample_initial(np.random.default_rng(0))
    if colour_shortfall(sample, target):
        raise StimulusError(f"{tid}: a sample of A lacks colours for B: {colour_shortfall(sample, target)}")
    return trial


def _list(where: str, value) -> list:
    if not isinstance(value, list):
        raise StimulusError(f"{where}: expected a list, got {value!r}")
    return value


class _TrialLoader(yaml.SafeLoader):
    """YAML's safe loader without anchors and aliases: a trial file never needs
    them, and aliases let a few lines expand into gigabytes ("billion laughs")."""

    def compose_node(self, parent, index):
        _refuse_anchors(self.name, self.peek_event())
        return super().compose_node(parent, index)


def _refuse_anchors(where: str, event) -> None:
    if isinstance(event, yaml.AliasEvent) or getattr(event, "anchor", None) is not None:
        raise StimulusError(f"{where}: line {event.start_mark.line + 1}: YAML anchors and aliases (&name, *name) "
                            "are not allowed in trial files")


def _check_events(where: str, events) -> None:
    """One pass over the parse events, before anything is built: no anchors or
    aliases, and no key given twice in one mapping (YAML would keep the last value
    silently; a trial file that says ``count`` twice is a mistake)."""
    stack: list[list] = []  # per open collection: [keys seen (None for a sequence), next node is a key]
    for event in events:
        _refuse_anchors(where, event)
        if isinstance(event, (yaml.ScalarEvent, yaml.MappingStartEvent, yaml.SequenceStartEvent)):
            top = stack[-1] if stack else None
            if top is not None and top[0] is not None:
                if top[1] and isinstance(event, yaml.ScalarEvent):
                    if event.value in top[0]:
                        raise StimulusError(f"{where}: line {event.start_mark.line + 1}: key {event.value!r} given twice "
                                            f"in one mapping (first on line {top[0][event.value]}); each field once")
                    top[0][event.value] = event.start_mark.line + 1
                top[1] = not top[1]
            if isinstance(event, yaml.MappingStartEvent):
                stack.append([{}, True])
            elif isinstance(event, yaml.SequenceStartEvent):
                stack.append([None, False])
        elif isinstance(event, (yaml.MappingEndEvent, yaml.SequenceEndEvent)):
            stack.pop()


def _at(mark) -> str:
    return f"line {mark.line + 1}, column {mark.column + 1}"


def yaml_error_line(e: yaml.YAMLError) -> str:
    """A YAML error as one line that keeps its position ("not valid YAML at line 8,
    column 11: mapping values are not allowed here"); PyYAML's own text spreads the
    position over further lines, which a one-line CLI error would cut off."""
    problem = getattr(e, "problem", None)
    mark = getattr(e, "problem_mark", None)
    if not problem or mark is None:
        return "not valid YAML: " + " ".join(str(e).split())
    text = f"not valid YAML at {_at(mark)}: {problem}"
    context, context_mark = getattr(e, "context", None), getattr(e, "context_mark", None)
    if context:
        text += f" ({context}" + (f" at {_at(context_mark)}" if context_mark is not None else "") + ")"
    return text


def _safe_load(text: str, where: str):
    """yaml.safe_load without anchors, aliases or duplicate keys; libyaml's C parser
    when present (a first pass over the parse events refuses them before anything
    is built)."""
    if getattr(yaml, "__with_libyaml__", False):
        _check_events(where, yaml.parse(text, Loader=yaml.CSafeLoader))
        return yaml.load(text, Loader=yaml.CSafeLoader)
    _check_events(where, yaml.parse(text, Loader=yaml.SafeLoader))
    loader = _TrialLoader(text)
    loader.name = where
    try:
        return loader.get_single_data()
    finally:
        loader.dispose()


def read_trial_bytes(path: str | Path) -> bytes:
    """The bytes of a trial file: a regular file of at most MAX_TRIAL_BYTES, read
    through the one bounded reader (lgp.inputs: no FIFO, device or endless file)."""
    from lgp.inputs import InputFileError, read_bounded

    try:
        return read_bounded(path, MAX_TRIAL_BYTES, "trial file", limit_name="stimuli.MAX_TRIAL_BYTES")
    except InputFileError as e:
        raise StimulusError(str(e)) from None


def load_file(path: str | Path, data: bytes | None = None) -> Trial:
    """Read, parse and validate one trial file (at most MAX_TRIAL_BYTES; `data`:
    its bytes, already read)."""
    path = Path(path)
    data = read_trial_bytes(path) if data is None else data
    try:
        text = data.decode("utf-8")
    except UnicodeDecodeError as e:
        raise StimulusError(f"{path}: cannot read the trial file as UTF-8 text ({e})") from None
    try:
        fields = _safe_load(text, str(path))
    except yaml.YAMLError as e:
        raise StimulusError(f"{path}: {yaml_error_line(e)}") from None
    if not isinstance(fields, dict):
        raise StimulusError(f"{path}: a trial file is a mapping of fields (id, pair, level, initial, target, ...), got {type(fields).__name__}")
    trial = parse_trial(fields, path)
    return replace(trial, sha256=hashlib.sha256(data).hexdigest())


def _sort_key(tid: str):
    m = TRIAL_ID.match(tid)
    return (int(m.group(1)), m.group(2)) if m else (10**6, tid)


def trial_ids(directory: str | Path | None = None) -> list[str]:
    """Ids of every trial file in `directory` (default ``stimuli/trials``), in order."""
    directory = TRIAL_DIR if directory is None else Path(directory)
    return sorted((p.stem for p in directory.glob("*.yaml")), key=_sort_key)


_cache: dict[tuple[str, str], Trial] = {}


def load_trial(trial_id: str, directory: str | Path | None = None) -> Trial:
    """The trial ``trial_id`` (e.g. ``"7H"``; case-insensitive, ``"7h"`` too) from `directory` (default
    ``stimuli/trials``), validated."""
    directory = TRIAL_DIR if directory is None else Path(directory)
    trial_id = canonical_trial_id(trial_id)
    path = directory / f"{trial_id}.yaml"
    if not path.exists():
        if path.is_symlink():
            raise StimulusError(f"no trial {trial_id!r}: {path} is a symbolic link to {os.readlink(path)}, which does not exist")
        misnamed = [p.name for p in directory.glob("*.yaml") if p.stem.upper() == trial_id and p.stem != trial_id]
        if misnamed:
            raise StimulusError(f"no trial {trial_id!r}: {directory} has {misnamed[0]}, but a trial file is named by its "
                                f"id in upper case: rename it {trial_id}.yaml")
        raise StimulusError(f"no trial {trial_id!r}: {path} does not exist (known: {', '.join(trial_ids(directory))})")
    data = read_trial_bytes(path)
    key = (str(path), hashlib.sha256(data).hexdigest())
    if key not in _cache:
        trial = load_file(path, data)
        if trial.id != trial_id:
            raise StimulusError(f"{path}: file name says {trial_id} but the id field says {trial.id}")
        _cache[key] = trial
    return _cache[key]


def load_all(directory: str | Path | None = None) -> list[Trial]:
    """Every trial in `directory`: 1E, 1H, ..., 12H, then any others (e.g. a
    user's 13E). The paper's set alone is `load_paper`."""
    return [load_trial(t, directory) for t in trial_ids(directory)]


def load_paper(directory: str | Path | None = None) -> list[Trial]:
    """The paper's 24 trials (lgp.paper.TRIAL_IDS, in the paper's order) from
    `directory`, ignoring any other trial file there."""
    return [load_trial(t, directory) for t in TRIAL_IDS]


def extra_ids(directory: str | Path | None = None) -> list[str]:
    """Ids of the trial files in `directory` that are not among the paper's 24."""
    return [t for t in trial_ids(directory) if t not in TRIAL_IDS]


def select_trials(ids: list[str] | None = None, directory: str | Path | None = None) -> tuple[list[Trial], list[str]]:
    """The trials of a run and the ids of the trial files it leaves out.

    With no `ids`: the paper's 24 from the default folder (the other trial files
    there are left out and returned, for the caller to name), or every trial file
    of `directory` when one is given. ``["all"]``: every trial file. Otherwise the
    trials named. Raises StimulusError for a `directory` with no trial files.
    """
    if not ids and directory is not None:  # a user's stimulus set: every trial file in it
        if not trial_ids(directory):
            raise StimulusError(f"--stimuli {directory}: no trial files (*.yaml) there")
        return load_all(directory), []
    if not ids:
        return load_paper(directory), extra_ids(directory)
    if [t.lower() for t in ids] == ["all"]:
        return load_all(directory), []
    return [load_trial(t, directory) for t in ids], []


def declared_pairs(trials) -> list[int]:
    """The pairs whose easy and hard trials (ids ``<pair>E``, ``<pair>H``) are both among `trials`."""
    ids = {t.id for t in trials}
    return sorted({t.pair for t in trials if t.pair is not None and {f"{t.pair}E", f"{t.pair}H"} <= ids})
