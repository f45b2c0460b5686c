"""The physical-risk API: risk as a fraction of falls, tidy tables, common random
numbers over sigma, reproducibility, parallel = serial, and clear errors."""
import numpy as np
import pandas as pd
import pytest

from lgp.scene import BLOCK_SIZE, Block, Scene
from models.risk import (
    DEFAULT_ENGINE,
    SIGMA_GRID,
    available_engines,
    UnstableSceneError,
    check_stable,
    physical_risk,
    risk_curve,
    risk_table,
)
from models.risk.structures import harmonic, line, staircase, tower, two_block

D = BLOCK_SIZE


def test_sigma_grid_is_the_papers():
    assert SIGMA_GRID == (0.05, 0.055, 0.06, 0.065, 0.07, 0.075, 0.08, 0.085, 0.09, 0.095, 0.1)


def test_risk_is_the_fraction_of_runs_that_fell():
    risk, runs = physical_risk(staircase(4), 0.1, n_sims=40, seed=1, return_table=True)
    assert list(runs.columns) == ["sigma", "run", "fell", "max_displacement", "max_displacement_3d", "sim_time", "engine", "fall_rule", "fall_threshold", "noise_rule"]
    assert list(runs["run"]) == list(range(40))
    assert risk == runs["fell"].mean()
    assert 0 < risk < 1  # a 4-block staircase at sigma = 0.1 d falls sometimes
    assert (runs["fell"] == (runs["max_displacement"] > 0.25 * D)).all()
    assert (runs["max_displacement_3d"] >= runs["max_displacement"] - 1e-12).all()
    assert (runs["sim_time"] <= 4.0).all() and (runs["engine"] == DEFAULT_ENGINE).all()


def test_zero_noise_never_falls_for_a_stable_scene():
    assert physical_risk(tower(5), 0.0, n_sims=5) == 0.0


def test_same_seed_gives_same_numbers_and_another_seed_other_numbers():
    a = physical_risk(staircase(4), 0.1, n_sims=30, seed=3, return_table=True)[1]
    b = physical_risk(staircase(4), 0.1, n_sims=30, seed=3, return_table=True)[1]
    c = physical_risk(staircase(4), 0.1, n_sims=30, seed=4, return_table=True)[1]
    pd.testing.assert_frame_equal(a, b)
    assert not a["max_displacement"].equals(c["max_displacement"])


def test_risk_curve_uses_the_same_random_numbers_for_every_sigma():
    curve, runs = risk_curve(staircase(4), [0.06, 0.08, 0.1], n_sims=30, seed=5, jobs=1, return_table=True)
    assert list(curve.columns) == ["sigma", "risk", "falls", "n", "engine", "fall_rule", "fall_threshold", "noise_rule",
                                   "risk_low", "risk_high"]
    assert list(curve["sigma"]) == [0.06, 0.08, 0.1] and (curve["n"] == 30).all()
    for sigma in (0.06, 0.1):
        alone = physical_risk(staircase(4), sigma, n_sims=30, seed=5, return_table=True)[1]
        pd.testing.assert_frame_equal(runs[runs["sigma"] == sigma].reset_index(drop=True), alone)


def test_risk_grows_with_noise_on_a_marginal_stack():
    curve = risk_curve(staircase(4), [0.02, 0.1, 0.3], n_sims=30, seed=0, jobs=1)
    assert list(curve["risk"]) == sorted(curve["risk"]) and curve["risk"].iloc[-1] > curve["risk"].iloc[0]


def test_risk_table_is_tidy_in_input_order_and_matches_physical_risk():
    scenes = {"stair": staircase(4), "tower": tower(4), "line": line(3)}
    table = risk_table(scenes, [0.07, 0.1], n_sims=20, seed=2, jobs=1)
    assert list(table.columns) == ["trial", "sigma", "risk", "falls", "n", "engine", "fall_rule", "fall_threshold", "noise_rule",
                                   "risk_low", "risk_high"]
    assert list(table["trial"]) == ["stair", "stair", "tower", "tower", "line", "line"]
    assert table.loc[(table.trial == "stair") & (table.sigma == 0.1), "risk"].item() == physical_risk(
        staircase(4), 0.1, n_sims=20, seed=2
    )
    runs = risk_table([staircase(4)], [0.1], n_sims=20, seed=2, jobs=1, runs=True)
    assert list(runs.columns) == ["trial", "sigma", "run", "fell", "max_displacement", "max_displacement_3d", "sim_time", "engine", "fall_rule", "fall_threshold",
                                  "noise_rule"]
    assert set(runs["trial"]) == {"staircase4 0.2d"}


