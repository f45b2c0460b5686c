"""What one run of `python -m lgp.reproduce` wrote, and how long its results took.

An output folder describes one run only, and a run deletes only what it can prove
an earlier run of its own wrote (lgp/owned.py): the files that run's manifest lists
whose bytes still have the listed sha256. A run writes its files into a staging
folder inside ``--out`` and swaps them in at the end; only then does it remove the
earlier run's own files that it did not write again. A folder with foreign content
and no manifest is refused (``--into-existing`` writes beside that content, deleting
nothing); a failed or stopped run leaves the earlier run's files byte-identical. The
cache (``<out>/cache``) is kept, so nothing expensive is lost and a rerun of the
earlier command rewrites its outputs in seconds. At the end it writes
``manifest.json``: the command's parameters, a hash of its inputs, the engine, both
times (see below) and every file it wrote (path, bytes, sha256). The list the
command prints is the manifest's.

Times: "this run" is the wall time of this command; "compute time of the
results" adds up, for every cached result the run used, the wall time spent
computing it when it was computed (kept in ``<out>/cache/compute_times.json``),
so a cached rerun reports both the seconds it took and what the numbers cost.
"""
from __future__ import annotations

import hashlib
import json
import math
import os
import stat
import time
from pathlib import Path

from lgp import owned
from lgp.app.cache import Cache
from lgp.app.files import write_json_atomic

MANIFEST = "manifest.json"
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


#: Largest manifest read (bytes): a full run lists a few hundred files.
MAX_MANIFEST_BYTES = owned.MAX_MANIFEST_BYTES
#: The files every run writes at the top of its folder: one of them that is not an
#: earlier run's own (a user's report.md) refuses the run before any work.
ALWAYS_WRITTEN = ("effort_samples.csv", "effort.csv", "risk.csv", "risk_precision.csv", "report.md", "index.html")
PROG = "python -m lgp.reproduce"


def is_run_manifest(data: dict) -> bool:
    """A manifest.json written by python -m lgp.reproduce (its command and file list)."""
    command = data.get("command")
    return isinstance(data.get("files"), list) and isinstance(command, list) and bool(command) and command[0] == PROG


def check_output_folder(out: Path, into_existing: bool = False) -> dict[str, set[str]]:
    """The earlier run's listed files in `out` (lgp.owned.manifest_entries; {} for
    none), once `out` is known to be a folder this run may write into; else
    ForeignFiles (one line, exit 2), before any work:

    - a manifest.json that is not this command's (or is damaged): refused;
    - no manifest and anything but a cache in the folder: refused, unless
      `into_existing` (--into-existing), which writes beside the foreign files;
    - a file this run always writes (ALWAYS_WRITTEN) there and not the earlier run's own.
    """
    out = Path(out)
    if not out.exists():
        return {}
    status, data = owned.read_manifest(out / MANIFEST, is_run_manifest)
    if status == "foreign":
        raise owned.ForeignFiles(f"--out {out}: its {MANIFEST} was not written by {PROG} (or is damaged): refusing to "
                                 "replace it; give another --out")
    entries = owned.manifest_entries(data) if data else {}
    if status == "absent":
        foreign = owned.foreign_entries(out, skip={"cache", OutputLock.NAME})
        if foreign and not into_existing:
            raise owned.ForeignFiles(
                f"--out {out} holds files no run of {PROG} wrote ({owned.describe(foreign)}) and no {MANIFEST}: "
                "refusing to write into it; give a new or empty folder, or --into-existing to add this run's files "
                "beside them (nothing there is deleted or overwritten)")
    bad = owned.collisions(out, list(ALWAYS_WRITTEN), set(owned.own_files(out, entries)))
    if bad:
        raise owned.ForeignFiles(f"--out {out}: {owned.describe(bad)} there {'is' if len(bad) == 1 else 'are'} not "
                                 f"an earlier run's output (not listed in its {MANIFEST} with these contents); this "
                                 f"run would overwrite {'it' if len(bad) == 1 else 'them'}: move "
                                 f"{'it' if len(bad) == 1 else 'them'} away or give another --out")
    return entries


class OutputFolderBusy(RuntimeError):
    """Another run holds the output folder's lock."""


def checked_before_the_lock(check, out, *args):
    """`check(out, *args)` (a command's refusal of a folder it may not write into),
    made early, before the command takes the folder's OutputLock. Made without the
    lock it may see a holder's files half written (its staging folder before its
    mark): when it refuses and another run holds the folder, that run is named
    instead (OutputFolderBusy), as the lock itself would."""
    try:
        return check(out, *args)
    except Exception:
        OutputLock(out).refuse_if_held()
        raise


