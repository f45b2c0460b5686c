"""Mental Jenga scenes (another lab's brick scenes, stimuli/mental_jenga.py) and the
counterfactual fall measure (models/counterfactual.py), on small scenes written by
hand in the repository's format (tests/data/mental_jenga/*.json)."""
import json
import math
import shutil
import subprocess
import sys
from pathlib import Path

import numpy as np
import pandas as pd
import pytest

from stimuli.mental_jenga import (GROUND_Y_A, SCALE, TABLE_TOP_Y_A, MentalJengaError, parse_scene, read_scene)

HERE = Path(__file__).parent / "data" / "mental_jenga"
#: The shared copy of Experiment 2 beside the clone (../shared), as CI places it.
EXP2 = Path(__file__).resolve().parents[2] / "shared" / "mental-jenga" / "repo-exp2"


def scene(name: str, black_index: int = 0):
    data = json.loads((HERE / f"{name}.json").read_text())
    return parse_scene(data, name, 2, 1, black_index=black_index)


def fake_repo(tmp_path: Path, scenes: dict, predictions: pd.DataFrame | None = None) -> Path:
    """A folder laid out like a clone of the repository, with `scenes` ({trial: file name})."""
    repo = tmp_path / "clone"
    (repo / "data" / "exp2").mkdir(parents=True)
    (repo / "code" / "R" / "data").mkdir(parents=True)
    for trial, name in scenes.items():
        shutil.copy(HERE / f"{name}.json", repo / "data" / "exp2" / f"{trial}.json")
    if predictions is not None:
        import pyreadr

        pyreadr.write_rdata(str(repo / "code" / "R" / "data" / "exp2_prediction.RData"), predictions,
                            df_name="df.exp2.prediction")
    return repo


# ----------------------------------------------------------------------------- reading


def test_extrusion_and_y_flip_put_a_brick_where_the_picture_shows_it():
    s = scene("picture")
    flat, standing, tilted = s.bricks
    # on the table, 0.5 right of its middle: x = 0.1 * 0.5, centre 0.1 * (5.8 - 4.615) above the ground
    assert np.allclose(flat.p_WB, [0.05, 0.0, SCALE * (GROUND_Y_A - 4.615)])
    assert np.allclose(flat.size, [0.08, 0.04, 0.04]) and flat.pitch == 0.0
    # a quarter turn: an axis-aligned box, width and height swapped, standing on the table top
    assert standing.pitch == 0.0 and np.allclose(standing.size, [0.04, 0.04, 0.08])
    assert math.isclose(standing.p_WB[2] - standing.size[2] / 2, SCALE * (GROUND_Y_A - TABLE_TOP_Y_A) + 0.0005, abs_tol=1e-9)
    # higher in the picture (smaller y) is higher in W
    assert tilted.p_WB[2] > standing.p_WB[2] > flat.p_WB[2]
    assert s.table.top == pytest.approx(SCALE * (GROUND_Y_A - TABLE_TOP_Y_A))


def test_a_positive_box2d_angle_lowers_the_bricks_right_end():
    """Box2D's angle turns +x towards +y, which points down on the screen: in W, MuJoCo's
    own rotation of the compiled body must put the brick's +x end below its centre."""
    import mujoco

    from models.counterfactual import mjcf

    s = scene("picture")
    m = mujoco.MjModel.from_xml_string(mjcf(s))
    d = mujoco.MjData(m)
    mujoco.mj_forward(m, d)
    x_axis = d.xmat[m.body("brick_2").id].reshape(3, 3)[:, 0]
    assert x_axis[2] == pytest.approx(-math.sin(0.3)) and x_axis[0] == pytest.approx(math.cos(0.3))


def test_parked_bricks_are_not_in_the_scene_and_brick_0_is_black():
    s = scene("lone")
    assert [b.name for b in s.bricks] == ["brick_0", "brick_1"]
    assert s.black.name == "brick_0" and [b.name for b in s.red()] == ["brick_1"]


