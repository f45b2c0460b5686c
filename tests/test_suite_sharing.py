"""A product of the suite (the session's --quick run, the studies) is built once per
pytest run, whichever xdist worker asks first (conftest.Claim, conftest.built_once):
the first claim builds and holds the lock; a claim made meanwhile does not build; once
it is finished every later claim reads it; a build that fails leaves it to the next."""
import os
import subprocess
import sys
import time
from pathlib import Path

import pytest

from conftest import Claim, built_once, suite_folder


def test_the_first_claim_builds_a_claim_meanwhile_waits_and_a_later_one_reads(tmp_path):
    first = Claim(tmp_path, "product", wait=False)
    assert first.build and first.folder.is_dir()
    meanwhile = Claim(tmp_path, "product", wait=False)  # another open file: the lock is held
    assert not meanwhile.held and not meanwhile.build
    (first.folder / "table.csv").write_text("x\n")
    first.finish()
    later = Claim(tmp_path, "product")
    assert not later.build and (later.folder / "table.csv").read_text() == "x\n"


def test_a_claim_in_another_process_waits_for_the_build_to_finish(tmp_path):
    first = Claim(tmp_path, "product", wait=False)
    root = str(Path(__file__).parent)
    asking = tmp_path / "asking"
    script = ("import sys; sys.path.insert(0, %r); from pathlib import Path; from conftest import Claim;"
              "Path(%r).touch(); c = Claim(Path(%r), 'product');"
              "print(c.build, (c.folder / 'table.csv').read_text().strip())") % (root, str(asking), str(tmp_path))
    other = subprocess.Popen([sys.executable, "-c", script], stdout=subprocess.PIPE, text=True,
                             env={**os.environ, "PYTHONPATH": str(Path(root).parent)})
    deadline = time.monotonic() + 60
    while not asking.exists() and time.monotonic() < deadline:
        time.sleep(0.01)
    time.sleep(0.2)  # the other process is waiting on the lock now
    assert other.poll() is None
    (first.folder / "table.csv").write_text("built\n")
    first.finish()
    out, _ = other.communicate(timeout=60)
    assert other.returncode == 0 and out.split() == ["False", "built"]


def test_a_failed_build_is_built_again_by_the_next_worker_that_asks(tmp_path_factory):
    calls = []

    def fails(folder):
        calls.append(folder)
        raise RuntimeError("no disk")

    with pytest.raises(RuntimeError, match="no disk"):
        built_once(tmp_path_factory, "sharing-test", fails)
    folder = built_once(tmp_path_factory, "sharing-test", lambda f: (f / "ok").write_text("y"))
    assert len(calls) == 1 and (folder / "ok").read_text() == "y"
    assert built_once(tmp_path_factory, "sharing-test", fails) == folder and len(calls) == 1  # built: read, not rebuilt
    assert folder.parent == suite_folder(tmp_path_factory)


def test_the_suite_renders_into_its_own_cache_and_no_module_freezes_the_environment_before_it():
    # conftest.suite_render_cache puts LGP_RENDER_CACHE in os.environ when the session
    # starts; a module that copies os.environ at import (test_output_folder.py's ENV did)
    # gave its subprocesses the user's ~/.cache instead: no module-level statement of a
    # test module may read os.environ into a value (os.environ.get of another variable
    # for a setting is fine).
    import ast

    from stimuli.render import render_cache_dir

    assert render_cache_dir() == Path(os.environ["LGP_RENDER_CACHE"])
    assert not str(render_cache_dir()).startswith(str(Path.home() / ".cache"))
    frozen = []
    for path in sorted(Path(__file__).parent.glob("*.py")):
        for node in ast.parse(path.read_text()).body:
            if isinstance(node, (ast.Assign, ast.AnnAssign)) and node.value is not None:
                uses = [n for n in ast.walk(node.value) if isinstance(n, ast.Attribute) and n.attr == "environ"]
                getter = isinstance(node.value, ast.Call) and getattr(node.value.func, "attr", "") == "get"
                if uses and not getter:
                    frozen.append(f"{path.name}:{node.lineno}")
    assert frozen == [], frozen


def test_the_files_are_handed_out_longest_first_each_in_its_own_order(tmp_path):
    import conftest
    from types import SimpleNamespace

    table = tmp_path / "seconds.csv"
    table.write_text("file,seconds\ntest_long.py,90\ntest_mid.py,10\ntest_short.py,1\n")
    items = [SimpleNamespace(fspath=f"/x/{f}", name=n) for f, n in
             [("test_short.py", "a"), ("test_new.py", "b"), ("test_long.py", "c"), ("test_long.py", "d"),
              ("test_mid.py", "e"), ("test_new.py", "f")]]
    conftest.longest_files_first(items, conftest.file_seconds(table))
    # the unlisted test_new.py counts as the median (10 s), tied with test_mid.py: the
    # file collected first goes first
    assert [(Path(i.fspath).name, i.name) for i in items] == [
        ("test_long.py", "c"), ("test_long.py", "d"), ("test_new.py", "b"), ("test_new.py", "f"), ("test_mid.py", "e"),
        ("test_short.py", "a")]
    # every file of the suite is listed, with a time
    listed = conftest.file_seconds()
    missing = {p.name for p in Path(__file__).parent.glob("test_*.py")} - set(listed)
    assert not missing, (f"{sorted(missing)}: not in tests/file_seconds.csv (bench/test_times.py CSV "
                         "--write-file-seconds writes it from a whole-suite run of bench/pytest_cpu.py)")