#: Drake (seconds per run): one two-block stack near its tipping edge (0.45 d), whose
#: 2 x 2 runs fall and stand, for 1.9 CPU-s serial against 6.4 for the 4-staircase.
SCENES = {"stair+harmonic": lambda: [staircase(4), harmonic(4, 0.8)], "two-block": lambda: [two_block(0.45)]}


@pytest.mark.parametrize("engine,scenes,n", [pytest.param("mujoco", "stair+harmonic", 12, marks=pytest.mark.slow),
                                             ("drake", "two-block", 2)]
                         + [("physx", "stair+harmonic", 6)] * ("physx" in available_engines()))
def test_parallel_grid_gives_identical_numbers_to_serial(engine, scenes, n):
    scenes = SCENES[scenes]()
    progress = []
    serial = risk_table(scenes, [0.06, 0.1], n_sims=n, seed=9, model=engine, jobs=1, runs=True)
    parallel = risk_table(
        scenes, [0.06, 0.1], n_sims=n, seed=9, model=engine, jobs=2, runs=True, progress=lambda d, t: progress.append((d, t))
    )
    pd.testing.assert_frame_equal(serial, parallel)
    total = len(scenes) * 2 * n
    assert progress[-1] == (total, total)


def test_unstable_scene_is_refused_naming_scene_and_block():
    scene = two_block(0.7, label="7X-B")
    with pytest.raises(UnstableSceneError, match=r"7X-B: unstable before any noise.*block b1 moved"):
        physical_risk(scene, 0.065, n_sims=3)
    with pytest.raises(UnstableSceneError, match="7X-B"):
        check_stable(scene)


def test_floating_scene_is_refused_before_simulating():
    from lgp.scene import StimulusError

    floating = Scene([Block("b0", [0.3, 0.0, 0.05])], label="floaty")
    with pytest.raises(StimulusError, match="floaty"):
        physical_risk(floating, 0.065, n_sims=3)


def test_unknown_engine_is_refused_naming_the_known_ones():
    with pytest.raises(ValueError, match=r"unknown physics engine 'bullet'; known engines: mujoco, drake, physx"):
        physical_risk(tower(2), 0.065, n_sims=2, model="bullet")
    with pytest.raises(ValueError, match="known engines"):
        risk_table([tower(2)], [0.1], n_sims=2, model="bullet")


def test_bad_sigma_or_n_is_refused():
    with pytest.raises(ValueError, match="sigma"):
        physical_risk(tower(2), -0.1, n_sims=2)
    for n in (-1, 0):  # risk is falls / n: no runs, no risk (never a NaN)
        with pytest.raises(ValueError, match="n_sims >= 1"):
            physical_risk(tower(2), 0.1, n_sims=n)


@pytest.mark.slow  # three trials' risk
def test_identical_scenes_are_simulated_once_with_the_same_numbers(monkeypatch):
    import stimuli
    from models.risk import core

    trials = [stimuli.load_trial(t) for t in ("1H", "9E", "4H")]  # 1H and 9E: the same 6-tower
    assert core.geometry_key(trials[0].target) == core.geometry_key(trials[1].target) != core.geometry_key(trials[2].target)
    calls = []
    real = core.simulate_runs
    monkeypatch.setattr(core, "simulate_runs", lambda task: calls.append(task.scene.label) or real(task))
    table = risk_table(trials, [0.1, 0.2], n_sims=12, seed=1, jobs=1, runs=True)
    assert trials[1].target.label not in calls and trials[0].target.label in calls
    a, b = (table[table["trial"] == t].drop(columns="trial").reset_index(drop=True) for t in ("1H", "9E"))
    pd.testing.assert_frame_equal(a, b)
    alone = risk_table([trials[1]], [0.1, 0.2], n_sims=12, seed=1, jobs=1, runs=True)
    pd.testing.assert_frame_equal(alone.drop(columns="trial"), b)  # what 9E gives simulated on its own
