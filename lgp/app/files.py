"""Writing a file whole or not at all: the one atomic writer of the application wing.

Every output and cache entry of a run is written to a temporary name beside its
final path and renamed over it (`os.replace`), so a run killed half way leaves
only whole files behind. A new file gets the mode the user's umask gives it
(0644 under the usual 022), not mkstemp's private 0600; the umask is read from
/proc/self/status, because `os.umask` can only be read by setting it, which races
with other threads.
"""
from __future__ import annotations

import json
import os
import tempfile
from contextlib import contextmanager
from pathlib import Path
from typing import Iterator

import pandas as pd


def umask() -> int:
    """The process umask, read without changing it where Linux allows (the
    Umask line of /proc/self/status); elsewhere set and restored at once."""
    try:
        for line in Path("/proc/self/status").read_text().splitlines():
            if line.startswith("Umask:"):
                return int(line.split()[1], 8)
    except (OSError, ValueError, IndexError):
        pass
    mask = os.umask(0o022)
    os.umask(mask)
    return mask


@contextmanager
def atomic_path(path: str | Path) -> Iterator[Path]:
    """A temporary path beside `path` (with its suffix, so writers that go by the
    suffix, like matplotlib's savefig, work) to write to: renamed to `path` when the
    block ends, removed if it raises."""
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    fd, tmp = tempfile.mkstemp(prefix=f".{path.name}.", suffix=f".tmp{path.suffix}", dir=path.parent)
    os.close(fd)
    try:
        yield Path(tmp)
        os.chmod(tmp, 0o666 & ~umask())
        os.replace(tmp, path)
    except BaseException:
        Path(tmp).unlink(missing_ok=True)
        raise


def write_bytes_atomic(data: bytes, path: str | Path) -> Path:
    """Write `data` to `path` whole or not at all (see atomic_path)."""
    with atomic_path(path) as tmp:
        tmp.write_bytes(data)
    return Path(path)


def write_text_atomic(text: str, path: str | Path) -> Path:
    """Write `text` (UTF-8) to `path` whole or not at all."""
    return write_bytes_atomic(text.encode(), path)


def write_csv_atomic(df: pd.DataFrame, path: str | Path) -> Path:
    """Write `df` as CSV (no index) to `path` whole or not at all."""
    return write_bytes_atomic(df.to_csv(index=False).encode(), path)


def write_json_atomic(data, path: str | Path) -> Path:
    """Write `data` as indented JSON (anything else as str) to `path` whole or not at all."""
    return write_text_atomic(json.dumps(data, indent=2, default=str) + "\n", path)
