"""A Dask scheduler address that cannot be one is refused in one line:
``tcp://`` (no host), ``inproc://x``, a web address or an unknown scheme at the
door; a peer that answers junk or HTTP (or nothing) after one look at its first
bytes, with no Client ever made, so no ``Client.__del__`` traceback and no 20 s
wait at exit follow the error. And a path that is not what a command expects is
named as what it is: a FIFO lock file, a loop of symbolic links (not "does not
exist"), an anchor that is a FIFO."""
from __future__ import annotations

import os
import re
import subprocess
import sys
import textwrap
from pathlib import Path

import pytest

from bench.common import deadline
from lgp.errors import InputError
from lgp.executor.cluster import check_address

ROOT = Path(__file__).resolve().parents[1]


@pytest.mark.parametrize("address, why", [
    ("tcp://", "names no host"),
    ("inproc://x", "names a scheduler inside this very process"),
    ("http://127.0.0.1:8787/status", "is a web address (the dashboard?), not a Dask scheduler"),
    ("udp://h:1", "unknown scheme 'udp://'"),
    ("tcp://h:99999", "the port must be a number in 1-65535"),
    ("tcp://h:0", "the port must be a number in 1-65535"),
])
def test_an_address_that_cannot_name_a_scheduler_is_refused(address, why):
    with pytest.raises(InputError, match=re.escape(why)):
        check_address(address)


def test_addresses_of_a_scheduler_pass():
    for address in ("tcp://127.0.0.1:8786", "tls://sched.example:8786", "127.0.0.1:8786", "LOCAL-DASK"):
        assert check_address(address) in (address, "local-dask")
    assert check_address("inproc://10.0.0.1/123/1", allow_inproc=True)  # the API may name its own in-process scheduler


@pytest.mark.parametrize("address", ["tcp://", "inproc://x"])
def test_the_command_line_refuses_such_an_address_before_any_work(capsys, address):
    from lgp.reproduce import parse_args

    with pytest.raises(SystemExit) as e:
        parse_args(["--scheduler", address])
    err = capsys.readouterr().err.strip()
    assert e.value.code == 2 and len(err.splitlines()) == 1 and "argument --scheduler:" in err, err


_PEERS = textwrap.dedent("""
    import socket, sys, threading, time
    from lgp import cli
    from lgp.executor import DaskExecutor

    def serve(reply):
        s = socket.socket()
        s.bind(("127.0.0.1", 0))
        s.listen(8)

        def loop():
            while True:
                c, _ = s.accept()
                if reply is not None:
                    c.sendall(reply)
                    c.close()
                else:
                    time.sleep(30)  # an HTTP server: waits for a request, says nothing first
        threading.Thread(target=loop, daemon=True).start()
        return s.getsockname()[1]

    reply = {"junk": b"junk junk junk\\n" * 50, "http": b"HTTP/1.0 400 Bad Request\\r\\n\\r\\n", "silent": None}[sys.argv[1]]
    port = serve(reply)

    def main(argv):
        with DaskExecutor(f"tcp://127.0.0.1:{port}", timeout=2.0):
            pass

    raise SystemExit(cli.run_cli(main, [], prog="probe"))
""")


@pytest.mark.slow  # a subprocess importing dask.distributed
@pytest.mark.parametrize("peer, why", [("junk", "it answered b'junk jun'..., not Dask's protocol: not a Dask scheduler"),
                                       ("http", "b'HTTP/1.0'..., an HTTP server: not a Dask scheduler"),
                                       ("silent", "something accepts connections there but sent nothing within 2 s")])
def test_a_peer_that_is_no_scheduler_is_named_in_one_line_and_nothing_follows(tmp_path, peer, why):
    pytest.importorskip("distributed")
    script = tmp_path / "peers.py"
    script.write_text(_PEERS)
    r = subprocess.run([sys.executable, str(script), peer], cwd=tmp_path, env={**os.environ, "PYTHONPATH": str(ROOT)},
                       capture_output=True, text=True, timeout=120)
    assert r.returncode == 1, r.stderr
    lines = [ln for ln in r.stderr.splitlines() if ln.strip()]
    assert len(lines) == 1 and lines[0].startswith("probe: error: tcp://127.0.0.1:") and why in lines[0], r.stderr
    assert "Client.__del__" not in r.stderr and "Traceback" not in r.stderr


# ----------------------------------------------------------------------------- what a path is, said


def test_a_fifo_or_a_symlinked_lock_file_is_named_not_opened(tmp_path):
    """A FIFO at <out>/.lgp-run.lock gave "[Errno 22] Invalid argument" and no path."""
    from lgp.app.manifest import OutputFolderBusy, OutputLock
    from lgp.cli import one_line

    lock = tmp_path / OutputLock.NAME
    os.mkfifo(lock)
    with deadline(10), pytest.raises(OutputFolderBusy) as e:
        with OutputLock(tmp_path, "x"):
            pass
    assert one_line(e.value) == f"{lock}: a FIFO (named pipe), not the lock file a run makes (a regular file); remove it and rerun"
    lock.unlink()
    lock.symlink_to("/etc/passwd")
    with pytest.raises(OutputFolderBusy, match=r"a symbolic link \(to /etc/passwd\), not the lock file"):
        with OutputLock(tmp_path, "x"):
            pass
    lock.unlink()
    with OutputLock(tmp_path, "x"):  # a sound folder still locks
        assert lock.is_file()
    assert not lock.exists()


def test_a_symlink_loop_is_called_a_loop(tmp_path, capsys):
    import stimuli
    from lgp.inputs import InputFileError, read_bounded
    from lgp.reproduce import parse_args

    (tmp_path / "loop").symlink_to("loop")
    with pytest.raises(SystemExit):
        parse_args(["--stimuli", str(tmp_path / "loop")])
    err = capsys.readouterr().err
    assert "argument --stimuli:" in err and "is a loop of symbolic links" in err and "does not exist" not in err, err
    (tmp_path / "trials").mkdir()
    (tmp_path / "trials" / "X1.yaml").symlink_to("X1.yaml")
    with pytest.raises(stimuli.StimulusError, match="X1.yaml is a loop of symbolic links"):
        stimuli.load_trial("X1", tmp_path / "trials")
    with pytest.raises(InputFileError, match="a loop of symbolic links"):
        read_bounded(tmp_path / "trials" / "X1.yaml", 100)


def test_an_anchor_that_is_a_fifo_is_named_as_one(tmp_path):
    from stimuli import experiment as ex

    os.mkfifo(tmp_path / "anchor.yaml")
    with deadline(10), pytest.raises(ex.StudyError, match=r"--anchor-easy .*anchor.yaml: a FIFO \(named pipe\), not a trial file"):
        ex.load_anchor(tmp_path / "anchor.yaml", "easy", set())
    (tmp_path / "loop.yaml").symlink_to("loop.yaml")
    with pytest.raises(ex.StudyError, match="a loop of symbolic links"):
        ex.load_anchor(tmp_path / "loop.yaml", "hard", set())
