"""Pictures of the trials as photographs of wooden blocks on a table: Start (A) and Finish (B).

    python -m stimuli.render --out DIR [--stimuli DIR] [--seed 0] [--size 960x640] [--trials 7E 7H] [--jobs 2]

For every trial it writes ``DIR/<id>-A.png`` (the layout of A that effort reports
first: sample 0 of `--seed`, drawn by ``models.effort.sample_rng(seed, 0)``) and
``DIR/<id>-B.png``, and ``DIR/renders.json`` (camera, size, seed and every
picture's inputs hash and sha256). A second run skips pictures whose inputs are
unchanged.

The renderer is Drake's RenderEngineVtk (VTK, OpenGL offscreen on the CPU; Drake is
already a dependency): directional lights clustered around one direction, each
casting a shadow map (their overlap gives soft penumbrae), ambient occlusion for
the contact shadows under blocks, and a wood-grain texture with darkened edges per
block colour so that touching blocks show their seams. One camera serves every
picture of a run (fixed direction: from the agent's side, 48 degrees above the
table), fitted once to the union of the paper's workspace and every scene of the
run, so sizes and places compare across pictures: a relocated tower looks
relocated. The pictures are renderings of the trial files, not the paper's
photographs (which are not public).
"""
from __future__ import annotations

import argparse
import hashlib
import json
import os
import sys
import tempfile
import time
from dataclasses import dataclass, replace
from pathlib import Path

import numpy as np

from lgp import cli
from lgp.paper import BLOCK_SIZE, DISPLAY_RGB

PROG = "python -m stimuli.render"
#: Picture size (pixels) unless --size says otherwise.
DEFAULT_SIZE = (960, 640)
#: Vertical field of view of the camera (degrees) and its elevation above the table.
FOV_Y_DEG = 36.0
ELEVATION_DEG = 48.0
#: The table area every camera frames at least (x, y in metres, on the table: the
#: footprint of every scene of the 24 trials lies inside), so the default camera
#: hardly depends on which trials a run renders (tall structures add their tops).
WORKSPACE_LO = np.array([0.15, -0.30, 0.0])
WORKSPACE_HI = np.array([0.70, 0.32, 0.0])
#: Fraction of the picture left free at each side.
MARGIN = 0.04
#: Each rendered block is this much (m) smaller than its cube so touching blocks show a seam.
SEAM = 0.0006
#: Colour of the fixed boxes (pair 12's bucket): grey-blue plastic.
FIXED_RGB = (0.45, 0.50, 0.58)
TABLE_RGB = (0.80, 0.78, 0.74)
BACKGROUND_RGB = (0.93, 0.93, 0.92)


@dataclass(frozen=True)
class Camera:
    """A pinhole camera: pose (eye, target, world up z) and vertical field of view."""

    eye: tuple[float, float, float]
    target: tuple[float, float, float]
    fov_y_deg: float
    width: int
    height: int

    def rotation(self) -> np.ndarray:
        """R_WC: columns are the camera's x (right), y (down), z (forward) in W."""
        z = np.subtract(self.target, self.eye)
        z = z / np.linalg.norm(z)
        x = np.cross(z, [0.0, 0.0, 1.0])
        x = x / np.linalg.norm(x)
        return np.column_stack([x, np.cross(z, x), z])

    def project(self, P: np.ndarray) -> np.ndarray:
        """Pixel coordinates (u right, v down) of world points P (n, 3)."""
        R = self.rotation()
        p_C = (np.asarray(P, float) - np.asarray(self.eye)) @ R
        f = 0.5 * self.height / np.tan(np.radians(self.fov_y_deg) / 2)
        return np.column_stack([self.width / 2 + f * p_C[:, 0] / p_C[:, 2], self.height / 2 + f * p_C[:, 1] / p_C[:, 2]])

    def as_dict(self) -> dict:
        return {"eye": [round(v, 6) for v in self.eye], "target": [round(v, 6) for v in self.target],
                "fov_y_deg": self.fov_y_deg, "width": self.width, "height": self.height,
                "frame": "world W: table top z = 0, x away from the agent, y to its left"}


