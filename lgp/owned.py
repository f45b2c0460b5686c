"""What a command can prove it wrote, how a new run's files replace an earlier
run's, and locks that cover nested output folders.

A command that writes a folder of outputs (``python -m lgp.reproduce``: manifest.json;
``python -m stimuli.experiment``: study.json) lists every file it wrote, with its
sha256, in that folder's manifest. The rule, written once here:

- **Own files.** A file is the command's own when the manifest of an earlier run
  lists it and its bytes still hash to the listed sha256: a regular file, inside
  the folder, reached through no symbolic link. Nothing else is ever deleted or
  overwritten: the user's files, a study's collected data, an output edited since
  the run wrote it, anything behind a link.
- **Staging and swap.** A run writes its files into a staging folder inside the
  output folder (``.lgp-new-XXXXXXXX``, marked by a ``.lgp-staging`` file) and moves
  them in only when all are written (`swap_in`): it first writes an interim
  manifest listing both runs' files (so a process killed half way through the move
  leaves every file provably its own), removes the earlier run's own files that the
  new run did not write again, renames the new files in and writes the new
  manifest last. Ctrl-C and SIGTERM wait until the move is done. A run that fails
  or is stopped before then removes its staging folder: the earlier run's files
  are left byte-identical.
- **Collisions.** A new file whose path holds something that is not the command's
  own (or that lies under a link or a file) is refused, before anything moves.
- **Locks over a tree** (`TreeLock`): a run holds an exclusive lock on its
  folder's resolved path and shared locks on every folder above it, as flock locks
  on files in one lock folder per user (``/tmp/lgp-run-locks-<uid>``); so a run in
  ``rn`` and one in ``rn/figures`` cannot both proceed, whichever starts first.
"""
from __future__ import annotations

import hashlib
import json
import os
import shutil
import signal
import stat
import tempfile
from contextlib import contextmanager
from pathlib import Path, PurePosixPath

from lgp.errors import InputError

STAGING_PREFIX = ".lgp-new-"
MARK = ".lgp-staging"
#: Largest manifest read (bytes): a full run lists a few hundred files.
MAX_MANIFEST_BYTES = 16 * 2**20


class ForeignFiles(InputError):
    """The output folder holds files the command cannot prove it wrote, where it would
    have to delete or overwrite them (a command line: one line, exit 2)."""


# ----------------------------------------------------------------------------- own files


def regular_inside(root: Path, rel: str) -> Path | None:
    """`root/rel` when it is a regular file reached through real folders only (no
    symbolic link on the way, the file itself none), `rel` relative and without
    '..'; else None."""
    pure = PurePosixPath(str(rel))
    if not str(rel).strip() or pure.is_absolute() or any(p in ("..", ".") for p in pure.parts):
        return None
    path = Path(root)
    for i, part in enumerate(pure.parts):
        path = path / part
        try:
            mode = os.lstat(path).st_mode
        except OSError:
            return None
        if i == len(pure.parts) - 1:
            return path if stat.S_ISREG(mode) else None
        if not stat.S_ISDIR(mode):
            return None
    return None


def sha256_of(path: Path) -> str | None:
    """sha256 of a regular file, opened without following a link or blocking on a
    FIFO swapped in; None when it cannot be read as one."""
    try:
        fd = os.open(path, os.O_RDONLY | os.O_NONBLOCK | getattr(os, "O_NOFOLLOW", 0) | getattr(os, "O_CLOEXEC", 0))
    except OSError:
        return None
    try:
        if not stat.S_ISREG(os.fstat(fd).st_mode):
            return None
        h = hashlib.sha256()
        while block := os.read(fd, 1 << 20):
            h.update(block)
        return h.hexdigest()
    except OSError:
        return None
    finally:
        os.close(fd)


def _pairs(files):
    if isinstance(files, dict):
        yield from files.items()
    elif isinstance(files, list):
        for f in files:
            if isinstance(f, dict):
                yield f.get("path"), f.get("sha256")


