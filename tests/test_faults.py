"""A run stopped from outside leaves nothing behind: SIGTERM stops it like Ctrl-C
(one line, workers terminated) and SIGKILL of the parent takes its workers with it
(issue 16, item 1). Descendants are read from /proc, so these tests need Linux."""
import os
import signal
import subprocess
import sys
import textwrap
import time
from pathlib import Path

import pytest

pytestmark = pytest.mark.skipif(not Path("/proc/self/stat").exists(), reason="needs Linux /proc")

ROOT = Path(__file__).resolve().parents[1]


def _children() -> dict[int, list[int]]:
    tree: dict[int, list[int]] = {}
    for entry in os.listdir("/proc"):
        if entry.isdigit():
            try:
                stat = Path(f"/proc/{entry}/stat").read_text()
            except OSError:  # exited while we looked
                continue
            ppid = int(stat.rsplit(")", 1)[1].split()[1])
            tree.setdefault(ppid, []).append(int(entry))
    return tree


def descendants(pid: int) -> list[int]:
    tree, out, todo = _children(), [], [pid]
    while todo:
        for child in tree.get(todo.pop(), []):
            out.append(child)
            todo.append(child)
    return out


def alive(pids) -> list[int]:
    """Those of `pids` that still run (a zombie has exited: it only waits to be reaped)."""
    out = []
    for pid in pids:
        try:
            state = Path(f"/proc/{pid}/stat").read_text().rsplit(")", 1)[1].split()[0]
        except OSError:
            continue
        if state != "Z":
            out.append(pid)
    return out


def _start(cmd, cwd, n_workers: int, timeout: float = 120.0):
    """Start `cmd`, wait until it has `n_workers` child processes; return (proc, workers)."""
    env = {**os.environ, "PYTHONPATH": str(ROOT)}
    proc = subprocess.Popen(cmd, cwd=cwd, env=env, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    deadline = time.monotonic() + timeout
    while time.monotonic() < deadline:
        workers = descendants(proc.pid)
        if len(workers) >= n_workers:
            return proc, workers
        if proc.poll() is not None:
            break
        time.sleep(0.05)
    proc.kill()
    out, err = proc.communicate()
    pytest.fail(f"{cmd} never had {n_workers} workers (exit {proc.returncode}):\n{err[-2000:]}")


def alive_after(pids, seconds: float = 5.0) -> list[int]:
    """Those of `pids` still running `seconds` from now; returns as soon as none is."""
    deadline = time.monotonic() + seconds
    while alive(pids) and time.monotonic() < deadline:
        time.sleep(0.05)
    return alive(pids)


def _reap(proc, sig):
    proc.send_signal(sig)
    try:
        out, err = proc.communicate(timeout=30)
    except subprocess.TimeoutExpired:
        proc.kill()
        out, err = proc.communicate()
        pytest.fail(f"still running 30 s after {sig.name}:\n{err[-2000:]}")
    return out, err


_POOL_SCRIPT = textwrap.dedent("""
    import os, signal, sys, time
    from lgp.executor import ProcessExecutor, stop_signals

    def busy(k):
        t = time.monotonic()
        while time.monotonic() - t < 0.3:  # compute, so signals land inside a task
            pass
        return k

    if __name__ == "__main__":
        with stop_signals(), ProcessExecutor(2, sys.argv[1]) as ex:
            ex.map(busy, range(10**5))
""")


@pytest.mark.slow
@pytest.mark.parametrize("start_method", ["fork", "spawn"])
def test_workers_die_with_a_killed_parent_quietly(tmp_path, start_method):
    """kill -9 cannot be handled by the parent: the kernel must end the workers
    (PR_SET_PDEATHSIG), and a worker that inherited the parent's SIGTERM handler
    must not catch the signal and print a traceback instead of dying."""
    script = tmp_path / "pool.py"
    script.write_text(_POOL_SCRIPT)
    proc, workers = _start([sys.executable, str(script), start_method], tmp_path, 2)
    time.sleep(0.5)  # the workers are inside tasks now
    workers = descendants(proc.pid)
    out, err = _reap(proc, signal.SIGKILL)
    left = alive_after(workers, 5)
    assert left == [], f"workers {left} outlived their parent by 5 s"
    assert "Traceback" not in err, err


@pytest.mark.slow
def test_sigterm_stops_the_pool_like_ctrl_c(tmp_path):
    script = tmp_path / "pool.py"
    script.write_text(_POOL_SCRIPT)
    proc, workers = _start([sys.executable, str(script), "fork"], tmp_path, 2)
    time.sleep(0.5)
    out, err = _reap(proc, signal.SIGTERM)
    assert "Interrupted: stopped by SIGTERM" in err  # raised in the parent, uncaught by this script
    assert alive_after(workers, 5) == []


REPRODUCE = [sys.executable, "-m", "lgp.reproduce", "--trials", "7H", "4H", "--samples", "4",
             "--n-sims", "400", "--jobs", "2", "--no-cache", "--out", "out"]


@pytest.mark.slow
@pytest.mark.parametrize("sig, wait", [(signal.SIGTERM, 0.0), (signal.SIGTERM, 1.0), (signal.SIGKILL, 1.0)],
                         ids=["SIGTERM-while-importing", "SIGTERM-while-computing", "SIGKILL"])
def test_a_stopped_reproduce_leaves_no_worker_alive(tmp_path, sig, wait):
    """A real parallel run, stopped once its pool exists (its workers start before
    the parent imports Drake, so wait 0 lands in those imports): no descendant
    survives 5 s later; SIGTERM ends it with one line on stderr and status 128 + 15."""
    proc, _ = _start(REPRODUCE, tmp_path, 2)
    seen = set(descendants(proc.pid))
    t0 = time.monotonic()
    while time.monotonic() - t0 < wait:  # collect every worker there was
        seen |= set(descendants(proc.pid))
        time.sleep(0.1)
    out, err = _reap(proc, sig)
    left = alive_after(seen, 5)
    assert left == [], f"{len(left)} descendants outlived the run by 5 s"
    if sig == signal.SIGTERM:
        assert proc.returncode == 128 + signal.SIGTERM, err[-3000:]
        last = err.strip().splitlines()[-1]
        assert "Traceback" not in err and last.startswith("python -m lgp.reproduce: terminated (SIGTERM)"), err
        # stopped like Ctrl-C: atomic writes clean up their temporary files
        # (a SIGKILL during a write may leave one; it is never read as a result)
        partial = [p for p in (tmp_path / "out").rglob("*") if p.name.startswith(".") or p.suffix == ".tmp"]
        assert partial == [], partial
