"""What one run of `python -m lgp.reproduce` wrote, and how long its results took.

An output folder describes one run only. Before the expensive stages a run
removes what an earlier run left in the folder (the files its manifest lists,
and the pipeline's own names for a folder written before manifests existed:
effort_samples.csv, effort.csv, risk.csv, pairs.csv, report.md, index.html,
build_risk*.csv, [simulated_]participant_sigma.csv, risk_sensitivity*.csv,
effort_sensitivity*.csv, figures/, analysis/, replays/, page/); the cache
(``<out>/cache``) is kept, so nothing expensive is lost and a rerun of the earlier command rewrites its outputs in seconds. At the end it
writes ``manifest.json``: the command's parameters, a hash of its inputs, the
engine, both times (see below) and every file it wrote (path, bytes, sha256).
The list the command prints is the manifest's.

Times: "this run" is the wall time of this command; "compute time of the
results" adds up, for every cached result the run used, the wall time spent
computing it when it was computed (kept in ``<out>/cache/compute_times.json``),
so a cached rerun reports both the seconds it took and what the numbers cost.
"""
from __future__ import annotations

import hashlib
import json
import shutil
import time
from pathlib import Path

from lgp.app.cache import Cache
from lgp.app.files import write_json_atomic

MANIFEST = "manifest.json"
#: What the pipeline writes at the top of an output folder (besides the manifest and the cache).
OUTPUT_NAMES = ("effort_samples.csv", "effort.csv", "risk.csv", "pairs.csv", "report.md", "index.html",
                "build_risk_stages.csv", "build_risk.csv", "build_risk_pairs.csv", "participant_sigma.csv",
                "simulated_participant_sigma.csv",
                "risk_sensitivity.csv", "risk_sensitivity_summary.csv", "effort_sensitivity.csv",
                "effort_sensitivity_pairs.csv",
                "figures", "analysis", "replays", "page")
TIMES = "compute_times.json"


def file_sha256(path: str | Path) -> str:
    h = hashlib.sha256()
    with open(path, "rb") as f:
        for block in iter(lambda: f.read(1 << 20), b""):
            h.update(block)
    return h.hexdigest()


def input_hash(**inputs) -> str:
    """sha256 of the JSON of everything a run's results depend on."""
    return hashlib.sha256(json.dumps(inputs, sort_keys=True, default=str).encode()).hexdigest()


def clear_previous(out: Path) -> list[str]:
    """Remove the outputs of an earlier run from `out` (never the cache); return what went."""
    out = Path(out)
    listed: list[str] = []
    manifest = out / MANIFEST
    if manifest.is_file():
        try:
            listed = [f["path"] for f in json.loads(manifest.read_text()).get("files", [])]
        except (ValueError, KeyError, TypeError):
            listed = []  # a damaged manifest: fall back on the pipeline's names
    removed = []
    for name in [*listed, *OUTPUT_NAMES, MANIFEST]:
        path = out / name
        if Path(name).is_absolute() or ".." in Path(name).parts or path.resolve() == (out / "cache").resolve():
            continue  # a manifest only ever lists files inside the folder
        if path.is_dir() and name in OUTPUT_NAMES:
            shutil.rmtree(path)
        elif path.is_file() or path.is_symlink():
            path.unlink()
        else:
            continue
        removed.append(name)
    dirs = {name for name in removed if name in OUTPUT_NAMES and not name.endswith((".csv", ".md", ".html"))}
    return sorted({name for name in removed if Path(name).parts[0] not in dirs or name in dirs})


def write_manifest(out: Path, files: list[Path], **record) -> Path:
    """Write ``<out>/manifest.json`` listing `files` (paths inside `out`) and `record`."""
    out = Path(out)
    entries = []
    for path in files:
        path = Path(path)
        entries.append({"path": path.resolve().relative_to(out.resolve()).as_posix(),
                        "bytes": path.stat().st_size, "sha256": file_sha256(path)})
    return write_json_atomic({**record, "files": entries}, out / MANIFEST)


def expand(paths) -> list[Path]:
    """Files of `paths`, directories replaced by the files in them (sorted)."""
    files = []
    for path in map(Path, paths):
        files += sorted(p for p in path.rglob("*") if p.is_file()) if path.is_dir() else [path]
    return files


class TimedCache(Cache):
    """A Cache that notes which entries a run used and how long fresh ones took.

    Every access to an entry goes through `path`, so recording it there sees the
    entries a stage read or wrote whatever the stage's code looks like. Call
    `stage()` around a stage: entries written during it are fresh, and each gets
    the wall time from the previous one's completion (or the stage start), so the
    fresh entries of a stage add up to its wall time.
    """

    def __init__(self, *args, **kwargs):
        super().__init__(*args, **kwargs)
        self.used: dict[str, Path] = {}
        self._times_path = self.root / TIMES

    def path(self, kind: str, key: str) -> Path:
        path = super().path(kind, key)
        self.used[path.name] = path
        return path

    def load_times(self) -> dict[str, float]:
        try:
            return {str(k): float(v) for k, v in json.loads(self._times_path.read_text()).items()}
        except (OSError, ValueError, AttributeError):
            return {}

    def stage(self):
        cache = self

        class _Stage:
            def __enter__(self):
                self.t0 = time.time()
                self.before = set(cache.used)
                return self

            def __exit__(self, *exc):
                fresh = sorted(((p.stat().st_mtime, name) for name, p in cache.used.items()
                                if p.exists() and p.stat().st_mtime >= self.t0 - 1e-3), key=lambda x: x[0])
                if not fresh:
                    return False
                times, last = cache.load_times(), self.t0
                for mtime, name in fresh:
                    times[name] = round(max(mtime - last, 0.0), 3)
                    last = max(last, mtime)
                cache.root.mkdir(parents=True, exist_ok=True)
                write_json_atomic(times, cache._times_path)
                return False

        return _Stage()

    def compute_time(self) -> tuple[float, int]:
        """Seconds spent computing the entries this run used, and how many entries
        had no recorded time (computed by a version that did not record it)."""
        times = self.load_times()
        known = [times[name] for name in self.used if name in times and self.used[name].exists()]
        unknown = sum(1 for name, p in self.used.items() if p.exists() and name not in times)
        return float(sum(known)), unknown
