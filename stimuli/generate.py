"""Random construction trials, for scaling runs and for users who want more stimuli.

    python -m stimuli.generate --out DIR --count N --seed S

writes N trial files (format: stimuli/README.md) named ``G0001.yaml`` ... : every
block of A scattered on the table, B one of the structures below, built at the
build site S. Trial i draws its kind and size from ``default_rng([S, i])``, so the
same seed gives the same files, and the first N of a larger set are the same
N files.

| kind | B |
|---|---|
| tower | 2-12 blocks stacked |
| line | 2-10 blocks side by side |
| wall | 2-4 wide x 2-4 high |
| staircase | 2-4 columns of 1, 2, ... blocks |
| bridge | two pillars of 1-3 blocks 0.5 d apart, a block spanning them, maybe one on top |
| pyramid | rows of 2-4, 1-3, ... blocks, each block on the seam of two below |
| stack | 1-3 columns of 1-4 blocks, each block shifted at random by up to d/6 |

``--kind rearrange`` writes rearrangement tasks instead (``R0001.yaml`` ...), where
A's structures stand in B's way, so a plan must set blocks aside (lgp.search;
the paper's pipeline has no plan for them):

| kind | A -> B |
|---|---|
| reverse | a tower of 2-4 blocks of distinct colours at S, rebuilt in place upside down |
| swap | two towers of 1-3 blocks (one red, one blue) at y = -s and +s, trading places |
| rebuild | a tower of 3-5 coloured blocks at y = -s, rebuilt at y = +s with its colours in another order |

Each file is loaded back with the loader's checks (`stimuli.load_file`) and its B
is checked stable without noise by the risk model's own check
(`models.risk.check_stable`, a physics run at sigma = 0); a draw that fails
either is drawn again. That check needs the models, so this CLI is an
application-level module (like stimuli.sheet): the stimuli package itself
imports nothing above the ground floor.
"""
from __future__ import annotations

from lgp.atomic import write_text_atomic

import argparse
import os
import sys
from pathlib import Path

import numpy as np
import yaml

from lgp import cli
from lgp.errors import InputError
from lgp.paper import BLOCK_SIZE as d
from lgp.paper import BUILD_SITE

KINDS = ("tower", "line", "wall", "staircase", "bridge", "pyramid", "stack")
#: Rearrangement tasks (--kind rearrange): A's structures stand where B needs its blocks.
REARRANGE_KINDS = ("reverse", "swap", "rebuild")
#: Colours of rearrangement tasks' blocks.
PALETTE = ("red", "green", "blue", "yellow")
#: Scatter region of A (m), the same as the paper's trial files use.
REGION = {"x": [0.2, 0.55], "y": [-0.25, 0.25]}
#: Draws of one trial before giving up (a random stack can come out unstable).
_ATTEMPTS = 20


def _column(y: float, height: int, base: int = 0, x: float = 0.0) -> list[tuple[float, float, int]]:
    return [(x, y, base + k) for k in range(height)]


def structure(kind: str, rng: np.random.Generator) -> tuple[list[tuple[float, float, float]], str]:
    """Block centres (x, y, z) relative to the build site (z absolute) and a description."""
    cells: list[tuple[float, float, float]]  # (dx, dy, level)
    if kind == "tower":
        n = int(rng.integers(2, 13))
        cells, text = _column(0.0, n), f"{n}-block tower"
    elif kind == "line":
        n = int(rng.integers(2, 11))
        cells, text = [(0.0, (i - (n - 1) / 2) * d, 0) for i in range(n)], f"line of {n} blocks side by side"
    elif kind == "wall":
        w, h = int(rng.integers(2, 5)), int(rng.integers(2, 5))
        cells, text = [(0.0, (i - (w - 1) / 2) * d, k) for k in range(h) for i in range(w)], f"wall {w} wide x {h} high"
    elif kind == "staircase":
        k = int(rng.integers(2, 5))
        cells = [c for i in range(k) for c in _column((i - (k - 1) / 2) * d, i + 1)]
        text = f"staircase of {k} steps"
    elif kind == "bridge":
        h = int(rng.integers(1, 4))
        offset = 0.75 * d  # pillars 0.5 d apart, the lintel resting 0.25 d on each
        cells = _column(-offset, h) + _column(offset, h) + [(0.0, 0.0, h)]
        top = bool(rng.integers(0, 2))
        if top:
            cells.append((0.0, 0.0, h + 1))
        text = f"bridge on pillars of {h}" + (" with a block on top" if top else "")
    elif kind == "pyramid":
        base = int(rng.integers(2, 5))
        cells = [(0.0, (i - (base - k - 1) / 2) * d, k) for k in range(base) for i in range(base - k)]
        text = f"pyramid on a row of {base}"
    elif kind == "stack":
        cols = int(rng.integers(1, 4))
        cells = []
        for c in range(cols):
            y0 = (c - (cols - 1) / 2) * 2 * d  # one block's gap between columns
            dx = dy = 0.0
            for k in range(int(rng.integers(1, 5))):
                cells.append((dx, y0 + dy, k))
                dx += rng.uniform(-d / 6, d / 6)
                dy += rng.uniform(-d / 6, d / 6)
        text = f"random stack of {len(cells)} blocks in {cols} column{'s' if cols > 1 else ''}"
    else:
        raise InputError(f"unknown structure kind {kind!r} (known: {', '.join(KINDS)})")
    return [(x, y, d / 2 + level * d) for x, y, level in cells], text


