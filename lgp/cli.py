"""What every command line of the project shares: argument checks, one-line errors, Ctrl-C.

Each CLI (``python -m lgp.reproduce``, ``lgp.show``, ``models.risk``,
``models.effort``, ``analysis.demo``, ``stimuli.sheet``) builds its parser with
`parser`, checks its arguments with the ``type=`` validators below (so a bad
count, sigma, trial id or path fails before any work, with argparse's usage line
and exit code 2), and runs under `run_cli`:

- an error the project raises on purpose (an exception class of the project:
  StimulusError, HumanDataError, PlanningError, lgp.errors.InputError for a bad
  value, ...; or an OSError) prints one line ``prog: error: ...`` and exits 1
  (bad data: a trial file, a human-data file, a results folder, a plan that
  cannot be made); ``--debug`` or ``LGP_DEBUG=1`` in the environment shows the
  traceback as well;
- any other exception is a bug and keeps its traceback: a plain ValueError too,
  wherever it is raised (a tuple unpacked wrongly in the project's own code is a
  bug, not bad input);
- Ctrl-C prints one line (the CLI says what survives, e.g. the cache) and exits 130.

Trial ids are case-insensitive everywhere (``7h`` is ``7H``; `lgp.paper.canonical_trial_id`).
This module imports nothing of the project but `lgp.paper` and `lgp.command_times` (wall times
in words, and the measured ones ``--help`` quotes), so a CLI on any floor may use it.
"""
from __future__ import annotations

import argparse
import math
import os
import re
import sys
import traceback
from pathlib import Path
from typing import Callable, Sequence

from lgp.command_times import COMMAND_TIMES, duration_text, measured_time  # noqa: F401 (every CLI's formats)
from lgp.paper import TRIAL_IDS, canonical_trial_id

#: Environment variable that turns on tracebacks, like ``--debug``.
DEBUG_ENV = "LGP_DEBUG"
#: The project's packages: an exception class defined in one of them is a known error.
PROJECT_PACKAGES = ("lgp", "models", "analysis", "stimuli")
#: Exit codes: 1 bad data or environment, 2 bad usage (argparse), 130 Ctrl-C (128 + SIGINT).
EXIT_DATA, EXIT_USAGE, EXIT_INTERRUPTED = 1, 2, 130


# ----------------------------------------------------------------------------- validators (argparse type=)


def _int_at_least(text: str, low: int) -> int:
    try:
        value = int(str(text).strip(), 10)
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected a whole number >= {low}, got {text!r}") from None
    if value < low:
        raise argparse.ArgumentTypeError(f"must be a whole number >= {low}, got {text!r}")
    return value


def positive_int(text: str) -> int:
    """A whole number >= 1 (counts: --samples, --n-sims, --jobs, --n-boot ...)."""
    return _int_at_least(text, 1)


def nonnegative_int(text: str) -> int:
    """A whole number >= 0 (seeds: numpy Generators take no negative seed; indices)."""
    return _int_at_least(text, 0)


seed = nonnegative_int

#: The largest counts a command line takes: past them the run needs
#: more memory or time than any machine it is meant for, and failed with a
#: MemoryError after minutes of work. Each refusal gives the estimate.
MAX_SAMPLES = 10_000          # --samples M: layouts of A per trial (the paper: 30)
MAX_N_SIMS = 1_000_000        # --n-sims N: noisy simulations per trial and sigma (the paper: 100)
MAX_N_BOOT = 100_000          # --n-boot: bootstrap resamples (the paper: 1000)
MAX_N_PERM = 100_000          # --n-perm: permutations per permutation test
MAX_TRIAL_COUNT = 10_000      # stimuli.generate --count: trial files to write


def bytes_text(n_bytes: float) -> str:
    """1.5 GiB, 87 TiB, ...: a byte count in binary units."""
    for unit in ("bytes", "KiB", "MiB", "GiB", "TiB", "PiB", "EiB"):
        if n_bytes < 1024 or unit == "EiB":
            return f"{n_bytes:.0f} {unit}" if unit == "bytes" else f"{n_bytes:.3g} {unit}"
        n_bytes /= 1024
    return ""


