"""Writing a file whole or not at all: the one atomic writer of the project.

Every output and cache entry of a run is written to a temporary name beside its
final path and renamed over it (`os.replace`), so a run killed half way leaves
only whole files behind. A new file gets the mode the user's umask gives it
(0644 under the usual 022), not mkstemp's private 0600; the umask is read from
/proc/self/status, because `os.umask` can only be read by setting it, which races
with other threads. Temporary names are unique (mkstemp), so two processes
writing the same file never share one.

A write that fails because the disk is full (ENOSPC, or EDQUOT: over quota)
leaves nothing behind and raises `DiskFull`, an OSError whose message names the
file and says the disk is full (``[Errno 28]`` alone names none).

CSV files written here are safe to open in a spreadsheet: a text cell that
starts with ``=``, ``+``, ``-``, ``@``, a tab or a carriage return (and is not a
plain number) gets a leading ``'`` (OWASP's advice against CSV formula
injection), so a participant id such as ``=cmd|' /C calc'!A0`` is shown as text,
never run as a formula. Numbers, including negative ones, are untouched.

It sits on the ground floor (lgp.app.files re-exports it) so the analysis and
every command line write through it too.
"""
from __future__ import annotations

import errno
import json
import os
import re
import tempfile
from contextlib import contextmanager
from pathlib import Path
from typing import Iterator

#: errno values that mean "no room": the disk is full or the user's quota is.
_NO_ROOM = {errno.ENOSPC, getattr(errno, "EDQUOT", errno.ENOSPC)}
#: A cell a spreadsheet would read as a formula (OWASP CSV injection).
_FORMULA = re.compile(r"^[=+\-@\t\r]")
_NUMBER = re.compile(r"^[+-]?(\d+\.?\d*|\.\d+)([eE][+-]?\d+)?$")


class DiskFull(OSError):
    """A write failed for want of space; the message names the file."""


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
    block ends, removed if it raises. A full disk raises DiskFull naming `path`."""
    path = Path(path)
    tmp = None
    try:
        path.parent.mkdir(parents=True, exist_ok=True)
        fd, tmp = tempfile.mkstemp(prefix=f".{path.name}.", suffix=f".tmp{path.suffix}", dir=path.parent)
        os.close(fd)
        yield Path(tmp)
        os.chmod(tmp, 0o666 & ~umask())
        os.replace(tmp, path)
    except BaseException as e:
        if tmp is not None:
            Path(tmp).unlink(missing_ok=True)
        code = _no_room(e)
        if code is not None and not isinstance(e, DiskFull):
            raise DiskFull(code, f"{os.strerror(code)}: the disk is full, so it was not written "
                                 "(nothing partial was left; free some space and rerun)", str(path)) from None
        raise


def _no_room(e: BaseException) -> int | None:
    """The errno if `e`, or an exception it was raised while handling, is a full
    disk (matplotlib's PDF writer, for one, hides the ENOSPC behind an
    AttributeError from its own clean-up)."""
    seen = set()
    while e is not None and id(e) not in seen:
        if isinstance(e, OSError) and e.errno in _NO_ROOM:
            return e.errno
        seen.add(id(e))
        e = e.__cause__ or e.__context__
    return None


def spreadsheet_safe(df):
    """`df` with every text cell that a spreadsheet would run as a formula
    prefixed by ``'`` (see the module docstring); numeric columns are untouched,
    and so are column names unless they too start like a formula."""
    out = None
    for column in df.columns:
        col = df[column]
        if col.dtype != object and str(col.dtype) not in ("string", "str"):
            continue
        text = col.map(lambda v: isinstance(v, str) and bool(_FORMULA.match(v)) and not _NUMBER.match(v.strip()))
        if text.any():
            out = df.copy() if out is None else out
            out[column] = col.where(~text, "'" + col.astype(str))
    names = [f"'{c}" if isinstance(c, str) and _FORMULA.match(c) and not _NUMBER.match(c.strip()) else c for c in df.columns]
    if names != list(df.columns):
        out = (df.copy() if out is None else out)
        out.columns = names
    return df if out is None else out


def write_bytes_atomic(data: bytes, path: str | Path) -> Path:
    """Write `data` to `path` whole or not at all (see atomic_path)."""
    with atomic_path(path) as tmp:
        tmp.write_bytes(data)
    return Path(path)


def write_text_atomic(text: str, path: str | Path) -> Path:
    """Write `text` (UTF-8) to `path` whole or not at all."""
    return write_bytes_atomic(text.encode(), path)


def write_csv_atomic(df, path: str | Path) -> Path:
    """Write `df` as CSV (no index) to `path` whole or not at all, its text cells
    spreadsheet-safe (`spreadsheet_safe`)."""
    return write_bytes_atomic(spreadsheet_safe(df).to_csv(index=False).encode(), path)


def write_json_atomic(data, path: str | Path) -> Path:
    """Write `data` as indented JSON (anything else as str) to `path` whole or not at all."""
    return write_text_atomic(json.dumps(data, indent=2, default=str) + "\n", path)