def trial_data(index: int, seed: int, kind: str | None = None) -> dict:
    """The mapping of generated trial `index` (as written to its YAML file)."""
    rng = np.random.default_rng([seed, index])
    kind = kind or KINDS[int(rng.integers(len(KINDS)))]
    cells, text = structure(kind, rng)
    sx, sy = BUILD_SITE
    tid = f"G{index + 1:04d}"
    return {
        "id": tid,
        "dimension": f"generated: {kind}",
        "description": f"{len(cells)} scattered blocks -> {text}",
        "build_site": [float(sx), float(sy)],
        "provenance": {"generated": [f"python -m stimuli.generate --seed {seed}: trial {index + 1}, kind {kind}; "
                                     "B checked stable without noise (models.risk.check_stable)"]},
        "initial": {"scattered": {"count": len(cells), "region": REGION, "min_gap": 0.01, "clearance": 0.02}},
        "target": {"blocks": [{"name": f"b{k + 1}", "p_WB": [round(sx + x, 5), round(sy + y, 5), round(z, 5)]}
                              for k, (x, y, z) in enumerate(cells)]},
    }


def _tower(prefix: str, x: float, y: float, colours) -> list[dict]:
    return [{"name": f"{prefix}{k + 1}", "p_WB": [round(x, 5), round(y, 5), round(d / 2 + k * d, 5)], "colour": c}
            for k, c in enumerate(colours)]


def rearrange_data(index: int, seed: int, kind: str | None = None) -> dict:
    """The mapping of rearrangement task `index` (--kind rearrange), drawn from
    default_rng([seed, index]): its kind (REARRANGE_KINDS), size and colours."""
    rng = np.random.default_rng([seed, index])
    kind = kind or REARRANGE_KINDS[int(rng.integers(len(REARRANGE_KINDS)))]
    sx, sy = BUILD_SITE
    if kind == "reverse":
        n = int(rng.integers(2, 5))
        colours = [PALETTE[i] for i in rng.permutation(len(PALETTE))[:n]]
        A, B = _tower("a", sx, sy, colours), _tower("b", sx, sy, colours[::-1])
        text = f"{n}-block tower reversed in place"
    elif kind == "swap":
        h1, h2 = int(rng.integers(1, 4)), int(rng.integers(1, 4))
        s = float(rng.uniform(0.08, 0.14))
        A = _tower("r", sx, sy - s, ["red"] * h1) + _tower("u", sx, sy + s, ["blue"] * h2)
        B = _tower("b", sx, sy - s, ["blue"] * h2) + _tower("c", sx, sy + s, ["red"] * h1)
        text = f"red tower of {h1} and blue tower of {h2}, {2 * s:.2f} m apart, trading places"
    elif kind == "rebuild":
        n = int(rng.integers(3, 6))
        s = float(rng.uniform(0.08, 0.14))
        colours = [PALETTE[i] for i in rng.integers(0, 3, n)]
        while len(set(colours)) < 2:
            colours = [PALETTE[i] for i in rng.integers(0, 3, n)]
        order = list(colours)
        while order == colours:
            order = [colours[i] for i in rng.permutation(n)]
        A, B = _tower("a", sx, sy - s, colours), _tower("b", sx, sy + s, order)
        text = f"{n}-block tower rebuilt {2 * s:.2f} m away in another colour order"
    else:
        raise InputError(f"unknown rearrangement kind {kind!r} (known: {', '.join(REARRANGE_KINDS)})")
    return {
        "id": f"R{index + 1:04d}",
        "dimension": f"generated rearrangement: {kind}",
        "description": text,
        "build_site": [float(sx), float(sy)],
        "provenance": {"generated": [f"python -m stimuli.generate --kind rearrange --seed {seed}: task {index + 1}, "
                                     f"kind {kind}; B checked stable without noise (models.risk.check_stable)"]},
        "initial": {"blocks": A},
        "target": {"blocks": B},
    }


