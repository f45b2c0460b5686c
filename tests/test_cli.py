"""Every command line refuses bad input in one line, before any work, and writes nothing.

Each case runs a CLI's ``main`` under `lgp.cli.run_cli` (as ``python -m ...`` does)
and checks the exit code (2: usage, refused by argparse; 1: bad data), that stderr
is exactly one line ``prog: error: ...`` naming the problem, and that no output
file was written. A few cases run the real ``python -m`` command in a subprocess.
"""
import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pandas as pd
import pytest

from lgp import cli
from lgp.paper import TRIAL_IDS

ROOT = Path(__file__).resolve().parent.parent


def _mains():
    from analysis import demo
    from lgp import reproduce, show
    from models.effort import __main__ as effort
    from models.risk import __main__ as risk_cli
    from stimuli import sheet

    return {"lgp.reproduce": reproduce, "lgp.show": show, "models.risk": risk_cli, "models.effort": effort,
            "analysis.demo": demo, "stimuli.sheet": sheet}


def run(module: str, argv, capsys):
    mod = _mains()[module]
    try:
        code = cli.run_cli(mod.main, list(argv), prog=mod.PROG)
    except SystemExit as e:
        code = e.code
    captured = capsys.readouterr()
    return code, captured.err


def human_csv(path: Path, response="3.5", columns=("dataset", "participant", "trial", "response")) -> str:
    rows = [("difficulty", "p1", t, response if k == 5 else str(k % 7)) for k, t in enumerate(TRIAL_IDS)]
    pd.DataFrame(rows, columns=list(columns)).to_csv(path, index=False)
    return str(path)


def files_in(folder: Path) -> list[Path]:
    return [p for p in folder.rglob("*") if p.is_file()] if folder.exists() else []


#: Where the commands' expensive work starts (module, attribute, what it is): a plan solved (KOMO,
#: by the paper planner and by the search planner), a risk simulated (the grid of runs, the check
#: that a structure stands), a worker pool started, a contact sheet drawn.
WORK = [("lgp.planner", "plan_symbolic", "a plan solved"), ("lgp.search.tree", "plan_symbolic", "a plan solved (search)"),
        ("models.risk.core", "simulate_grid", "risk simulated"), ("models.risk.core", "check_stable", "a stability check simulated"),
        ("lgp.executor.processes", "ProcessExecutor.__init__", "a worker pool started"),
        ("stimuli.sheet", "contact_sheet", "a contact sheet drawn")]


@pytest.fixture
def work_started(monkeypatch) -> list[str]:
    """What expensive work the command began (WORK's names, in order): each entry point is
    wrapped by a spy that notes the call and then does the work."""
    import importlib

    seen: list[str] = []
    for module, attribute, what in WORK:
        owner = importlib.import_module(module)
        *path, name = attribute.split(".")
        for a in path:
            owner = getattr(owner, a)
        real = getattr(owner, name)

        def spy(*args, _real=real, _what=what, **kwargs):
            seen.append(_what)
            return _real(*args, **kwargs)

        monkeypatch.setattr(owner, name, spy)
    return seen


