"""Shared fixtures and the suite's conventions.

    python -m pytest -q                 # everything (budget: 8 min on 2 quiet cores)
    python -m pytest -q -m "not slow"   # the fast subset (budget: 40 s; README: how long each takes)
    python -m pytest -q -n 0 tests/test_x.py   # one process (pyproject's addopts run two workers)

Session fixtures are per worker process: with two workers (pytest-xdist, --dist loadfile) a
session fixture used by files on both workers is built twice, unless it is built once
per suite run (`suite_folder`, `Claim`): the session's --quick run, the undisturbed pool
run and the studies are; the first worker to ask builds, the other waits and reads.

Fixtures: the trials (loaded once per session, not at import time), the synthetic
effort and risk tables of the analysis tests, and the session's one small
`lgp.reproduce --quick` run (`quick_run`, QUICK_RUN) that end-to-end checks read
instead of running their own; a test that must rerun copies its cache
(`copy_of_run`: the cache is keyed by content, so a copy computes nothing again).
Only the cache tests keep caches of their own.

Slow (`@pytest.mark.slow`, in the full suite only): a case over ~0.3 CPU-s (tests/slow_cases.txt), a Drake or
PhysX engine case (the rule below), a subprocess, pool or figure-heavy case; a case
whose B copies an earlier trial's blocks (`trials_with_copies_slow`) when the fast
subset already checks that B. A second engine runs on each distinct B once
(`distinct_b_trials`, 17 of 24); MuJoCo on all 24. Measure with bench/pytest_cpu.py
and bench/test_times.py (CPU seconds per test; wall times on a shared machine follow
the load).

Numbers must not depend on the CPU's BLAS kernel. A test of the numeric core runs
the computation in a fresh interpreter under two OpenBLAS core types and compares
(`under_blas_core`; tests/test_analysis_ties.py::test_two_blas_core_types_choose_the_same_sigmas):
OPENBLAS_CORETYPE=SkylakeX (AVX-512 kernels) and Haswell (AVX2) round differently,
and an x86-64 CPU with AVX-512 runs both. The whole fast subset passes under each:

    OPENBLAS_CORETYPE=SkylakeX python -m pytest -q -m "not slow"
    OPENBLAS_CORETYPE=Haswell python -m pytest -q -m "not slow"

A tie the data leave open is broken by an explicit rule (e.g. the smaller sigma
within 1e-9, analysis.sigma.least_sigma_index), never left to rounding.
"""
import fcntl
import functools
import os
import shutil
import subprocess
import sys
import threading
from pathlib import Path

import numpy as np
import pandas as pd
import pytest

from lgp.paper import SIGMA_GRID, TRIAL_IDS


#: Cases measured over the fast subset's share (CPU seconds beside each; written by
#: `python bench/test_times.py CSV --over 0.3 --write-slow`): in the full suite only.
SLOW_CASES = Path(__file__).with_name("slow_cases.txt")


def slow_cases(path: Path = SLOW_CASES) -> set[str]:
    """'test_file.py::test_name[params]' (or without [params]: every case) per line; '#' comments."""
    if not path.exists():
        return set()
    return {line.split("#", 1)[0].strip() for line in path.read_text().splitlines()} - {""}


def case_key(item) -> str:
    """How SLOW_CASES names a case: its file's name, '::', its name with parameters."""
    return f"{Path(str(item.fspath)).name}::{item.name}"


#: Each test file's wall seconds in a whole-suite run (now: the mean of two in-place
#: runs' per-test timelines on the two workers; `python bench/test_times.py CSV
#: --write-file-seconds` writes it from bench/pytest_cpu.py's CSV): the order in which
#: the files are handed out.
FILE_SECONDS = Path(__file__).with_name("file_seconds.csv")


def file_seconds(path: Path = FILE_SECONDS) -> dict[str, float]:
    """{test file name: seconds} of FILE_SECONDS ({} if it is missing)."""
    if not path.exists():
        return {}
    import csv

    with path.open() as f:
        return {row["file"]: float(row["seconds"]) for row in csv.DictReader(f)}


