"""Reader of another lab's brick scenes: Mental Jenga (Zhou, Smith, Tenenbaum &
Gerstenberg, "Mental Jenga: A counterfactual simulation model of causal judgments
about physical support", J. Exp. Psychol.: General, 2023; repository
`cicl-stanford/mental_jenga`). The project does not ship those data: this module
reads a user's clone of that repository.

    python -m stimuli.mental_jenga --repo PATH --experiment 2 --out DIR

writes DIR/bricks.csv (one row per brick of every scene, in the project's frame and
units), DIR/scenes.csv (one row per scene: black brick, counts, whether the scene
went into the trial format), DIR/trials/MJ<N>_<TT>.yaml (the trial format, for the
scenes whose bricks all lie within SNAP_TOLERANCE of a quarter turn) and
DIR/predictions.csv (the human predictions, tidy: participant, trial, response).

Frames and units (docs/mental-jenga.md). The authors' world is a 2-D Box2D world
with y pointing down (screen coordinates). A scene becomes the x-z plane of the
project's world W: x_W = SCALE * (x - X_CENTRE), z_W = SCALE * (GROUND_Y - y) (the
ground is z = 0; their y flipped), every brick extruded DEPTH along y. A Box2D
angle theta (turning +x towards +y, which points down) is a pitch of +theta about
W's y axis (R_y(theta) turns +x towards -z, i.e. down). A brick within
SNAP_TOLERANCE of a quarter turn becomes an axis-aligned box (sizes swapped on odd
turns); the others keep their pitch. The table is a fixed box standing on the
ground with its top at the table top's height. The black brick is the authors'
"special" brick, index 0 (`brick_0`) in their code.

Scaling (SCALE = 0.1): the project refuses solids with edges over 0.5 m, and its
engines are validated on blocks of a few centimetres; the authors' bricks are
0.8 x 0.4 "metres". A rigid-body world with Coulomb friction, a restitution and a
linear damping rate is similar to itself under a change of length scale s when time
scales by sqrt(s * g_authors / g) (Froude scaling), so each brick's verdict (falls
or stays) is unchanged; the contact model's own time and length constants do not
scale, which is why the verdicts at two scales are measured side by side
(bench/mental_jenga.py, docs/mental-jenga.md) rather than assumed.
"""
from __future__ import annotations

import argparse
import copy
import json
import math
import sys
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from lgp.scene import FixedBox

#: Length scale: project metres per authors' metre.
SCALE = 0.1
#: Facts of the authors' Box2D world (code/js/brick_world.js, brick_tools.js).
BRICK_A = (0.8, 0.4)  # full width, height (SetAsBox half-extents 0.4, 0.2)
DEPTH_A = 0.4  # our extrusion along y (a 2-D world has none)
TABLE_X_A = (2.5, 5.5)
TABLE_TOP_Y_A = 4.82
GROUND_Y_A = 5.8
FALL_Y_A = 5.0  # a brick whose centre is below this (y > 5) is destroyed: fallen
X_CENTRE_A = 4.0  # middle of the table: x_W = 0
GRAVITY_A = 10.0
LINEAR_DAMPING_A = 1.0  # bodyDef.linearDamping, 1/s
FRICTION_A = 0.6
#: Table friction per experiment ("experiment 1 conducted with table friction == 1").
TABLE_FRICTION_A = {1: 1.0, 2: 0.6, 3: 0.6}
#: Box2D steps at 1/60 s: 50 to settle the scene as loaded, 700 after the removal.
STEP_A = 1 / 60
PRESETTLE_STEPS_A = 50
SETTLE_STEPS_A = 700
BLACK_INDEX = 0
#: A brick within this angle (rad) of a quarter turn is an axis-aligned box: at
#: 0.01 rad a 0.8-wide brick's ends move 4 mm (authors' units), the size of Box2D's
#: own contact slop (linear slop 0.005).
SNAP_TOLERANCE = 0.01
EXPERIMENTS = (1, 2, 3)
MAX_SCENE_BYTES = 1_000_000


class MentalJengaError(ValueError):
    """Input that is not what the repository holds: the message names the file and the problem."""


def time_scale(scale: float = SCALE, gravity: float = 9.81) -> float:
    """Project seconds per authors' second under Froude scaling."""
    return math.sqrt(scale * GRAVITY_A / gravity)


