"""Every snippet of README.md and docs/*.md runs as written, or says it is output.

A fenced block is labelled by its language: ``python`` (run as a script in a scratch
folder), ``pycon`` (run as a doctest), ``bash`` (each ``python -m MODULE ...`` line is
checked against the module's own command line: ``lgp.reproduce``'s parser reads it,
any other module's ``--help`` must name each of its options; each ``python -c`` line
runs), or one of OUTPUT (what a command prints or a file holds: not run). A block
that cannot run here says why in a comment on the line above it,
``<!-- snippet not run: REASON -->`` (a cluster this machine does not have). Lines
of a ``bash`` block that are not Python (``pip install``, ``npm ci``, ``dask
scheduler``) are the installation and the cluster's own commands: test_readme.py
checks that README's install line is the one .ci/run runs. Indented (4-space) lines
``python -m ...`` outside fences are checked like a bash block's. The README's
``pycon`` block is run by test_readme.py, not again here.
"""
from __future__ import annotations

import functools
import os
import re
import shlex
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parent.parent
DOCS = [ROOT / "README.md", *sorted((ROOT / "docs").glob("*.md"))]
#: Labels of blocks that show output or file content.
OUTPUT = {"text", "console", "csv", "yaml", "json", "output"}
RUN = {"python", "pycon", "bash"}
FENCE = re.compile(r"^(?P<indent>[ ]*)```(?P<lang>[^\n`]*)\n(?P<body>.*?)^(?P=indent)```[ ]*$", re.S | re.M)
NOT_RUN = re.compile(r"<!-- snippet not run: (?P<why>[^>]+?) -->\s*$")


def snippets() -> list[tuple[str, int, str, str, str | None]]:
    """(doc, k, label, body, reason not run) of every fenced block, in order."""
    out = []
    for doc in DOCS:
        text = doc.read_text()
        for k, m in enumerate(FENCE.finditer(text), 1):
            before = text[:m.start()].rstrip("\n").rsplit("\n", 1)[-1]
            why = NOT_RUN.search(before)
            body = "\n".join(line[len(m.group("indent")):] for line in m.group("body").splitlines())
            out.append((doc.name, k, m.group("lang").strip(), body, why.group("why") if why else None))
    return out


def indented_commands() -> list[tuple[str, str]]:
    """(doc, line) of every `python -m` line of an indented code block (outside fences)."""
    out = []
    for doc in DOCS:
        text = FENCE.sub("", doc.read_text())
        out += [(doc.name, m.group(1)) for m in re.finditer(r"^ {4}(python -m [^\n#]*?)\s*(?:#.*)?$", text, flags=re.M)]
    return out


SNIPPETS = snippets()


def _id(s) -> str:
    return f"{s[0]}:{s[1]}:{s[2]}"


def test_every_snippet_says_whether_it_runs_or_is_output():
    unlabelled = [_id(s) for s in SNIPPETS if s[2] not in RUN | OUTPUT]
    assert unlabelled == [], f"blocks without a known label (python, pycon, bash, or output: {sorted(OUTPUT)}): {unlabelled}"
    skipped = [s for s in SNIPPETS if s[4] is not None]
    assert all(len(s[4]) > 10 for s in skipped) and len(skipped) <= 3, [(_id(s), s[4]) for s in skipped]


# ----------------------------------------------------------------------------- python and pycon


def _stand_ins(folder: Path) -> None:
    """What docs/human-data.md's snippet reads: responses.csv (random responses in the
    human-data format, no claim tested on them, as in test_analysis_compare) and a
    run's results/effort_samples.csv and results/risk.csv (the analysis tests' stand-in
    tables, conftest.synthetic_*)."""
    import numpy as np
    import pandas as pd

    from conftest import synthetic_effort, synthetic_risk
    from lgp.paper import TRIAL_IDS

    rng = np.random.default_rng(0)
    rows = [("difficulty", f"p{k}", t, float(rng.normal())) for k in range(6) for t in TRIAL_IDS]
    pd.DataFrame(rows, columns=["dataset", "participant", "trial", "response"]).to_csv(folder / "responses.csv", index=False)
    (folder / "results").mkdir()
    effort = synthetic_effort()
    pd.DataFrame({"trial": effort.index, "sample": 0, "effort": effort.to_numpy()}).to_csv(
        folder / "results" / "effort_samples.csv", index=False)
    synthetic_risk().to_csv(folder / "results" / "risk.csv", index=False)


#: Files a doc's snippet reads, made in its scratch folder first.
SETUP = {"human-data.md": _stand_ins}


@pytest.mark.slow
@pytest.mark.parametrize("snippet", [s for s in SNIPPETS if s[2] in ("python", "pycon") and s[4] is None
                                     and not (s[0] == "README.md" and s[2] == "pycon")], ids=_id)