def manifest_entries(data: dict) -> dict[str, set[str]]:
    """Listed path -> sha256s, from a manifest's "files" (a list of {path, sha256}
    or a mapping path -> sha256) and "files_earlier" (an interim manifest's earlier run)."""
    entries: dict[str, set[str]] = {}
    for key in ("files", "files_earlier"):
        for path, sha in _pairs(data.get(key)):
            if isinstance(path, str) and isinstance(sha, str) and len(sha) == 64:
                entries.setdefault(path, set()).add(sha.lower())
    return entries


def read_manifest(path: Path, is_ours) -> tuple[str, dict | None]:
    """("absent" | "ours" | "foreign", the parsed manifest when ours). `is_ours(data)`
    says whether a parsed JSON object is this command's manifest."""
    from lgp.inputs import InputFileError, read_bounded

    if not (path.exists() or path.is_symlink()):
        return "absent", None
    if path.is_symlink():
        return "foreign", None
    try:
        data = json.loads(read_bounded(path, MAX_MANIFEST_BYTES, "manifest", within=path.parent))
    except (InputFileError, ValueError, OSError):
        return "foreign", None
    if not isinstance(data, dict) or not is_ours(data):
        return "foreign", None
    return "ours", data


def own_files(root: Path, entries: dict[str, set[str]]) -> dict[str, str]:
    """The listed files that are still what the run wrote: path -> sha256."""
    own = {}
    for rel, shas in entries.items():
        path = regular_inside(root, rel)
        if path is not None:
            sha = sha256_of(path)
            if sha in shas:
                own[PurePosixPath(rel).as_posix()] = sha
    return own


def foreign_entries(root: Path, skip=(), limit: int = 5) -> list[str]:
    """Up to `limit` top-level names in `root` that no run of the command wrote:
    everything but the names in `skip` and staging folders (`is_staging`)."""
    found = []
    try:
        names = sorted(os.listdir(root))
    except FileNotFoundError:
        return []
    for name in names:
        if name in skip or is_staging(Path(root) / name):
            continue
        found.append(name)
        if len(found) >= limit:
            break
    return found


def refuse_foreign_folder(out: Path, record: str, what: str = "--out", is_ours=None) -> None:
    """ForeignFiles if `out` holds anything but is not a folder an earlier run of the
    command wrote: no `record` file there (the file such a run writes, e.g. its
    summary.json), or one that `is_ours(path)` (`json_record`, `csv_record`) says
    is not the command's (a user's own summary.json). For commands that write into
    their folder without a manifest: they never write beside a user's files."""
    out = Path(out)
    path = out / record
    if regular_inside(out, record) is not None:
        if is_ours is None or is_ours(path):
            return
        raise ForeignFiles(f"{what} {out}: its {record} was not written by this command (it is not its record); "
                           "nothing was written: give a new or empty folder")
    names = foreign_entries(out, limit=5)
    if names:
        raise ForeignFiles(f"{what} {out} holds files no run of this command wrote ({describe(names, len(names) >= 5)}) "
                           f"and no {record}; give a new or empty folder")


def json_record(*keys: str):
    """`is_ours` for refuse_foreign_folder: a JSON object holding every key in `keys`."""
    return lambda path: read_manifest(Path(path), lambda data: all(k in data for k in keys))[0] == "ours"


def csv_record(*columns: str):
    """`is_ours` for refuse_foreign_folder: a CSV whose header names every column in `columns`."""
    def ours(path) -> bool:
        try:
            with open(path, newline="", encoding="utf-8") as fh:
                header = fh.readline(1 << 16)
        except (OSError, UnicodeDecodeError):
            return False
        import csv

        names = next(csv.reader([header]), [])
        return all(c in names for c in columns)

    return ours


def collisions(root: Path, new: list[str], replaceable: set[str]) -> list[str]:
    """The paths among `new` that would overwrite something not in `replaceable`
    (a file that is not the command's own, a folder, a link), or lie under a link or
    a file."""
    bad = []
    for rel in new:
        path = Path(root)
        parts = PurePosixPath(rel).parts
        for i, part in enumerate(parts):
            path = path / part
            try:
                mode = os.lstat(path).st_mode
            except FileNotFoundError:
                break
            except OSError:
                bad.append(rel)
                break
            if i < len(parts) - 1:
                if not stat.S_ISDIR(mode):  # a link or a file where a folder goes
                    bad.append(rel)
                    break
            elif rel not in replaceable:
                bad.append(rel)
    return bad