# (module, arguments, exit code, words the one line must contain); {out} is an output folder
# and {tmp} the test's temporary folder.
BAD = [
    ("lgp.show", ["99X"], 2, "unknown trial id '99X'"),
    ("lgp.show", ["13E"], 1, "no trial '13E'"),
    ("lgp.show", ["7H", "--sample", "-1"], 2, "--sample"),
    ("lgp.show", ["7H", "--seed", "x"], 2, "--seed"),
    ("lgp.show", ["7H", "--png", "/proc/x.png"], 2, "is not writable"),
    ("lgp.show", ["7H", "--html", "{tmp}/a_file/x.html"], 2, "is not a directory"),
    ("lgp.show", ["REV", "--stimuli", "{tmp}/missing"], 2, "argument --stimuli: "),
    ("lgp.show", ["REV", "--stimuli", "{tmp}/a_file"], 2, "is not a directory"),
    ("lgp.show", ["REV", "--stimuli", "{tmp}/empty"], 1, "no trial 'REV'"),
    ("lgp.reproduce", ["--out", "{out}", "--trials", "99X"], 2, "unknown trial id"),
    ("lgp.reproduce", ["--out", "{out}", "--trials"], 2, "--trials"),
    ("lgp.reproduce", ["--out", "{out}", "--trials", "13h"], 1, "no trial '13H'"),
    ("lgp.reproduce", ["--out", "{out}", "--samples", "0"], 2, "--samples"),
    ("lgp.reproduce", ["--out", "{out}", "--samples", "-1"], 2, "--samples"),
    ("lgp.reproduce", ["--out", "{out}", "--samples", "1.5"], 2, "--samples"),
    ("lgp.reproduce", ["--out", "{out}", "--n-sims", "0"], 2, "--n-sims"),
    ("lgp.reproduce", ["--out", "{out}", "--sigmas", "-0.05"], 2, "(0, 1]"),
    ("lgp.reproduce", ["--out", "{out}", "--sigmas", "0"], 2, "(0, 1]"),
    ("lgp.reproduce", ["--out", "{out}", "--sigmas", "1.5"], 2, "(0, 1]"),
    ("lgp.reproduce", ["--out", "{out}", "--sigmas", "nan"], 2, "(0, 1]"),
    ("lgp.reproduce", ["--out", "{out}", "--jobs", "0"], 2, "--jobs"),
    ("lgp.reproduce", ["--out", "{out}", "--n-boot", "0"], 2, "--n-boot"),
    ("lgp.reproduce", ["--out", "{out}", "--human-data", "{tmp}/missing.csv"], 2, "does not exist"),
    ("lgp.reproduce", ["--out", "{out}", "--human-data", "{tmp}/wrong_columns.csv"], 1, "missing column(s) response"),
    ("lgp.reproduce", ["--out", "{out}", "--human-data", "{tmp}/non_numeric.csv"], 1, "non-numeric response 'lots'"),
    ("lgp.reproduce", ["--out", "{out}", "--human-data", "{tmp}/good.csv", "--trials", "1E"], 1, "unknown trial id '1H'; expected one of the run's trials 1E"),
    ("lgp.reproduce", ["--out", "{out}", "--human-data", "{tmp}/good.csv", "--trials", "1E", "1H", "2E", "2H", "3E"], 1,
     "unknown trial id '3H'; expected one of the run's trials 1E, 1H, 2E, 2H, 3E"),
    ("lgp.reproduce", ["--out", "{tmp}/a_file"], 2, "not a directory"),
    ("lgp.reproduce", ["--out", "{out}", "--sigma-grid", "huge"], 2, "--sigma-grid: invalid choice: 'huge' (choose from 'paper', 'wide')"),
    ("lgp.reproduce", ["--out", "{out}", "--noise-rule", "drop"], 2, "--noise-rule: invalid choice: 'drop' (choose from 'lift', 'settle')"),
    ("lgp.reproduce", ["--out", "{out}", "--sigma-grid", "wide", "--sigmas", "0.1"], 2, "--sigmas: not allowed with argument --sigma-grid"),
    ("lgp.reproduce", ["--out", "{out}", "--build-sigmas", "1.2"], 2, "--build-sigmas: a sigma must be in (0, 1]"),
    ("models.risk", ["--table", "{tmp}/t.csv", "--n-sims", "0"], 2, "--n-sims"),
    ("models.risk", ["--table", "{tmp}/t.csv", "--n", "0"], 2, "--n-sims"),
    ("models.risk", ["--table", "{tmp}/t.csv", "--sigmas", "-0.065"], 2, "(0, 1]"),
    ("models.risk", ["--table", "{tmp}/t.csv", "--trials", "99X"], 2, "unknown trial id"),
    ("models.risk", ["--table", "{tmp}/t.csv", "--jobs", "0"], 2, "--jobs"),
    ("models.risk", ["--table", "{tmp}/t.csv", "--sigma-grid", "huge"], 2, "--sigma-grid: invalid choice: 'huge' (choose from 'paper', 'wide')"),
    ("models.risk", ["--table", "{tmp}/t.csv", "--noise-rule", "drop"], 2, "--noise-rule: invalid choice: 'drop' (choose from 'lift', 'settle')"),
    ("models.risk", ["--table", "{tmp}/t.csv", "--sigmas", "1.01"], 2, "--sigmas: a sigma must be in (0, 1]"),
    ("models.risk", ["--table", "{tmp}/t.csv", "--precision", "{tmp}/p.csv", "--precision-levels", "1"], 2,
     "--precision-levels: a precision level must be a risk in (0, 1)"),
    ("models.risk", ["--table", "{tmp}/t.csv", "--precision-levels", "0"], 2, "--precision-levels"),
    ("models.risk", ["--build-risk", "7H", "--mode", "parallel"], 2, "--mode: invalid choice: 'parallel' (choose from 'stages', 'sequential')"),
    ("models.risk", ["--table", "{tmp}/a_file/dir/t.csv"], 2, "is not a directory"),
    ("models.risk", ["--table", "/proc/t.csv"], 2, "is not writable"),
    ("models.effort", ["99X", "--out", "{tmp}/e.csv"], 2, "unknown trial id"),
    ("models.effort", ["7H", "--samples", "0", "--out", "{tmp}/e.csv"], 2, "--samples"),
    ("models.effort", ["7H", "--out", "{tmp}/a_file/e.csv"], 2, "is not a directory"),
    ("analysis.demo", ["--results", "/nonexistent", "--out", "{out}"], 2, "does not exist"),
    ("analysis.demo", ["--results", "{tmp}/empty", "--out", "{out}"], 1, "effort_samples.csv does not exist"),
    ("analysis.demo", ["--results", "{tmp}/empty", "--out", "{out}", "--n-boot", "0"], 2, "--n-boot"),
    ("analysis.demo", ["--results", "{tmp}/garbage", "--out", "{out}"], 1, "not a readable CSV"),
    ("stimuli.sheet", ["--out", "/proc/nodir/s.png"], 2, "is not writable"),
    ("stimuli.sheet", ["--out", "{tmp}/s.png", "--trials", "99X"], 2, "unknown trial id"),
    ("stimuli.sheet", ["--out", "{tmp}/s.png", "--trials"], 2, "--trials"),
]


