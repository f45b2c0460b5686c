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
#: Seconds to wait for the first bytes a Dask scheduler sends on a new connection
#: (its handshake): a real one sends them at once; an HTTP server sends nothing.
HANDSHAKE_TIMEOUT = 5.0
#: Address schemes of a running Dask scheduler this project connects to.
SCHEMES = ("tcp", "tls", "ws", "wss")


def check_address(address: str, allow_inproc: bool = False) -> str:
    """`address` if it can name a running Dask scheduler (``local-dask``, or
    ``tcp://HOST:PORT``; also tls, ws, wss; ``HOST:PORT`` means tcp), else
    InputError in one line: ``tcp://`` names no host, ``inproc://x`` a scheduler
    inside this very process (allowed only with `allow_inproc`, for a caller that
    made one), ``http://...`` a dashboard, not a scheduler."""
    from urllib.parse import urlsplit

    text = str(address).strip()
    if text.lower() == "local-dask":
        return "local-dask"
    parts = urlsplit(text if "://" in text else f"tcp://{text}")
    scheme = parts.scheme.lower()
    if scheme == "inproc" and allow_inproc and parts.netloc:
        return text
    if scheme == "inproc":
        raise InputError(f"{text!r} names a scheduler inside this very process (inproc://), which a command line "
                         "never has; give tcp://HOST:PORT of a running scheduler, or local-dask")
    if scheme in ("http", "https"):
        raise InputError(f"{text!r} is a web address (the dashboard?), not a Dask scheduler; give tcp://HOST:8786")
    if scheme not in SCHEMES:
        raise InputError(f"unknown scheme {parts.scheme + '://'!r} in {text!r}; a Dask scheduler is "
                         f"{', '.join(s + '://HOST:PORT' for s in SCHEMES)}, or local-dask")
    try:
        port = parts.port
    except ValueError:
        raise InputError(f"{text!r}: the port must be a number in 1-65535") from None
    if not parts.hostname:
        raise InputError(f"{text!r} names no host; give {scheme}://HOST:PORT (e.g. tcp://127.0.0.1:8786)")
    if port == 0:
        raise InputError(f"{text!r}: the port must be a number in 1-65535")
    return text


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
        self.address = address = check_address(address, allow_inproc=True) if client is None else address
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
            except NotAScheduler as e:
                raise SchedulerUnreachable(f"{address}: {e}") from None
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


class NotAScheduler(ConnectionError):
    """Something answers at the address, but not as a Dask scheduler does."""


def _probe(host: str, port: int, timeout: float) -> None:
    """Connect and read the first 8 bytes a Dask scheduler sends on a new connection
    (the length of its handshake message, a little-endian uint64): nothing within
    HANDSHAKE_TIMEOUT, or bytes that are no such length (``HTTP/1.0 ...``, junk),
    raise NotAScheduler, so no Client is ever made for them (a half-made Client
    prints a traceback from its __del__ and waits 20 s when the program ends)."""
    import socket
    import struct

    with socket.create_connection((host, port), timeout=timeout) as sock:
        sock.settimeout(min(timeout, HANDSHAKE_TIMEOUT))
        data = b""
        try:
            while len(data) < 8:
                chunk = sock.recv(8 - len(data))
                if not chunk:
                    break
                data += chunk
        except socket.timeout:
            raise NotAScheduler(f"something accepts connections there but sent nothing within "
                                f"{min(timeout, HANDSHAKE_TIMEOUT):g} s (a Dask scheduler greets at once: an HTTP "
                                "server or another service?)") from None
    if len(data) < 8:
        raise NotAScheduler(f"something accepted the connection and closed it after {len(data)} byte(s): not a Dask scheduler")
    (length,) = struct.unpack("<Q", data)
    if not 0 < length < 1 << 26:
        kind = "an HTTP server" if data.startswith(b"HTTP/") else "not Dask's protocol"
        raise NotAScheduler(f"it answered {data!r}..., {kind}: not a Dask scheduler")


def _connect(Client, address: str, timeout: float):
    """A Client for `address`, or an exception within about `timeout` s.

    A plain TCP connection is tried first, and its first bytes read (`_probe`): a
    refused, silent or foreign address then fails at once and cleanly (a half-made
    Client would complain on exit)."""
    from urllib.parse import urlsplit

    parts = urlsplit(address if "://" in address else f"tcp://{address}")
    if parts.scheme == "tcp" and parts.hostname:
        _probe(parts.hostname, parts.port or 8786, timeout)

    class QuietClient(Client):
        """A Client that, when its connection failed, goes without closing: the
        close of a half-made Client waits 20 s and prints a traceback at exit."""

        def __del__(self):
            if getattr(self, "status", None) == "running":
                super().__del__()

    # Client's own timeout does not cover a peer that accepts TCP and then stays
    # silent, so the connection is made in a daemon thread with a hard deadline.
    box: dict = {}

    def connect():
        try:
            box["client"] = QuietClient(address, timeout=f"{timeout}s", set_as_default=False)
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
