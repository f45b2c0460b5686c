"""The one bounded reader of every input file.

``read_bounded(path, limit, what)`` returns the bytes of a *regular file* of at
most `limit` bytes, or raises `InputFileError` in one line naming the file and
the rule broken. It never trusts a size it has not read: a symlink to
``/dev/zero`` (size 0, endless), a FIFO (opening it would wait for a writer
forever), a directory, a device or a socket is refused before a byte is read,
and at most ``limit + 1`` bytes are ever read, so a file that grows while it is
read, or a ``/proc`` file whose size reads 0, cannot exhaust memory either.

The file is opened with O_NONBLOCK (a FIFO swapped in after the check does not
block the open) and checked again on the open descriptor (``fstat``), so what is
read is what was checked. A dangling symbolic link is named as one (not "does
not exist"). ``within`` makes a file outside a folder (after resolving every
symbolic link) an error too: cache entries are read only from inside the cache.

This module knows nothing of the paper: stimuli, human data and the cache use it.
"""
from __future__ import annotations

import errno
import os
import stat
from pathlib import Path


class InputFileError(ValueError):
    """An input file that is not a regular file, too large, or unreadable."""

    def __init__(self, message: str, path: str | Path | None = None, rule: str = ""):
        super().__init__(message)
        self.path = path
        self.rule = rule


def _kind(mode: int) -> str:
    for test, name in ((stat.S_ISDIR, "a directory"), (stat.S_ISFIFO, "a FIFO (named pipe)"),
                       (stat.S_ISCHR, "a character device"), (stat.S_ISBLK, "a block device"),
                       (stat.S_ISSOCK, "a socket")):
        if test(mode):
            return name
    return "not a regular file"


def _link_note(path: Path) -> str:
    return f" (a symbolic link to {os.readlink(path)})" if path.is_symlink() else ""


def check_regular(path: str | Path, what: str = "input file") -> os.stat_result:
    """The stat of `path` if it is (or links to) a regular file, else InputFileError."""
    path = Path(path)
    try:
        st = path.stat()
    except OSError as e:
        if e.errno == errno.ELOOP:
            raise InputFileError(f"{path}: a loop of symbolic links (a link that leads back to itself), not a {what}",
                                 path, "symlink loop") from None
        if not isinstance(e, FileNotFoundError):
            raise InputFileError(f"{path}: cannot read the {what} ({e.strerror})", path, "unreadable") from None
        if path.is_symlink():
            raise InputFileError(f"{path}: a dangling symbolic link (to {os.readlink(path)}, which does not exist), "
                                 f"not a {what}", path, "dangling symlink") from None
        raise InputFileError(f"{path}: no such {what}", path, "missing") from None
    if not stat.S_ISREG(st.st_mode):
        raise InputFileError(f"{path}: {_kind(st.st_mode)}{_link_note(path)}, not a regular file; a {what} must "
                             "be a regular file", path, "not a regular file")
    return st


def read_bounded(path: str | Path, limit: int, what: str = "input file", within: str | Path | None = None,
                 limit_name: str | None = None) -> bytes:
    """The bytes of `path`, a regular file of at most `limit` bytes (see the module
    docstring); `limit_name` names the setting that raises the limit in the message."""
    path = Path(path)
    if within is not None:
        base = Path(within).resolve()
        try:
            path.resolve().relative_to(base)
        except ValueError:
            raise InputFileError(f"{path}: resolves to {path.resolve()}, outside {base}; a {what} is read only "
                                 f"from inside {base}", path, "outside its folder") from None
    st = check_regular(path, what)
    how = f" ({limit_name})" if limit_name else ""
    if st.st_size > limit:
        raise InputFileError(f"{path}: {what} is {st.st_size} bytes, more than the {limit} allowed{how}", path, "too large")
    try:
        fd = os.open(path, os.O_RDONLY | os.O_NONBLOCK | getattr(os, "O_CLOEXEC", 0))
    except OSError as e:
        raise InputFileError(f"{path}: cannot open the {what} ({e.strerror})", path, "unreadable") from None
    try:
        st = os.fstat(fd)
        if not stat.S_ISREG(st.st_mode):  # swapped between the check and the open
            raise InputFileError(f"{path}: {_kind(st.st_mode)}, not a regular file; a {what} must be a regular file",
                                 path, "not a regular file")
        chunks, got = [], 0
        while got <= limit:
            try:
                chunk = os.read(fd, min(1 << 20, limit + 1 - got))
            except OSError as e:
                if e.errno in (errno.EAGAIN, errno.EWOULDBLOCK):
                    continue
                raise InputFileError(f"{path}: cannot read the {what} ({e.strerror})", path, "unreadable") from None
            if not chunk:
                break
            chunks.append(chunk)
            got += len(chunk)
        if got > limit:
            raise InputFileError(f"{path}: {what} holds more than the {limit} bytes allowed{how} "
                                 "(it grew while being read, or its size is not what stat says)", path, "too large")
        return b"".join(chunks)
    finally:
        os.close(fd)