def test_a_python_snippet_runs_as_written(snippet, tmp_path, monkeypatch):
    doc, k, label, body, _ = snippet
    if doc in SETUP:
        SETUP[doc](tmp_path)
    if label == "python":
        # a script: run in this process (its imports paid once, ~2.5 CPU-s a fresh interpreter would
        # spend on them), in the scratch folder, in a namespace of its own as `python script.py` has
        monkeypatch.chdir(tmp_path)
        monkeypatch.setenv("MPLBACKEND", "Agg")
        exec(compile(body, f"{doc} block {k}", "exec"), {"__name__": "__main__", "__builtins__": __builtins__})
        return
    script = ("import doctest, sys\n"  # pycon: a doctest, in a fresh interpreter
              f"t = doctest.DocTestParser().get_doctest({body!r}, {{}}, {f'{doc} block {k}'!r}, {doc!r}, 0)\n"
              "r = doctest.DocTestRunner(optionflags=doctest.ELLIPSIS | doctest.NORMALIZE_WHITESPACE)\n"
              "r.run(t); sys.exit(1 if r.summarize(verbose=False).failed else 0)\n")
    run = subprocess.run([sys.executable, "-c", script], cwd=tmp_path, capture_output=True, text=True,
                         env={**os.environ, "PYTHONPATH": str(ROOT), "MPLBACKEND": "Agg"})
    assert run.returncode == 0, f"{doc} block {k} failed:\n{run.stdout[-1500:]}\n{run.stderr[-2500:]}"


# ----------------------------------------------------------------------------- commands


def _commands() -> list[tuple[str, str]]:
    out = []
    for doc, k, label, body, why in SNIPPETS:
        if label != "bash" or why is not None:
            continue
        for line in body.splitlines():
            line = line.strip()
            if line.startswith("python -m ") or line.startswith("python -c "):
                out.append((f"{doc}:{k}", line))
    return out + [(doc, line) for doc, line in indented_commands()]


COMMANDS = _commands()


@functools.lru_cache(maxsize=None)
def _help(module: str) -> tuple[int, str, str]:
    """(exit code, stdout, stderr) of `python -m module --help`, once per module: the
    main(argv) that `python -m module` runs (the module's, or its package's
    __main__'s), called with --help in this process (no fresh interpreter, ~2 CPU-s
    each, to print the same parser's help)."""
    import contextlib
    import importlib
    import importlib.util
    import io

    spec = importlib.util.find_spec(module)
    entry = importlib.import_module(f"{module}.__main__" if spec.submodule_search_locations else module)
    out, err, code = io.StringIO(), io.StringIO(), 0
    with contextlib.redirect_stdout(out), contextlib.redirect_stderr(err):
        try:
            code = entry.main(["--help"]) or 0
        except SystemExit as e:
            code = e.code if isinstance(e.code, int) else (0 if e.code is None else 1)
    return code, out.getvalue(), err.getvalue()


def _strip_comment(line: str) -> list[str]:
    words = shlex.split(line, comments=True)
    return words


@pytest.mark.slow
@pytest.mark.parametrize("where,line", [c for c in COMMANDS if c[1].startswith("python -m ")],
                         ids=[f"{w}:{' '.join(line.split()[2:4])}" for w, line in COMMANDS if line.startswith("python -m ")])
def test_a_documented_command_uses_only_options_its_module_has(where, line, tmp_path, monkeypatch):
    words = _strip_comment(line)
    module, argv = words[2], words[3:]
    if module == "pytest":
        return  # test_readme.py: the pytest commands are .ci/run's
    if module == "lgp.reproduce" and "--sigma-from" not in argv:  # that file's content comes from another tool's run
        from lgp import reproduce

        monkeypatch.chdir(tmp_path)
        for flag in ("--human-data", "--stimuli"):  # an input an earlier line of the block made must exist to parse
            if flag in argv:
                path = tmp_path / argv[argv.index(flag) + 1]
                path.parent.mkdir(parents=True, exist_ok=True)
                path.mkdir() if flag == "--stimuli" else path.write_text("dataset,participant,trial,response\n")
        args = reproduce.parse_args([w for w in argv if not w.startswith("<")])
        assert args.out
        return
    code, text, err = _help(module)
    assert code == 0 and "usage:" in text, f"{where}: {module} --help: {err[-1000:]}"
    options = {w.split("=")[0] for w in argv if w.startswith("--")}
    missing = [o for o in options if not re.search(rf"(?<![\w-]){re.escape(o)}(?![\w-])", text)]
    assert missing == [], f"{where}: `{line}` uses options {module} does not have: {missing}"


@pytest.mark.slow
@pytest.mark.parametrize("where,line", [c for c in COMMANDS if c[1].startswith("python -c ")], ids=lambda v: str(v)[:40])
def test_a_documented_python_c_line_runs(where, line, tmp_path):
    words = shlex.split(line)
    run = subprocess.run([sys.executable, *words[1:]], cwd=tmp_path, capture_output=True, text=True,
                         env={**os.environ, "PYTHONPATH": str(ROOT), "MPLBACKEND": "Agg"})
    assert run.returncode == 0, f"{where}: {line}\n{run.stderr[-2000:]}"