class OutputLock:
    """An exclusive lock on an output folder for a whole run: ``<out>/.lgp-run.lock``,
    locked with flock (so the kernel releases it on any exit, ``kill -9``
    included) and holding the holder's pid and command. A second run in the same
    folder raises OutputFolderBusy naming that process. The holder removes the
    file on its way out, while still holding the lock; a run that locks a file
    checks that it is still the one at that path (else it retries), so two runs
    never hold two files. A killed run leaves an unlocked file: it is free.
    It also holds lgp.owned.TreeLock: a run in a folder inside this one, or around
    it, is refused the same way (two runs in rn and rn/figures cannot both proceed)."""

    NAME = ".lgp-run.lock"

    def __init__(self, out: Path, command: str = ""):
        self.path = Path(out) / self.NAME
        self.command = command
        self._fd = None

    def __enter__(self):
        import fcntl

        while True:
            self._check_kind()
            fd = os.open(self.path, os.O_RDWR | os.O_CREAT | getattr(os, "O_CLOEXEC", 0) | getattr(os, "O_NOFOLLOW", 0)
                         | os.O_NONBLOCK, 0o644)
            if not stat.S_ISREG(os.fstat(fd).st_mode):  # swapped in after the check
                os.close(fd)
                self._check_kind()
                continue
            try:
                fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
            except BlockingIOError:
                message = self._busy(fd)
                os.close(fd)
                raise OutputFolderBusy(message) from None
            try:  # the holder we waited on may have removed the file as we opened it: lock the one on disk
                same = os.stat(self.path, follow_symlinks=False).st_ino == os.fstat(fd).st_ino
            except FileNotFoundError:
                same = False
            if same:
                break
            os.close(fd)
        os.ftruncate(fd, 0)
        os.pwrite(fd, f"{os.getpid()}\n{self.command}\n".encode(), 0)
        self._fd = fd
        self._tree = owned.TreeLock(self.path.parent, self.command)
        try:  # and no run in a folder inside this one or around it (issue 30)
            self._tree.__enter__()
        except owned.OutputTreeBusy as e:
            self._tree = None
            self.__exit__()
            raise OutputFolderBusy(str(e)) from None
        return self

    def _busy(self, fd: int) -> str:
        """What a run refused by the holder of `fd`'s lock is told: who holds it."""
        holder = os.pread(fd, 4096, 0).decode("utf-8", "replace").strip().splitlines()
        pid = holder[0] if holder else "?"
        what = f": {holder[1]}" if len(holder) > 1 else ""
        return f"{self.path.parent} is in use by another run (process {pid}{what}); wait for it to end or give another --out"

    def refuse_if_held(self) -> None:
        """OutputFolderBusy if another run holds this folder's lock now; creates
        nothing (no lock file: not held). For `checked_before_the_lock`."""
        import fcntl

        try:
            fd = os.open(self.path, os.O_RDONLY | getattr(os, "O_NOFOLLOW", 0) | os.O_NONBLOCK)
        except OSError:  # absent, a link, unreadable: no run of ours holds it
            return
        try:
            if not stat.S_ISREG(os.fstat(fd).st_mode):
                return
            try:
                fcntl.flock(fd, fcntl.LOCK_SH | fcntl.LOCK_NB)
            except BlockingIOError:
                raise OutputFolderBusy(self._busy(fd)) from None
        finally:
            os.close(fd)  # closing releases a lock taken here

    def _check_kind(self) -> None:
        """The lock file must be a regular file (or absent): a FIFO, a device, a
        directory or a symbolic link at its path is named, not opened (issue 30:
        a FIFO gave "[Errno 22] Invalid argument" with no path)."""
        from lgp.cli import path_kind

        if os.path.islink(self.path):
            raise OutputFolderBusy(f"{self.path}: a symbolic link (to {os.readlink(self.path)}), not the lock file a "
                                   "run makes (a regular file); remove it and rerun")
        kind = path_kind(self.path) or ("a directory" if self.path.is_dir() else None)
        if kind is not None:
            raise OutputFolderBusy(f"{self.path}: {kind}, not the lock file a run makes (a regular file); remove it "
                                   "and rerun")

    def __exit__(self, *exc):
        if getattr(self, "_tree", None) is not None:
            self._tree.__exit__()
            self._tree = None
        if self._fd is not None:
            try:
                os.unlink(self.path)  # while still locked, so no one can lock the old file after us
            except FileNotFoundError:
                pass
            os.close(self._fd)  # closing releases the flock
            self._fd = None
        return False


#: Settings of a run that say where and how it ran, not what it computed: left out of its input hash.
PLACEMENT = ("out", "jobs", "scheduler", "verbose", "into_existing", "risk_chunk", "no_replays", "max_participants")


def _json_value(v):
    """A setting as the manifest holds it: tuples as lists, a value without a JSON form (a Budget) as its repr."""
    if isinstance(v, tuple):
        return [_json_value(x) for x in v]
    return v if v is None or isinstance(v, (bool, int, float, str)) else repr(v)


def manifest_record(result, run_time_s: float) -> dict:
    """What manifest.json says of a RunResult besides its files: the parameters
    (RunConfig.parameters, with the trials the run resolved and the pair table's
    sigma), the inputs, their hash, the engine, the software and the times."""
    from dataclasses import replace

    from lgp.app.report import engine_description

    config, record = result.config, result.record
    parameters = {k: _json_value(v) for k, v in replace(config, trials=tuple(t.id for t in result.trials)).parameters().items()}
    parameters["sigma_of_pairs"] = result.sigma if result.pairs is not None else None
    inputs = record.inputs
    return dict(parameters=parameters, inputs=inputs,
                input_hash=input_hash(**{k: v for k, v in parameters.items() if k not in PLACEMENT}, **inputs),
                engine=engine_description(config.engine, record.software["engine"]), software=record.software,
                run_time_s=run_time_s, compute_time_s=round(record.compute[0], 1),
                compute_time_unknown_results=record.compute[1])


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
            from lgp.inputs import read_bounded

            data = read_bounded(self._times_path, MAX_MANIFEST_BYTES, "compute-times file", within=self.root)
            times = json.loads(data)
        except (OSError, ValueError):
            return {}
        if not isinstance(times, dict):
            return {}
        # only finite, non-negative numbers of seconds: {"x": null} or "abc" is dropped, not a crash
        return {str(k): float(v) for k, v in times.items()
                if isinstance(v, (int, float)) and not isinstance(v, bool) and math.isfinite(v) and v >= 0}

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
