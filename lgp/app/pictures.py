"""The trial pictures of the results page: ``<out>/page/<trial>.png``, A (the layout
of sample 0 of the run's seed, as the replay plays it) and B side by side: rendered
by stimuli.render (`rendered_trial_pictures`, what the page uses), or drawn on
matplotlib's own Figure on one world frame (`trial_pictures`, stimuli.sheet.draw_trial,
where the renderer cannot run) and copied from the run's cache when drawn before.
"""
from __future__ import annotations

import shutil
from pathlib import Path

from lgp.app.cache import Cache, input_key, modules_digest
from lgp.app.files import atomic_path


def trial_picture(trial, seed: int, path: Path) -> Path:
    """A (the layout of sample 0 of `seed`, as the replay shows it) and B, side by side."""
    from matplotlib.backends.backend_agg import FigureCanvasAgg
    from matplotlib.figure import Figure

    from models.effort import sample_rng
    from stimuli.sheet import draw_trial

    A = trial.sample_initial(sample_rng(seed, 0))
    fig = Figure(figsize=(4.4, 2.2))
    FigureCanvasAgg(fig)
    # one world frame for A and B (the table, the build site as a dashed ring): a moved structure is seen to
    # move; B shows the blocks A leaves (stimuli.sheet.finished_scene)
    draw_trial(fig, trial, A, ("Start (A, sample 0)", "Finish (B)"))
    fig.subplots_adjust(left=0.0, right=1.0, bottom=0.0, top=0.92, wspace=0.0)
    with atomic_path(path) as tmp:
        fig.savefig(tmp, dpi=100)
    return path


def trial_pictures(trials, seed: int, out_dir: Path, cache: Cache | None = None) -> dict[str, Path]:
    """Picture of every trial under `out_dir`, copied from `cache` when drawn before."""
    version = modules_digest("stimuli.sheet", "stimuli", "models.effort", "lgp.app.pictures")
    paths = {}
    for trial in trials:
        path = Path(out_dir) / f"{trial.id}.png"
        cached = None
        if cache is not None and cache.enabled:
            cached = cache.root / f"picture-{input_key(trial=trial.id, digest=trial.digest, seed=seed, code=version)}.png"
            if cached.exists():
                path.parent.mkdir(parents=True, exist_ok=True)
                shutil.copyfile(cached, path)
                cache.files["picture", "hit"] += 1
                paths[trial.id] = path
                continue
        trial_picture(trial, seed, path)
        if cached is not None:
            cached.parent.mkdir(parents=True, exist_ok=True)
            shutil.copyfile(path, cached)
            cache.files["picture", "miss"] += 1
        paths[trial.id] = path
    return paths


#: Size (pixels) of each half of a rendered trial card picture.
CARD_PICTURE = (480, 320)


def _label_font():
    """(font, header height in px) of a card's A/B labels: Pillow's own scalable font
    at 26 px, 14 px or more where the page shows the card (560 px wide and up); the
    old bitmap font (11 px) where Pillow is older than 10.1."""
    from PIL import ImageFont

    try:
        return ImageFont.load_default(size=26), 36
    except TypeError:  # Pillow < 10.1: no size
        return ImageFont.load_default(), 18


def rendered_trial_pictures(trials, seed: int, out_dir: Path, cache: Cache | None = None, jobs: int = 2,
                            executor=None) -> dict[str, Path]:
    """Picture of every trial under `out_dir`: A (sample 0 of `seed`) | B rendered like
    photographs (stimuli.render: an oblique camera per trial, the same for A and B, so
    a tower's height shows and a relocated tower looks relocated; B the finished table), kept in the render cache
    (stimuli.render.render_cache_dir, shared with stimuli.experiment) between runs.
    Where the renderer cannot run (no OpenGL), the sketches of `trial_pictures`,
    saying why on stderr. `executor`: a running local lgp.executor to render on
    (stimuli.render.render_trials)."""
    import sys

    from PIL import Image, ImageDraw

    from stimuli.render import cache_folder, picture_store, render_trials

    where = cache_folder(trials, seed, CARD_PICTURE)
    try:  # a trial's pictures rendered for another set of trials are copied from the store, not rendered again
        record = render_trials(trials, where, seed, CARD_PICTURE, jobs, log=lambda m: None, executor=executor,
                               store=picture_store())
    except Exception as e:  # noqa: BLE001 - any failure of VTK/OpenGL: the sketch still serves
        print(f"lgp.reproduce: trial pictures: rendering failed ({type(e).__name__}: {e}); drawing sketches instead",
              file=sys.stderr, flush=True)
        return trial_pictures(trials, seed, out_dir, cache)
    if cache is not None:
        cache.files["picture", "miss"] += record["rendered"]
        cache.files["picture", "hit"] += len(record["pictures"]) - record["rendered"]
    w, h = CARD_PICTURE
    font, top = _label_font()
    paths = {}
    for trial in trials:
        card = Image.new("RGB", (2 * w + 4, h + top), "white")
        draw = ImageDraw.Draw(card)
        for j, (state, label) in enumerate((("A", "Start (A, sample 0)"), ("B", "Finish (B)"))):
            card.paste(Image.open(where / f"{trial.id}-{state}.png").convert("RGB"), (j * (w + 4), top))
            draw.text((j * (w + 4) + 6, 4), label, fill="black", font=font)
        path = Path(out_dir) / f"{trial.id}.png"
        path.parent.mkdir(parents=True, exist_ok=True)
        with atomic_path(path) as tmp:
            card.save(tmp, format="PNG")
        paths[trial.id] = path
    return paths


def png_size(path: Path) -> tuple[int, int] | None:
    """(width, height) of a PNG from its header (24 bytes), None if it is not one."""
    try:
        with open(path, "rb") as fh:
            head = fh.read(24)
    except OSError:
        return None
    if len(head) < 24 or head[:8] != b"\x89PNG\r\n\x1a\n":
        return None
    return int.from_bytes(head[16:20], "big"), int.from_bytes(head[20:24], "big")