@pytest.mark.parametrize("content, problem", [("{not json", "not valid JSON"), ("[]", "names no bricks"),
                                               ('[{"x": 1}]', "brick 0 is not a mapping")])
def test_a_bad_scene_file_is_refused_with_its_name(tmp_path, content, problem):
    p = tmp_path / "3.json"
    p.write_text(content)
    with pytest.raises(MentalJengaError, match=problem) as e:
        read_scene(p, 2, 3)
    assert str(p) in str(e.value)


def _cli(*args):
    return subprocess.run([sys.executable, "-m", "stimuli.mental_jenga", *args], capture_output=True, text=True)


@pytest.mark.slow
def test_cli_refuses_bad_input_in_one_line_and_writes_nothing(tmp_path):
    repo = fake_repo(tmp_path, {1: "lone"})
    (repo / "data" / "exp2" / "2.json").write_text("[]")
    cases = [(tmp_path / "nowhere", 2, "not a clone"), (repo, 9, "unknown experiment 9"), (repo, 2, "2.json: names no bricks")]
    for path, exp, problem in cases:
        out = tmp_path / f"out{exp}"
        r = _cli("--repo", str(path), "--experiment", str(exp), "--out", str(out))
        assert r.returncode == 2 and problem in r.stderr and len(r.stderr.strip().splitlines()) == 1, r.stderr
        assert not out.exists()
    user = tmp_path / "mine"  # a folder of the user's: refused, left as it was
    user.mkdir()
    (user / "notes.txt").write_text("mine\n")
    r = _cli("--repo", str(repo), "--experiment", "2", "--out", str(user))
    assert r.returncode == 2 and "no run of this command wrote (notes.txt) and no scenes.csv" in r.stderr, r.stderr
    assert [p.name for p in user.iterdir()] == ["notes.txt"] and (user / "notes.txt").read_text() == "mine\n"


@pytest.mark.slow
def test_cli_writes_bricks_scenes_trials_and_tidy_predictions(tmp_path):
    pred = pd.DataFrame({"participant": [1, 1, 2, 2], "condition": "prediction", "order": [1, 2, 2, 1],
                         "trial": [1.0, 2.0, 1.0, 2.0], "response": [0.0, 1.0, 0.0, 2.0]})
    repo = fake_repo(tmp_path, {1: "lone", 2: "stacked"}, pred)
    out = tmp_path / "out"
    r = _cli("--repo", str(repo), "--experiment", "2", "--out", str(out))
    assert r.returncode == 0, r.stderr
    p = pd.read_csv(out / "predictions.csv")
    assert list(p.columns) == ["participant", "trial", "response"] and len(p) == 4
    assert p.groupby("trial").response.mean().to_dict() == {1: 0.0, 2: 1.5}
    scenes = pd.read_csv(out / "scenes.csv")
    assert scenes.trial_format.str.startswith("written").all()
    import stimuli

    trial = stimuli.load_file(out / "trials" / "MJ2_01.yaml")  # the project's own checks accept it
    assert {b.name for b in trial.target.blocks} == {"black_brick_0", "brick_1"}
    assert [f.name for f in trial.target.fixed] == ["table"]


# ----------------------------------------------------------------------------- the fall measure


def test_a_lone_brick_on_the_table_never_falls():
    from models.counterfactual import counterfactual_runs

    runs = counterfactual_runs(scene("lone"), "authors-x", [0.0, 0.1, 0.3], 5)
    assert (runs.fallen == 0).all()


def test_a_brick_overhanging_past_its_centre_falls_and_one_short_of_it_stands():
    from models.counterfactual import deterministic_falls

    s = scene("overhang")
    falls = dict(zip([b.name for b in s.bricks], deterministic_falls(s)))
    assert falls == {"brick_0": False, "brick_1": True, "brick_2": False}


