"""The authors' exact engine, box2dweb through Node (models/box2dweb_engine.py,
models/box2dweb/jenga.js): with the authors' own random numbers it reproduces their
saved perceptual-noise runs bit for bit (an independent answer: their file, made
by their code); a scene file's parked bricks keep their indices; without node or
its packages it says what to install in one line."""
import hashlib
import json

import numpy as np
import pytest

from models.box2dweb_engine import box2dweb_missing
from tests.test_mental_jenga import EXP2, HERE, scene

needs_box2dweb = pytest.mark.skipif(box2dweb_missing() is not None, reason=str(box2dweb_missing()))
#: The authors' saved simulations of experiment 2, perceptual noise at their level 8
#: (sigma 0.24), 200 runs per scene (code/R/simulations/exp2 of their repository).
LEVEL_8 = EXP2 / "code" / "R" / "simulations" / "exp2" / "perceptual,impulse-aligned,dynamics_8,0,0.json"


def authors_level_8(trials, n_runs: int, early_stop: bool) -> tuple[list, list]:
    """(ours, theirs): the fallen bricks of the first n_runs at level 8 per scene, ours
    from one Node process with the authors' seed."""
    from models.box2dweb_engine import Box2DWebJengaWorld, run_batch
    from stimuli.mental_jenga import read_scene

    saved = json.loads(LEVEL_8.read_text())
    batch = [Box2DWebJengaWorld(read_scene(EXP2 / "data" / "exp2" / f"{t}.json", 2, t))._scene(
        authors_seed={"levels": [8], "runs": n_runs}) for t in trials]
    return [s["fallen"] for s in run_batch(batch, early_stop)], [saved[f"trial_{t}"][:n_runs] for t in trials]


@needs_box2dweb
@pytest.mark.skipif(not LEVEL_8.is_file(), reason="the Experiment 2 copy (../shared/mental-jenga) is not here")
def test_the_authors_seed_reproduces_their_saved_runs_brick_for_brick():
    """Scenes 26 and 35 lose bricks in the authors' runs and none in pybox2d; 7 is a
    big collapse. Their first 5 runs at level 8, identical brick for brick."""
    ours, theirs = authors_level_8([26, 35, 7], 5, early_stop=True)
    assert ours == theirs
    assert [sum(map(len, runs)) for runs in theirs] == [8, 15, 19]  # they lose bricks: the check is not vacuous


@needs_box2dweb
@pytest.mark.slow  # about 1 CPU-s
@pytest.mark.skipif(not LEVEL_8.is_file(), reason="the Experiment 2 copy (../shared/mental-jenga) is not here")
def test_without_the_early_stop_the_runs_are_the_same():
    ours, theirs = authors_level_8([35], 5, early_stop=False)
    assert ours == theirs


@needs_box2dweb
def test_a_parked_brick_keeps_the_file_indices_of_the_others(tmp_path):
    """A brick parked off the scene (x = -5, as experiment 1's files hold) is created
    and destroyed as the authors' loadData does; the fallen brick is still reported
    as the scene's brick_1, now file index 2."""
    from models.counterfactual import deterministic_falls
    from stimuli.mental_jenga import parse_scene

    data = json.loads((HERE / "stacked.json").read_text())
    data.insert(1, {"name": "brick_1", "x": -5, "y": -5, "angle": 0.0})
    for k, b in enumerate(data):
        b["name"] = f"brick_{k}"
    s = parse_scene(data, "parked", 2, 1)
    assert [b.index for b in s.bricks] == [0, 2, 3] and len(s.authors_bricks) == 4
    assert deterministic_falls(s, engine="box2dweb").tolist() == [False, True, False]


def test_without_node_or_its_packages_the_engine_says_what_to_install_in_one_line(monkeypatch, tmp_path):
    import models.box2dweb_engine as web
    from lgp.errors import InputError
    from models.counterfactual import make_world

    monkeypatch.setattr(web, "NODE", "lgp-no-such-node")
    with pytest.raises(InputError) as e:
        make_world(scene("lone"), engine="box2dweb")
    assert "\n" not in str(e.value) and "npm ci --prefix models/box2dweb" in str(e.value) and "node" in str(e.value)
    monkeypatch.undo()
    if web.shutil.which(web.NODE) is None:
        pytest.skip("node is not installed: the missing-packages case needs it")
    monkeypatch.setattr(web, "ENGINE_DIR", tmp_path)  # no node_modules there
    with pytest.raises(InputError, match=r"npm ci --prefix models/box2dweb \(missing: box2dweb, seedrandom\)$"):
        make_world(scene("lone"), engine="box2dweb")


@pytest.mark.slow  # about 2 CPU-s: imports the analysis command
def test_the_command_refuses_to_start_without_node_and_writes_nothing(monkeypatch, tmp_path, capsys):
    import models.box2dweb_engine as web
    from analysis.mental_jenga import main

    monkeypatch.setattr(web, "NODE", "lgp-no-such-node")
    out = tmp_path / "out"
    assert main(["--repo", str(tmp_path), "--experiment", "2", "--out", str(out)]) == 2  # box2dweb: the default
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1 and "npm ci --prefix models/box2dweb" in err and not out.exists()


@needs_box2dweb
def test_the_cache_key_names_jenga_js_and_the_locked_package_versions():
    from analysis.mental_jenga import _code_key
    from models.box2dweb_engine import ENGINE_DIR

    key = _code_key("box2dweb")["box2dweb"]
    lock = json.loads((ENGINE_DIR / "package-lock.json").read_text())["packages"]
    assert key["box2dweb"] == lock["node_modules/box2dweb"]["version"] == "2.1.0"
    assert key["seedrandom"] == lock["node_modules/seedrandom"]["version"] == "3.0.5"
    assert key["jenga.js"] == hashlib.sha256((ENGINE_DIR / "jenga.js").read_bytes()).hexdigest()[:16]
    assert key["node"].startswith("v")


@needs_box2dweb
def test_one_node_process_runs_every_start_of_a_scene(monkeypatch):
    """counterfactual_runs hands the engine all its distinct starts at once."""
    import models.box2dweb_engine as web
    from models.counterfactual import counterfactual_runs

    calls = []
    real = web.run_batch
    monkeypatch.setattr(web, "run_batch", lambda scenes, *a: calls.append(len(scenes[0].get("runs", []))) or real(scenes, *a))
    runs = counterfactual_runs(scene("stacked"), "authors-x", [0.0, 0.1, 0.2], 4, engine="box2dweb")
    assert len(runs) == 12 and calls == [9]  # sigma 0: one distinct start; 0.1 and 0.2: 4 each
    assert (runs[runs.sigma == 0].fallen == 1).all() and np.isin(runs.fallen, [0, 1, 2]).all()