def scene_corners(scene) -> np.ndarray:
    """The 8 corners of every block and fixed box of a scene (n, 3)."""
    signs = np.array([[x, y, z] for x in (-1, 1) for y in (-1, 1) for z in (-1, 1)], float)
    out = []
    for b in scene.blocks:
        c, s = np.cos(b.yaw), np.sin(b.yaw)
        R = np.array([[c, -s, 0], [s, c, 0], [0, 0, 1]])
        out.append((signs * np.asarray(b.size) / 2) @ R.T + b.p_WB)
    for f in scene.fixed:
        out.append(signs * np.asarray(f.size) / 2 + f.p_WO)
    return np.vstack(out) if out else np.zeros((0, 3))


def fit_camera(points: np.ndarray, width: int, height: int) -> Camera:
    """The camera of fixed direction (from -x, ELEVATION_DEG above the table) that
    frames `points` and the paper's workspace with MARGIN to spare: the target is
    moved until the points' projection is centred, the distance until it fills the
    picture."""
    box = np.array([[x, y, z] for x in (WORKSPACE_LO[0], WORKSPACE_HI[0]) for y in (WORKSPACE_LO[1], WORKSPACE_HI[1])
                    for z in (WORKSPACE_LO[2], WORKSPACE_HI[2])])
    P = np.vstack([box, np.asarray(points, float).reshape(-1, 3)])
    e = np.radians(ELEVATION_DEG)
    back = np.array([-np.cos(e), 0.0, np.sin(e)])  # from target towards the eye
    target = np.array([(P[:, 0].min() + P[:, 0].max()) / 2, (P[:, 1].min() + P[:, 1].max()) / 2, 0.0])
    dist = 1.0
    for _ in range(40):
        cam = Camera(tuple(target + dist * back), tuple(target), FOV_Y_DEG, width, height)
        uv = cam.project(P)
        lo, hi = uv.min(axis=0), uv.max(axis=0)
        # Shift the target by the offset of the projection's centre (right, down in W).
        R = cam.rotation()
        f = 0.5 * height / np.tan(np.radians(FOV_Y_DEG) / 2)
        du, dv = (lo + hi) / 2 - (width / 2, height / 2)
        target = target + dist * (du / f * R[:, 0] + dv / f * R[:, 1])
        target[2] = 0.0
        fill = max((hi[0] - lo[0]) / (width * (1 - 2 * MARGIN)), (hi[1] - lo[1]) / (height * (1 - 2 * MARGIN)))
        dist *= fill ** 0.8
    cam = Camera(tuple(float(v) for v in target + dist * back), tuple(float(v) for v in target), FOV_Y_DEG, width, height)
    return cam


# ----------------------------------------------------------------------------- textures


def _texture(colour: str, n: int = 128) -> np.ndarray:
    """A face texture (n, n, 3) in 0..1: wood grain (stronger on natural wood than
    under paint) and edges darkened over 5 % of the face, like a sanded block's."""
    rng = np.random.default_rng(sum(map(ord, colour)))
    u = np.linspace(0, 1, n)[None, :]
    v = np.linspace(0, 1, n)[:, None]
    wobble = 0.25 * np.sin(2 * np.pi * (1.3 * v + 0.2)) + 0.05 * np.cumsum(rng.standard_normal((n, 1)), axis=0) / np.sqrt(n)
    grain = 0.5 + 0.5 * np.sin(2 * np.pi * (7 * u + wobble))
    k = 0.10 if colour == "natural" else 0.04
    shade = 1 - k / 2 + k * (grain - 0.5) + 0.025 * rng.standard_normal((n, n))
    edge = np.minimum(np.minimum(u, 1 - u), np.minimum(v, 1 - v))
    shade = shade * (1 - 0.28 * np.clip(1 - edge / 0.05, 0, 1) ** 2)
    return np.clip(np.asarray(DISPLAY_RGB[colour])[None, None, :] * shade[..., None], 0, 1)


