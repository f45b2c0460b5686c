"""The 3-D replays of a reproduce run: ``<out>/replays/<trial>.html``, one per trial.

Each replay plans layout sample 0 of the run's seed again (the plan behind row
(trial, 0) of effort_samples.csv, `models.effort.plan_of_sample`) and records it
with `lgp.app.view.replay_html`; the Meshcat library the replays share is written
once beside them (REPLAY_LIBRARY). A replay made before with the same trial, seed,
design and code is copied from the run's cache.
"""
from __future__ import annotations

import logging
import shutil
from pathlib import Path

from lgp.app.cache import Cache, files_digest, input_key, library_versions, modules_digest
from lgp.app.files import write_text_atomic


#: The viewer's JavaScript library, shared by the replays of a run (3 MB; each replay
#: is then a few hundred kB of recording instead of 3 MB).
REPLAY_LIBRARY = "meshcat.min.js"
_LIB_TAG = '<script type="text/javascript">'


def split_library(page: str) -> tuple[str, str | None]:
    """(page with the inlined Meshcat library replaced by a relative <script src>, library)."""
    start = page.find(_LIB_TAG)
    end = page.find("</script>", start)
    if start < 0 or end < 0 or "MeshCat" not in page[start:start + 2000]:
        return page, None  # not the layout this expects: keep the page whole
    return page[:start] + f'<script src="{REPLAY_LIBRARY}"></script>' + page[end + len("</script>"):], page[start + len(_LIB_TAG):end]


def _replay_job(item) -> float:
    """Plan sample 0 of a trial and write its replay; returns the wall time (s)."""
    import time

    from lgp.app.view import replay_html
    from models.effort import plan_of_sample

    trial, seed, path, spec = item
    logging.getLogger("drake").setLevel(logging.WARNING)  # not a line per replay about Meshcat's port
    t0 = time.perf_counter()
    plan = plan_of_sample(trial, seed, 0, **spec.planner_options())
    title = f"{trial.id}: {trial.description} (sample 0 of seed {seed})"
    page, library = split_library(replay_html(plan, title, back=f"../index.html#trial-{trial.id}"))  # replays/<id>.html -> its card
    path = Path(path)
    if library is not None and not (path.parent / REPLAY_LIBRARY).exists():
        write_text_atomic(library, path.parent / REPLAY_LIBRARY)
    write_text_atomic(page, path)
    return time.perf_counter() - t0


def write_replays(trials, seed: int, out_dir, cache: Cache | None = None, executor=None, log=None,
                  spec=None) -> dict[str, Path]:
    """``<out_dir>/<trial>.html`` for every trial: the replay of layout sample 0 of `seed`
    (planned with the lgp.planner.EffortSpec `spec`; None: the paper's).

    One plan per trial (the one behind row (trial, 0) of effort_samples.csv); a replay
    made before with the same trial, seed and code is copied from `cache`.
    """
    from lgp.executor import SerialExecutor
    from lgp.planner import DEFAULT_EFFORT

    spec = DEFAULT_EFFORT if spec is None else spec
    out_dir = Path(out_dir)
    out_dir.mkdir(parents=True, exist_ok=True)
    drake = library_versions(("drake",))["drake"]
    version = input_key(code=modules_digest("lgp.app.replays", "lgp.app.view", "models.effort", "stimuli"),
                        data=files_digest("models/*.sdf", "models/*.urdf", "models/*.yaml"),
                        libraries=library_versions(("drake", "numpy", "scipy", "matplotlib")))
    paths, todo, cached = {}, [], {}
    for trial in trials:
        paths[trial.id] = out_dir / f"{trial.id}.html"
        if cache is not None and cache.enabled:
            key = input_key(trial=trial.id, digest=trial.digest, seed=seed, code=version, **spec.key())
            cached[trial.id] = cache.root / f"replay-{key}.html"
    lib = out_dir / REPLAY_LIBRARY
    lib_cache = cache.root / f"meshcat-{drake}.min.js" if cache is not None and cache.enabled else None
    if lib_cache is not None and lib_cache.exists():
        shutil.copyfile(lib_cache, lib)
    else:
        lib.unlink(missing_ok=True)  # the first job writes it, from this Drake
    for trial in trials:
        c = cached.get(trial.id)
        if c is not None and c.exists() and lib.exists():
            shutil.copyfile(c, paths[trial.id])
            cache.files["replay", "hit"] += 1
        else:
            todo.append(trial)
    if todo:
        times = (executor or SerialExecutor()).map(_replay_job, [(t, seed, str(paths[t.id]), spec) for t in todo])
        if log:
            log(f"[replays] {len(todo)} trials planned (sample 0) and recorded: {sum(times):.1f} s of work, "
                f"{max(times):.1f} s the longest")
        for trial in todo:
            if trial.id in cached:
                cached[trial.id].parent.mkdir(parents=True, exist_ok=True)
                shutil.copyfile(paths[trial.id], cached[trial.id])
                cache.files["replay", "miss"] += 1
        if lib_cache is not None and lib.exists():
            lib_cache.parent.mkdir(parents=True, exist_ok=True)
            shutil.copyfile(lib, lib_cache)
    return paths
