"""The counterfactual fall measure in the authors' exact engine: box2dweb 2.1.0 (the
JavaScript port of Box2D 2.1a their Node simulator ran), driven through Node by
models/box2dweb/jenga.js, a JavaScript port of models/box2d_engine.py's protocol
(the same steps, with the same references to the authors' code/js/brick_world.js
and brick_tools.js).

pybox2d (models/box2d_engine.py) wraps Box2D 2.3, whose contact points differ from
2.1a's enough to change which bricks the black one carries in four scenes of
experiment 2 (25, 26, 33, 35): the carried set decides which bricks the authors'
noise leaves awake, and in 26 and 35 pybox2d loses no brick where the authors'
runs lose about 3.5. In box2dweb the authors' own outputs are reproduced run for
run (jenga.js's `authors_seed` mode: their seedrandom(0) stream and gaussian; the
first 100 runs of every scene of experiment 2 at level 8 are identical to their
saved file, tests/test_box2dweb_engine.py checks a few).

With the project's noise (Box2DNoise: numpy normals, common across sigma) one
Node process runs every start of a scene (`runs`): all sigmas and runs at once.
A run stops early once a step leaves every brick asleep and unmoved, a fixed point
of Box2D's step (jenga.js `settle`); measured to change no run (docs/mental-jenga.md).

Needs Node.js (`node` on PATH) and the two npm packages in models/box2dweb
(`npm ci --prefix models/box2dweb`); without them a world raises InputError with
that one-line hint.
"""
from __future__ import annotations

import hashlib
import json
import shutil
import subprocess
from pathlib import Path

import numpy as np

from lgp.errors import InputError
from models.box2d_engine import Box2DNoise, authors_xy
from stimuli.mental_jenga import JengaScene

#: The folder of the Node side: jenga.js, package.json, package-lock.json, node_modules/.
ENGINE_DIR = Path(__file__).resolve().parent / "box2dweb"
#: The Node executable looked up on PATH.
NODE = "node"
#: The npm packages jenga.js needs (exact versions: package-lock.json).
PACKAGES = ("box2dweb", "seedrandom")
#: The install hint, one line.
INSTALL_HINT = ("the box2dweb engine needs Node.js (node on PATH) and its npm packages: "
                "npm ci --prefix models/box2dweb")
#: The early stop of a run (jenga.js `settle`): on by default; off runs every one of the 700 steps.
EARLY_STOP = True
__all__ = ["Box2DWebJengaWorld", "Box2DNoise", "node_command", "node_version", "box2dweb_missing", "engine_versions", "run_batch"]


def node_command() -> list[str]:
    """[node, jenga.js], or InputError with the install hint when node or the
    packages are missing."""
    node = shutil.which(NODE)
    if node is None:
        raise InputError(f"{INSTALL_HINT} (no {NODE!r} found)")
    missing = [p for p in PACKAGES if not (ENGINE_DIR / "node_modules" / p / "package.json").is_file()]
    if missing:
        raise InputError(f"{INSTALL_HINT} (missing: {', '.join(missing)})")
    return [node, str(ENGINE_DIR / "jenga.js")]


def box2dweb_missing() -> str | None:
    """None when the engine can run, else the one-line install hint (what is missing)."""
    try:
        node_command()
    except InputError as e:
        return str(e)
    return None


def engine_versions() -> dict:
    """What the Node side's output depends on, for cache keys: a digest of jenga.js
    and the locked versions of its packages (package-lock.json)."""
    lock = json.loads((ENGINE_DIR / "package-lock.json").read_text())
    pkgs = lock.get("packages", {})
    return {"jenga.js": hashlib.sha256((ENGINE_DIR / "jenga.js").read_bytes()).hexdigest()[:16],
            **{p: pkgs.get(f"node_modules/{p}", {}).get("version", "not locked") for p in PACKAGES}}


def node_version() -> str:
    """`node --version` (cache keys: V8's Math.log and Math.sqrt enter the authors' gaussian)."""
    out = subprocess.run([node_command()[0], "--version"], capture_output=True, text=True)
    return out.stdout.strip() or f"unknown (exit {out.returncode})"