def _table_texture(n: int = 512) -> np.ndarray:
    rng = np.random.default_rng(7)
    fine = rng.standard_normal((n, n))
    fine = (fine + np.roll(fine, 1, 0) + np.roll(fine, 1, 1) + np.roll(fine, (1, 1), (0, 1))) / 4
    return np.clip(np.asarray(TABLE_RGB)[None, None, :] * (1 + 0.018 * fine[..., None]), 0, 1)


#: VTK reads a texture as sRGB and writes the picture without converting back, so a
#: texture is stored with this gamma applied (1.5: dark colours keep their hue, light ones are not washed out; judged by eye).
TEXTURE_GAMMA = 1 / 1.5


def _write_png(path: Path, rgb: np.ndarray) -> None:
    from PIL import Image

    Image.fromarray((np.clip(rgb, 0, 1) ** TEXTURE_GAMMA * 255).round().astype(np.uint8)).save(path)


# ----------------------------------------------------------------------------- the engine


class Renderer:
    """One RenderEngineVtk with the table and lights, reused for every picture (its
    shaders are compiled once per process)."""

    def __init__(self, camera: Camera):
        from pydrake.geometry import (Box, ClippingRange, ColorRenderCamera, GeometryId, LightParameter,
                                      MakeRenderEngineVtk, RenderCameraCore, RenderEngineVtkParams, SsaoParameter)
        from pydrake.math import RigidTransform, RotationMatrix
        from pydrake.systems.sensors import CameraInfo

        self._Box, self._GeometryId, self._RigidTransform, self._RotationMatrix = Box, GeometryId, RigidTransform, RotationMatrix
        self._textures = tempfile.TemporaryDirectory(prefix="lgp-render-")
        tex = Path(self._textures.name)
        for colour in DISPLAY_RGB:
            _write_png(tex / f"{colour}.png", _texture(colour))
        _write_png(tex / "table.png", _table_texture())
        self._tex = tex
        key = np.array([0.25, 0.30, -1.0])  # the key light: high above, a little behind and right of the agent
        lights = [LightParameter(type="directional", direction=(key + np.array(j)).tolist(), intensity=0.15, frame="world")
                  for j in ((0.025, 0.025, 0), (-0.025, 0.025, 0), (0.025, -0.025, 0), (-0.025, -0.025, 0))]
        # Fill from the camera: its shadows lie behind the blocks, out of sight.
        lights.append(LightParameter(type="directional", direction=[0.0, 0.0, 1.0], intensity=0.56, frame="camera"))
        # Small pictures (the page's cards, tests) need no finer shadow map nor more AO
        # samples to look the same, and render about 3 times faster with these.
        small = max(camera.width, camera.height) <= 640
        params = RenderEngineVtkParams(cast_shadows=True, shadow_map_size=1024 if small else 2048, lights=lights,
                                       default_clear_color=list(BACKGROUND_RGB),
                                       ssao=SsaoParameter(radius=0.03, bias=0.002, sample_count=16 if small else 32))
        self.engine = MakeRenderEngineVtk(params)
        self.camera = camera
        self.engine.RegisterVisual(GeometryId.get_new_id(), Box(1.8, 1.8, 0.02), self._props(rgb=TABLE_RGB),
                                   RigidTransform([0.55, 0.0, -0.01]), False)
        core = RenderCameraCore("vtk", CameraInfo(camera.width, camera.height, np.radians(camera.fov_y_deg)),
                                ClippingRange(0.05, 6.0), RigidTransform())
        self._cam = ColorRenderCamera(core, False)
        self.engine.UpdateViewpoint(RigidTransform(RotationMatrix(camera.rotation()), np.asarray(camera.eye)))

    def _props(self, texture: str | None = None, rgb=None):
        from pydrake.geometry import PerceptionProperties, RenderLabel, Rgba

        p = PerceptionProperties()
        if texture is not None:
            p.AddProperty("phong", "diffuse_map", str(self._tex / f"{texture}.png"))
        if rgb is not None:
            p.AddProperty("phong", "diffuse", Rgba(*rgb, 1.0))
        p.AddProperty("label", "id", RenderLabel(1))
        return p

    def render(self, scene, path: Path) -> None:
        """Render `scene` (blocks and fixed boxes) to the PNG `path` (written atomically)."""
        from pydrake.systems.sensors import ImageRgba8U

        ids = []
        try:
            for b in scene.blocks:
                g = self._GeometryId.get_new_id()
                size = np.maximum(np.asarray(b.size) - SEAM, 0.5 * np.asarray(b.size))
                self.engine.RegisterVisual(g, self._Box(*size), self._props(texture=b.colour),
                                           self._RigidTransform(self._RotationMatrix.MakeZRotation(b.yaw), b.p_WB), False)
                ids.append(g)
            for f in scene.fixed:
                g = self._GeometryId.get_new_id()
                self.engine.RegisterVisual(g, self._Box(*f.size), self._props(rgb=FIXED_RGB), self._RigidTransform(f.p_WO), False)
                ids.append(g)
            image = ImageRgba8U(self.camera.width, self.camera.height)
            self.engine.RenderColorImage(self._cam, image)
        finally:
            for g in ids:
                self.engine.RemoveGeometry(g)
        rgb = np.array(image.data)[:, :, :3]
        tmp = path.with_name(f".{path.name}.tmp.png")
        from PIL import Image

        Image.fromarray(rgb).save(tmp)
        os.replace(tmp, path)


