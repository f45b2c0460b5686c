"""A cached render run: A and B of every trial rendered into a folder, each trial
with its own camera shared by A and B (`render_trials`), recorded in renders.json with each picture's inputs hash, so a
second run renders only what changed; where the pictures are kept between runs
(`render_cache_dir`, `cache_folder`) and a contact sheet of a run's pictures."""
from __future__ import annotations

import hashlib
import json
import os
import sys
import pickle
import time
from pathlib import Path

import numpy as np

from stimuli.render.camera import AZIMUTH_DEG, DEFAULT_SIZE, ELEVATION_DEG, FOV_Y_DEG, MIN_AREA, Camera, trial_camera
from stimuli.render.engine import Renderer
from lgp.owned import (ForeignFiles, collisions, describe, foreign_entries, new_staging, own_files, read_manifest,
                       regular_inside, remove_staging, sha256_of, signals_deferred)
from stimuli.sheet import finished_scene

PROG = "python -m stimuli.render"


#: Which layout of A the pictures show: "sample0" (sample 0 of the seed for every
#: trial: the layout effort reports first and the results page's replay plays) or
#: "pair" (a trial of pair p shows sample p - 1 of the seed, a trial of no pair sample
#: 0: the two trials of a pair share their Start, no two pairs do; the study's
#: choice, docs/experiment.md section 8).
LAYOUTS = ("sample0", "pair")


def layout_sample(trial, layout: str = "sample0") -> int:
    """The sample of the seed whose layout of A the picture of `trial` shows."""
    if layout not in LAYOUTS:
        from lgp.errors import InputError

        raise InputError(f"layout {layout!r}: expected one of {', '.join(LAYOUTS)}")
    return trial.pair - 1 if layout == "pair" and trial.pair is not None else 0


def pictures_of(trials, seed: int, layout: str = "sample0"):
    """(trial id, state, scene) of every picture: A is the layout of sample
    `layout_sample(trial, layout)` of `seed` (models.effort.sample_rng(seed, k), as
    effort draws it), B the finished table (the target and whatever of A it leaves:
    stimuli.sheet.finished_scene, the same table the sketches draw)."""
    from models.effort import sample_rng

    out = []
    for t in trials:
        A = t.sample_initial(sample_rng(seed, layout_sample(t, layout)))
        out.append((t.id, "A", A))
        out.append((t.id, "B", finished_scene(A, t.target)))
    return out


def _code_version() -> str:
    """Hash of this package's source (every module of stimuli/render/, by name) and
    Drake's version: editing the renderer renders the pictures again."""
    h = hashlib.sha256()
    for path in sorted(Path(__file__).parent.glob("*.py")):
        h.update(path.name.encode() + b"\0" + path.read_bytes())
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


def _render_chunk(jobs: list[tuple[str, str, Camera]]) -> list[float]:
    """Worker: render (scene pickle path, png path, camera) triples with one engine; seconds each."""
    import pickle

    seconds = []
    renderer = Renderer(jobs[0][2]) if jobs else None
    for scene_file, png, camera in jobs:
        with open(scene_file, "rb") as fh:
            scene = pickle.load(fh)
        t0 = time.perf_counter()
        renderer.render(scene, Path(png), camera)
        seconds.append(time.perf_counter() - t0)
    return seconds


