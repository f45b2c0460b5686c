"""Progress of a long stage (effort plans, risk runs): a bar with count, rate and ETA.

On a terminal each stage draws a `tqdm` bar on stderr, in words:
``effort: plans  38%|#####      | 24/62 plans, 7.1 plans/s, 5 s left``; lines
printed with `log` go above it. When stderr is not a terminal (a log file, CI, a
batch job) nothing is printed until the stage ends, then one line:
``[effort] 62/62 plans in 8.7 s (7.1/s)``. Works with any executor: pass
``progress.update`` (or ``progress.advance``) as the ``on_result`` callback of
``Executor.map``.
"""
from __future__ import annotations

import shutil
import sys
import threading
import time
from typing import TextIO

from lgp.cli import duration_text


def log(msg: str) -> None:
    """Print a line to stderr; on a terminal with a bar drawn, above the bar (which is redrawn)."""
    bar = Progress.active
    if bar is not None and bar._bar is not None:
        bar._bar.write(msg, file=sys.stderr)
    else:
        print(msg, file=sys.stderr, flush=True)


def _tqdm_class():
    from tqdm import tqdm

    class _Bar(tqdm):
        """tqdm whose bar reads "..., 7.1 plans/s, 5 s left" (ETA in words, not 00:05)."""

        @property
        def format_dict(self):
            d = super().format_dict
            rate = d.get("rate") or (d["n"] / d["elapsed"] if d.get("elapsed") else 0)
            left = (d["total"] - d["n"]) / rate if rate and d.get("total") else None
            if d.get("total") and d["n"] >= d["total"]:
                d["eta"] = "done in " + duration_text(d.get("elapsed", 0))
            else:
                d["eta"] = "ETA " + duration_text(left) if left is not None else "ETA ?"
            d["speed"] = f"{rate:.3g} {d.get('unit', '')}/s" if rate else "starting"
            return d

    return _Bar


BAR_FORMAT = "{desc}: {percentage:3.0f}%|{bar:24}| {n}/{total} {unit}, {speed}, {eta}"


class Progress:
    """``Progress(stage, total, unit)``; ``advance(n)`` as work finishes; ``close()`` at the end.

    `what` (optional) says in words what is counted, e.g. "distinct layouts to plan";
    it is the bar's label on a terminal.
    """

    #: The bar being drawn on a terminal now (lines from `log` go above it).
    active: "Progress | None" = None

    def __init__(self, stage: str, total: int, unit: str = "tasks", stream: TextIO | None = None,
                 tty: bool | None = None, interval: float = 0.2, what: str | None = None):
        self.stage, self.total, self.unit = stage, int(total), unit
        self.stream = sys.stderr if stream is None else stream
        self.tty = (hasattr(self.stream, "isatty") and self.stream.isatty()) if tty is None else tty
        self.done = 0
        self.t0 = time.perf_counter()
        self._closed = False
        self._bar = None
        if self.tty and self.total:
            size = shutil.get_terminal_size((100, 24))  # a terminal of unknown size (0 x 0) gets 100 x 24: tqdm hides at 0 rows
            self._bar = _tqdm_class()(total=self.total, desc=f"{stage}: {what}" if what else stage, unit=unit,
                                      file=self.stream, mininterval=interval, bar_format=BAR_FORMAT, ascii=" #",
                                      ncols=min(120, size.columns), nrows=size.lines, leave=True,
                                      smoothing=0)  # ETA from the stage's mean rate
            Progress.active = self
            self._ticker = threading.Thread(target=self._tick, name=f"progress-{stage}", daemon=True)
            self._ticker.start()

    def _tick(self) -> None:
        """Redraw every second, so elapsed time and ETA move while a long item (a
        21 s plan) is being worked on."""
        while not self._closed:
            time.sleep(1.0)
            bar = self._bar
            if bar is not None and not self._closed:
                try:
                    bar.refresh()
                except Exception:  # closed meanwhile
                    return

    def advance(self, n: int = 1) -> None:
        self.done += n
        if self._bar is not None:
            self._bar.update(n)

    def update(self, index=None, result=None) -> None:
        """``on_result(index, result)`` of Executor.map: one item done."""
        self.advance(1)

    def line(self) -> str:
        """The stage's one-line summary (printed at the end when stderr is not a terminal)."""
        elapsed = time.perf_counter() - self.t0
        rate = self.done / elapsed if elapsed > 0 else 0.0
        return f"[{self.stage}] {self.done}/{self.total} {self.unit} in {elapsed:.1f} s ({rate:.3g}/s)"

    def close(self) -> None:
        if self._closed:
            return
        self._closed = True
        if Progress.active is self:
            Progress.active = None
        if self.total == 0:  # nothing to do (all cached): nothing to report
            return
        if self._bar is not None:
            self._bar.close()
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
