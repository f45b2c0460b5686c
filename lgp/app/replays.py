"""The 3-D replays of a reproduce run: ``<out>/replays/<trial>.html``, one per trial.

Each replay records the plan of layout sample 0 of the run's seed (the plan behind
row (trial, 0) of effort_samples.csv, `models.effort.plan_of_sample`) with
`lgp.app.view.replay_html`; the Meshcat library the replays share is written once
beside them (REPLAY_LIBRARY). Where the effort stage plans that sample in this run,
its worker records the replay from the same plan (`effort_job`), so it is planned
once; otherwise the replay stage plans it again (`_replay_job`). A replay made
before with the same trial, seed, design and code is copied from the run's cache.
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


def replay_page(plan, trial, seed: int) -> tuple[str, str | None]:
    """(page, Meshcat library or None) of the replay of `plan`, sample 0 of `trial`."""
    from lgp.app.view import replay_html

    logging.getLogger("drake").setLevel(logging.WARNING)  # not a line per replay about Meshcat's port
    title = f"{trial.id}: {trial.description} (sample 0 of seed {seed})"
    return split_library(replay_html(plan, title, back=f"../index.html#trial-{trial.id}"))  # replays/<id>.html -> its card


def effort_job(item) -> tuple[dict, tuple[str, str | None] | None]:
    """A worker's unit of the effort stage (lgp.app.stages.effort_tables) in a run that
    writes replays: (unit, replay, library) -> (its effort row, and when `replay` the
    replay page of the same plan with, when `library`, the Meshcat library (3 MB,
    asked of one unit only); else None). One plan for both."""
    from models.effort import effort_of_unit, effort_row, plan_of_sample

    unit, replay, library = item
    if not replay:
        return effort_of_unit(unit), None
    plan = plan_of_sample(unit.trial, unit.seed, unit.sample, **unit.spec.planner_options())
    page, lib = replay_page(plan, unit.trial, unit.seed)
    return effort_row(unit.trial, unit.seed, unit.sample, plan), (page, lib if library else None)


def _write_page(page: str, library: str | None, path: Path) -> None:
    if library is not None and not (path.parent / REPLAY_LIBRARY).exists():
        write_text_atomic(library, path.parent / REPLAY_LIBRARY)
    write_text_atomic(page, path)


def _replay_job(item) -> float:
    """Plan sample 0 of a trial and write its replay; returns the wall time (s)."""
    import time

    from models.effort import plan_of_sample

    trial, seed, path, spec = item
    t0 = time.perf_counter()
    plan = plan_of_sample(trial, seed, 0, **spec.planner_options())
    _write_page(*replay_page(plan, trial, seed), Path(path))
    return time.perf_counter() - t0


def replay_cache_paths(trials, seed: int, cache: Cache | None, spec=None) -> dict[str, Path]:
    """{trial id: the run cache's file of its replay} (empty without a cache)."""
    from lgp.planner import DEFAULT_EFFORT

    if cache is None or not cache.enabled:
        return {}
    spec = DEFAULT_EFFORT if spec is None else spec
    version = input_key(code=modules_digest("lgp.app.replays", "lgp.app.view", "models.effort", "stimuli"),
                        data=files_digest("models/*.sdf", "models/*.urdf", "models/*.yaml"),
                        libraries=library_versions(("drake", "numpy", "scipy", "matplotlib")))
    return {t.id: cache.root / f"replay-{input_key(trial=t.id, digest=t.digest, seed=seed, code=version, **spec.key())}.html"
            for t in trials}


def replays_to_make(trials, cached: dict[str, Path]) -> set[str]:
    """Ids of the trials whose replay the run's cache does not hold (`cached`:
    replay_cache_paths; the effort stage records these from its own plans of sample
    0: `effort_job`)."""
    return {t.id for t in trials if not (t.id in cached and cached[t.id].exists())}


def write_replays(trials, seed: int, out_dir, cache: Cache | None = None, executor=None, log=None,
                  spec=None, made: dict | None = None, cached: dict[str, Path] | None = None) -> dict[str, Path]:
    """``<out_dir>/<trial>.html`` for every trial: the replay of layout sample 0 of `seed`
    (planned with the lgp.planner.EffortSpec `spec`; None: the paper's).

    One plan per trial (the one behind row (trial, 0) of effort_samples.csv); a replay
    made before with the same trial, seed and code is copied from `cache`; `made`
    ({trial id: replay_page}) holds the pages the effort stage recorded from its own
    plans, written as they are; the others are planned again. `cached`: the cache's
    replay files (replay_cache_paths), if the caller has them.
    """
    from lgp.executor import SerialExecutor
    from lgp.planner import DEFAULT_EFFORT

    spec = DEFAULT_EFFORT if spec is None else spec
    made = made or {}
    out_dir = Path(out_dir)
    out_dir.mkdir(parents=True, exist_ok=True)
    drake = library_versions(("drake",))["drake"]
    cached = replay_cache_paths(trials, seed, cache, spec) if cached is None else cached
    paths, todo = {trial.id: out_dir / f"{trial.id}.html" for trial in trials}, []
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
        recorded = [t for t in todo if t.id in made]
        for trial in recorded:
            _write_page(*made[trial.id], paths[trial.id])
        planned = [t for t in todo if t.id not in made]
        times = (executor or SerialExecutor()).map(_replay_job, [(t, seed, str(paths[t.id]), spec) for t in planned]) if planned else []
        if log and recorded:
            log(f"[replays] {len(recorded)} trials recorded from the effort stage's plans of sample 0")
        if log and planned:
            log(f"[replays] {len(planned)} trials planned (sample 0) and recorded: {sum(times):.1f} s of work, "
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