def test_removing_the_only_support_of_a_stacked_brick_makes_it_fall():
    from models.counterfactual import deterministic_falls

    removed = scene("stacked")  # brick_0 carries brick_1, whose centre is past the table's edge
    assert deterministic_falls(removed).tolist() == [False, True, False]
    kept = scene("stacked", black_index=2)  # remove a brick elsewhere instead: brick_1 stays
    assert not deterministic_falls(kept).any()


@pytest.mark.parametrize("rule", ["authors-x", "paper-3d"])
def test_the_count_at_sigma_zero_is_the_deterministic_simulation(rule):
    from models.counterfactual import counterfactual_runs, deterministic_falls

    for name in ("stacked", "overhang"):
        s = scene(name)
        runs = counterfactual_runs(s, rule, [0.0], 3)
        assert (runs.fallen == int(deterministic_falls(s).sum())).all()


def test_the_noise_moves_only_what_the_black_brick_carries_and_never_deepens_an_overlap():
    """authors-x moves the bricks above the black one (the authors' sleeping of the
    others) along x only; ":all" moves every red brick; side neighbours never overlap
    more than they did before the noise."""
    from models.counterfactual import JengaWorld, Perturbation, draw_normals

    s = parse_scene([{"x": 4.4, "y": 4.615, "angle": 0.0}, {"x": 4.4, "y": 4.21, "angle": 0.0},
                     {"x": 3.58, "y": 4.615, "angle": 0.0}, {"x": 4.39, "y": 3.805, "angle": 0.0},
                     {"x": 2.76, "y": 4.615, "angle": 0.0}], "hand", 2, 1)
    w = Perturbation(JengaWorld(s))
    assert w.above.tolist() == [False, True, False, True, False]  # brick 1 on the black one, brick 3 on brick 1
    z = draw_normals(200, 5, 0, 1)
    settled = w.world.q_settled[:, :3]
    p = w.positions("authors-x", 0.3, z)
    moved = np.abs(p - settled[None]) > 1e-12
    assert not moved[:, [0, 2, 4]].any() and moved[:, [1, 3], 0].all() and not moved[:, :, 1:].any()
    q = w.positions("authors-x:all", 0.3, z)
    assert (np.abs(q[:, 2, 0] - settled[2, 0]) > 0).all()
    # bricks 2 and 4 stand side by side, 0.02 (authors') apart: the noise pushes them into
    # each other in about half the runs, and the rule pushes them apart again
    half = w.half
    raw = np.abs(settled[2, 0] - settled[4, 0] + 0.1 * 0.3 * (z[:, 2, 0] - z[:, 4, 0])) - half[2, 0] - half[4, 0]
    assert (raw < 0).mean() > 0.3
    for arr in (q, w.positions("paper-3d:all", 0.3, z)):
        gap = np.abs(arr[:, 2, 0] - arr[:, 4, 0]) - half[2, 0] - half[4, 0]
        assert gap.min() >= -1e-12 and (arr[:, 2, 0] > arr[:, 4, 0]).all()


def test_held_out_sigma_is_chosen_without_the_scene_it_predicts():
    """Leave-one-scene-out against brute force: refit on the other scenes by hand."""
    from analysis.mental_jenga import best_sigma_index, fit_stats, held_out_r

    rng = np.random.default_rng(3)
    M = rng.uniform(0, 6, (7, 9))
    h = rng.uniform(0, 6, 9)
    r, rmse, chosen = held_out_r(M, h)
    for i in range(9):
        others = [j for j in range(9) if j != i]
        errs = [np.sqrt(np.mean((M[k, others] - h[others]) ** 2)) for k in range(7)]
        assert chosen[i] == int(np.argmin(errs))
    pred = M[chosen, np.arange(9)]
    assert r == pytest.approx(np.corrcoef(pred, h)[0, 1]) and rmse == pytest.approx(np.sqrt(np.mean((pred - h) ** 2)))
    assert best_sigma_index(M, h) == int(np.argmin(np.sqrt(np.mean((M - h) ** 2, axis=1))))
    assert np.isnan(fit_stats(np.ones(9), h)[0])


