"""The bad calls of bench/faults.py: counts and addresses on the command line, bad
arguments to the API (models.risk.physical_risk, lgp.plan). Each `*_cases` yields
(input, case) as in bench/faults_files.py."""
from __future__ import annotations

import contextlib
import io
import os
import shutil
import tempfile
import time
from pathlib import Path

import stimuli
from faults_files import UsageRefusal


# ----------------------------------------------------------------------------- counts on the command line


def _argv_case(module, argv):
    """A case: `module`'s argument checks (main, or lgp.reproduce.parse_args) on `argv`;
    argparse's usage exit counts as a refusal."""
    def run():
        import importlib

        main = importlib.import_module(module).main if module != "lgp.reproduce" else importlib.import_module(module).parse_args
        err = io.StringIO()
        with contextlib.redirect_stderr(err):
            try:
                result = main(argv)
            except SystemExit as e:
                raise UsageRefusal(f"exit {e.code}: {err.getvalue().strip()}") from None
        return f"accepted: {result}"
    return run


def _loop_case(tmp: Path, make, module="lgp.reproduce", flag="--stimuli"):
    """A case: `flag` given a path that `make(folder)` makes in a fresh folder."""
    def run():
        folder = Path(tempfile.mkdtemp(dir=tmp))
        try:
            return _argv_case(module, [flag, str(make(folder))])()
        finally:
            shutil.rmtree(folder, ignore_errors=True)
    return run


def _anchor_fifo(tmp: Path):
    """A case: stimuli.experiment's anchor file a FIFO (it must not block)."""
    from stimuli import experiment as ex

    folder = Path(tempfile.mkdtemp(dir=tmp))
    try:
        os.mkfifo(folder / "anchor.yaml")
        return ex.load_anchor(folder / "anchor.yaml", "easy", set())
    finally:
        shutil.rmtree(folder, ignore_errors=True)


def _lock_fifo(tmp: Path):
    """A case: the output folder's lock file a FIFO (it must not block)."""
    from lgp.app.manifest import OutputLock

    folder = Path(tempfile.mkdtemp(dir=tmp))
    try:
        os.mkfifo(folder / OutputLock.NAME)
        with OutputLock(folder, "probe"):
            return "locked"
    finally:
        shutil.rmtree(folder, ignore_errors=True)


def _peer(reply):
    """A case: a Dask client at a TCP peer that answers `reply` (or nothing): refused in time."""
    def run():
        import socket
        import threading

        from lgp.executor import DaskExecutor

        server = socket.socket()
        server.bind(("127.0.0.1", 0))
        server.listen(4)

        def serve():
            try:
                c, _ = server.accept()
                if reply:
                    c.sendall(reply)
                time.sleep(3)
                c.close()
            except OSError:
                pass
        threading.Thread(target=serve, daemon=True).start()
        try:
            DaskExecutor(f"tcp://127.0.0.1:{server.getsockname()[1]}", timeout=2.0).close()
            return "connected"
        finally:
            server.close()
    return run


def _jobs():
    """A case: --jobs 400 on a 2-core machine is capped at the usable cores, saying so."""
    from lgp import cli
    from lgp.reproduce import parse_args

    err = io.StringIO()
    with contextlib.redirect_stderr(err):
        got = parse_args(["--jobs", "400"]).jobs
    if got <= cli.usable_cores() and "--oversubscribe" in err.getvalue():
        return f"accepted: capped at {got}: {err.getvalue().strip()}"
    raise AssertionError(f"--jobs 400 gave {got} workers")


def command_cases(tmp: Path):
    big = "1000000000000"
    yield "lgp.reproduce --n-sims 1000000000000 (a MemoryError after minutes before)", _argv_case("lgp.reproduce", ["--n-sims", big])
    yield "lgp.reproduce --n-boot 1000000000000", _argv_case("lgp.reproduce", ["--n-boot", big])
    yield "lgp.reproduce --samples 1000000000", _argv_case("lgp.reproduce", ["--samples", "1000000000"])
    yield "lgp.reproduce --n-perm 1000000000", _argv_case("lgp.reproduce", ["--n-perm", "1000000000"])
    yield "models.risk --n-sims 1000000000000", _argv_case("models.risk.__main__", ["--n-sims", big])
    yield "models.effort --samples 1000000000", _argv_case("models.effort.__main__", ["--samples", "1000000000"])
    yield "analysis.demo --n-boot 1000000000000", _argv_case("analysis.demo", ["--n-boot", big])
    yield "stimuli.generate --count 1000000000000", _argv_case("stimuli.generate", ["--out", "/nonexistent/x", "--count", big])

    yield "lgp.reproduce --scheduler tcp:// (no host)", _argv_case("lgp.reproduce", ["--scheduler", "tcp://"])
    yield "lgp.reproduce --scheduler inproc://x", _argv_case("lgp.reproduce", ["--scheduler", "inproc://x"])
    yield "lgp.reproduce --stimuli DIR, DIR a loop of symbolic links (\"does not exist\" before)", _loop_case(
        tmp, lambda f: (f / "loop").symlink_to("loop") or f / "loop")
    yield "stimuli.experiment --anchor-easy FIFO (\"no such file\" before)", lambda: _anchor_fifo(tmp)
    yield "<out>/.lgp-run.lock a FIFO (\"[Errno 22] Invalid argument\" before)", lambda: _lock_fifo(tmp)
    yield "--scheduler at a peer answering junk (MemoryError, Client.__del__ traceback, 20 s before)", _peer(b"junk junk " * 50)
    yield "--scheduler at an HTTP server (silent until asked; 14 s then a traceback before)", _peer(None)
    yield "lgp.reproduce --jobs 400 on 2 cores (started 400 workers)", ("accept", _jobs)


# ----------------------------------------------------------------------------- the API


def api_cases():
    from models.risk import RiskModel, physical_risk
    from models.risk.structures import tower

    def risk(sigma=0.05, **kw):
        return lambda: physical_risk(tower(2), sigma, **{"n_sims": 3, "seed": 0, **kw})

    def model(**kw):  # the risk model is checked when made, inside the probe
        return lambda: physical_risk(tower(2), 0.05, n_sims=3, seed=0, model=RiskModel(**kw))

    for value in (float("inf"), 1e308, float("nan"), 1.5, -0.1, "0.1"):
        yield f"physical_risk sigma={value!r}", risk(value)
    for value in (2.5, "4", True, 0, 10**12):
        yield f"physical_risk n_sims={value!r}", risk(n_sims=value)
    for value in (None, -1, 1.5):
        yield f"physical_risk seed={value!r}", risk(seed=value)
    yield "physical_risk fall_rule='sideways'", model(fall_rule="sideways")
    yield "physical_risk fall_threshold=0", model(fall_threshold=0)
    yield "physical_risk engine='bullet'", model(engine="bullet")

    import lgp

    B = stimuli.load_trial("1E").target
    yield "lgp.plan(None, B)", lambda: lgp.plan(None, B)
    yield "lgp.plan(B, None)", lambda: lgp.plan(B, None)
