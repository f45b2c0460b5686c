"""Progress of a long stage (effort plans, risk runs): counts, rate and ETA on stderr.

On a terminal one line is redrawn in place (at most every 0.2 s); when stderr is
not a terminal (a log file, CI, a batch job) nothing is printed until the stage
ends, then one line: ``[effort] 720/720 plans in 95.3 s (7.6/s)``. Works with
any executor: pass ``progress.update`` (or ``progress.advance``) as the
``on_result`` callback of ``Executor.map``.
"""
from __future__ import annotations

import sys
import time
from typing import TextIO


def _duration(seconds: float) -> str:
    seconds = max(0.0, seconds)
    if seconds < 60:
        return f"{seconds:.0f} s"
    if seconds < 3600:
        return f"{seconds // 60:.0f} min {seconds % 60:02.0f} s"
    return f"{seconds // 3600:.0f} h {seconds % 3600 // 60:02.0f} min"


def log(msg: str) -> None:
    """Print a line to stderr; on a terminal with a bar drawn, above the bar (which is redrawn)."""
    bar = Progress.active
    if bar is not None and bar.tty and bar.stream is sys.stderr:
        sys.stderr.write("\r\033[K" + msg + "\n")
        bar._draw()
    else:
        print(msg, file=sys.stderr, flush=True)


class Progress:
    """``Progress(stage, total, unit)``; ``advance(n)`` as work finishes; ``close()`` at the end."""

    #: The bar being drawn on a terminal now (lines from `log` go above it).
    active: "Progress | None" = None

    def __init__(self, stage: str, total: int, unit: str = "tasks", stream: TextIO | None = None,
                 tty: bool | None = None, interval: float = 0.2):
        self.stage, self.total, self.unit = stage, int(total), unit
        self.stream = sys.stderr if stream is None else stream
        self.tty = (hasattr(self.stream, "isatty") and self.stream.isatty()) if tty is None else tty
        self.interval = interval
        self.done = 0
        self.t0 = time.perf_counter()
        self._drawn = 0.0
        self._closed = False
        if self.tty and self.total:
            Progress.active = self

    def advance(self, n: int = 1) -> None:
        self.done += n
        if self.tty and (time.perf_counter() - self._drawn >= self.interval or self.done >= self.total):
            self._draw()

    def update(self, index=None, result=None) -> None:
        """``on_result(index, result)`` of Executor.map: one item done."""
        self.advance(1)

    def line(self) -> str:
        elapsed = time.perf_counter() - self.t0
        rate = self.done / elapsed if elapsed > 0 else 0.0
        head = f"[{self.stage}] {self.done}/{self.total} {self.unit}"
        if self.done >= self.total or self._closed:
            return f"{head} in {elapsed:.1f} s ({rate:.3g}/s)"
        width = 24
        filled = int(width * self.done / self.total) if self.total else width
        eta = (self.total - self.done) / rate if rate > 0 else float("nan")
        eta_s = _duration(eta) if eta == eta else "?"
        return f"[{self.stage}] |{'#' * filled}{'.' * (width - filled)}| {self.done}/{self.total} {self.unit}, {rate:.3g}/s, ETA {eta_s}"

    def _draw(self) -> None:
        self._drawn = time.perf_counter()
        self.stream.write("\r\033[K" + self.line())
        self.stream.flush()

    def close(self) -> None:
        if self._closed:
            return
        self._closed = True
        if Progress.active is self:
            Progress.active = None
        if self.total == 0:  # nothing to do (all cached): nothing to report
            return
        if self.tty:
            self.stream.write("\r\033[K" + self.line() + "\n")
        else:
            self.stream.write(self.line() + "\n")
        self.stream.flush()

    def __enter__(self):
        return self

    def __exit__(self, *exc):
        self.close()


class Stopwatch:
    """Wall time per stage of a run: ``lap(name)`` closes the stage that ended now."""

    def __init__(self):
        self.laps: dict[str, float] = {}
        self._t = time.perf_counter()

    def lap(self, name: str) -> float:
        now = time.perf_counter()
        self.laps[name] = self.laps.get(name, 0.0) + now - self._t
        self._t = now
        return self.laps[name]
