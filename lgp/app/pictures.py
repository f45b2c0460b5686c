"""The trial pictures of the results page: ``<out>/page/<trial>.png``, A (the layout
of sample 0 of the run's seed, as the replay plays it) and B side by side, drawn
on matplotlib's own Figure and copied from the run's cache when drawn before.
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
    from stimuli.sheet import draw_scene

    A = trial.sample_initial(sample_rng(seed, 0))
    fig = Figure(figsize=(4.4, 2.2))
    FigureCanvasAgg(fig)
    for j, (scene, state) in enumerate(((A, "A: start (sample 0)"), (trial.target, "B: finish"))):
        ax = fig.add_subplot(1, 2, j + 1, projection="3d")
        draw_scene(ax, scene, state)
    fig.subplots_adjust(left=0.0, right=1.0, bottom=0.0, top=0.92, wspace=0.0)
    with atomic_path(path) as tmp:
        fig.savefig(tmp, dpi=100)
    return path


def trial_pictures(trials, seed: int, out_dir: Path, cache: Cache | None = None) -> dict[str, Path]:
    """Picture of every trial under `out_dir`, copied from `cache` when drawn before."""
    version = modules_digest("stimuli.sheet", "stimuli", "models.effort")
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
