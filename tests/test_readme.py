"""The README's examples are run as doctests, so the README cannot drift from the code."""
import doctest
import re
from pathlib import Path

README = Path(__file__).resolve().parent.parent / "README.md"


def test_readme_examples_run_and_print_what_the_readme_says():
    blocks = re.findall(r"```pycon\n(.*?)```", README.read_text(), flags=re.S)
    assert blocks, "the README has no ```pycon example"
    parser = doctest.DocTestParser()
    runner = doctest.DocTestRunner(optionflags=doctest.ELLIPSIS | doctest.NORMALIZE_WHITESPACE)
    for k, text in enumerate(blocks):
        test = parser.get_doctest(text, {}, f"README.md example {k + 1}", str(README), 0)
        runner.run(test)
    result = runner.summarize(verbose=False)
    assert result.attempted > 5 and result.failed == 0, f"{result.failed} README example line(s) failed (see above)"


def test_plan_repr_is_one_short_line():
    import numpy as np

    import stimuli
    from lgp import plan

    trial = stimuli.load_trial("9E")
    p = plan(trial.sample_initial(np.random.default_rng([0, 0])), trial.target)
    text = repr(p)
    assert "\n" not in text and len(text) < 300, text
    assert f"{len(p.actions)} actions" in text and trial.target.label.split("-")[0] in text
    # no optimiser cost that a reader takes for the effort (that is models.effort.kinetic_energy(plan))
    assert "cost" not in text and "effort" not in text, text


# ----------------------------------------------------------------------------- the README's commands
#
# Every `python -m ...` command the README shows (in a ```bash block or inline) is
# checked here: the cheap ones run as written (in a scratch folder, with the
# README's placeholders filled in), the long ones (the paper's pipeline) have their
# arguments parsed and checked by the command's own parser (their run is tested
# end to end in test_reproduce.py / test_page_browser.py), and the two pytest
# commands are the ones .ci/run runs.

import os
import shlex
import subprocess
import sys

import pytest

ROOT = README.parent
#: The README's placeholders (DIR, N, S ...) and the values a test run gives them.
PLACEHOLDERS = {"DIR": "generated", "N": "3", "S": "0", "FILE.csv": "human.csv", "H": "0.02"}
#: Commands whose run is the paper's pipeline (minutes): parsed, not run.
PARSED_ONLY = ("lgp.reproduce",)
#: Commands that read the results of an `lgp.reproduce` run: their --help runs here,
#: their work in the test named (which makes the results first).
NEEDS_A_RUN = {"analysis.demo": "tests/test_analysis_simulated.py::test_demo_labels_every_output_as_simulated",
               "analysis.recovery": "tests/test_analysis_compare.py::test_recovery_confusion_matrix_and_its_seeds"}


def readme_commands(text: str | None = None) -> list[str]:
    """Every `python -m MODULE ...` command line of the README, as written."""
    text = README.read_text() if text is None else text
    found = []
    for block in re.findall(r"```bash\n(.*?)```", text, flags=re.S):
        for line in block.splitlines():
            line = line.split("#", 1)[0].strip()
            if line.startswith("python -m "):
                found.append(line)
    for span in re.findall(r"`([^`]+)`", re.sub(r"```.*?```", "", text, flags=re.S)):
        span = " ".join(span.split())
        if re.fullmatch(r"python -m [\w.]+( [^:]*)?", span):
            found.append(span)
    return list(dict.fromkeys(found))


def _argv(command: str) -> tuple[str, list[str]]:
    words = shlex.split(command)
    assert words[:2] == ["python", "-m"], command
    return words[2], [PLACEHOLDERS.get(w, w) for w in words[3:]]


def test_the_readme_names_its_commands():
    modules = {_argv(c)[0] for c in readme_commands()}
    assert {"pytest", "lgp.reproduce", "lgp.show", "stimuli.sheet", "stimuli.generate", "models.risk"} <= modules, modules


def test_the_readmes_test_commands_are_what_ci_runs():
    ci = (ROOT / ".ci" / "run").read_text()
    for command in readme_commands():
        module, argv = _argv(command)
        if module == "pytest" and argv == ["-q"]:
            assert command in ci, f"README's {command!r} is not what .ci/run runs"
    install = re.search(r"```bash\n(pip install [^#\n]*?)\s*#", README.read_text()).group(1).strip()
    assert install in ci, f"README's install line {install!r} is not .ci/run's"
    assert "slow:" in (ROOT / "pyproject.toml").read_text(), "the README's -m 'not slow' needs the marker registered"