def describe(names: list[str], more: bool = False) -> str:
    text = ", ".join(names[:4])
    return text + (", ..." if more or len(names) > 4 else "")


# ----------------------------------------------------------------------------- staging and swap


def is_staging(path: Path) -> bool:
    """A staging folder a run of ours made (a real folder named .lgp-new-*, holding the mark)."""
    path = Path(path)
    return (path.name.startswith(STAGING_PREFIX) and path.is_dir() and not path.is_symlink()
            and regular_inside(path, MARK) is not None)


def new_staging(root: Path) -> Path:
    """A fresh staging folder inside `root` (created), with its mark."""
    root.mkdir(parents=True, exist_ok=True)
    stage = Path(tempfile.mkdtemp(prefix=STAGING_PREFIX, dir=root))
    (stage / MARK).write_text("a run's new files, moved into the folder above when the run ends (lgp/owned.py)\n")
    return stage


def remove_staging(stage: Path) -> None:
    """Remove a staging folder of ours (nothing else): a failed run's new files."""
    if is_staging(stage):
        shutil.rmtree(stage, ignore_errors=True)


def remove_stale_staging(root: Path) -> None:
    """Staging folders left by a run killed outright (call under the folder's lock)."""
    for name in os.listdir(root):
        if name.startswith(STAGING_PREFIX):
            remove_staging(Path(root) / name)


@contextmanager
def signals_deferred():
    """SIGINT and SIGTERM wait (blocked, then delivered) until the block ends."""
    sigs = {signal.SIGINT, signal.SIGTERM}
    try:
        old = signal.pthread_sigmask(signal.SIG_BLOCK, sigs)
    except (AttributeError, ValueError, OSError):
        old = None
    try:
        yield
    finally:
        if old is not None:
            signal.pthread_sigmask(signal.SIG_SETMASK, old)


def staged_files(stage: Path) -> list[str]:
    """Files of a staging folder (relative, posix), its mark left out."""
    files = []
    for dirpath, dirnames, filenames in os.walk(stage):
        for name in filenames:
            rel = Path(dirpath, name).relative_to(stage).as_posix()
            if rel != MARK:
                files.append(rel)
    return sorted(files)


def swap_in(root: Path, stage: Path, earlier: dict[str, set[str]], manifest: str, what: str = "--out") -> list[str]:
    """Move a finished run's files from `stage` into `root` (module docstring):
    `earlier` lists the earlier run's files (manifest_entries; {} for none), `manifest`
    is the name of the manifest (written into `stage` by the run, moved in last).
    Raises ForeignFiles, moving nothing, when a new file would overwrite something not
    the command's own. Returns the earlier run's files it removed."""
    root, stage = Path(root), Path(stage)
    new = [f for f in staged_files(stage) if f != manifest]
    own = own_files(root, earlier)
    bad = collisions(root, new, set(own))
    if bad or (root / manifest).is_symlink() or ((root / manifest).exists() and regular_inside(root, manifest) is None):
        names = bad or [manifest]
        raise ForeignFiles(f"{what} {root}: {describe(names)} would replace what this command did not write (or what "
                           "changed since); nothing was moved: move it away and rerun (finished results are cached)")
    interim = json.loads((stage / manifest).read_text())
    interim["files_earlier"] = own
    interim["swap"] = "incomplete: a run was moving its files in; both runs' files are listed"
    removed = []
    from lgp.atomic import write_json_atomic

    with signals_deferred():
        write_json_atomic(interim, root / manifest)
        new_set = set(new)
        for rel in sorted(own):
            if rel in new_set:
                continue
            path = regular_inside(root, rel)
            if path is not None and sha256_of(path) == own[rel]:
                path.unlink()
                removed.append(rel)
                _prune_empty(root, path.parent)
        for rel in new:
            target = root / rel
            target.parent.mkdir(parents=True, exist_ok=True)
            os.replace(stage / rel, target)
        os.replace(stage / manifest, root / manifest)
        remove_staging(stage)
    return removed


def _prune_empty(root: Path, folder: Path) -> None:
    """Remove `folder` and its parents below `root` while they are empty."""
    root = Path(root)
    while folder != root and root in folder.parents:
        try:
            folder.rmdir()
        except OSError:
            return
        folder = folder.parent