def _estimates() -> dict[str, Callable[[int], str]]:
    from lgp.paper import N_BOOT, N_SIMS, SAMPLES, SIGMA_GRID

    n_trials, n_sigmas = len(TRIAL_IDS), len(SIGMA_GRID)
    return {
        "MAX_SAMPLES": lambda v: (f"{v:,} layouts x {n_trials} trials = {v * n_trials:,} KOMO plans, {v / SAMPLES:,.3g} times "
                                  f"the paper's M = {SAMPLES}"),
        "MAX_N_SIMS": lambda v: (f"the noise of one 10-block trial alone takes {v:,} x 10 blocks x 3 x 8 bytes = "
                                 f"{bytes_text(v * 240)} and {n_trials} trials x {n_sigmas} sigmas x {v:,} = "
                                 f"{v * n_trials * n_sigmas:,} simulations, {v / N_SIMS:,.3g} times the paper's N = {N_SIMS}"),
        "MAX_N_BOOT": lambda v: (f"{v:,} resamples x {n_trials} trial means x 8 bytes = {bytes_text(v * n_trials * 8)} per "
                                 f"dataset, {v / N_BOOT:,.3g} times the paper's {N_BOOT} resamples of work"),
        "MAX_N_PERM": lambda v: f"{v:,} refits of the model per permutation test",
        "MAX_TRIAL_COUNT": lambda v: (f"{v:,} trials, each sampled and simulated for stability and written as a file of "
                                      f"about 2 kB: {bytes_text(v * 2048)} on disk"),
    }


def bounded_count(limit_name: str) -> Callable[[str], int]:
    """A validator for a count (a whole number >= 1) of at most ``lgp.cli.<limit_name>``;
    a larger one is refused before any work with what it would cost, e.g.
    ``type=bounded_count("MAX_N_SIMS")`` refuses ``--n-sims 1000000000000`` naming
    87 TiB of noise."""
    limit = globals()[limit_name]

    def check(text: str) -> int:
        value = positive_int(text)
        if value > limit:
            raise argparse.ArgumentTypeError(f"{value:,} is more than the {limit:,} allowed (lgp.cli.{limit_name}): "
                                             f"{_estimates()[limit_name](value)}")
        return value

    check.__name__ = limit_name.lower().replace("max_", "")
    return check


def usable_cores() -> int:
    """Cores this process may use (its CPU affinity)."""
    return len(os.sched_getaffinity(0)) if hasattr(os, "sched_getaffinity") else (os.cpu_count() or 1)


def add_jobs_argument(p: argparse.ArgumentParser, default, help: str) -> None:
    """``--jobs N`` (a whole number >= 1) and ``--oversubscribe``: see `capped_jobs`."""
    p.add_argument("--jobs", type=positive_int, default=default, help=help + "; more than the usable cores is capped "
                   "at them unless --oversubscribe")
    p.add_argument("--oversubscribe", action="store_true",
                   help="start every --jobs worker even when there are more than the usable cores")


def capped_jobs(jobs: int | None, prog: str, oversubscribe: bool = False) -> int | None:
    """`jobs` capped at the usable cores, saying so in one line on stderr: 400
    workers on 2 cores only share them, each with its own memory (a process pool
    of 400 Python processes). ``--oversubscribe`` keeps them all; None stays None
    (the command's default)."""
    cores = usable_cores()
    if jobs is None or jobs <= cores or oversubscribe:
        return jobs
    print(f"{prog}: --jobs {jobs} is more than the {cores} usable core(s): using {cores} "
          "(--oversubscribe starts them all)", file=sys.stderr, flush=True)
    return cores