def longest_files_first(items, seconds: dict[str, float] | None = None) -> None:
    """Sort `items` (in place) by their file's FILE_SECONDS, longest first, each file's
    own order kept; a file not listed counts as the median. With pyproject's
    `--dist loadfile --no-loadscope-reorder` the workers take the files in this order,
    one at a time: the last files handed out are the short ones, so the two workers end
    together (xdist's default order, by the number of tests in a file, handed out the
    long end-to-end files last: in one fresh-clone run one worker ran alone for most of
    its last minute, 140 idle core-s of 1015). `seconds`: {file name: s} instead of FILE_SECONDS."""
    seconds = file_seconds() if seconds is None else seconds
    default = float(np.median(list(seconds.values()))) if seconds else 0.0
    first_seen: dict[str, int] = {}
    for item in items:
        first_seen.setdefault(Path(str(item.fspath)).name, len(first_seen))

    def rank(item) -> tuple[float, int]:
        name = Path(str(item.fspath)).name
        return -seconds.get(name, default), first_seen[name]

    items.sort(key=rank)


def pytest_collection_modifyitems(items):
    """Slow: a case run with the Drake or a PhysX engine (a parameter "drake",
    "physx", "physx:..."): Drake's hydroelastic contact at 1 ms steps costs seconds
    per scene, and PhysX is an optional extra; the fast subset checks MuJoCo. And
    every case SLOW_CASES lists (measured over the fast subset's share). Then the
    files longest first (`longest_files_first`)."""
    listed = slow_cases()
    for item in items:
        params = getattr(getattr(item, "callspec", None), "params", {})
        key = case_key(item)
        if (any(isinstance(v, str) and (v == "drake" or v.split(":")[0] == "physx") for v in params.values())
                or key in listed or key.split("[", 1)[0] in listed):
            item.add_marker(pytest.mark.slow)
    longest_files_first(items)


@functools.lru_cache(maxsize=None)
def _paper_trials() -> dict:
    import stimuli

    loaded = {t.id: t for t in stimuli.load_all()}
    return {tid: loaded[tid] for tid in TRIAL_IDS}


def b_structure(scene, *, translated: bool = True) -> tuple:
    """What the physics of a scene depends on: every block's centre, yaw and size and
    every fixed box, in no order, without names or colours; `translated`: relative to
    the lowest corner of the blocks' centres on the table (a copy moved on the table
    is the same structure)."""
    origin = np.zeros(3)
    if translated:
        origin[:2] = np.min([b.p_WB for b in scene.blocks], axis=0)[:2]
    r = lambda v: tuple(np.round(np.asarray(v, float) - origin, 9) + 0.0)  # noqa: E731  (+0.0: no -0.0)
    return (tuple(sorted((r(b.p_WB), round(float(b.yaw), 9) + 0.0, tuple(np.round(b.size, 9))) for b in scene.blocks)),
            tuple(sorted((r(f.p_WO), tuple(np.round(f.size, 9))) for f in scene.fixed)))


@functools.lru_cache(maxsize=None)
def same_b_as(*, translated: bool = True) -> dict[str, str]:
    """Each of the paper's 24 trials -> the first trial (in TRIAL_IDS order) whose
    Finish state B has the same `b_structure`. Exact copies (B the same blocks at
    the same places): 1H = 9E = 9H = 11E = 11H and 2E = 2H; moved copies as well
    (`translated`): 4E = 10E = 10H. 24 trials, 17 distinct B structures."""
    first: dict[tuple, str] = {}
    return {tid: first.setdefault(b_structure(t.target, translated=translated), tid)
            for tid, t in _paper_trials().items()}


def distinct_b_trials(*, translated: bool = True) -> list[str]:
    """The trials whose B is the first of its structure (`same_b_as`): a check that
    depends only on B's physics runs once per structure."""
    return [tid for tid, first in same_b_as(translated=translated).items() if tid == first]


def trials_with_copies_slow(trial_ids=TRIAL_IDS) -> list:
    """`trial_ids` as pytest params: each B structure's first trial as is, a trial
    whose B is a copy of an earlier one (`same_b_as`) marked slow: the fast subset
    checks every distinct B once, the full suite every trial."""
    firsts = same_b_as()
    return [tid if firsts[tid] == tid else pytest.param(tid, marks=pytest.mark.slow) for tid in trial_ids]


