"""`DaskExecutor`: the same ``map`` on a ``dask.distributed`` cluster (a running
scheduler, or a LocalCluster on this machine); dask.distributed is an optional
extra, imported only when a DaskExecutor is made."""
from __future__ import annotations

import threading

from lgp.errors import InputError
from lgp.executor.serial import default_jobs


class SchedulerUnreachable(ConnectionError):
    """A Dask scheduler address that does not answer within the timeout."""


class DaskMissing(ImportError):
    """The Dask backend was asked for but dask.distributed is not installed."""


#: Seconds to wait for a Dask scheduler to answer before giving up.
CONNECT_TIMEOUT = 10.0


class DaskExecutor:
    """The same ``map`` on a ``dask.distributed`` cluster.

    `address` is a scheduler address (``tcp://HOST:8786``) or ``"local-dask"``:
    start a ``distributed.LocalCluster`` of `jobs` single-threaded worker
    processes (None: all cores) and close it with the executor. Each item is one
    task with its own key; results come back to this process (the client) and
    are returned in input order, so the numbers do not depend on the number of
    workers or on which worker ran what. A worker that dies mid-task has its
    tasks rescheduled by Dask; each item's result is kept once, by index. An
    exception here (Ctrl-C included) cancels every pending future of the map.
    """

    def __init__(self, address: str = "local-dask", jobs: int | None = None, timeout: float = CONNECT_TIMEOUT,
                 client=None):
        try:
            from distributed import Client, LocalCluster
        except ImportError:  # pragma: no cover - depends on the install
            raise DaskMissing('the Dask backend (--scheduler) needs the optional extra: pip install -e ".[dask]"') from None
        self.address = address
        self._cluster = None
        if client is not None:
            self.client = client
            self._own_client = False
        elif address == "local-dask":
            n = default_jobs() if jobs is None else int(jobs)
            if n < 1:
                raise InputError(f"jobs must be >= 1, got {jobs}")
            self._cluster = LocalCluster(n_workers=n, threads_per_worker=1, processes=True,
                                         dashboard_address=None, silence_logs=50)
            self.client = Client(self._cluster, set_as_default=False)
            self._own_client = True
        else:
            try:
                self.client = _connect(Client, address, timeout)
            except Exception as e:  # refused, timed out, or something else answered (not a scheduler)
                raise SchedulerUnreachable(f"no Dask scheduler answered at {address} within {timeout:g} s ({e.__class__.__name__})") from None
            self._own_client = True
        self._batch = 0

    @property
    def jobs(self) -> int:
        """Worker threads the cluster has now (at least 1)."""
        info = self.client.scheduler_info()
        return max(1, sum(w.get("nthreads", 1) for w in info.get("workers", {}).values()))

    def map(self, fn, items, on_result=None) -> list:
        from distributed import as_completed

        items = list(items)
        results: list = [None] * len(items)
        if not items:
            return results
        self._batch += 1
        # Explicit keys: identical items stay distinct tasks, and a future's index is its key.
        tag = f"{getattr(fn, '__name__', 'task')}-{id(self):x}-{self._batch}"
        keys = [f"{tag}-{k}" for k in range(len(items))]
        index = {key: k for k, key in enumerate(keys)}
        futures = self.client.map(fn, items, key=keys, pure=False)
        got = [False] * len(items)
        try:
            for future, result in as_completed(futures, with_results=True, loop=self.client.loop):
                k = index[future.key]
                if got[k]:  # cannot happen with one future per key; guards the "no duplicates" promise
                    continue
                got[k] = True
                results[k] = result
                if on_result is not None:
                    on_result(k, result)
        except BaseException:
            self.client.cancel(futures, force=True)
            raise
        finally:
            del futures
        return results

    def terminate(self) -> None:
        self.close()

    def close(self) -> None:
        if self._own_client and self.client is not None:
            self.client.close()
            self.client = None
        if self._cluster is not None:
            self._cluster.close()
            self._cluster = None

    def __enter__(self):
        return self

    def __exit__(self, *exc):
        self.close()


def _connect(Client, address: str, timeout: float):
    """A Client for `address`, or an exception within about `timeout` s.

    A plain TCP connection is tried first: a refused or silent address then
    fails at once and cleanly (a half-made Client would complain on exit)."""
    import socket
    from urllib.parse import urlsplit

    parts = urlsplit(address if "://" in address else f"tcp://{address}")
    if parts.scheme in ("tcp", "tls") and parts.hostname:
        socket.create_connection((parts.hostname, parts.port or 8786), timeout=timeout).close()
    # Client's own timeout does not cover a peer that accepts TCP and then stays
    # silent, so the connection is made in a daemon thread with a hard deadline.
    box: dict = {}

    def connect():
        try:
            box["client"] = Client(address, timeout=f"{timeout}s", set_as_default=False)
        except BaseException as e:  # handed to the caller
            box["error"] = e

    thread = threading.Thread(target=connect, name="dask-connect", daemon=True)
    thread.start()
    thread.join(timeout + 1.0)
    if thread.is_alive():
        raise TimeoutError(f"no answer within {timeout:g} s")
    if "error" in box:
        raise box["error"]
    return box["client"]
