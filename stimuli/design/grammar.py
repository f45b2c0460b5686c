"""A grammar of construction tasks: target structures B beyond the paper's, with
continuous offsets, and start states A (scattered near or far, a structure to
relocate, a structure half built).

Candidate `index` of seed `S` is drawn from ``numpy.random.default_rng([S, index])``
alone, so the same (seed, index) gives the same candidate wherever it is drawn,
and the first N candidates of a larger pool are the same N.

| kind | B (every block a 1-inch cube, yaw 0) | continuous parameters |
|---|---|---|
| staircase | a column whose every level steps by dx sideways | dx in [0.05, 0.35] d |
| zigzag | a column whose levels alternate +a, -a | a in [0.1, 0.48] d |
| bridge | two pillars of h, gap g, a lintel, 0-2 blocks on it | g in [0.1, 0.9] d, top offsets |
| cantilever | a column, then blocks stepping out by o each, maybe a counterweight | o in [0.1, 0.5] d |
| tee | a row of w on the table and a column on one of its blocks (an inverted T), or a T in plan | column offset |
| wall | w wide x h high, rows shifted by a running bond | bond in [0, 0.5] d |
| row | n blocks in a line with gaps | gap in [0, 0.4] d |
| pile | a row of k, then blocks laid on the seams at random | seam offsets |
| arch | two pillars, corbels stepping inward by c, a keystone | c in [0.1, 0.45] d, gap |
| precarious | an aligned column with its top block offset by p | p in [0.25, 0.49] d |

| start | A |
|---|---|
| near | every block of B scattered 4-14 cm from the build site S |
| far | every block scattered 24-40 cm from S |
| anywhere | scattered over the paper's region (stimuli/trials) |
| relocate | B's structure standing elsewhere on the table (8-30 cm away in y) |
| partial | B's bottom level already in place, the rest scattered |

A candidate is a `Candidate` (the trial file's mapping and its features); it is
only a proposal: `stimuli.design.checks` loads it with the project's trial rules,
checks it stands and plans, and counts every discard by its reason.
"""
from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from lgp.paper import BLOCK_SIZE as d
from lgp.paper import BUILD_SITE
from lgp.errors import InputError

KINDS = ("staircase", "zigzag", "bridge", "cantilever", "tee", "wall", "row", "pile", "arch", "precarious")
STARTS = ("near", "far", "anywhere", "relocate", "partial")
#: The scatter region of A, as the paper's trial files (x, y in m).
REGION = {"x": [0.2, 0.55], "y": [-0.25, 0.25]}
#: Bands of distance to S (m) of the near and far starts (the spec's pair 2: 4-10 cm, 25-40 cm).
NEAR = [0.04, 0.14]
FAR = [0.24, 0.40]
#: Paper's most blocks in a trial B (7E, 7H: 10): the default block budget.
MAX_BLOCKS = 10


@dataclass(frozen=True)
class Candidate:
    """One proposed trial: `data` is the trial file's mapping (stimuli/README.md),
    `kind` and `start` name its grammar rule, `params` its drawn parameters."""

    index: int
    kind: str
    start: str
    data: dict
    params: dict = field(default_factory=dict)

    @property
    def id(self) -> str:
        return self.data["id"]


def _col(x: float, y: float, h: int, base: int = 0) -> list[tuple[float, float, int]]:
    return [(x, y, base + k) for k in range(h)]


#: Kinds drawn along x below and turned to run across the view (along y): the
#: pictures look from the agent's side (-x), so an offset in depth would not show.
ACROSS = ("staircase", "zigzag", "bridge", "cantilever", "arch", "precarious")


def structure(kind: str, rng: np.random.Generator, budget: int = MAX_BLOCKS) -> tuple[list[tuple[float, float, int]], str, dict]:
    """Cells (dx, dy, level) of B relative to S, a description and the drawn
    parameters. Offsets, spans and overhangs run across the view (y), where a
    person looking at the picture sees them."""
    cells, text, params = _structure(kind, rng, budget)
    if kind in ACROSS:
        cells = [(y, x, lv) for x, y, lv in cells]
    return cells, text, params