@pytest.mark.parametrize("module, argv, code, words", BAD, ids=[f"{m} {' '.join(a)}" for m, a, _, _ in BAD])
def test_bad_input_fails_in_one_line_before_any_work_and_writes_nothing(module, argv, code, words, tmp_path, capsys,
                                                                         work_started):
    out = tmp_path / "out"
    (tmp_path / "empty").mkdir()
    (tmp_path / "garbage").mkdir()
    (tmp_path / "garbage" / "effort_samples.csv").write_bytes(b"\xff\xfe\x00garbage\n\x00\x01")
    (tmp_path / "a_file").write_text("not a folder")
    human_csv(tmp_path / "good.csv")
    human_csv(tmp_path / "wrong_columns.csv", columns=("dataset", "participant", "trial", "answer"))
    human_csv(tmp_path / "non_numeric.csv", response="lots")
    before = set(files_in(tmp_path))
    argv = [a.format(out=out, tmp=tmp_path) for a in argv]
    got, err = run(module, argv, capsys)
    assert not work_started, f"{module} {' '.join(argv)}: refused only after work began: {', '.join(work_started)}"
    assert got == code, err
    lines = err.strip().splitlines()
    assert len(lines) == 1, err
    assert lines[0].startswith(f"python -m {module}: error: ") and words in lines[0], lines[0]
    assert "Traceback" not in err
    assert set(files_in(tmp_path)) == before  # nothing written anywhere
    assert not files_in(out)


# (module, arguments) of a cheap run of each CLI that writes files; {new} is a folder that does not exist yet
WRITERS = [
    ("stimuli.sheet", ["--out", "{new}/sheet/s.png", "--trials", "1E"]),
    ("models.risk", ["--table", "{new}/risk/t.csv", "--runs", "{new}/runs/r.csv", "--trials", "1E", "--n-sims", "2",
                     "--sigmas", "0.05", "--jobs", "1"]),
    ("models.effort", ["1E", "--samples", "1", "--jobs", "1", "--out", "{new}/effort/e.csv"]),
]


@pytest.mark.parametrize("module, argv", WRITERS, ids=[m for m, _ in WRITERS])
def test_a_missing_output_folder_is_created(module, argv, tmp_path, capsys, work_started):
    """The output-folder rule (README): a folder that does not exist is created,
    by every CLI, as `lgp.reproduce --out a/missing/sub` does. (The work these runs
    do is seen by the spies of `work_started`: the refusals' "no work" is not vacuous.)"""
    new = tmp_path / "a" / "missing"
    argv = [a.format(new=new) for a in argv]
    got, err = run(module, argv, capsys)
    assert got == 0, err
    assert work_started, f"{module}: the spies of WORK saw none of this run's work"
    for k, a in enumerate(argv[:-1]):
        if a in ("--out", "--table", "--runs"):
            assert Path(argv[k + 1]).is_file() and Path(argv[k + 1]).stat().st_size > 0, argv[k + 1]