@dataclass(frozen=True)
class Brick:
    """One brick in W: centre p_WB (m), pitch about W's y axis (rad), full size in
    its own frame (m), its name in the authors' file and whether it is the black one."""

    name: str
    index: int
    p_WB: np.ndarray
    pitch: float
    size: np.ndarray
    black: bool = False
    angle_a: float = 0.0  # the authors' angle, as read

    def __post_init__(self):
        object.__setattr__(self, "p_WB", np.asarray(self.p_WB, float).reshape(3))
        object.__setattr__(self, "size", np.asarray(self.size, float).reshape(3))

    @property
    def axis_aligned(self) -> bool:
        return self.pitch == 0.0

    def half_extents_xz(self) -> np.ndarray:
        """Half extents of the brick's outline in the x-z plane's axes (an AABB for a pitched brick)."""
        c, s = abs(math.cos(self.pitch)), abs(math.sin(self.pitch))
        hx, hz = self.size[0] / 2, self.size[2] / 2
        return np.array([c * hx + s * hz, s * hx + c * hz])


@dataclass(frozen=True)
class JengaScene:
    """One Mental Jenga scene in the project's frame: bricks, the table and the fall line."""

    experiment: int
    trial: int
    bricks: tuple[Brick, ...]
    table: FixedBox
    table_friction: float
    scale: float = SCALE
    source: str = ""
    digest: str = ""
    #: (x, y, angle) of every brick of the scene file, in file order, parked ones
    #: included, exactly as read (the authors' units): the box2dweb engine loads
    #: these, as the authors' code does (models/box2dweb_engine.py).
    authors_bricks: tuple = ()

    @property
    def label(self) -> str:
        return f"MJ{self.experiment}_{self.trial:02d}"

    @property
    def black(self) -> Brick:
        return next(b for b in self.bricks if b.black)

    @property
    def table_top(self) -> float:
        return self.table.top

    @property
    def fall_z(self) -> float:
        """A brick whose centre ends below this height (m) has fallen off the table."""
        return self.scale * (GROUND_Y_A - FALL_Y_A)

    def red(self) -> tuple[Brick, ...]:
        return tuple(b for b in self.bricks if not b.black)


def table_box(scale: float = SCALE) -> FixedBox:
    """The table as one fixed box on the ground, top at the authors' table top."""
    width = scale * (TABLE_X_A[1] - TABLE_X_A[0])
    height = scale * (GROUND_Y_A - TABLE_TOP_Y_A)
    x = scale * ((TABLE_X_A[0] + TABLE_X_A[1]) / 2 - X_CENTRE_A)
    return FixedBox("table", [x, 0.0, height / 2], [width, 2 * scale * DEPTH_A, height])


def to_world(x: float, y: float, scale: float = SCALE) -> np.ndarray:
    """Authors' (x, y down) -> p_W (x, 0, z up), m."""
    return np.array([scale * (x - X_CENTRE_A), 0.0, scale * (GROUND_Y_A - y)])


def brick_from_authors(name: str, index: int, x: float, y: float, angle: float, black: bool,
                       scale: float = SCALE) -> Brick:
    w, h, d = (scale * BRICK_A[0], scale * BRICK_A[1], scale * DEPTH_A)
    turns = round(angle / (math.pi / 2))
    if abs(angle - turns * math.pi / 2) <= SNAP_TOLERANCE:
        size = [h, d, w] if turns % 2 else [w, d, h]
        pitch = 0.0
    else:
        size, pitch = [w, d, h], float(angle)
    return Brick(name, index, to_world(x, y, scale), pitch, size, black, float(angle))