def summarise(paths: list[str]) -> list[str]:
    """Paths shortened to their top-level folder ('figures') or file name, sorted."""
    return sorted({PurePosixPath(p).parts[0] for p in paths})


# ----------------------------------------------------------------------------- locks over a tree


class OutputTreeBusy(RuntimeError):
    """Another run writes into a folder inside or around this one."""


def lock_dir() -> Path:
    """One folder of lock files per user, at a fixed place (so TMPDIR does not split it)."""
    base = Path("/tmp") if Path("/tmp").is_dir() else Path(tempfile.gettempdir())
    d = base / f"lgp-run-locks-{os.getuid()}"
    try:
        d.mkdir(mode=0o700)
    except FileExistsError:
        pass
    st = os.lstat(d)
    if not stat.S_ISDIR(st.st_mode) or st.st_uid != os.getuid():
        raise OutputTreeBusy(f"{d}: the lock folder of output folders is not a folder of this user; remove it")
    return d


def _lock_path(folder: Path) -> Path:
    return lock_dir() / (hashlib.sha256(str(folder).encode()).hexdigest()[:32] + ".lock")


def _open(path: Path) -> int:
    return os.open(path, os.O_RDWR | os.O_CREAT | getattr(os, "O_CLOEXEC", 0) | getattr(os, "O_NOFOLLOW", 0), 0o600)


def _holder_text(fd: int) -> tuple[str, str]:
    """(folder, 'process N: command') written by the holder of an exclusive lock."""
    lines = os.pread(fd, 8192, 0).decode("utf-8", "replace").splitlines()
    folder = lines[1] if len(lines) > 1 else "?"
    who = f"process {lines[0] if lines else '?'}" + (f": {lines[2]}" if len(lines) > 2 and lines[2] else "")
    return folder, who


class TreeLock:
    """Exclusive on `out` (resolved), shared on every folder above it (module docstring)."""

    def __init__(self, out: Path, command: str = ""):
        self.folder = Path(out).resolve()
        self.command = command
        self._fds: list[int] = []
        self._exclusive = False

    def __enter__(self):
        import fcntl

        try:
            for above in reversed(self.folder.parents):
                fd = _open(_lock_path(above))
                self._fds.append(fd)
                try:
                    fcntl.flock(fd, fcntl.LOCK_SH | fcntl.LOCK_NB)
                except BlockingIOError:
                    _, who = _holder_text(fd)
                    raise OutputTreeBusy(f"{self.folder} lies inside {above}, the output folder of another run ({who}); "
                                         "wait for it to end or give an --out outside it") from None
            fd = _open(_lock_path(self.folder))
            self._fds.append(fd)
            try:
                fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
            except BlockingIOError:
                inner, who = self._nested_holder()
                raise OutputTreeBusy(f"{self.folder} holds {inner}, the output folder of another run ({who}); "
                                     "wait for it to end or give another --out") from None
            self._exclusive = True
            os.ftruncate(fd, 0)
            os.pwrite(fd, f"{os.getpid()}\n{self.folder}\n{self.command}\n".encode(), 0)
        except BaseException:
            self.__exit__()
            raise
        return self

    def _nested_holder(self) -> tuple[str, str]:
        import fcntl

        for path in sorted(lock_dir().glob("*.lock")):
            try:
                fd = os.open(path, os.O_RDONLY | getattr(os, "O_NOFOLLOW", 0))
            except OSError:
                continue
            try:
                folder, who = _holder_text(fd)
                if self.folder not in Path(folder).parents:
                    continue
                try:
                    fcntl.flock(fd, fcntl.LOCK_SH | fcntl.LOCK_NB)  # free: a stale record
                except BlockingIOError:
                    return folder, who
            finally:
                os.close(fd)
        return "a folder", "a run that started as this one did"

    def __exit__(self, *exc):
        if self._exclusive:  # only the holder of the exclusive lock writes its record
            try:
                os.ftruncate(self._fds[-1], 0)
            except OSError:
                pass
        for fd in self._fds:
            os.close(fd)
        self._fds, self._exclusive = [], False
        return False