def _n_in(rng: np.random.Generator, b: int, lo: int, hi: int) -> int:
    """A count in [lo, min(hi, b)] (b: the block budget)."""
    hi = min(hi, b)
    return int(rng.integers(min(lo, hi), hi + 1))


def _staircase(rng: np.random.Generator, b: int) -> tuple[list, str, dict]:
    """A column whose every level steps dx sideways."""
    h, dx = _n_in(rng, b, 2, 10), float(rng.uniform(0.05, 0.35)) * d
    cells = [(k * dx - (h - 1) * dx / 2, 0.0, k) for k in range(h)]
    return cells, f"staircase column of {h}, each level {dx / d:.2f} d further to the side", {"h": h, "step": dx / d}


def _zigzag(rng: np.random.Generator, b: int) -> tuple[list, str, dict]:
    """A column whose levels alternate +a, 0."""
    h, a = _n_in(rng, b, 3, 10), float(rng.uniform(0.1, 0.48)) * d
    cells = [((a if k % 2 else 0.0), 0.0, k) for k in range(h)]
    return cells, f"zig-zag column of {h}, alternate levels {a / d:.2f} d out", {"h": h, "offset": a / d}


def _bridge(rng: np.random.Generator, b: int) -> tuple[list, str, dict]:
    """Two pillars of h, gap g, a lintel, 0-2 blocks on it."""
    h = _n_in(rng, b, 1, max(1, (b - 1) // 2))
    g = float(rng.uniform(0.1, 0.9)) * d
    off = (g + d) / 2
    cells = _col(-off, 0.0, h) + _col(off, 0.0, h) + [(0.0, 0.0, h)]
    tops = int(rng.integers(0, 3)) if len(cells) < b else 0
    tops = min(tops, b - len(cells))
    shift = 0.0
    for k in range(tops):
        shift += float(rng.uniform(-0.3, 0.3)) * d
        cells.append((shift, 0.0, h + 1 + k))
    return cells, f"bridge: pillars of {h}, gap {g / d:.2f} d, lintel and {tops} on top", {"h": h, "gap": g / d, "tops": tops}


def _cantilever(rng: np.random.Generator, b: int) -> tuple[list, str, dict]:
    """A column, then blocks stepping out by o each, maybe a counterweight on top."""
    base = _n_in(rng, b, 1, max(1, b - 2))
    steps = int(rng.integers(1, max(2, min(4, b - base) + 1)))
    o = float(rng.uniform(0.1, 0.5)) * d
    cells = _col(0.0, 0.0, base)
    x = 0.0
    for k in range(steps):
        x += o
        cells.append((x, 0.0, base + k))
    counter = bool(rng.integers(0, 2)) and len(cells) < b
    if counter:
        cells.append((x - float(rng.uniform(0.3, 0.8)) * d, 0.0, base + steps))
    return cells, (f"cantilever: column of {base}, {steps} blocks stepping out {o / d:.2f} d each"
                   + (", a counterweight on top" if counter else "")), {"base": base, "steps": steps, "step": o / d,
                                                                           "counterweight": counter}


def _tee(rng: np.random.Generator, b: int) -> tuple[list, str, dict]:
    """An inverted T (a row, a column on one of its blocks) or a T in plan."""
    if rng.integers(0, 2) and b >= 3:  # inverted T in elevation: a row, a column on one of its blocks
        w = _n_in(rng, b, 2, 4)
        h = int(rng.integers(1, max(2, min(6, b - w) + 1))) if b > w else 0
        on = int(rng.integers(0, w))
        shift = float(rng.uniform(-0.3, 0.3)) * d
        y0 = -(w - 1) * d / 2
        cells = [(0.0, y0 + i * d, 0) for i in range(w)]
        cells += [(0.0, y0 + on * d + shift, 1 + k) for k in range(h)]
        return cells, f"inverted T: a row of {w}, a column of {h} on block {on + 1} shifted {shift / d:.2f} d", \
            {"w": w, "h": h, "shift": shift / d}
    w, s = _n_in(rng, b, 3, 5), int(rng.integers(1, 4))
    s = max(0, min(s, b - w))
    y0 = -(w - 1) * d / 2
    cells = [(0.0, y0 + i * d, 0) for i in range(w)] + [(-(k + 1) * d, 0.0 if w % 2 else y0 + (w // 2) * d, 0) for k in range(s)]
    layer2 = min(int(rng.integers(0, 3)), b - len(cells))
    cells += [(0.0, y0 + i * d, 1) for i in range(layer2)]
    return cells, f"T in plan: a bar of {w}, a stem of {s}, {layer2} on the bar", {"w": w, "stem": s, "layer2": layer2}


def _wall(rng: np.random.Generator, b: int) -> tuple[list, str, dict]:
    """w wide x h high, rows shifted by a running bond."""
    w = _n_in(rng, b, 2, 4)
    h = int(rng.integers(1, max(2, b // w) + 1)) if b >= w else 1
    h = max(1, min(h, b // w))
    bond = float(rng.uniform(0.0, 0.5)) * d
    cells = [(0.0, (i - (w - 1) / 2) * d + (bond if k % 2 else 0.0), k) for k in range(h) for i in range(w)]
    return cells, f"wall {w} wide x {h} high, running bond {bond / d:.2f} d", {"w": w, "h": h, "bond": bond / d}


def _row(rng: np.random.Generator, b: int) -> tuple[list, str, dict]:
    """n blocks in a line with gaps, away from the viewer or across."""
    n, gap = _n_in(rng, b, 2, 10), float(rng.uniform(0.0, 0.4)) * d
    along_x = bool(rng.integers(0, 2))
    pitch = d + gap
    cells = [(((i - (n - 1) / 2) * pitch, 0.0, 0) if along_x else (0.0, (i - (n - 1) / 2) * pitch, 0)) for i in range(n)]
    return cells, f"row of {n} {'away from you' if along_x else 'across'}, gaps {gap / d:.2f} d", \
        {"n": n, "gap": gap / d, "along_x": along_x}


def _pile(rng: np.random.Generator, b: int) -> tuple[list, str, dict]:
    """A row of k, blocks laid on its seams at random, maybe one on top."""
    k = _n_in(rng, b, 2, 5)
    y0 = -(k - 1) * d / 2
    cells = [(0.0, y0 + i * d, 0) for i in range(k)]
    upper = min(int(rng.integers(1, k + 1)), b - k)
    seams = rng.permutation(k - 1)[:upper] if k > 1 else []
    for s in sorted(seams):
        cells.append((float(rng.uniform(-0.2, 0.2)) * d, y0 + (s + 0.5) * d + float(rng.uniform(-0.25, 0.25)) * d, 1))
    if len(cells) < b and len(seams) >= 1 and rng.integers(0, 2):
        top = cells[-1]
        cells.append((top[0] + float(rng.uniform(-0.3, 0.3)) * d, top[1] + float(rng.uniform(-0.3, 0.3)) * d, 2))
    return cells, f"pile: a row of {k}, {len(cells) - k} laid on seams", {"k": k, "upper": len(cells) - k}


def _arch(rng: np.random.Generator, b: int) -> tuple[list, str, dict]:
    """Two pillars, corbels stepping inward by c, a keystone."""
    h = _n_in(rng, b, 1, max(1, (b - 3) // 2))
    g = float(rng.uniform(1.0, 1.8)) * d  # the opening: too wide for one lintel
    c = float(rng.uniform(0.1, 0.45)) * d
    off = (g + d) / 2
    cells = _col(-off, 0.0, h) + _col(off, 0.0, h) + [(-off + c, 0.0, h), (off - c, 0.0, h)]
    cells.append((0.0, 0.0, h + 1))
    return cells, f"arch: pillars of {h}, opening {g / d:.2f} d, corbels {c / d:.2f} d in, a keystone", \
        {"h": h, "gap": g / d, "corbel": c / d}


def _precarious(rng: np.random.Generator, b: int) -> tuple[list, str, dict]:
    """An aligned column with its top block offset by p."""
    h = _n_in(rng, b, 2, 10)
    p = float(rng.uniform(0.25, 0.49)) * d
    cells = _col(0.0, 0.0, h - 1) + [(p, 0.0, h - 1)]
    return cells, f"column of {h - 1} with a top block {p / d:.2f} d over the edge", {"h": h, "top_offset": p / d}


#: The rule of each structure kind: (rng, budget) -> (cells along x, description, parameters).
RULES = {"staircase": _staircase, "zigzag": _zigzag, "bridge": _bridge, "cantilever": _cantilever, "tee": _tee,
         "wall": _wall, "row": _row, "pile": _pile, "arch": _arch, "precarious": _precarious}


def _structure(kind: str, rng: np.random.Generator, budget: int = MAX_BLOCKS) -> tuple[list[tuple[float, float, int]], str, dict]:
    """`structure` as drawn (the ACROSS kinds along x); a draw may exceed the
    budget (the screen's check discards it)."""
    rule = RULES.get(kind)
    if rule is None:
        raise InputError(f"unknown structure kind {kind!r} (known: {', '.join(KINDS)})")
    return rule(rng, max(1, int(budget)))

def _blocks(cells, x0: float, y0: float, prefix: str) -> list[dict]:
    return [{"name": f"{prefix}{k + 1}", "p_WB": [round(float(x0 + x), 5), round(float(y0 + y), 5), round(float(d / 2 + lv * d), 5)]}
            for k, (x, y, lv) in enumerate(cells)]


def draw(index: int, seed: int, budget: int = MAX_BLOCKS, kinds=KINDS, starts=STARTS, prefix: str = "C") -> Candidate:
    """Candidate `index` of `seed`: its kind and start state, then its parameters,
    all from default_rng([seed, index]). Trial id ``<prefix><index+1:05d>``."""
    rng = np.random.default_rng([seed, index])
    kind = kinds[int(rng.integers(len(kinds)))]
    start = starts[int(rng.integers(len(starts)))]
    cells, text, params = structure(kind, rng, budget)
    sx, sy = BUILD_SITE
    target = _blocks(cells, sx, sy, "b")
    initial: dict = {}
    scatter = {"region": dict(REGION), "min_gap": 0.01, "clearance": 0.02}
    if start in ("near", "far"):
        initial["scattered"] = {"count": len(cells), **scatter,
                                "region": {**REGION, "r_S": list(NEAR if start == "near" else FAR)}}
        what = f"{len(cells)} blocks scattered {'near' if start == 'near' else 'far from'} S"
    elif start == "anywhere":
        initial["scattered"] = {"count": len(cells), **scatter}
        what = f"{len(cells)} blocks scattered"
    elif start == "relocate":
        dist = float(rng.uniform(0.08, 0.30)) * (1 if rng.integers(0, 2) else -1)
        params = {**params, "relocate": dist}
        initial["blocks"] = _blocks(cells, sx, sy + dist, "a")
        what = f"the structure standing {abs(dist) * 100:.0f} cm {'left' if dist > 0 else 'right'}"
    elif start == "partial":
        bottom = [c for c in cells if c[2] == 0]
        rest = len(cells) - len(bottom)
        if rest == 0:  # nothing above the bottom level: half the row in place
            bottom = bottom[: max(1, len(bottom) // 2)]
            rest = len(cells) - len(bottom)
        initial["blocks"] = _blocks(bottom, sx, sy, "a")
        if rest:
            initial["scattered"] = {"count": rest, **scatter}
        what = f"{len(bottom)} of B's blocks in place, {rest} scattered"
    else:
        raise InputError(f"unknown start {start!r} (known: {', '.join(STARTS)})")
    tid = f"{prefix}{index + 1:05d}"
    data = {
        "id": tid,
        "dimension": f"designed: {kind}, start {start}",
        "description": f"{what} -> {text}",
        "build_site": [float(sx), float(sy)],
        "provenance": {"generated": [f"stimuli.design grammar, seed {seed}, candidate {index + 1}: kind {kind}, start {start}"]},
        "initial": initial,
        "target": {"blocks": target},
    }
    return Candidate(index, kind, start, data, {k: (round(v, 4) if isinstance(v, float) else v) for k, v in params.items()})