# ----------------------------------------------------------------------------- a run


def finished_table(A, B):
    """What the table holds when B is built from A: B's blocks, and every block of A
    that B does not use where A left it (lgp.assignment: unassigned blocks stay put;
    pair 12's bucket keeps its other 15 blocks)."""
    from lgp.assignment import assign_blocks
    from lgp.scene import Scene

    used = set(assign_blocks(A, B))
    taken = {b.name for b in B.blocks}
    left = [b if b.name not in taken else replace(b, name=f"{b.name} (left)") for b in A.blocks if b.name not in used]
    return Scene(tuple(B.blocks) + tuple(left), B.fixed, B.label)


def pictures_of(trials, seed: int):
    """(trial id, state, scene) of every picture: A is sample 0 of `seed` (the layout
    effort reports first, models.effort.sample_rng(seed, 0)), B the finished table
    (the target and whatever of A it leaves)."""
    from models.effort import sample_rng

    out = []
    for t in trials:
        A = t.sample_initial(sample_rng(seed, 0))
        out.append((t.id, "A", A))
        out.append((t.id, "B", finished_table(A, t.target)))
    return out


def _code_version() -> str:
    h = hashlib.sha256(Path(__file__).read_bytes())
    try:
        from importlib.metadata import version

        h.update(version("drake").encode())
    except Exception:  # noqa: BLE001 - a source build of drake has no metadata
        pass
    return h.hexdigest()[:16]


def _scene_key(scene) -> list:
    return [[b.name, b.colour, np.round(b.p_WB, 6).tolist(), round(float(b.yaw), 6), np.round(b.size, 6).tolist()] for b in scene.blocks] + \
           [[f.name, np.round(f.p_WO, 6).tolist(), np.round(f.size, 6).tolist()] for f in scene.fixed]


def _picture_key(scene, camera: Camera, code: str) -> str:
    blob = json.dumps({"scene": _scene_key(scene), "camera": camera.as_dict(), "code": code}, sort_keys=True)
    return hashlib.sha256(blob.encode()).hexdigest()[:20]


def _sha256(path: Path) -> str:
    return hashlib.sha256(path.read_bytes()).hexdigest()


def _render_chunk(camera: Camera, jobs: list[tuple[str, str]]) -> list[float]:
    """Worker: render (scene pickle path, png path) pairs with one engine; seconds each."""
    import pickle

    renderer = Renderer(camera)
    seconds = []
    for scene_file, png in jobs:
        with open(scene_file, "rb") as fh:
            scene = pickle.load(fh)
        t0 = time.perf_counter()
        renderer.render(scene, Path(png))
        seconds.append(time.perf_counter() - t0)
    return seconds


