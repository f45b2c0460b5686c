"""Cached results are keyed by everything they depend on, checked on every read,
and written atomically with the file mode the user's umask gives."""
import json
import os
import shutil
import stat
import subprocess
import sys

import pandas as pd
import pytest

from lgp.app import cache as cache_module
from lgp.app import stages
from lgp.app.cache import (PACKAGES, ROOT, Cache, import_closure, input_key, library_versions, module_imports,
                       modules_digest, write_csv_atomic)


def _table():
    return pd.DataFrame({"trial": ["7H", "10E"], "effort": [1.25, 0.1 + 0.2]})


def test_second_call_reuses_the_cached_table(tmp_path):
    cache, calls = Cache(tmp_path), []

    def compute():
        calls.append(1)
        return _table()

    a = cache.get_or_compute("effort", input_key(trial="7H", samples=3), compute)
    b = cache.get_or_compute("effort", input_key(trial="7H", samples=3), compute)
    assert len(calls) == 1 and (cache.hits, cache.misses, cache.recomputed) == (1, 1, 0)
    pd.testing.assert_frame_equal(a, b)  # floats survive the round trip to the last digit


def test_key_changes_with_any_input():
    assert input_key(trial="7H", samples=3) != input_key(trial="7H", samples=4)
    assert input_key(trial="7H", samples=3) == input_key(samples=3, trial="7H")


def test_interrupted_write_leaves_no_file(tmp_path):
    class Boom(pd.DataFrame):
        def to_csv(self, *a, **k):
            raise KeyboardInterrupt

    with pytest.raises(KeyboardInterrupt):
        write_csv_atomic(Boom({"x": [1]}), tmp_path / "r.csv")
    assert list(tmp_path.iterdir()) == []


@pytest.mark.parametrize("umask", [0o022, 0o027, 0o002])
def test_results_get_the_mode_the_umask_gives(tmp_path, umask):
    """The atomic write must not keep mkstemp's private 0600: results get the mode the umask gives."""
    old = os.umask(umask)
    try:
        write_csv_atomic(_table(), tmp_path / "r.csv")
        Cache(tmp_path / "c").put("effort", "k", _table())
        (tmp_path / "plain.csv").write_text("x\n")  # what open() gives under this umask
    finally:
        os.umask(old)
    expected = 0o666 & ~umask
    assert stat.S_IMODE((tmp_path / "plain.csv").stat().st_mode) == expected
    assert stat.S_IMODE((tmp_path / "r.csv").stat().st_mode) == expected
    assert stat.S_IMODE((tmp_path / "c" / "effort-k.csv").stat().st_mode) == expected


# ----------------------------------------------------------------------------- damaged entries