def test_trial_ids_are_case_insensitive_on_the_command_line_and_in_the_loaders(tmp_path):
    import argparse

    import stimuli
    from analysis import load_human_data

    assert cli.trial_id("7h") == cli.trial_id(" 7H ") == "7H"
    assert stimuli.load_trial("7h") is stimuli.load_trial("7H")
    path = tmp_path / "h.csv"
    pd.DataFrame([("time", "p", t.lower(), k) for k, t in enumerate(TRIAL_IDS)],
                 columns=["dataset", "participant", "trial", "response"]).to_csv(path, index=False)
    assert list(load_human_data(path)["trial"]) == list(TRIAL_IDS)
    with pytest.raises(argparse.ArgumentTypeError):
        cli.trial_id("7X")
    with pytest.raises(stimuli.StimulusError, match="no trial '13E'"):
        stimuli.load_trial("13e")  # a well-formed id without a file: the loader's one-line error


def test_effort_help_says_which_trials_it_runs_by_default(capsys, tmp_path, monkeypatch):
    """With no trial named, python -m models.effort runs every trial file the
    loader finds (stimuli.load_all), and its help says so, not "all 24"."""
    from models.effort import __main__ as effort_cli

    with pytest.raises(SystemExit):
        effort_cli.main(["--help"])
    help_text = " ".join(capsys.readouterr().out.split())
    assert "all 24" not in help_text and "every trial file" in help_text
    import stimuli

    seen = []
    monkeypatch.setattr(stimuli, "load_all", lambda: seen.append("load_all") or [])
    monkeypatch.setattr(effort_cli.pd, "concat", lambda tables, **kw: pd.DataFrame())
    assert effort_cli.main([]) == 0 and seen == ["load_all"]


def test_counts_and_sigmas_are_checked_exactly():
    import argparse

    assert cli.positive_int("3") == 3
    assert cli.sigma("1") == 1.0 and cli.sigma("0.065") == 0.065
    for bad in ("0", "-2", "1.5", "1e3", "", "three"):
        with pytest.raises(argparse.ArgumentTypeError):
            cli.positive_int(bad)
    for bad in ("0", "-0.05", "1.0001", "inf", "nan", "x"):
        with pytest.raises(argparse.ArgumentTypeError):
            cli.sigma(bad)


def test_a_bug_keeps_its_traceback_and_a_known_error_is_one_line(capsys):
    def numpy_bug(argv):
        np.zeros(2).reshape(3)  # a ValueError raised inside numpy: a bug, not bad input

    with pytest.raises(ValueError):
        cli.run_cli(numpy_bug, [], prog="p")

    def project_check(argv):
        from models.effort import physical_effort

        physical_effort("7H", samples=0)  # a ValueError raised by the project's own check

    assert cli.run_cli(project_check, [], prog="p") == 1
    assert capsys.readouterr().err == "p: error: physical_effort needs samples >= 1, got 0\n"

    def many_problems(argv):
        from analysis import HumanDataError

        raise HumanDataError("h.csv: line 2: non-numeric response 'x'\nh.csv: line 3: empty participant id")

    assert cli.run_cli(many_problems, [], prog="p") == 1
    assert capsys.readouterr().err == ("p: error: h.csv: line 2: non-numeric response 'x' "
                                       "(and 1 more line(s); --debug shows all)\n")


def test_a_plain_value_error_from_the_projects_own_code_is_a_bug_with_its_traceback(capsys):
    """A ValueError raised in project code by a mistake (a tuple unpacked wrongly:
    a replay job with two fields instead of four) is a bug, not bad input: it
    keeps its traceback. A check of input raises a class of the project."""
    from lgp.app.replays import _replay_job
    from lgp.errors import InputError
    from lgp.executor import executor_for

    def bug(argv):
        _replay_job(("7H", 0))  # not enough values to unpack, inside lgp/app/replays

    with pytest.raises(ValueError, match="not enough values to unpack"):
        cli.run_cli(bug, [], prog="p")
    assert capsys.readouterr().err == ""

    def check(argv):
        executor_for(0)  # the project's own check of a count: InputError

    with pytest.raises(InputError):
        executor_for(0)
    assert cli.run_cli(check, [], prog="p") == 1
    assert capsys.readouterr().err == "p: error: jobs must be >= 1, got 0\n"


def test_no_project_module_raises_a_plain_value_error():
    """A check of input raises a class of the project (lgp.errors.InputError or a
    domain one), so that run_cli prints it in one line; a plain ``raise
    ValueError(...)`` would now reach the user as a traceback. Read with ast."""
    import ast

    from lgp.app.cache import PACKAGES

    found = []
    for package in PACKAGES:
        for path in sorted((ROOT / package).rglob("*.py")):
            for node in ast.walk(ast.parse(path.read_text(), filename=str(path))):
                if isinstance(node, ast.Raise) and node.exc is not None:
                    exc = node.exc.func if isinstance(node.exc, ast.Call) else node.exc
                    if isinstance(exc, ast.Name) and exc.id == "ValueError":
                        found.append(f"{path.relative_to(ROOT)}:{node.lineno}")
    assert not found, "raise lgp.errors.InputError (or a domain error class) instead of ValueError at: " + ", ".join(found)