def write_trial(data: dict, directory: Path) -> Path:
    path = directory / f"{data['id']}.yaml"
    write_text_atomic(f"# Generated trial {data['id']}: {data['description']}\n"
                      + yaml.safe_dump(data, sort_keys=False, default_flow_style=None), path)
    return path


def generate(directory: str | Path, count: int, seed: int = 0, engine: str | None = None,
             kind: str = "scatter") -> list[Path]:
    """Write `count` valid, statically stable random trials into `directory`:
    scattered blocks -> a structure (kind "scatter"), or rearrangement tasks
    (kind "rearrange", `rearrange_data`)."""
    import stimuli
    from models.risk import check_stable
    from models.risk.core import UnstableSceneError

    if count < 1:
        raise InputError(f"count must be >= 1, got {count}")
    if count > cli.MAX_TRIAL_COUNT:
        raise InputError(f"count {count:,} is more than the {cli.MAX_TRIAL_COUNT:,} allowed (lgp.cli.MAX_TRIAL_COUNT)")
    if kind not in ("scatter", "rearrange"):
        raise InputError(f"kind must be scatter or rearrange, got {kind!r}")
    directory = Path(directory)
    prefix = "R" if kind == "rearrange" else "G"
    # A file of the user's with one of our names is never replaced (nor deleted when a
    # draw turns out unstable): refuse before any work, naming the files.
    taken = [f"{prefix}{i + 1:04d}.yaml" for i in range(count)
             if os.path.lexists(directory / f"{prefix}{i + 1:04d}.yaml")]
    if taken:
        listed = ", ".join(taken[:3]) + (f" and {len(taken) - 3} more" if len(taken) > 3 else "")
        raise InputError(f"{directory} already holds {listed}: choose an empty or new folder "
                         f"(this command never replaces a file it did not write in this call)")
    directory.mkdir(parents=True, exist_ok=True)
    paths = []
    for i in range(count):
        for attempt in range(_ATTEMPTS):
            # a redraw uses its own stream: trial i's first draw does not depend on the attempts of others
            draw = rearrange_data if kind == "rearrange" else trial_data
            data = draw(i, seed if attempt == 0 else seed + 1_000_003 * attempt)
            data["id"] = f"{prefix}{i + 1:04d}"
            path = write_trial(data, directory)
            try:
                trial = stimuli.load_file(path)
                check_stable(trial.target, engine)
            except (stimuli.StimulusError, UnstableSceneError):
                path.unlink()
                continue
            paths.append(path)
            break
        else:
            raise RuntimeError(f"trial {i + 1}: no valid, stable draw in {_ATTEMPTS} attempts")
    return paths


def main(argv=None) -> int:
    p = cli.parser("python -m stimuli.generate", description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--out", required=True, help="directory for the trial files (created if missing)")
    p.add_argument("--count", type=cli.bounded_count("MAX_TRIAL_COUNT"), required=True, help="number of trials (at most %d)" % cli.MAX_TRIAL_COUNT)
    p.add_argument("--seed", type=int, default=0)
    p.add_argument("--engine", help="engine of the stability check (default: the risk model's)")
    p.add_argument("--kind", choices=("scatter", "rearrange"), default="scatter",
                   help="scatter: scattered blocks -> a structure (default); rearrange: A's structures in B's way")
    args = p.parse_args(argv)
    if args.count < 1:
        p.error(f"--count must be >= 1, got {args.count}")
    try:
        paths = generate(args.out, args.count, args.seed, args.engine, args.kind)
    except (OSError, RuntimeError, ValueError) as e:
        p.exit(1, f"{p.prog}: error: {e}\n")
    planner = " --planner search" if args.kind == "rearrange" else ""
    print(f"wrote {len(paths)} trials to {Path(args.out).resolve()} (python -m lgp.reproduce --stimuli {args.out}{planner})")
    return 0


if __name__ == "__main__":
    sys.exit(main())