def parse_scene(data, where: str, experiment: int, trial: int, scale: float = SCALE, black_index: int = BLACK_INDEX) -> JengaScene:
    """A scene from the parsed JSON of `data/exp<N>/<trial>.json`; MentalJengaError naming `where`."""
    import hashlib

    if not isinstance(data, list):
        raise MentalJengaError(f"{where}: expected a list of bricks, got {type(data).__name__}")
    bricks, raw = [], []
    for k, item in enumerate(data):
        if not isinstance(item, dict) or not {"x", "y", "angle"} <= set(item):
            raise MentalJengaError(f"{where}: brick {k} is not a mapping with x, y and angle")
        try:
            x, y, a = (float(item["x"]), float(item["y"]), float(item["angle"]))
        except (TypeError, ValueError):
            raise MentalJengaError(f"{where}: brick {k} has a non-numeric x, y or angle") from None
        if not all(map(math.isfinite, (x, y, a))):
            raise MentalJengaError(f"{where}: brick {k} has a non-finite x, y or angle")
        raw.append((x, y, a))
        if x < 0:  # parked off-screen: not in the scene (the authors' loadData destroys it)
            if k == black_index:
                raise MentalJengaError(f"{where}: the black brick (index {k}) is parked off the scene")
            continue
        name = str(item.get("name", f"brick_{k}"))
        bricks.append(brick_from_authors(name, k, x, y, a, k == black_index, scale))
    if not bricks:
        raise MentalJengaError(f"{where}: names no bricks")
    if not any(b.black for b in bricks):
        raise MentalJengaError(f"{where}: has no brick of index {black_index} (the black brick)")
    digest = hashlib.sha256(json.dumps(data, sort_keys=True).encode()).hexdigest()[:16]
    return JengaScene(experiment, trial, tuple(bricks), table_box(scale), TABLE_FRICTION_A.get(experiment, FRICTION_A),
                      scale, where, digest, tuple(raw))


def read_scene(path: str | Path, experiment: int, trial: int, scale: float = SCALE) -> JengaScene:
    from lgp.inputs import InputFileError, read_bounded

    try:
        raw = read_bounded(path, MAX_SCENE_BYTES, "scene file")
    except InputFileError as e:
        raise MentalJengaError(f"{path}: {e}") from None
    try:
        data = json.loads(raw.decode("utf-8"))
    except (UnicodeDecodeError, json.JSONDecodeError) as e:
        raise MentalJengaError(f"{path}: not valid JSON ({e})") from None
    return parse_scene(data, str(path), experiment, trial, scale)


def check_repo(repo: str | Path, experiment: int) -> Path:
    """The scene folder of `experiment` in a clone of the repository; MentalJengaError otherwise."""
    repo = Path(repo)
    if not repo.is_dir() or not (repo / "data").is_dir() or not (repo / "code" / "R" / "data").is_dir():
        raise MentalJengaError(f"{repo}: not a clone of cicl-stanford/mental_jenga (no data/ and code/R/data/ folders)")
    if experiment not in EXPERIMENTS:
        raise MentalJengaError(f"{repo}: unknown experiment {experiment} (the repository has {', '.join(map(str, EXPERIMENTS))})")
    folder = repo / "data" / f"exp{experiment}"
    if not folder.is_dir():
        raise MentalJengaError(f"{folder}: missing: this copy of the repository has no experiment {experiment}")
    return folder


def scene_files(folder: Path) -> list[tuple[int, Path]]:
    out = []
    for p in folder.glob("*.json"):
        if p.stem.isdigit():
            out.append((int(p.stem), p))
    if not out:
        raise MentalJengaError(f"{folder}: holds no scene files (<trial>.json)")
    return sorted(out)


def read_scenes(repo: str | Path, experiment: int, scale: float = SCALE) -> list[JengaScene]:
    """Every scene of `experiment`, in trial order; the first bad file raises MentalJengaError."""
    return [read_scene(p, experiment, t, scale) for t, p in scene_files(check_repo(repo, experiment))]


def _rdata_table(path: Path, *names: str):
    """The first of `names` that the R data file holds (the repository names its
    tables ``df.exp2.prediction``)."""
    try:
        import pyreadr
    except ImportError:  # pragma: no cover - pyreadr is a dependency
        raise MentalJengaError(f"{path}: reading R data needs the pyreadr package (pip install pyreadr)") from None
    if not path.is_file():
        raise MentalJengaError(f"{path}: missing")
    try:
        tables = pyreadr.read_r(str(path))
    except Exception as e:  # pyreadr raises its own LibrdataError and others
        raise MentalJengaError(f"{path}: not readable R data ({type(e).__name__}: {e})") from None
    for name in names:
        if name in tables:
            return tables[name]
    raise MentalJengaError(f"{path}: holds no table {' or '.join(map(repr, names))} (it holds {', '.join(tables) or 'nothing'})")