@pytest.mark.slow
@pytest.mark.skipif(not EXP2.is_dir(), reason="the shared copy of Mental Jenga experiment 2 is not on this machine")
def test_removing_brick_0_reproduces_the_authors_fall_column_better_than_another_brick():
    """exp2_info's `fall` column is the authors' deterministic run; removing brick_0
    (their default "special" brick) should match it best on the first structure's scenes."""
    from models.counterfactual import deterministic_falls
    from stimuli.mental_jenga import read_info

    info = read_info(EXP2, 2)
    for trial in (2, 3):
        data = json.loads((EXP2 / "data" / "exp2" / f"{trial}.json").read_text())
        ref = info[info.trial == trial].set_index("index")["fall"]
        agree = {}
        for k in (0, 1, 5, 9):
            s = parse_scene(data, str(trial), 2, trial, black_index=k)
            f = deterministic_falls(s)
            agree[k] = np.mean([int(x) == ref.get(b.index, 0) for b, x in zip(s.bricks, f) if not b.black])
        assert agree[0] >= max(agree.values()) and agree[0] >= 0.9, agree


@pytest.mark.slow
def test_the_function_and_the_command_share_their_default_engine_and_its_rules():
    # analyse() defaulted to MuJoCo with both rules while the command ran box2dweb
    import inspect

    from analysis import mental_jenga as mj

    assert inspect.signature(mj.analyse).parameters["engine"].default == mj.DEFAULT_ENGINE == "box2dweb"
    assert inspect.signature(mj.analyse).parameters["rules"].default is None  # the engine's own rules
    assert mj.engine_rules("box2dweb") == mj.engine_rules("box2d") == ("authors-x",)
    assert mj.engine_rules("mujoco") == mj.engine_rules("physx") == ("authors-x", "paper-3d")


def test_the_whole_check_writes_fit_summary_and_figure_from_a_clone(tmp_path):
    """analysis.mental_jenga end to end on three hand-written scenes and four
    SIMULATED participants (made up here for the test, not data)."""
    from analysis.mental_jenga import analyse

    pred = pd.DataFrame({"participant": np.repeat([1, 2, 3, 4], 3), "condition": "prediction", "order": 1,
                         "trial": np.tile([1.0, 2.0, 3.0], 4), "response": [0, 1, 1, 0, 1, 2, 1, 1, 1, 0, 2, 1.0]})
    repo = fake_repo(tmp_path, {1: "lone", 2: "stacked", 3: "overhang"}, pred)
    out = tmp_path / "fit"
    s = analyse(repo, 2, out, sigmas=(0.0, 0.1), n_runs=3, jobs=1, log=open("/dev/null", "w"),
                fixed={"authors-x": 0.1, "paper-3d": 0.0}, engine="mujoco")  # a 3-D engine: both rules
    fit = pd.read_csv(out / "fit.csv")
    assert len(fit) == 4 and set(fit.rule) == {"authors-x", "paper-3d"}
    assert s["scenes_used"] == 3 and s["participants"] == 4 and s["linear_map"] is False
    # at sigma 0 the model says 0, 1, 1 (lone stands; stacked and overhang lose one red brick each)
    assert fit[(fit.sigma == 0)].rmse.iloc[0] == pytest.approx(np.sqrt(np.mean((np.array([0, 1, 1]) - [0.25, 1.25, 1.25]) ** 2)))
    assert s["rules"]["paper-3d"]["at_fixed_sigma"]["sigma"] == 0.0
    assert (out / "scatter.png").stat().st_size > 10_000 and json.loads((out / "summary.json").read_text())["experiment"] == 2
    again = analyse(repo, 2, out, sigmas=(0.0, 0.1), n_runs=3, jobs=1, log=open("/dev/null", "w"), engine="mujoco")
    assert again["timing"]["computed"] == 0 and again["timing"]["cached"] == 6  # second run: every table from the cache