def test_debug_flag_and_environment_variable_show_the_traceback(capsys, monkeypatch):
    from stimuli import StimulusError

    def fails(argv):
        raise StimulusError("7H-B block b3 overlaps b2 by 4 mm")

    assert cli.run_cli(fails, [], prog="p") == 1
    assert capsys.readouterr().err.count("\n") == 1
    assert cli.run_cli(fails, ["--debug"], prog="p") == 1
    assert "Traceback" in capsys.readouterr().err
    monkeypatch.setenv("LGP_DEBUG", "1")
    assert cli.run_cli(fails, [], prog="p") == 1
    err = capsys.readouterr().err
    assert "Traceback" in err and err.strip().splitlines()[-1] == "p: error: 7H-B block b3 overlaps b2 by 4 mm"


def test_keyboard_interrupt_is_one_line_and_exit_130(capsys):
    def interrupted(argv):
        raise KeyboardInterrupt

    assert cli.run_cli(interrupted, [], prog="p", interrupted="interrupted; finished trials are cached, rerun to resume") == 130
    assert capsys.readouterr().err == "p: interrupted; finished trials are cached, rerun to resume\n"


def _env():
    return {**os.environ, "PYTHONPATH": str(ROOT) + os.pathsep + os.environ.get("PYTHONPATH", "")}


@pytest.mark.parametrize("argv, code", [(["-m", "lgp.show", "99X"], 2), (["-m", "stimuli.sheet", "--out", "/proc/nodir/s.png"], 2),
                                        pytest.param(["-m", "lgp.reproduce", "--sigmas", "-0.05", "--out", "{tmp}/r"], 2,
                                                     marks=pytest.mark.slow)])  # imports the pipeline: ~2 s
def test_python_dash_m_commands_exit_with_one_line(argv, code, tmp_path):
    argv = [a.format(tmp=tmp_path) for a in argv]
    proc = subprocess.run([sys.executable, *argv], capture_output=True, text=True, env=_env(), cwd=tmp_path, timeout=120)
    assert proc.returncode == code
    assert len(proc.stderr.strip().splitlines()) == 1 and "error:" in proc.stderr
    assert not (tmp_path / "r").exists()


@pytest.mark.slow
@pytest.mark.parametrize("after", [0.3, 2.5])
def test_ctrl_c_during_a_run_prints_one_line_and_exits_130(tmp_path, after):
    """SIGINT while Drake loads (0.3 s) or effort is being planned: one line, exit 130, no traceback."""
    proc = subprocess.Popen([sys.executable, "-m", "lgp.reproduce", "--trials", "7H", "3H", "--samples", "30", "--jobs", "1",
                             "--no-cache", "--out", str(tmp_path / "r")], stderr=subprocess.PIPE, text=True, env=_env(),
                            cwd=tmp_path, preexec_fn=lambda: signal.signal(signal.SIGINT, signal.SIG_DFL))  # as in a terminal
    first = proc.stderr.readline()  # "lgp.reproduce: 2 trials ..." once validation is over
    assert first.startswith("lgp.reproduce:"), first
    time.sleep(after)
    proc.send_signal(signal.SIGINT)
    rest = proc.stderr.read()
    assert proc.wait(timeout=60) == 130, rest
    assert "Traceback" not in rest
    last = rest.strip().splitlines()[-1]
    assert last == "python -m lgp.reproduce: interrupted; nothing cached (--no-cache)"


@pytest.mark.slow  # a subprocess plans, replays and draws
def test_show_creates_missing_folders_and_prints_no_meshcat_server_line(tmp_path):
    """The replay is a static HTML file: Drake's "Meshcat listening for connections"
    log line would send a user to a server that is not needed (and gone at exit)."""
    html, png = tmp_path / "new" / "a" / "9E.html", tmp_path / "new" / "b" / "9E.png"
    proc = subprocess.run([sys.executable, "-m", "lgp.show", "9E", "--html", str(html), "--png", str(png)],
                          capture_output=True, text=True, env=_env(), cwd=tmp_path, timeout=300)
    assert proc.returncode == 0, proc.stderr
    assert html.stat().st_size > 0 and png.stat().st_size > 0
    assert "listening" not in proc.stdout + proc.stderr and "localhost" not in proc.stdout + proc.stderr, proc.stderr