@pytest.fixture(scope="session")
def trials():
    """The paper's 24 trials by id (stimuli.load_all, once per session)."""
    return _paper_trials()


# ----------------------------------------------------------------------------- synthetic model output (analysis tests)


def synthetic_effort(seed=0) -> pd.Series:
    """24 positive efforts, keyed by trial id (stand-in for the planner's output)."""
    return pd.Series(np.random.default_rng(seed).uniform(1, 10, 24), index=list(TRIAL_IDS))


def synthetic_risk(seed=0, sigmas=SIGMA_GRID) -> pd.DataFrame:
    """Risk per trial and sigma: a logistic in sigma around a per-trial threshold, so
    each trial's risk increases with sigma and the ranking of trials changes with it
    (if R(sigma) were c(sigma) R0, Eq. 1 would fit every sigma equally well)."""
    threshold = np.random.default_rng(seed + 100).uniform(0.04, 0.12, 24)
    return pd.DataFrame([(t, s, 1 / (1 + np.exp(-(s - threshold[i]) / 0.01)))
                         for s in sigmas for i, t in enumerate(TRIAL_IDS)],
                        columns=["trial", "sigma", "risk"])


@pytest.fixture(scope="session")
def make_effort():
    """synthetic_effort(seed): 24 positive efforts keyed by trial id."""
    return synthetic_effort


@pytest.fixture(scope="session")
def make_risk():
    """synthetic_risk(seed, sigmas): a tidy (trial, sigma, risk) table, logistic in sigma."""
    return synthetic_risk


# ----------------------------------------------------------------------------- built once per suite run


def suite_folder(tmp_path_factory) -> Path:
    """A folder shared by every worker of this pytest run: under pytest-xdist each worker's
    base temporary folder is <run>/popen-gwN, so <run>/suite; with -n 0 (no workers) the
    session's own <run>/suite (the parent then holds other runs' folders)."""
    base = tmp_path_factory.getbasetemp()
    root = (base.parent if os.environ.get("PYTEST_XDIST_WORKER") else base) / "suite"
    root.mkdir(exist_ok=True)
    return root


class Claim:
    """The right to build `name` in `suite_folder` (the pytest-xdist recipe: a file lock
    under the run's shared folder). `Claim(root, name, wait=False)` takes the fcntl lock
    <name>.lock if it is free; `.build` is True when this worker must build (nobody
    finished it: <name>/done is absent) and then holds the lock until `finish` (or its
    process ends, which frees the lock). With `wait=True` it waits while another worker
    holds the lock. `.held` is False when another worker holds it (wait=False)."""

    def __init__(self, root: Path, name: str, wait: bool = True):
        self.folder, self.done = root / name, root / name / "done"
        self._fd = os.open(root / f"{name}.lock", os.O_RDWR | os.O_CREAT, 0o600)
        try:
            fcntl.flock(self._fd, fcntl.LOCK_EX | (0 if wait else fcntl.LOCK_NB))
        except BlockingIOError:
            os.close(self._fd)
            self._fd, self.held, self.build = None, False, False
            return
        self.held = True
        self.build = not self.done.exists()
        if self.build:  # nobody built it, or a worker died half way: start afresh (this run's own folder)
            shutil.rmtree(self.folder, ignore_errors=True)
            self.folder.mkdir()
        else:
            self.release()

    def finish(self, text: str = "ok") -> None:
        """Mark it built (`text`: "ok" or why not) and let the other workers read it."""
        tmp = self.done.with_name("done.tmp")
        tmp.write_text(text)
        tmp.replace(self.done)
        self.release()

    def release(self) -> None:
        if self._fd is not None:
            os.close(self._fd)  # frees the lock
            self._fd = None


def built_once(tmp_path_factory, name: str, build) -> Path:
    """The folder `name` of this suite run, `build(folder)` run in it by the first worker
    that asks (the others wait, then read it). A build that raises leaves no `done`:
    the next worker to ask builds again (and fails again, with its own message)."""
    claim = Claim(suite_folder(tmp_path_factory), name)
    if claim.build:
        try:
            build(claim.folder)
        except BaseException:
            claim.release()
            raise
        claim.finish()
    return claim.folder