def _finite_number(text: str, ok: Callable[[float], bool], expected: str, rule: str) -> float:
    """`text` as a finite float for which `ok` holds: "expected {expected}" when it is
    not a number, "{rule}" when it breaks the rule (both name the text)."""
    try:
        value = float(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected {expected}, got {text!r}") from None
    if not (math.isfinite(value) and ok(value)):
        raise argparse.ArgumentTypeError(f"{rule}, got {text!r}")
    return value


def sigma(text: str) -> float:
    """A noise SD in units of the block length d, in (0, 1]."""
    return _finite_number(text, lambda v: 0 < v <= 1, "a number in (0, 1] (units of d)",
                          "a sigma must be in (0, 1] (units of the block size d)")


def precision_level(text: str) -> float:
    """A risk level of the required precision sigma*, in (0, 1)."""
    return _finite_number(text, lambda v: 0 < v < 1, "a risk in (0, 1)", "a precision level must be a risk in (0, 1)")


def checked(check: Callable[[str], object], what: str) -> Callable[[str], object]:
    """A validator from a library's own check: ``check(text)`` returns the value or
    raises ValueError, whose message argparse then prints (prefixed ``argument
    --flag:``). The rule stays written once, in the library: e.g.
    ``type=checked(lgp.planner.check_approach_height, "approach height")``."""

    def parse(text: str):
        try:
            return check(text)
        except ValueError as e:
            raise argparse.ArgumentTypeError(str(e)) from None

    parse.__name__ = what.replace(" ", "_")
    return parse


def positive_number(text: str) -> float:
    """A finite number > 0 (a budget of seconds)."""
    return _finite_number(text, lambda v: v > 0, "a number > 0", "must be a finite number > 0")


def trial_id(text: str) -> str:
    """A trial id, case-insensitive, returned in its canonical spelling: the paper's
    1E ... 12H, or another <pair><E|H> (a trial file the loader then looks for)."""
    tid = canonical_trial_id(text)
    if tid not in TRIAL_IDS and not re.fullmatch(r"\d+[EH]", tid) and not re.fullmatch(r"[A-Z][A-Z0-9_-]{0,63}", tid):
        raise argparse.ArgumentTypeError(f"unknown trial id {text!r}; expected <pair><E|H> such as 1E, 1H, ..., 12H "
                                         "or the name of a trial of no pair such as G0001 (case-insensitive)")
    return tid


def trial_id_or_all(text: str) -> str:
    """A trial id (see `trial_id`) or the word ``all``."""
    return "all" if str(text).strip().lower() == "all" else trial_id(text)


def one_of(names: Sequence[str], what: str) -> Callable[[str], str]:
    """A validator for a word from `names`, case-insensitive (``3D`` is ``3d``), returned
    in its listed spelling; anything else is refused as ``unknown <what> ...``
    (argparse prefixes ``argument --flag:``). E.g. ``type=one_of(FALL_RULES, "fall rule")``."""
    names = tuple(names)

    def check(text: str) -> str:
        for name in names:
            if str(text).strip().lower() == name.lower():
                return name
        raise argparse.ArgumentTypeError(f"unknown {what} {text!r}; known {what}s: {', '.join(names)} (case-insensitive)")

    check.__name__ = what.replace(" ", "_")
    return check


def _nearest_existing(path: Path) -> Path:
    path = path.absolute()
    while not path.exists() and path != path.parent:
        path = path.parent
    return path


def _writable(directory: Path) -> bool:
    """Whether a file can be made in `directory`: permissions, and one nameless
    temporary file (O_TMPFILE: nothing appears in the folder), because root passes
    every permission check yet cannot write in /proc or on a read-only mount."""
    if not os.access(directory, os.W_OK | os.X_OK):
        return False
    import tempfile

    try:
        with tempfile.TemporaryFile(dir=directory):
            pass
    except OSError:
        return False
    return True


def output_dir(text: str) -> str:
    """A directory that exists and is writable, or can be created (its nearest
    existing ancestor is a writable directory). The command creates it when it
    writes (every CLI's rule: a missing output folder is created)."""
    path = Path(text)
    if path.exists() and not path.is_dir():
        raise argparse.ArgumentTypeError(f"{text!r} exists and is not a directory")
    base = _nearest_existing(path)
    if not base.is_dir():
        raise argparse.ArgumentTypeError(f"cannot create directory {text!r}: {base} is not a directory")
    if not _writable(base):
        raise argparse.ArgumentTypeError(f"cannot write to {text!r}: {base} is not writable")
    return text


def output_file(text: str) -> str:
    """A file to write: not a directory; its folder exists and is writable, or can
    be created (its nearest existing ancestor is a writable directory). Checked
    before any work; the command creates the folder when it writes (`make_parent`)."""
    path = Path(text)
    if path.is_dir():
        raise argparse.ArgumentTypeError(f"{text!r} is a directory, expected a file name")
    parent = path.parent if str(path.parent) else Path(".")
    base = _nearest_existing(parent)
    if not base.is_dir():
        raise argparse.ArgumentTypeError(f"cannot write {text!r}: {str(base)!r} is not a directory")
    if not _writable(base) or (path.exists() and not os.access(path, os.W_OK)):
        raise argparse.ArgumentTypeError(f"cannot write {text!r}: {str(base)!r} is not writable")
    return text


def make_parent(path: str | Path) -> Path:
    """Create the folder of an output file (checked by `output_file`) and return the path."""
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    return path


def path_kind(path: str | Path) -> str | None:
    """What `path` is when it is not a plain file or folder, in words: "a FIFO
    (named pipe)", "a character device (a symbolic link to /dev/zero)", "a loop of
    symbolic links", "a dangling symbolic link (to X)"; None for a regular file, a
    directory or a path that does not exist. Never opens the path (a FIFO would block)."""
    import errno
    import stat

    path = Path(path)
    try:
        mode = os.stat(path).st_mode
    except OSError as e:
        if e.errno == errno.ELOOP:
            return "a loop of symbolic links (a link that leads back to itself)"
        if os.path.islink(path):
            return f"a dangling symbolic link (to {os.readlink(path)}, which does not exist)"
        return None
    if stat.S_ISREG(mode) or stat.S_ISDIR(mode):
        return None
    link = f" (a symbolic link to {os.readlink(path)})" if os.path.islink(path) else ""
    for test, name in ((stat.S_ISFIFO, "a FIFO (named pipe)"), (stat.S_ISCHR, "a character device"),
                       (stat.S_ISBLK, "a block device"), (stat.S_ISSOCK, "a socket")):
        if test(mode):
            return name + link
    return "not a regular file" + link


def input_file(text: str) -> str:
    """A regular file that exists and can be read (a FIFO, a device, a loop of
    symbolic links is named as what it is)."""
    path = Path(text)
    kind = path_kind(path)
    if kind is not None:
        raise argparse.ArgumentTypeError(f"{text!r} is {kind}, not a regular file")
    if not path.exists():
        raise argparse.ArgumentTypeError(f"{text!r} does not exist")
    if not path.is_file():
        raise argparse.ArgumentTypeError(f"{text!r} is not a file")
    if not os.access(path, os.R_OK):
        raise argparse.ArgumentTypeError(f"{text!r} is not readable")
    return text


def input_dir(text: str) -> str:
    """A directory that exists and can be read (a loop of symbolic links is named as one)."""
    path = Path(text)
    kind = path_kind(path)
    if kind is not None:
        raise argparse.ArgumentTypeError(f"{text!r} is {kind}, not a directory")
    if not path.is_dir():
        raise argparse.ArgumentTypeError(f"{text!r} is not a directory" if path.exists() else f"{text!r} does not exist")
    if not os.access(path, os.R_OK | os.X_OK):
        raise argparse.ArgumentTypeError(f"{text!r} is not readable")
    return text


# ----------------------------------------------------------------------------- parser and runner


class _Parser(argparse.ArgumentParser):
    """argparse, but a usage error is one line on stderr (exit 2); --help shows the usage."""

    def error(self, message: str):
        self.exit(EXIT_USAGE, f"{self.prog}: error: {message} (--help shows the usage)\n")


def parser(prog: str, description: str | None = None, **kwargs) -> argparse.ArgumentParser:
    """An ArgumentParser with the shared ``--debug`` flag whose usage errors are one line."""
    p = _Parser(prog=prog, description=description, **kwargs)
    p.add_argument("--debug", action="store_true",
                   help=f"show the traceback of an error (or set {DEBUG_ENV}=1)")
    return p


def debug_requested(argv: Sequence[str] | None = None) -> bool:
    argv = sys.argv[1:] if argv is None else argv
    return "--debug" in argv or os.environ.get(DEBUG_ENV, "").strip().lower() not in ("", "0", "false", "no")


def is_known_error(exc: BaseException) -> bool:
    """An error the project raises on purpose: an instance of an exception class of
    its own (StimulusError, HumanDataError, ModelInputError, PlanningError,
    UnstableSceneError, lgp.errors.InputError, ...) or an OSError (a file).
    Anything else is a bug: a ValueError from inside numpy, a TypeError, and a
    plain ValueError even when the project's own code raised it (a tuple unpacked
    wrongly): checks of input raise a class of the project."""
    if isinstance(exc, OSError):
        return True
    if not isinstance(exc, Exception):
        return False
    module = type(exc).__module__
    if module == "__main__":  # a class of a project module run as ``python -m package.module``
        spec = getattr(sys.modules.get("__main__"), "__spec__", None)
        module = getattr(spec, "name", None) or module
    return module.split(".")[0] in PROJECT_PACKAGES


def one_line(exc: BaseException) -> str:
    """The message of `exc` on one line: its first line, and how many more there were."""
    text = str(exc).strip() or type(exc).__name__
    if isinstance(exc, OSError) and exc.filename is not None and exc.strerror:
        text = f"{exc.filename}: {exc.strerror}"
    lines = [line for line in text.splitlines() if line.strip()]
    if len(lines) > 1:
        return f"{lines[0]} (and {len(lines) - 1} more line(s); --debug shows all)"
    return lines[0]


def run_cli(main: Callable[[Sequence[str] | None], int | None], argv: Sequence[str] | None = None, *,
            prog: str, interrupted: str = "interrupted") -> int:
    """Run ``main(argv)`` and turn known errors and Ctrl-C into one line on stderr.

    Returns the exit code (main's, 1 for a known error, 2 for an output folder it may
    not write into (lgp.owned.ForeignFiles), 130 for Ctrl-C); argparse's
    own exit (2 for usage) passes through as SystemExit. Use as
    ``raise SystemExit(run_cli(main, prog=PROG))``.
    """
    debug = debug_requested(argv)
    try:
        return int(main(argv) or 0)
    except KeyboardInterrupt:
        return _interrupted(prog, interrupted, debug)
    except Exception as exc:
        if _caused_by_interrupt(exc):  # e.g. pydrake turns Ctrl-C during its import into ImportError
            return _interrupted(prog, interrupted, debug)
        if not is_known_error(exc):
            raise
        if debug:
            traceback.print_exc()
        print(f"{prog}: error: {one_line(exc)}", file=sys.stderr, flush=True)
        from lgp.owned import ForeignFiles

        return EXIT_USAGE if isinstance(exc, ForeignFiles) else EXIT_DATA  # a folder it may not write into: as a bad --out


class deferred_interrupt:
    """Context manager: a Ctrl-C inside the block takes effect when the block ends.

    For imports of compiled libraries: pydrake turns a KeyboardInterrupt during its
    import into ImportError, logs a critical message, and leaves CPython marked to
    kill itself with SIGINT at exit. Main thread only (elsewhere it does nothing).
    """

    def __enter__(self):
        import signal

        self.hit, self.old = False, None
        try:
            self.old = signal.signal(signal.SIGINT, self._note)
        except ValueError:  # not the main thread
            pass
        return self

    def _note(self, signum, frame):
        self.hit = True

    def __exit__(self, *exc):
        import signal

        if self.old is not None:
            signal.signal(signal.SIGINT, self.old)
        if self.hit and exc[0] is None:
            raise KeyboardInterrupt
        return False


def _caused_by_interrupt(exc: BaseException) -> bool:
    seen = set()
    while exc is not None and id(exc) not in seen:
        if isinstance(exc, KeyboardInterrupt):
            return True
        seen.add(id(exc))
        exc = exc.__cause__ or exc.__context__
    return False


def _interrupted(prog: str, message: str, debug: bool) -> int:
    import signal

    signal.signal(signal.SIGINT, signal.SIG_IGN)  # a second Ctrl-C must not interrupt the goodbye
    if debug:
        traceback.print_exc()
    print(f"{prog}: {message}", file=sys.stderr, flush=True)
    return EXIT_INTERRUPTED