def read_predictions(repo: str | Path, experiment: int):
    """Human predictions, tidy: participant, trial, response (one row per judgement)."""
    import pandas as pd

    path = Path(repo) / "code" / "R" / "data" / f"exp{experiment}_prediction.RData"
    df = _rdata_table(path, f"df.exp{experiment}.prediction", f"exp{experiment}_prediction")
    need = {"participant", "trial", "response"}
    if not need <= set(df.columns):
        raise MentalJengaError(f"{path}: lacks column(s) {', '.join(sorted(need - set(df.columns)))}")
    out = pd.DataFrame({"participant": df["participant"].astype(str).to_numpy(),
                        "trial": df["trial"].astype(float).astype(int).to_numpy(),
                        "response": df["response"].astype(float).to_numpy()})
    if out["response"].isna().any():
        raise MentalJengaError(f"{path}: {int(out['response'].isna().sum())} responses are missing")
    return out.sort_values(["trial", "participant"], kind="stable").reset_index(drop=True)


def read_info(repo: str | Path, experiment: int):
    """The authors' deterministic run: trial, index, fall (0/1) per brick."""
    import pandas as pd

    path = Path(repo) / "code" / "R" / "data" / f"exp{experiment}_info.RData"
    df = _rdata_table(path, f"df.exp{experiment}.info", f"exp{experiment}_info")
    return pd.DataFrame({"trial": df["trial"].astype(float).astype(int), "index": df["index"].astype(float).astype(int),
                         "fall": df["fall"].astype(float).astype(int)})


def bricks_table(scenes):
    import pandas as pd

    rows = []
    for s in scenes:
        for b in s.bricks:
            rows.append({"trial": s.trial, "brick": b.name, "index": b.index, "black": int(b.black),
                         "x": b.p_WB[0], "z": b.p_WB[2], "pitch": b.pitch, "size_x": b.size[0], "size_y": b.size[1],
                         "size_z": b.size[2], "angle_authors": b.angle_a})
    return pd.DataFrame(rows)


#: Box2D keeps resting polygons apart by a skin (b2_polygonRadius 0.01 each, two per contact; twice its linear
#: slop of 0.005): the bricks of a settled scene rest about 0.006 above what carries
#: them. The trial format's support rule allows 0.1 mm, so gaps up to this much
#: (authors' units) are closed when a scene is written in the trial format.
SKIN_A = 0.02


def close_gaps(scene: JengaScene) -> tuple[JengaScene, float]:
    """The scene with every axis-aligned brick lowered onto what lies beneath it
    (the table or lower bricks whose outlines it overlaps in x) when the gap is at
    most SKIN_A, bottom-up; and the largest move (m). Pitched bricks stay."""
    from dataclasses import replace

    skin = SKIN_A * scene.scale
    order = sorted(range(len(scene.bricks)), key=lambda i: scene.bricks[i].p_WB[2] - scene.bricks[i].half_extents_xz()[1])
    old, new = scene.bricks, list(scene.bricks)
    t = scene.table
    moved = 0.0
    for i in order:  # bottom-up: a brick's supports are placed before it
        b = old[i]
        if not b.axis_aligned:
            continue
        hx, hz = b.half_extents_xz()
        x, bottom = b.p_WB[0], b.p_WB[2] - hz
        tops = []  # (top as read, top as placed) of what carries it, decided on the scene as read
        if abs(x - t.p_WO[0]) < hx + t.size[0] / 2 and 0.0 <= bottom - t.top <= skin:
            tops.append((t.top, t.top))
        for j in order:
            o = old[j]
            ohx, ohz = o.half_extents_xz()
            if j != i and abs(x - o.p_WB[0]) < hx + ohx - 1e-9 and 0.0 <= bottom - (o.p_WB[2] + ohz) <= skin:
                tops.append((o.p_WB[2] + ohz, new[j].p_WB[2] + new[j].half_extents_xz()[1]))
        if tops:
            z = max(placed for _, placed in tops) + hz
            moved = max(moved, abs(z - b.p_WB[2]))
            new[i] = replace(b, p_WB=np.array([x, 0.0, z]))
    return replace(scene, bricks=tuple(new)), moved


