"""Stopping a command: SIGTERM as Ctrl-C (`stop_signals`, `Interrupted`)."""
from __future__ import annotations

import signal
import threading


class Interrupted(KeyboardInterrupt):
    """KeyboardInterrupt raised by `stop_signals`; ``signal`` is the signal received."""

    def __init__(self, signum: int):
        self.signal = signal.Signals(signum)
        super().__init__(f"stopped by {self.signal.name}")


class stop_signals:
    """Context manager for command-line entry points: SIGINT (Ctrl-C) and SIGTERM
    (what ``timeout``, ``kill`` and job schedulers send) both raise `Interrupted`
    in the main thread, so a run stops the same way on either: the executor
    terminates its workers, atomic writes leave no partial file, and the caller
    prints one line. ``received`` keeps the first signal even when the exception is
    converted on its way up (a C extension being imported turns it into an
    ImportError), so the caller can still tell a stop from a failure. The previous
    handlers are restored on exit; outside the main thread this does nothing."""

    SIGNALS = (signal.SIGINT, signal.SIGTERM)

    def __enter__(self):
        self.received: signal.Signals | None = None
        self._previous = {}
        if threading.current_thread() is threading.main_thread():
            self._previous = {s: signal.signal(s, self._raise) for s in self.SIGNALS}
        return self

    def _raise(self, signum, frame):
        if self.received is None:
            self.received = signal.Signals(signum)
        raise Interrupted(signum)

    def __exit__(self, *exc):
        for s, handler in self._previous.items():
            signal.signal(s, handler)