# ----------------------------------------------------------------------------- one small --quick run for the session

#: The session's --quick run of the paper's 24 trials (2 layouts, 5 runs, 4 sigmas): the
#: results page, the study's simulated participants and "every trial plans" read it.
QUICK_RUN = ["--quick", "--samples", "2", "--n-sims", "5", "--sigmas", "0.05", "0.065", "0.08", "0.2"]


class _Run:
    """`python -m lgp.reproduce ARGS --out DIR` started in the background; `wait()`
    checks it exited 0 (the tail of its stderr if not) and returns DIR. With a `claim`
    (`Claim`): its exit status goes to the claim's `done` when the run ends, which lets
    the other workers read DIR."""

    def __init__(self, args: list[str], out: Path, log: Path, claim: "Claim | None" = None):
        self.out, self.log = out, log
        with open(log, "w") as err:
            self.process = subprocess.Popen([sys.executable, "-m", "lgp.reproduce", *args, "--out", str(out)],
                                            stdout=subprocess.DEVNULL, stderr=err)
        self.code = None
        if claim is not None:
            threading.Thread(target=lambda: claim.finish(str(self.process.wait())), daemon=True).start()

    def wait(self) -> Path:
        if self.code is None:
            self.code = self.process.wait()
        assert self.code == 0, self.log.read_text()[-3000:]
        return self.out

    def stop(self) -> None:
        if self.process.poll() is None:
            self.process.kill()
            self.process.wait()


class _RunOfAnotherWorker:
    """The session's run that another worker started: `wait()` waits for its lock (held
    until the run ends), checks its exit status and returns its folder; if that worker
    died before the run ended, this one runs it."""

    def __init__(self, root: Path, name: str, args: list[str]):
        self.root, self.name, self.args = root, name, args
        self.out, self.log = root / name / "out", root / name / "stderr"

    def wait(self) -> Path:
        claim = Claim(self.root, self.name)
        if claim.build:  # the worker that started it ended before the run did: run it here
            return _Run(self.args, self.out, self.log, claim).wait()
        code = claim.done.read_text()
        assert code == "0", f"the session's run (exit status {code}): " + self.log.read_text()[-3000:]
        return self.out

    def stop(self) -> None:
        pass


@pytest.fixture(scope="session")
def quick_run_started(tmp_path_factory):
    """The session's QUICK_RUN, started (a fixture that has other work to do meanwhile,
    as the study build, asks for this one first and waits on `quick_run`). Once per
    suite run: the first worker to ask starts it, another waits for it (`Claim`)."""
    root = suite_folder(tmp_path_factory)
    claim = Claim(root, "quick-run", wait=False)
    if claim.build:
        run = _Run(QUICK_RUN, claim.folder / "out", claim.folder / "stderr", claim)
    else:  # started (or finished) by another worker
        run = _RunOfAnotherWorker(root, "quick-run", QUICK_RUN)
    yield run
    if os.environ.get("PYTEST_XDIST_WORKER") and isinstance(run, _Run) and run.process.poll() is None:
        run.process.wait()  # another worker may be waiting for it
    run.stop()


@pytest.fixture(scope="session")
def quick_run(quick_run_started) -> Path:
    """The folder of the session's QUICK_RUN (read it, do not write into it: a test
    that reruns copies it first, `copy_of_run`)."""
    return quick_run_started.wait()


# ----------------------------------------------------------------------------- the studies, built once per suite run

#: The picture size of the suite's studies: the study's own (stimuli.render.DEFAULT_SIZE), larger
#: than a laptop shows them, so that their size on screen is set by the layout
#: (tests/test_study_layout.py), and the size of the README's study build, which then finds
#: every picture in the suite's render cache (`suite_render_cache`). LGP_STUDY_LAYOUT_SIZE
#: sets another.
STUDY_SIZE = os.environ.get("LGP_STUDY_LAYOUT_SIZE", "960x640")