def render_trials(trials, out_dir: str | Path, seed: int = 0, size: tuple[int, int] = DEFAULT_SIZE, jobs: int = 2,
                  log=None) -> dict:
    """Render A and B of every trial into `out_dir`; returns the run's record (the
    content of renders.json). Pictures whose inputs (scene, camera, code) are
    unchanged since the last run into `out_dir` are kept, not rendered again."""
    import pickle

    log = log or (lambda msg: print(msg, file=sys.stderr, flush=True))
    out = Path(out_dir)
    pictures = pictures_of(trials, seed)
    camera = fit_camera(np.vstack([scene_corners(s) for _, _, s in pictures]), *size)
    code = _code_version()
    record_path = out / "renders.json"
    old = {}
    if record_path.exists():
        try:
            old = {p["file"]: p for p in json.loads(record_path.read_text()).get("pictures", [])}
        except (ValueError, KeyError, TypeError):
            old = {}
    out.mkdir(parents=True, exist_ok=True)
    rows, todo = [], []
    scratch = tempfile.TemporaryDirectory(prefix="lgp-scenes-")
    for k, (tid, state, scene) in enumerate(pictures):
        name = f"{tid}-{state}.png"
        key = _picture_key(scene, camera, code)
        rows.append({"trial": tid, "state": state, "file": name, "key": key,
                     "blocks": len(scene.blocks), "sample": 0 if state == "A" else None})
        prev = old.get(name)
        if prev and prev.get("key") == key and (out / name).exists() and prev.get("sha256") == _sha256(out / name):
            continue
        scene_file = Path(scratch.name) / f"{k}.pkl"
        scene_file.write_bytes(pickle.dumps(scene))
        todo.append((str(scene_file), str(out / name)))
    t0 = time.perf_counter()
    seconds: list[float] = []
    if todo:
        # A process costs a second or two to start (pydrake, shaders): worth it for many pictures only.
        jobs = max(1, min(jobs, len(todo) // 8))
        log(f"{PROG}: rendering {len(todo)} of {len(rows)} pictures ({size[0]}x{size[1]}, RenderEngineVtk) with {jobs} process(es)")
        chunks = [todo[i::jobs] for i in range(jobs)]
        if jobs == 1:
            seconds = _render_chunk(camera, chunks[0])
        else:
            import multiprocessing as mp
            from concurrent.futures import ProcessPoolExecutor

            with ProcessPoolExecutor(jobs, mp_context=mp.get_context("spawn")) as pool:
                for s in pool.map(_render_chunk, [camera] * jobs, chunks):
                    seconds += s
    else:
        log(f"{PROG}: all {len(rows)} pictures are up to date in {out}")
    scratch.cleanup()
    for r in rows:
        r["sha256"] = _sha256(out / r["file"])
    record = {"renderer": "drake RenderEngineVtk (VTK OpenGL, offscreen)", "seed": seed,
              "layout_of_A": "sample 0 of the seed: models.effort.sample_rng(seed, 0)", "camera": camera.as_dict(),
              "code": code, "rendered": len(todo), "render_seconds": round(time.perf_counter() - t0, 2),
              "pictures": rows}
    tmp = record_path.with_name(".renders.json.tmp")
    tmp.write_text(json.dumps(record, indent=1) + "\n")
    os.replace(tmp, record_path)
    return record


def render_cache_dir() -> Path:
    """Where rendered pictures are kept between runs: $LGP_RENDER_CACHE, else
    $XDG_CACHE_HOME/lgp-difficulty/renders (~/.cache/...). A picture is found again by
    the hash of its scene, camera and this module's code (renders.json), so a stale
    one is never used."""
    base = os.environ.get("LGP_RENDER_CACHE")
    if base:
        return Path(base)
    return Path(os.environ.get("XDG_CACHE_HOME") or Path.home() / ".cache") / "lgp-difficulty" / "renders"


def cache_folder(trials, seed: int, size) -> Path:
    """The render cache's folder for one set of trials, seed and picture size (one
    camera is fitted per set)."""
    key = hashlib.sha256(json.dumps([[t.id, t.digest] for t in trials] + [seed, list(size)]).encode()).hexdigest()[:16]
    return render_cache_dir() / key


def contact_sheet(out_dir: str | Path, path: str | Path, columns: int = 4, thumb: int = 320) -> Path:
    """All pictures of `out_dir`'s renders.json on one PNG (A | B per trial, labelled)."""
    from PIL import Image, ImageDraw

    out = Path(out_dir)
    record = json.loads((out / "renders.json").read_text())
    by_trial: dict[str, dict] = {}
    for p in record["pictures"]:
        by_trial.setdefault(p["trial"], {})[p["state"]] = out / p["file"]
    w = thumb
    h = round(thumb * record["camera"]["height"] / record["camera"]["width"])
    rows = -(-len(by_trial) // columns)
    sheet = Image.new("RGB", (columns * 2 * w + (columns - 1) * 8, rows * (h + 16)), "white")
    draw = ImageDraw.Draw(sheet)
    for k, (tid, states) in enumerate(by_trial.items()):
        r, c = divmod(k, columns)
        for j, state in enumerate(("A", "B")):
            x, y = c * (2 * w + 8) + j * w, r * (h + 16)
            sheet.paste(Image.open(states[state]).convert("RGB").resize((w, h)), (x, y + 16))
            draw.text((x + 4, y + 2), f"{tid}-{state} ({'Start' if state == 'A' else 'Finish'})", fill="black")
    sheet.save(path)
    return Path(path)


def parse_size(text: str) -> tuple[int, int]:
    """WIDTHxHEIGHT in pixels, each 64..4096."""
    try:
        w, h = (int(v, 10) for v in str(text).lower().split("x"))
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected WIDTHxHEIGHT in pixels such as 960x640, got {text!r}") from None
    if not (64 <= w <= 4096 and 64 <= h <= 4096):
        raise argparse.ArgumentTypeError(f"width and height must be 64..4096 pixels, got {text!r}")
    return w, h


def main(argv=None) -> int:
    import stimuli

    parser = cli.parser(PROG, description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--out", required=True, type=cli.output_dir, help="folder for the PNGs and renders.json (created)")
    parser.add_argument("--stimuli", metavar="DIR", type=cli.input_dir, help="folder of trial files (default: stimuli/trials)")
    parser.add_argument("--trials", nargs="+", type=cli.trial_id, help="trial ids (default: every trial file of the folder)")
    parser.add_argument("--seed", type=cli.seed, default=0, help="A is sample 0 of this seed, as effort's (default 0)")
    parser.add_argument("--size", type=parse_size, default=DEFAULT_SIZE, help="WIDTHxHEIGHT in pixels (default 960x640)")
    parser.add_argument("--jobs", type=cli.positive_int, default=2, help="rendering processes (default 2)")
    parser.add_argument("--sheet", metavar="PNG", type=cli.output_file, help="also write a contact sheet of all pictures")
    args = parser.parse_args(argv)
    if args.trials:
        trials = [stimuli.load_trial(t, args.stimuli) for t in args.trials]
    else:
        if args.stimuli and not stimuli.trial_ids(args.stimuli):
            parser.error(f"--stimuli {args.stimuli}: no trial files (*.yaml) there")
        trials = stimuli.load_all(args.stimuli)
    record = render_trials(trials, args.out, args.seed, args.size, args.jobs)
    print(f"{len(record['pictures'])} pictures in {args.out} ({record['rendered']} rendered in {record['render_seconds']} s)")
    if args.sheet:
        print(contact_sheet(args.out, args.sheet))
    return 0


if __name__ == "__main__":
    raise SystemExit(cli.run_cli(main, prog=PROG))