@pytest.mark.parametrize("command", [c for c in readme_commands() if _argv(c)[0] in PARSED_ONLY])
def test_the_readmes_pipeline_commands_parse(command, tmp_path, monkeypatch):
    import importlib

    module, argv = _argv(command)
    monkeypatch.chdir(tmp_path)
    args = importlib.import_module(module).parse_args(argv)
    assert args.out == "results"


def _runnable(commands: list[str]) -> list[str]:
    """The commands to run: not the pipeline's or pytest's, and not a bare module name
    (the layout table's `python -m lgp.show`) when the README shows that module's use."""
    used = {_argv(c)[0] for c in commands if _argv(c)[1]}
    return [c for c in commands if _argv(c)[0] not in PARSED_ONLY + ("pytest", *NEEDS_A_RUN)
            and (_argv(c)[1] or _argv(c)[0] not in used)]


@pytest.mark.parametrize("command", [c for c in readme_commands() if _argv(c)[0] in NEEDS_A_RUN])
def test_the_readmes_commands_on_a_runs_results_have_their_cli(command):
    module, _ = _argv(command)
    assert (ROOT / NEEDS_A_RUN[module].split("::")[0]).exists()
    run = subprocess.run([sys.executable, "-m", module, "--help"], cwd=ROOT, env={**os.environ, "PYTHONPATH": str(ROOT)},
                         capture_output=True, text=True, timeout=120)
    assert run.returncode == 0 and "usage:" in run.stdout, run.stderr


@pytest.mark.slow
@pytest.mark.parametrize("command", _runnable(readme_commands()))
def test_the_readmes_commands_run_as_written(command, tmp_path, request):
    module, argv = _argv(command)
    if module == "stimuli.experiment":  # its pictures are the suite's studies' (conftest.STUDY_SIZE): rendered once
        request.getfixturevalue("suite_studies")
    env = {**os.environ, "PYTHONPATH": str(ROOT)}
    run = subprocess.run([sys.executable, "-m", module, *argv], cwd=tmp_path, env=env,
                         capture_output=True, text=True, timeout=300)
    assert run.returncode == 0, f"{command}\n{run.stderr[-2000:]}"
    for flag in ("--out", "--html", "--png"):  # what it says it writes is there
        if flag in argv:
            target = tmp_path / argv[argv.index(flag) + 1]
            assert target.exists() and (target.is_dir() or target.stat().st_size > 0), (command, target)


# ----------------------------------------------------------------------------- the README's times


def _measured() -> dict[str, str]:
    import csv

    from lgp.command_times import COMMAND_TIMES, measured_time

    with open(COMMAND_TIMES, newline="") as f:
        commands = list(dict.fromkeys(r["command"] for r in csv.DictReader(f)))
    return {c: measured_time(c) for c in commands}


def test_every_time_in_the_readme_is_one_bench_run_quoted_with_its_machine():
    """README, `lgp.reproduce --help` and docs/results.md quote the same figures,
    those of the last `python bench/commands.py` run (lgp/command_times.csv), each with
    the machine (cores, CPU model, load average); no hand-kept test counts."""
    measured = _measured()
    assert {"python -m lgp.reproduce --quick", "python -m lgp.reproduce"} <= set(measured), measured
    readme = " ".join(README.read_text().split())
    for command, phrase in measured.items():
        assert "cores" in phrase and "load average" in phrase, phrase
        assert phrase in readme, f"README does not quote {command!r} as measured: {phrase!r}"
    results = " ".join((ROOT / "docs" / "results.md").read_text().split())
    assert measured["python -m lgp.reproduce"] in results, "docs/results.md does not quote the full run's time"
    assert not re.search(r"\b\d{3,} (?:tests|passed)\b", readme), "a hand-kept test count in the README"
    assert "@@" not in readme


def test_help_of_quick_quotes_the_same_time(capsys):
    from lgp import reproduce

    with pytest.raises(SystemExit):
        reproduce.parse_args(["--help"])
    text = "".join(capsys.readouterr().out.split())  # argparse wraps lines (also after hyphens)
    assert "".join(_measured()["python -m lgp.reproduce --quick"].split()) in text