@pytest.fixture(scope="session", autouse=True)
def suite_render_cache(tmp_path_factory) -> Path:
    """One render cache for every picture the suite renders (its runs, studies and
    commands, in this process and the ones it starts): a folder of this suite run,
    shared by the workers (a picture is found by the hash of its scene, camera and
    code, so sharing is safe). So no test writes into the user's ~/.cache, and a
    picture one test rendered is not rendered again by the next (on a fresh machine
    the README's study build alone rendered its 52 pictures, 37 CPU-s, again). A
    caller's LGP_RENDER_CACHE (bench/commands.py: a cold folder per command) is used
    as given."""
    if not os.environ.get("LGP_RENDER_CACHE"):
        os.environ["LGP_RENDER_CACHE"] = str(suite_folder(tmp_path_factory) / "render-cache")
    return Path(os.environ["LGP_RENDER_CACHE"])


@pytest.fixture(scope="session")
def suite_studies(tmp_path_factory) -> dict:
    """{task: folder} of the paper's three studies (`python -m stimuli.experiment --task
    T --size STUDY_SIZE`), built once per suite run (`built_once`): the first build
    renders the pictures into the suite's render cache (`suite_render_cache`), the
    other two (and the README's study build) find them there. Read them, do not write
    into them."""
    from stimuli import experiment as ex

    def build(root: Path) -> None:
        from lgp.cli import run_cli
        from stimuli.experiment.__main__ import PROG, main

        for task in ex.TASKS:  # the command's own main, in this process: no interpreter, pydrake or VTK loaded
            # again per study (the README's build runs it as a command); rendering in this process too
            code = run_cli(main, ["--task", task, "--out", str(root / task), "--size", STUDY_SIZE, "--jobs", "1"], prog=PROG)
            assert code == 0, f"python -m stimuli.experiment --task {task}: exit {code}"

    root = built_once(tmp_path_factory, "studies", build)
    return {task: root / task for task in ex.TASKS}


def copy_of_run(run: Path, out: Path) -> Path:
    """A fresh output folder `out` holding a copy of `run`'s cache only: a rerun with
    the same trials and parameters computes nothing (the cache is keyed by content)."""
    out.mkdir(parents=True, exist_ok=True)
    shutil.copytree(run / "cache", out / "cache")
    return out


#: The OpenBLAS core types a numeric-core test compares (both run on an AVX-512 x86-64 CPU).
BLAS_CORE_TYPES = ("SkylakeX", "Haswell")


def under_blas_core(core: str, script: str, timeout: float = 300) -> str:
    """stdout of `python -c script` in a fresh interpreter with OPENBLAS_CORETYPE=core
    (numpy and scipy read it when they load, so it cannot change in-process); fails
    with the script's stderr if it exits non-zero."""
    import os

    root = str(Path(__file__).resolve().parents[1])
    env = dict(os.environ, OPENBLAS_CORETYPE=core, PYTHONPATH=root + os.pathsep + os.environ.get("PYTHONPATH", ""))
    done = subprocess.run([sys.executable, "-c", script], cwd=root, env=env, capture_output=True, text=True, timeout=timeout)
    assert done.returncode == 0, f"OPENBLAS_CORETYPE={core}: {done.stderr[-2000:]}"
    return done.stdout



# ----------------------------------------------------------------------------- a worker of a running command, signalled


def workers_of(pid: int) -> list[int]:
    """The descendants of process `pid` but spawn's resource tracker (no worker)."""
    from tests.test_faults import descendants

    out = []
    for p in descendants(pid):
        try:
            if b"resource_tracker" not in Path(f"/proc/{p}/cmdline").read_bytes():
                out.append(p)
        except OSError:
            pass
    return out