def _truncate(b):
    return b[: len(b) // 2]


def _empty(b):
    return b""


def _garble(b):  # bytes that are not UTF-8, in the middle of the CSV
    return b[: len(b) // 2] + b"\xff\xfe\x00\x9c" + b[len(b) // 2 + 4:]


def _lose_line(b):  # a whole data row gone, the file still a valid CSV
    lines = b.splitlines(keepends=True)
    return b"".join(lines[:-1])


def _flip_digit(b):  # one digit changed: a valid CSV with a wrong number
    i = b.rindex(b"1.25")
    return b[:i] + b"1.26" + b[i + 4:]


def _strip_header(b):  # a bare CSV, e.g. an entry of the old format
    return b.partition(b"\n")[2]


@pytest.mark.parametrize("damage", [_truncate, _empty, _garble, _lose_line, _flip_digit, _strip_header])
def test_damaged_entry_is_reported_and_recomputed_never_used(tmp_path, capsys, damage):
    cache = Cache(tmp_path)
    cache.get_or_compute("effort", "k", _table)
    path = cache.path("effort", "k")
    path.write_bytes(damage(path.read_bytes()))
    capsys.readouterr()

    again = Cache(tmp_path)
    df = again.get_or_compute("effort", "k", _table)
    pd.testing.assert_frame_equal(df, _table())
    assert (again.hits, again.misses, again.recomputed) == (0, 0, 1)
    assert again.damaged == [path]
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and str(path) in err[0] and "recomputing" in err[0]
    # ... and the entry is whole again: a third run uses it
    third = Cache(tmp_path)
    pd.testing.assert_frame_equal(third.get_or_compute("effort", "k", _table), _table())
    assert (third.hits, third.recomputed) == (1, 0)


def test_disabled_cache_counts_misses_and_rewrites(tmp_path):
    Cache(tmp_path).put("risk", "k", _table().assign(effort=0.0))
    cache = Cache(tmp_path, enabled=False)
    pd.testing.assert_frame_equal(cache.get_or_compute("risk", "k", _table), _table())
    assert (cache.count("miss", "risk"), cache.hits) == (1, 0)
    assert Cache(tmp_path).get("risk", "k").equals(_table())


# ----------------------------------------------------------------------------- the key


def test_library_versions_name_the_installed_versions():
    from importlib.metadata import version

    versions = library_versions()
    assert {"mujoco", "drake", "numpy", "scipy", "pandas", "python"} <= set(versions)
    assert versions["numpy"] == version("numpy") and versions["mujoco"] == version("mujoco")
    assert library_versions(["no-such-library-xyz"])["no-such-library-xyz"] == "not installed"


def test_import_reader_sees_imports_inside_functions():
    imports = dict(module_imports("models.effort"))
    assert imports["lgp.planner"] is True  # at import time
    assert imports["stimuli"] is False  # inside physical_effort
    assert dict(module_imports("lgp"))["lgp.planner"] is False  # lgp.plan, lazily


def _project_modules_loaded_by(code: str) -> set[str]:
    """The project modules a fresh interpreter has loaded after running `code`."""
    code += f"\nimport sys\nprint(' '.join(m for m in sys.modules if m.split('.')[0] in {PACKAGES!r}))"
    env = {**os.environ, "PYTHONPATH": str(ROOT)}
    return set(subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True, env=env,
                              cwd=ROOT).stdout.split())


@pytest.mark.slow
def test_import_closure_holds_every_module_python_loads():
    """An independent answer: the project modules a fresh interpreter has loaded
    after importing the computation and running it are all in the closure."""
    loaded = _project_modules_loaded_by("import stimuli, models.effort, models.risk\n"
                                        "from models.risk import get_engine\n"
                                        "get_engine('mujoco'); models.effort.physical_effort('9E', samples=1)\n")
    closure = set(import_closure("models.effort", "models.risk", "models.risk.mujoco_engine", "stimuli"))
    assert {"models.effort", "lgp.planner", "lgp.komo", "models.risk.mujoco_engine", "stimuli"} <= loaded
    assert loaded <= closure, loaded - closure


@pytest.mark.slow
def test_the_risk_key_covers_what_a_risk_run_loads_and_not_the_planner():
    """Risk needs no plan: a fresh interpreter that computes a risk table loads only
    modules of the risk key's closure, and neither holds the planner or KOMO, so
    editing the motion planner keeps cached risks (build risk, which plans, is
    re-exported by models.risk lazily)."""

    loaded = _project_modules_loaded_by("import stimuli\n"
                                        "from models.risk import risk_table\n"
                                        "risk_table([stimuli.load_trial('7H')], [0.065], n_sims=2, jobs=1)\n")
    closure = set(import_closure("models.risk.core", "models.risk.mujoco_engine", "stimuli"))
    assert {"models.risk.core", "models.risk.mujoco_engine", "stimuli"} <= loaded
    assert loaded <= closure, loaded - closure
    assert not {"lgp.planner", "lgp.komo", "models.effort", "models.risk.build"} & (loaded | closure)
    assert stages.risk_key_inputs(None)["code"] == modules_digest("models.risk.core", "models.risk.mujoco_engine", "stimuli")


@pytest.mark.slow  # copies the project
def test_editing_the_planner_keeps_the_risk_key(tmp_path):
    root = _copy_project(tmp_path)
    risk = modules_digest("models.risk.core", "models.risk.mujoco_engine", "stimuli", root=root)
    effort = modules_digest("models.effort", "stimuli", root=root)
    for module in ("lgp/planner/__init__.py", "lgp/planner/clearance.py", "lgp/komo/solve.py", "models/risk/build.py"):
        (root / module).write_text((root / module).read_text() + "\n# edited\n")
    assert modules_digest("models.risk.core", "models.risk.mujoco_engine", "stimuli", root=root) == risk
    assert modules_digest("models.effort", "stimuli", root=root) != effort
    noise = root / "models" / "risk" / "noise.py"
    noise.write_text(noise.read_text() + "\n# edited\n")
    assert modules_digest("models.risk.core", "models.risk.mujoco_engine", "stimuli", root=root) != risk


def test_a_packages_lazy_imports_count_only_when_the_package_is_imported_by_name(tmp_path):
    """`lgp/__init__` runs for `import lgp.scene`, but its lazy `lgp.plan` (an import
    inside a function) runs only if some module imports `lgp` itself."""
    (tmp_path / "lgp").mkdir()
    (tmp_path / "lgp" / "__init__.py").write_text("from lgp.scene import X\n\ndef __getattr__(name):\n    from lgp import planner\n")
    (tmp_path / "lgp" / "scene.py").write_text("X = 1\n")
    (tmp_path / "lgp" / "planner.py").write_text("import models.heavy\n")
    (tmp_path / "models").mkdir()
    (tmp_path / "models" / "__init__.py").write_text("")
    (tmp_path / "models" / "heavy.py").write_text("")
    (tmp_path / "models" / "risk.py").write_text("from lgp.scene import X\n")
    (tmp_path / "models" / "effort.py").write_text("def f():\n    import lgp\n    return lgp.plan\n")
    assert import_closure("models.risk", root=tmp_path) == ["lgp", "lgp.scene", "models", "models.risk"]
    assert import_closure("models.effort", root=tmp_path) == ["lgp", "lgp.planner", "lgp.scene", "models", "models.effort",
                                                              "models.heavy"]


def _copy_project(dst):
    for package in PACKAGES:
        shutil.copytree(ROOT / package, dst / package, ignore=shutil.ignore_patterns("__pycache__", "*.yaml", "*.md"))
    return dst


@pytest.mark.slow  # copies the project
def test_editing_a_module_the_computation_imports_changes_the_key(tmp_path):
    root = _copy_project(tmp_path)
    before = modules_digest("models.effort", root=root)
    assert before == modules_digest("models.effort")  # same bytes, same key

    # symbolic is reached through lgp.planner, komo.linear through the lgp.komo
    # package, executor.processes through the lgp.executor package, stimuli through
    # an import inside physical_effort.
    for module in ("lgp/symbolic.py", "lgp/komo/linear.py", "lgp/executor/processes.py", "stimuli/__init__.py", "models/effort/__init__.py"):
        path = root / module
        text = path.read_text()
        path.write_text(text + "\n# edited\n")
        assert modules_digest("models.effort", root=root) != before, module
        path.write_text(text)
    assert modules_digest("models.effort", root=root) == before

    # files the effort computation never imports do not invalidate it
    for module in ("lgp/reproduce.py", "lgp/app/view.py", "analysis/models.py", "models/risk/core.py"):
        (root / module).write_text((root / module).read_text() + "\n# edited\n")
    assert modules_digest("models.effort", root=root) == before


def test_the_effort_key_does_not_hash_the_command_line(tmp_path):
    """The effort CLI is models/effort/__main__.py: its help strings and the shared
    argument checks of lgp.cli are no input of an effort, so editing them keeps
    every cached effort (models.effort must not import lgp.cli)."""

    closure = set(import_closure("models.effort", "stimuli"))
    assert "models.effort" in closure and "lgp.planner" in closure
    assert not {"models.effort.__main__", "lgp.cli"} & closure
    assert stages.effort_key_inputs()["code"] == modules_digest("models.effort", "stimuli")
    root = _copy_project(tmp_path)
    before = modules_digest("models.effort", "stimuli", root=root)
    for module in ("models/effort/__main__.py", "lgp/cli.py"):
        (root / module).write_text((root / module).read_text() + "\n# a help string edited\n")
    assert modules_digest("models.effort", "stimuli", root=root) == before
    (root / "models" / "effort" / "__init__.py").write_text((root / "models" / "effort" / "__init__.py").read_text() + "\n# edited\n")
    assert modules_digest("models.effort", "stimuli", root=root) != before


def test_a_new_import_is_followed(tmp_path):
    """A new project import in the computation brings the new module into the key."""
    root = _copy_project(tmp_path)
    (root / "lgp" / "extra.py").write_text("X = 1\n")
    before = modules_digest("models.risk", root=root)
    assert "lgp.extra" not in import_closure("models.risk", root=root)
    noise = root / "models" / "risk" / "noise.py"
    noise.write_text(noise.read_text() + "\n\ndef _f():\n    from lgp import extra\n    return extra.X\n")
    assert "lgp.extra" in import_closure("models.risk", root=root)
    after = modules_digest("models.risk", root=root)
    (root / "lgp" / "extra.py").write_text("X = 2\n")
    assert len({before, after, modules_digest("models.risk", root=root)}) == 3


def test_a_file_that_appears_is_followed_though_the_importer_is_unchanged(tmp_path):
    """Parsed imports are remembered by the importer's bytes, but which names are
    modules is decided from the files each time: `from lgp import extra` means the
    package until lgp/extra.py exists, then that module."""
    (tmp_path / "lgp").mkdir()
    (tmp_path / "lgp" / "__init__.py").write_text("")
    (tmp_path / "models").mkdir()
    (tmp_path / "models" / "__init__.py").write_text("")
    (tmp_path / "models" / "risk.py").write_text("def f():\n    from lgp import extra\n")
    assert import_closure("models.risk", root=tmp_path) == ["lgp", "models", "models.risk"]
    (tmp_path / "lgp" / "extra.py").write_text("X = 1\n")
    assert import_closure("models.risk", root=tmp_path) == ["lgp", "lgp.extra", "models", "models.risk"]


def test_reproduce_keys_cover_libraries_and_engine_settings(monkeypatch):
    from models.risk import get_engine

    risk = stages.risk_key_inputs(None)
    assert risk["engine"] == "mujoco" and risk["engine_settings"] == get_engine("mujoco").settings()
    assert risk["libraries"] == library_versions()
    drake = stages.risk_key_inputs("drake")
    assert drake["engine_settings"]["engine"] == "drake" and drake["code"] != risk["code"]
    effort = stages.effort_key_inputs()
    assert {"drake", "numpy", "scipy", "pandas"} <= set(effort["libraries"])

    # a library upgrade changes both keys
    real = cache_module.metadata.version
    monkeypatch.setattr(cache_module.metadata, "version", lambda name: "99.0" if name == "mujoco" else real(name))
    assert stages.risk_key_inputs(None)["libraries"] != risk["libraries"]
    monkeypatch.setattr(cache_module.metadata, "version", lambda name: "99.0" if name == "drake" else real(name))
    assert stages.effort_key_inputs() != effort


def test_the_manifest_is_written_without_setting_the_umask(tmp_path, monkeypatch):
    """Issue 21: manifest._umask read the mask with os.umask(0), the race this
    module's writer avoids; every output now goes through lgp.app.files, which reads
    /proc/self/status (Linux) and gives the mode the umask gives."""
    from lgp.app.files import umask
    from lgp.app.manifest import write_manifest

    mask = umask()
    (tmp_path / "a.csv").write_text("x\n")

    def no_umask(*a):
        raise AssertionError("os.umask called: it changes the mask of every thread")

    monkeypatch.setattr(os, "umask", no_umask)
    path = write_manifest(tmp_path, [tmp_path / "a.csv"], command=["x"])
    assert stat.S_IMODE(path.stat().st_mode) == 0o666 & ~mask
    assert json.loads(path.read_text())["files"][0]["path"] == "a.csv"


def test_the_build_risk_key_names_the_engines_own_library_as_the_risk_key_does(monkeypatch):
    """Issue 21: the build-risk key left out sapien (PhysX's library), so `--engine
    physx --build-risk` reused stale stage tables after a sapien upgrade."""
    pytest.importorskip("sapien")
    from lgp.app.build_risk import build_key_inputs

    physx = build_key_inputs("physx")
    assert "sapien" in physx["libraries"] and physx["libraries"] == stages.risk_key_inputs("physx")["libraries"]
    real = cache_module.metadata.version
    monkeypatch.setattr(cache_module.metadata, "version", lambda name: "99.0" if name == "sapien" else real(name))
    assert build_key_inputs("physx")["libraries"] != physx["libraries"]
    assert build_key_inputs("mujoco")["libraries"] == library_versions()  # no engine library of its own