def render_trials(trials, out_dir: str | Path, seed: int = 0, size: tuple[int, int] = DEFAULT_SIZE, jobs: int = 2,
                  log=None, executor=None, layout: str = "sample0", store: Path | None = None) -> dict:
    """Render A and B of every trial into `out_dir`, each trial seen by its own camera
    (`trial_camera`: the same for its A and B); `layout`: which sample's layout A shows
    (LAYOUTS). Returns the run's record (the content of renders.json). Pictures whose inputs (scene, camera, code) are
    unchanged since the last run into `out_dir` are kept, not rendered again.

    `executor`: a running local lgp.executor (ProcessExecutor or SerialExecutor,
    e.g. lgp.reproduce's, whose workers have pydrake loaded already) renders the
    pictures in its own processes, one chunk per worker; otherwise `jobs` fresh
    processes are started (worth it for many pictures only).

    `store`: a folder of pictures by the hash of their inputs (`picture_store`, in the
    render cache): a picture found there is copied, not rendered, and a rendered one
    is added. So a picture rendered for one set of trials (a run's cache folder,
    `cache_folder`) is not rendered again for another set that holds the same trial.

    The folder is the user's: a picture's name, or renders.json, holding what no
    render run wrote (sha256 in renders.json), or a folder of other files and no
    renders.json, is refused with ForeignFiles before anything is written; new
    pictures are rendered into a staging folder inside `out_dir` and moved in when
    all are done (lgp/owned.py), so an interrupted run leaves the folder as it was."""
    log = log or (lambda msg: print(f"{PROG}: {msg}", file=sys.stderr, flush=True))
    out = Path(out_dir)
    pictures = pictures_of(trials, seed, layout)
    scenes: dict[str, list] = {}
    for tid, _, scene in pictures:
        scenes.setdefault(tid, []).append(scene)
    cameras = {tid: trial_camera(both, *size) for tid, both in scenes.items()}
    code = _code_version()
    names = [f"{tid}-{state}.png" for tid, state, _ in pictures]
    old, own = _refuse_foreign(out, names)
    out.mkdir(parents=True, exist_ok=True)
    rows, todo = [], []
    stage = new_staging(out)  # new pictures are rendered here and moved in when all are done
    try:
        for k, (tid, state, scene) in enumerate(pictures):
            name = f"{tid}-{state}.png"
            camera = cameras[tid]
            key = _picture_key(scene, camera, code)
            sample = layout_sample(next(t for t in trials if t.id == tid), layout)
            rows.append({"trial": tid, "state": state, "file": name, "key": key,
                         "blocks": len(scene.blocks), "sample": sample})
            prev = old.get(name)
            if prev and prev.get("key") == key and name in own:
                rows[-1]["sha256"] = own[name]
                continue
            if store is not None and _from_store(store, key, stage / name):
                continue
            scene_file = stage / f"{k}.pkl"
            scene_file.write_bytes(pickle.dumps(scene))
            todo.append((str(scene_file), str(stage / name), camera))
        t0 = time.perf_counter()
        _render_all(todo, len(rows), size, jobs, executor, log, out)
        for r in rows:
            if "sha256" not in r:
                r["sha256"] = sha256_of(stage / r["file"])
        if store is not None:
            key_of = {r["file"]: r["key"] for r in rows}
            for _, png, _ in todo:
                _to_store(store, key_of[Path(png).name], Path(png))
        record = _run_record(seed, layout, size, cameras, code, len(todo), time.perf_counter() - t0, rows)
        _move_in(out, stage, record, names)
    finally:
        remove_staging(stage)
    return record


def picture_store() -> Path:
    """The render cache's pictures by the hash of their inputs (scene, camera, code:
    `_picture_key`), shared by every set of trials (`render_trials(store=...)`)."""
    return render_cache_dir() / "by-key"


def _from_store(store: Path, key: str, dest: Path) -> bool:
    """Copy the stored picture of `key` to `dest` (True), or False when the store has
    none (a regular file only: no link is followed)."""
    import shutil

    kept = regular_inside(Path(store), f"{key}.png")
    if kept is None:
        return False
    shutil.copyfile(kept, dest)
    return True


def _to_store(store: Path, key: str, png: Path) -> None:
    """Add a rendered picture to the store (lgp.atomic: written whole, then renamed in;
    one already there is left as it is: the same inputs rendered it)."""
    import shutil

    from lgp.atomic import atomic_path

    kept = Path(store) / f"{key}.png"
    if kept.exists():
        return
    with atomic_path(kept) as tmp:
        shutil.copyfile(png, tmp)


def _is_render_record(data) -> bool:
    return isinstance(data, dict) and "renderer" in data and isinstance(data.get("pictures"), list)


def _listed(record: dict) -> dict[str, set[str]]:
    """file -> sha256s a render record lists (its pictures and, in an interim record,
    the earlier run's)."""
    listed: dict[str, set[str]] = {}
    for p in record.get("pictures", []) + record.get("pictures_earlier", []):
        if isinstance(p, dict) and isinstance(p.get("file"), str) and isinstance(p.get("sha256"), str):
            listed.setdefault(p["file"], set()).add(p["sha256"])
    return listed