def run_signalling_a_worker(cmd: list[str], cwd: Path, env: dict, sig=None, after: float = 0.0,
                            deadline: float = 60.0, what: str = "a worker died") -> tuple[int, str, str]:
    """(exit status, stdout, stderr) of `cmd`; with a signal `sig`: once the command
    has two workers, wait `after` s and send `sig` to one of them from outside
    (as `kill -9` or `kill -STOP` from another shell does). A command still running
    `deadline` s later is killed and the test fails: it hung after `what`."""
    import os
    import time

    t0 = time.monotonic()
    proc = subprocess.Popen(cmd, cwd=cwd, env=env, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    if sig is not None:
        while len(workers_of(proc.pid)) < 2 and time.monotonic() - t0 < 30:
            time.sleep(0.02)
        time.sleep(after)
        workers = workers_of(proc.pid)
        assert workers, f"the command ended before a worker could be signalled ({sig!r})"
        os.kill(workers[0], sig)
    try:
        out, err = proc.communicate(timeout=deadline)
    except subprocess.TimeoutExpired:
        proc.kill()
        out, err = proc.communicate()
        pytest.fail(f"the command hung: still running {deadline:g} s after {what}\n{err[-2000:]}")
    return proc.returncode, out, err


#: A small default (process-pool) run whose workers the worker-death and worker-stall
#: tests kill or stop mid-stage: 4H's layouts first (quick), then 7H's (about 1 s
#: each), so when "[effort  1/2]" is printed both workers are planning 7H; --verbose:
#: the per-trial lines the cues wait for.
POOL_RUN = ["-m", "lgp.reproduce", "--trials", "4H", "7H", "--samples", "4", "--n-sims", "40",
            "--sigmas", "0.05", "0.1", "--jobs", "2", "--no-replays", "--verbose"]


def result_csvs(out: Path) -> dict:
    """A run's effort_samples.csv, effort.csv and risk.csv, less the wall-clock solve_time."""
    tables = {name: pd.read_csv(out / name) for name in ("effort_samples.csv", "effort.csv", "risk.csv")}
    tables["effort_samples.csv"] = tables["effort_samples.csv"].drop(columns="solve_time")
    return tables


def _project_env(**extra) -> dict:
    import os

    root = str(Path(__file__).resolve().parents[1])
    return {**os.environ, "PYTHONPATH": root + os.pathsep + os.environ.get("PYTHONPATH", ""), **extra}


@pytest.fixture(scope="session")
def pool_run_undisturbed(tmp_path_factory) -> Path:
    """The output folder of POOL_RUN without a fault and without a cache (once per
    suite run, `built_once`: the worker-death and worker-stall cases compare their CSVs with it)."""
    def build(folder: Path) -> None:
        ref = subprocess.run([sys.executable, *POOL_RUN, "--no-cache", "--out", str(folder / "undisturbed")],
                             cwd=Path(__file__).resolve().parents[1], env=_project_env(),
                             capture_output=True, text=True, timeout=600)
        assert ref.returncode == 0, ref.stderr[-3000:]

    return built_once(tmp_path_factory, "pool-run", build) / "undisturbed"


def pool_run_signalling_a_worker(out: Path, cue: str, sig, pause: float = 0.0, **env) -> tuple[int, str]:
    """(exit status, stderr) of POOL_RUN into `out`, one of whose workers gets `sig`
    `pause` s after the run prints a line holding `cue`; fails if the cue never
    comes or the run is still going 240 s after the signal. `env`: extra variables."""
    import os
    import threading
    import time

    root = Path(__file__).resolve().parents[1]
    proc = subprocess.Popen([sys.executable, *POOL_RUN, "--out", str(out)], cwd=root, env=_project_env(**env),
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    lines, seen = [], threading.Event()

    def read():
        for line in proc.stderr:
            lines.append(line)
            if cue in line:
                seen.set()

    reader = threading.Thread(target=read, daemon=True)
    reader.start()
    try:
        assert seen.wait(240), "".join(lines)[-3000:]
        time.sleep(pause)
        victims = workers_of(proc.pid)
        assert victims, "".join(lines)[-3000:]
        os.kill(victims[0], sig)
        try:
            proc.wait(timeout=240)
        except subprocess.TimeoutExpired:
            pytest.fail(f"the run hung after a worker got {sig!r}:\n" + "".join(lines)[-3000:])
    finally:
        if proc.poll() is None:
            proc.kill()
            proc.wait()
    reader.join(5)
    return proc.returncode, "".join(lines)