def run_batch(scenes: list[dict], early_stop: bool = EARLY_STOP) -> list[dict]:
    """One Node process for a batch of scenes (jenga.js's input format, its header):
    per scene {"label", "fallen": [[file indices], ...], "steps"}."""
    cmd = node_command()
    payload = json.dumps({"early_stop": bool(early_stop), "scenes": scenes})
    out = subprocess.run(cmd, input=payload.encode(), capture_output=True, cwd=ENGINE_DIR)
    if out.returncode != 0:
        tail = out.stderr.decode(errors="replace").strip().splitlines()[-1:] or ["no message"]
        raise RuntimeError(f"models/box2dweb/jenga.js exited with {out.returncode}: {tail[0]}")
    return json.loads(out.stdout)["scenes"]


def file_bricks(scene: JengaScene) -> tuple[np.ndarray, np.ndarray]:
    """((m, 3), (n,)): x, y (down), angle of every brick of the scene's file in file
    order, parked ones included, exactly as read (the authors create and destroy
    parked bricks, which the broad-phase remembers), and the file index of each of
    the scene's bricks. Falls back to the scene's own bricks (authors_xy, in scene
    order) when the scene does not carry its file's bricks or was changed since."""
    xya = authors_xy(scene)
    raw = np.array(scene.authors_bricks, float).reshape(-1, 3)
    idx = np.array([b.index for b in scene.bricks])
    if len(raw) and idx.max() < len(raw) and np.allclose(raw[idx], xya, rtol=0, atol=1e-9):
        return raw, idx
    return xya, np.arange(len(xya))


class Box2DWebJengaWorld:
    """One scene for box2dweb runs, the authors' protocol (models/box2d_engine.py's
    docstring; a fresh world per run, as theirs). Attributes n, scene, black as the
    other engines'. `runs(starts)` simulates many starts in one Node process;
    `run(start)` one."""

    def __init__(self, scene: JengaScene, settings=None):
        node_command()  # the install hint now, not after the noise is drawn
        self.scene, self.settings = scene, settings
        self.n = len(scene.bricks)
        self.black = np.array([b.black for b in scene.bricks])
        self.bricks_a, self.file_index = file_bricks(scene)
        self.position = {int(k): i for i, k in enumerate(self.file_index)}
        self.black_file = int(self.file_index[np.flatnonzero(self.black)[0]])

    def _scene(self, **what) -> dict:
        return {"label": self.scene.label, "bricks": self.bricks_a.tolist(), "black": self.black_file,
                "table_friction": float(self.scene.table_friction), **what}

    def _fallen(self, ids) -> np.ndarray:
        f = np.zeros(self.n, bool)
        f[[self.position[int(k)] for k in ids]] = True
        return f & ~self.black

    def batch(self, starts) -> dict:
        """The scene with its starts (each (n, 3) as Box2DNoise.positions gives, or
        None: no noise) in jenga.js's input format."""
        runs = []
        for start in starts:
            dx = np.zeros(len(self.bricks_a))
            sleep = False
            if start is not None:
                dx[self.file_index] = start[:, 0]
                sleep = bool(np.any(start[:, 1] > 0))
            runs.append({"dx": dx.tolist(), "sleep": sleep})
        return self._scene(runs=runs)

    def fallen(self, result: dict) -> list[np.ndarray]:
        """(n,) bools per run of jenga.js's result for this scene."""
        return [self._fallen(ids) for ids in result["fallen"]]

    def runs(self, starts, early_stop: bool = EARLY_STOP) -> list[np.ndarray]:
        """One Node process for every start (batch). Returns (n,) bools per start."""
        (res,) = run_batch([self.batch(starts)], early_stop)
        return self.fallen(res)

    def run(self, start: np.ndarray | None = None) -> np.ndarray:
        """One counterfactual run: (n,) bools, True for a red brick that fell."""
        return self.runs([start])[0]

    def authors_seed(self, levels, n_runs: int, early_stop: bool = EARLY_STOP) -> dict[int, list[list[int]]]:
        """The authors' own noise (their seedrandom(0) stream, reset per level, and
        draw order): per level, the fallen bricks' file indices of each run, as
        their saved simulations list them."""
        (res,) = run_batch([self._scene(authors_seed={"levels": [int(k) for k in levels], "runs": int(n_runs)})],
                           early_stop)
        f = res["fallen"]
        return {int(k): f[i * n_runs:(i + 1) * n_runs] for i, k in enumerate(levels)}