def _refuse_foreign(out: Path, names: list[str]) -> tuple[dict, dict[str, str]]:
    """(file -> row of the earlier run's record, file -> sha256 of the pictures still
    as an earlier run wrote them), or ForeignFiles before anything is written: a
    picture's name or renders.json holds what no render run wrote (a user's file, an
    edited picture, a renders.json of another program), or the folder holds the
    user's files and no render record."""
    status, record = read_manifest(out / "renders.json", _is_render_record)
    if status == "foreign":
        raise ForeignFiles(f"--out {out}: renders.json there is not a render record of {PROG}; nothing was written: "
                           "give a new or empty folder")
    if status == "absent":
        names_there = foreign_entries(out, limit=5)
        if names_there:
            raise ForeignFiles(f"--out {out} holds files no render run wrote ({describe(names_there, len(names_there) >= 5)}) "
                               "and no renders.json; nothing was written: give a new or empty folder")
        return {}, {}
    own = own_files(out, _listed(record))
    bad = collisions(out, names + ["renders.json"], set(own) | {"renders.json"})
    if bad:
        raise ForeignFiles(f"--out {out}: {describe(bad)} would replace what no render run wrote (or what changed since); "
                           "nothing was written: move it away and rerun")
    return {p["file"]: p for p in record["pictures"] if isinstance(p, dict) and "file" in p}, own


def _move_in(out: Path, stage: Path, record: dict, names: list[str]) -> None:
    """Move the new pictures from `stage` into `out` and write renders.json: an interim
    record listing the earlier run's pictures too comes first, so a process killed
    during the move leaves every picture provably a render run's own. Checks the
    folder again (a run beside this one may have written since)."""
    from lgp.atomic import write_json_atomic

    status, earlier = read_manifest(out / "renders.json", _is_render_record)
    if status == "foreign":
        raise ForeignFiles(f"--out {out}: renders.json changed into something not a render record while rendering; "
                           "nothing was moved")
    own = own_files(out, _listed(earlier)) if earlier else {}
    new = [r["file"] for r in record["pictures"] if (stage / r["file"]).exists()]
    bad = collisions(out, new, set(own))
    if bad:
        raise ForeignFiles(f"--out {out}: {describe(bad)} appeared while rendering and is not a render run's; nothing was moved")
    with signals_deferred():
        interim = dict(record, pictures_earlier=[{"file": f, "sha256": sha} for f, sha in sorted(own.items())])
        write_json_atomic(interim, out / "renders.json")
        for name in new:
            os.replace(stage / name, out / name)
        write_json_atomic(record, out / "renders.json")