def trial_mapping(scene: JengaScene) -> dict:
    """The project's trial format for an all-quarter-turn scene: B (the target) is the
    scene, A the same blocks; the black brick is named `black_<name>` (the project's
    colours have no black), the red ones are red; the table is a fixed box."""
    blocks = [{"name": (f"black_{b.name}" if b.black else b.name), "p_WB": [round(float(v), 6) for v in b.p_WB],
               "yaw": 0.0, "colour": "natural" if b.black else "red", "size": [round(float(v), 6) for v in b.size]}
              for b in scene.bricks]
    t = scene.table
    return {
        "id": scene.label, "dimension": "Mental Jenga scene", "description":
        f"Mental Jenga exp {scene.experiment} trial {scene.trial}: remove black_brick_0, count the red bricks that fall",
        "build_site": [0.0, 0.0],
        "provenance": {"paper": [f"Zhou, Smith, Tenenbaum & Gerstenberg (2023), exp {scene.experiment}, trial {scene.trial}"],
                       "reconstructed": [f"scaled by {scene.scale} (stimuli/mental_jenga.py), extruded {DEPTH_A * scene.scale} m along y"]},
        "fixed": [{"name": "table", "boxes": [{"p_WO": [float(v) for v in t.p_WO], "size": [float(v) for v in t.size]}]}],
        "initial": {"blocks": copy.deepcopy(blocks)},  # two lists: YAML would write one as an alias
        "target": {"blocks": blocks},
    }


def write_outputs(repo, experiment: int, out: str | Path) -> dict:
    """Read everything first (a bad input raises before anything is written), then write."""
    import pandas as pd
    import yaml

    from stimuli.trial import parse_trial

    scenes = read_scenes(repo, experiment)
    predictions = read_predictions(repo, experiment)
    rows, trials = [], {}
    for s in scenes:
        pitched = sum(not b.axis_aligned for b in s.bricks)
        status = "skipped: %d pitched brick(s); the scene model knows only yaw" % pitched if pitched else "written"
        if not pitched:
            closed, moved = close_gaps(s)
            mapping = trial_mapping(closed)
            try:
                parse_trial(mapping)
                trials[s.label] = mapping
                status = f"written (gaps closed: bricks lowered by at most {moved * 1000:.2f} mm)"
            except ValueError as e:  # StimulusError: the project's checks refuse it, and say which rule
                status = "refused: " + " ".join(str(e).split())
        rows.append({"trial": s.trial, "id": s.label, "black": s.black.name, "bricks": len(s.bricks),
                     "pitched": pitched, "trial_format": status, "file": s.source})
    out = Path(out)
    out.mkdir(parents=True, exist_ok=True)
    (out / "trials").mkdir(exist_ok=True)
    for label, mapping in trials.items():
        (out / "trials" / f"{label}.yaml").write_text(yaml.safe_dump(mapping, sort_keys=False))
    pd.DataFrame(rows).to_csv(out / "scenes.csv", index=False)
    bricks_table(scenes).to_csv(out / "bricks.csv", index=False)
    predictions.to_csv(out / "predictions.csv", index=False)
    return {"scenes": len(scenes), "trial_files": len(trials), "predictions": len(predictions)}


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(prog="python -m stimuli.mental_jenga", description=__doc__.split("\n\n")[0])
    ap.add_argument("--repo", required=True, help="a clone of cicl-stanford/mental_jenga")
    ap.add_argument("--experiment", type=int, required=True)
    ap.add_argument("--out", required=True)
    args = ap.parse_args(argv)
    from lgp.owned import ForeignFiles, csv_record, refuse_foreign_folder

    try:
        refuse_foreign_folder(Path(args.out), "scenes.csv", is_ours=csv_record("trial", "id", "black", "trial_format"))  # a user's folder is not written into
        done = write_outputs(args.repo, args.experiment, args.out)
    except (MentalJengaError, ForeignFiles) as e:
        print(f"stimuli.mental_jenga: {e}", file=sys.stderr)
        return 2
    print(f"stimuli.mental_jenga: {done['scenes']} scenes, {done['trial_files']} in the trial format, "
          f"{done['predictions']} predictions -> {args.out}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
