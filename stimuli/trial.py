"""A trial (`Trial`: start state A, target state B, where facts come from) and how
one is built and validated from the mapping of a trial file (`parse_trial`; every
field read by a typed reader that names the trial, block and rule broken)."""
from __future__ import annotations

import hashlib
import re
from collections import Counter
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from lgp.paper import BLOCK_SIZE, BUILD_SITE
from lgp.scene import SOLID_SIZE, WORKSPACE_XY, Block, FixedBox, Scene, StimulusError, colour_shortfall
from stimuli.reading import read_trial_bytes
from stimuli.start import ScatterRegion, StartState, room_check

TRIAL_ID = re.compile(r"^(\d+)([EH])$")
#: Id of a trial that belongs to no pair (a user's or generated stimulus, e.g. G0001).
FREE_ID = re.compile(r"^[A-Z][A-Z0-9_-]{0,63}$")

_TRIAL_KEYS = {"id", "pair", "level", "dimension", "description", "build_site", "provenance", "fixed", "initial", "target"}
_INITIAL_KEYS = {"blocks", "scattered", "recolour"}
_SCATTER_KEYS = {"count", "colour", "colours", "region", "min_gap", "clearance", "prefix"}
_BLOCK_KEYS = {"name", "p_WB", "yaw", "colour", "size"}
#: Most blocks a state (A or B) of a trial may hold: the paper's trials have at most
#: 26, a generated one a few dozen. Checking a 10,000-block trial takes 29 s and
#: MuJoCo cannot allocate it, so a larger count is refused before any block is read.
MAX_BLOCKS = 500


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


def _trial_id(data: dict, path: Path | None) -> tuple[str, int | None, str | None]:
    """(id, pair, level) of a trial file: a paper-style id <pair><E|H> whose pair and
    level fields agree with it, or a free name (of no pair) without them."""
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
    return tid, pair, level


def _scattered(tid: str, s: dict, n_listed: int) -> tuple[tuple, ScatterRegion, dict]:
    """(names and colours, region, {min_gap, clearance}) of A's scattered blocks,
    checked: the region inside the workspace, the gaps in range, and the room for
    the count before any list of that length is made; `n_listed` blocks are listed besides."""
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
        colours = [_text(f"{where} colours", c) for c in _blocks(where, s["colours"], n_listed, "colours")]
    else:
        count = _integer(f"{where} count", s.get("count", 0), 0)
        # the room first: a count of 10**12 must not become a list of 10**12 colours
        room_check(f"{tid}-A", count, region, kw.get("min_gap", StartState.min_gap),
                   kw.get("clearance", StartState.clearance))
        _too_many(where, count + n_listed, "count")
        colours = [_text(f"{where} colour", s.get("colour", "natural"))] * count
    prefix = _text(f"{where} prefix", s.get("prefix", "s"))
    scattered = tuple((f"{prefix}{i + 1}", c) for i, c in enumerate(colours))
    return scattered, region, kw


def _recolour(tid: str, rc: dict, n_listed: int) -> tuple[int, str]:
    """(count, colour) of A's listed blocks to recolour: at most the `n_listed` listed."""
    _check_keys(f"{tid}-A recolour", rc, {"count", "colour"})
    if "count" not in rc or "colour" not in rc:
        raise StimulusError(f"{tid}-A recolour: needs count and colour")
    recolour = (_integer(f"{tid}-A recolour count", rc["count"], 0), _text(f"{tid}-A recolour colour", rc["colour"]))
    if recolour[0] > n_listed:
        raise StimulusError(f"{tid}-A recolour: {recolour[0]} blocks asked, only {n_listed} listed")
    return recolour


def parse_trial(data: dict, path: Path | None = None) -> Trial:
    """Build and validate a Trial from the mapping in a trial file."""
    where = str(data.get("id", path)) if isinstance(data, dict) else str(path)
    _check_keys(where, data, _TRIAL_KEYS)
    tid, pair, level = _trial_id(data, path)
    fixed = _fixed(f"{tid} fixed", data.get("fixed"))
    build_site = tuple(_vector(f"{tid} build_site", data.get("build_site", list(BUILD_SITE)), 2))
    if not (np.all(np.isfinite(build_site)) and np.all(np.abs(build_site) <= WORKSPACE_XY)):
        raise StimulusError(f"{tid} build_site: {[float(v) for v in build_site]} must lie inside the workspace |x|, |y| <= {WORKSPACE_XY:g} m")

    target_data = data.get("target") or {}
    _check_keys(f"{tid}-B", target_data, {"blocks"})
    target = Scene([_block(f"{tid}-B", b) for b in _blocks(f"{tid}-B", target_data.get("blocks", []))], fixed, f"{tid}-B").validate()
    if not target.blocks:
        raise StimulusError(f"{tid}-B: the target has no blocks")

    init = data.get("initial") or {}
    _check_keys(f"{tid}-A", init, _INITIAL_KEYS)
    fixed_blocks = tuple(_block(f"{tid}-A", b) for b in _blocks(f"{tid}-A", init.get("blocks", [])))
    Scene(fixed_blocks, fixed, f"{tid}-A").validate()
    scattered, region, kw = _scattered(tid, init["scattered"], len(fixed_blocks)) if "scattered" in init else ((), None, {})
    recolour = _recolour(tid, init["recolour"], len(fixed_blocks)) if "recolour" in init else None
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


def _too_many(where: str, n: int, what: str = "blocks") -> None:
    if n > MAX_BLOCKS:
        raise StimulusError(f"{where} {what}: {n} blocks in one state, more than the {MAX_BLOCKS} allowed "
                            "(stimuli.trial.MAX_BLOCKS; the paper's trials have at most 26)")


def _blocks(where: str, value, already: int = 0, what: str = "blocks") -> list:
    """A list of blocks (or of their colours) of one state, at most MAX_BLOCKS with
    the `already` listed: counted before any block is read or checked."""
    items = _list(f"{where} {what}", value)
    _too_many(where, len(items) + already, what)
    return items


def _list(where: str, value) -> list:
    if not isinstance(value, list):
        raise StimulusError(f"{where}: expected a list, got {value!r}")
    return value