def _render_all(todo: list, n_pictures: int, size, jobs: int, executor, log, out: Path) -> list[float]:
    """Render the pictures `todo` (of `n_pictures`), one chunk per process: the
    executor's warm workers, else fresh spawned processes when there are many
    pictures; seconds each. Says what it renders and what it reuses."""
    if not todo:
        log(f"all {n_pictures} pictures reused from {_where(out)}")
        return []
    seconds: list[float] = []
    if executor is not None:  # warm workers: a chunk costs one renderer (0.2 s) and its first picture's shaders
        jobs = max(1, min(getattr(executor, "jobs", 1), len(todo)))
    else:  # a fresh process costs a second or two to start (pydrake, shaders): worth it for many pictures only
        jobs = max(1, min(jobs, len(todo) // 8))
    kept = n_pictures - len(todo)
    log(f"rendering {len(todo)} of {n_pictures} pictures ({size[0]}x{size[1]}, RenderEngineVtk) with {jobs} process(es)"
        + (f"; {kept} reused from {_where(out)}" if kept else ""))
    chunks = [todo[i::jobs] for i in range(jobs)]
    if executor is not None:
        for s in executor.map(_render_chunk, chunks):
            seconds += s
    elif jobs == 1:
        seconds = _render_chunk(chunks[0])
    else:
        import multiprocessing as mp
        from concurrent.futures import ProcessPoolExecutor

        with ProcessPoolExecutor(jobs, mp_context=mp.get_context("spawn")) as pool:
            for s in pool.map(_render_chunk, chunks):
                seconds += s
    return seconds


def _run_record(seed: int, layout: str, size, cameras: dict, code: str, rendered: int, render_seconds: float,
                rows: list) -> dict:
    """The run's record (renders.json): renderer, seed, layout, cameras, code and every picture."""
    return {"renderer": "drake RenderEngineVtk (VTK OpenGL, offscreen)", "seed": seed, "layout": layout,
            "layout_of_A": ("sample 0 of the seed for every trial: models.effort.sample_rng(seed, 0)" if layout == "sample0" else
                            "a trial of pair p: sample p - 1 of the seed (models.effort.sample_rng(seed, p - 1)); no pair: sample 0"),
            "camera": {"elevation_deg": ELEVATION_DEG, "azimuth_deg": AZIMUTH_DEG, "fov_y_deg": FOV_Y_DEG,
                       "width": size[0], "height": size[1], "min_area_m": MIN_AREA,
                       "fit": "one camera per trial, the same for its A and B, framing both scenes (stimuli.render.trial_camera)"},
            "cameras": {tid: cam.as_dict() for tid, cam in cameras.items()},
            "code": code, "rendered": rendered, "render_seconds": round(render_seconds, 2),
            "pictures": rows}


def _where(folder: Path) -> str:
    """A render folder in words: the shared render cache (which every run and every
    checkout of this user reads) or the folder given."""
    try:
        inside = Path(folder).resolve().is_relative_to(render_cache_dir().resolve())
    except OSError:
        inside = False
    home = str(Path.home())
    text = str(folder)
    text = "~" + text[len(home):] if home != "/" and text.startswith(home + os.sep) else text
    return f"the render cache shared by every run and checkout ({text})" if inside else text


def render_cache_dir() -> Path:
    """Where rendered pictures are kept between runs: $LGP_RENDER_CACHE, else
    $XDG_CACHE_HOME/lgp-difficulty/renders (~/.cache/...). A picture is found again by
    the hash of its scene, camera and this package's code (renders.json), so a stale
    one is never used."""
    base = os.environ.get("LGP_RENDER_CACHE")
    if base:
        return Path(base)
    return Path(os.environ.get("XDG_CACHE_HOME") or Path.home() / ".cache") / "lgp-difficulty" / "renders"


def cache_folder(trials, seed: int, size, layout: str = "sample0") -> Path:
    """The render cache's folder for one set of trials, seed, picture size and layout
    of A (LAYOUTS)."""
    key = [[t.id, t.digest] for t in trials] + [seed, list(size)] + ([layout] if layout != "sample0" else [])
    key = hashlib.sha256(json.dumps(key).encode()).hexdigest()[:16]
    return render_cache_dir() / key


#: Contact sheet spacing (pixels): white between a trial's A and B, and between two trials
#: (with a grey rule down its middle), so that no two pictures touch.
SHEET_AB_GAP = 6
SHEET_TRIAL_GAP = 24
SHEET_LABEL = 16


def contact_sheet(out_dir: str | Path, path: str | Path, columns: int = 4, thumb: int = 320) -> Path:
    """All pictures of `out_dir`'s renders.json on one PNG (A | B per trial, labelled;
    SHEET_AB_GAP between A and B, SHEET_TRIAL_GAP and a grey rule between trials)."""
    from PIL import Image, ImageDraw

    out = Path(out_dir)
    record = json.loads((out / "renders.json").read_text())
    by_trial: dict[str, dict] = {}
    for p in record["pictures"]:
        by_trial.setdefault(p["trial"], {})[p["state"]] = out / p["file"]
    w = thumb
    h = round(thumb * record["camera"]["height"] / record["camera"]["width"])
    rows = -(-len(by_trial) // columns)
    cell = 2 * w + SHEET_AB_GAP  # one trial: A, gap, B
    sheet = Image.new("RGB", (columns * cell + (columns - 1) * SHEET_TRIAL_GAP,
                              rows * (h + SHEET_LABEL) + (rows - 1) * SHEET_AB_GAP), "white")
    draw = ImageDraw.Draw(sheet)
    for c in range(1, columns):  # a rule between trial columns
        x = c * (cell + SHEET_TRIAL_GAP) - SHEET_TRIAL_GAP // 2 - 1
        draw.rectangle((x, 0, x + 1, sheet.height - 1), fill=(160, 160, 160))
    for k, (tid, states) in enumerate(by_trial.items()):
        r, c = divmod(k, columns)
        for j, state in enumerate(("A", "B")):
            x, y = c * (cell + SHEET_TRIAL_GAP) + j * (w + SHEET_AB_GAP), r * (h + SHEET_LABEL + SHEET_AB_GAP)
            sheet.paste(Image.open(states[state]).convert("RGB").resize((w, h)), (x, y + SHEET_LABEL))
            draw.text((x + 4, y + 2), f"{tid}-{state} ({'Start' if state == 'A' else 'Finish'})", fill="black")
    sheet.save(path)
    return Path(path)
