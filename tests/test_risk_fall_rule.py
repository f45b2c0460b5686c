"""The fall rule as a parameter (docs/risk.md, "Fall rule"): horizontal (default)
or 3-D displacement over a threshold in units of d; early termination gives the
verdict of the full 4 s under every rule; bad engines, profiles, rules and
thresholds are refused with one clear line."""
import functools
import subprocess
import sys

import numpy as np
import pytest

from lgp.paper import BLOCK_SIZE
from models.risk import (
    ENGINES,
    FALL_RULES,
    RiskModel,
    available_engines,
    get_engine,
    physical_risk,
    risk_table,
)
from models.risk.noise import draw_normals, perturb_from_normals
from models.risk.structures import grid, staircase, tower

D = BLOCK_SIZE
FAITHFUL = [e for e in available_engines() if ENGINES[e].faithful and e != "drake"]  # drake: too slow for 40+ scenes
RULES = [("horizontal", 0.25), ("3d", 0.25), ("3d", 0.1)]


def lifted_top(n=4, lift=0.006):
    """A tower whose top block starts `lift` m above its support (as the noise
    rule leaves a block lifted by its own noise)."""
    base = tower(n)
    top = base.blocks[-1]
    return base.with_blocks([*base.blocks[:-1], top.moved_to(top.p_WB + [0, 0, lift])])


def verdict(rollout, scene, rule, thr):
    model = RiskModel(fall_rule=rule, fall_threshold=thr)
    return bool(model.displacement(rollout).max() > model.fall_distance(scene))


def stop(thr):
    """The early-stop distance (units of d) of a model with threshold `thr`."""
    return RiskModel(fall_threshold=thr).stop_distance


@pytest.mark.parametrize("engine", FAITHFUL)
def test_3d_rule_counts_a_6mm_drop_at_a_tenth_of_d_but_not_at_a_quarter(engine):
    """6 mm lies between 0.1 d (2.5 mm) and 0.25 d (6.35 mm); the block lands on
    its support and stays (horizontal move far below 0.1 d)."""
    scene = lifted_top()
    rollout = get_engine(engine).simulate(scene)
    drop = rollout.p_WB_start[-1, 2] - rollout.p_WB_final[-1, 2]
    assert drop == pytest.approx(0.006, abs=0.0005)
    assert verdict(rollout, scene, "3d", 0.1)
    assert not verdict(rollout, scene, "3d", 0.25)
    assert not verdict(rollout, scene, "horizontal", 0.1)
    assert rollout.horizontal_displacement().max() < 0.02 * D


def test_rules_through_the_api_agree_with_the_displacements():
    """physical_risk with each rule = the fraction of runs whose displacement by
    that rule exceeds the threshold; the 3-D rule never counts fewer falls, and
    at 0.1 d it counts the few-mm drops of noise-lifted blocks."""
    scene = tower(6)
    risks = {}
    for rule, thr in RULES:
        risk, runs = physical_risk(scene, 0.08, n_sims=12, seed=3, return_table=True,
                                   model=RiskModel(fall_rule=rule, fall_threshold=thr))
        column = "max_displacement" if rule == "horizontal" else "max_displacement_3d"
        assert risk == pytest.approx(np.mean(runs[column] > thr * D))
        assert (runs["fall_rule"] == rule).all() and (runs["fall_threshold"] == thr).all()
        risks[(rule, thr)] = risk
    assert risks[("3d", 0.1)] > risks[("3d", 0.25)] >= risks[("horizontal", 0.25)]


def test_re_judging_runs_by_another_rule_equals_simulating_with_it():
    scenes = [tower(5), staircase(3, 0.3)]
    base = risk_table(scenes, [0.08], n_sims=10, seed=1, runs=True, jobs=1)
    for rule, thr in RULES[1:]:
        model = RiskModel(fall_rule=rule, fall_threshold=thr)
        direct = risk_table(scenes, [0.08], n_sims=10, seed=1, model=model, runs=True, jobs=1)
        again = model.rejudge(base, D)
        assert again["fell"].tolist() == direct["fell"].tolist()
        assert (again["fall_rule"] == rule).all()


def noisy_scenes():
    """Perturbed copies of stacks with middling risk and of a wall (both verdicts
    occur under every rule), 48 scenes."""
    out = []
    for scene, sigma, n in ((staircase(4), 0.1, 16), (tower(6), 0.1, 16), (grid(1, 3, 3), 0.1, 16)):
        for z in draw_normals(n, len(scene), seed=5):
            out.append(perturb_from_normals(scene, sigma, z))
    return out


def test_every_rule_stops_runs_at_the_same_distance():
    """The three rules' early stop lies at the same horizontal move (fall_certain:
    1 d for any threshold <= 0.5 d), so each engine's early and full rollouts of the
    48 scenes are the same for every rule and are simulated once (`rollouts`)."""
    assert len({stop(thr) for _, thr in RULES}) == 1


@functools.lru_cache(maxsize=None)
def rollouts(engine, stop_distance):
    """Each noisy scene's rollout with early termination and in full 4 s, simulated
    once per engine and early-stop distance and judged by every rule."""
    eng, scenes = get_engine(engine), noisy_scenes()
    return (scenes, [eng.simulate(s, stop_distance=stop_distance) for s in scenes],
            [eng.simulate(s, early_stop=False, stop_distance=stop_distance) for s in scenes])


@pytest.mark.slow
@pytest.mark.parametrize("engine", FAITHFUL)
@pytest.mark.parametrize("rule,thr", RULES, ids=lambda x: str(x))
def test_early_termination_gives_the_full_four_second_verdict_for_every_rule(engine, rule, thr):
    scenes, early_runs, full_runs = rollouts(engine, stop(thr))
    assert len(scenes) >= 40
    early = [verdict(r, s, rule, thr) for r, s in zip(early_runs, scenes)]
    full = [verdict(r, s, rule, thr) for r, s in zip(full_runs, scenes)]
    assert 0 < sum(full) < len(full), "the check needs both verdicts"
    wrong = [k for k in range(len(scenes)) if early[k] != full[k]]
    assert not wrong, f"{engine}, {rule} {thr} d: early stop changes the verdict of scenes {wrong}: " + ", ".join(
        f"{RiskModel(fall_rule=rule).displacement(early_runs[k]).max() / D:.3f} d early vs "
        f"{RiskModel(fall_rule=rule).displacement(full_runs[k]).max() / D:.3f} d full"
        for k in wrong)


@pytest.mark.parametrize("kwargs,message", [
    ({"fall_rule": "vertical"}, r"unknown fall rule 'vertical'; known rules: horizontal, 3d"),
    ({"fall_threshold": 0}, r"fall threshold must be > 0"),
    ({"fall_threshold": -0.1}, r"fall threshold must be > 0"),
    ({"engine": "bullet"}, r"unknown physics engine 'bullet'"),
    ({"engine": "physx", "profile": "fast"}, r"unknown physx profile 'fast'; known profiles: faithful, game-defaults"),
    ({"engine": "mujoco", "profile": "game-defaults"}, r"engine 'mujoco' has one profile, faithful"),
])
def test_bad_engine_profile_or_rule_is_refused(kwargs, message):
    with pytest.raises(ValueError, match=message):
        physical_risk(tower(2), 0.05, n_sims=2, model=RiskModel(**kwargs))


def test_rules_are_the_documented_ones():
    assert FALL_RULES == ("horizontal", "3d")


BAD_CLI_INPUT = [
    (["--fall-rule", "vertical"], "argument --fall-rule: unknown fall rule 'vertical'"),
    (["--fall-threshold", "0"], "fall threshold must be > 0"),
    # 3D is 3d (like trial ids, case-insensitive): the rule passes and the threshold is what is refused
    (["--fall-rule", "3D", "--fall-threshold", "0"], "fall threshold must be > 0"),
    (["--engine", "bullet"], "unknown physics engine"),
    (["--engine", "physx", "--profile", "fast"], "unknown physx profile"),
]


@pytest.mark.parametrize("args,message", BAD_CLI_INPUT)
def test_cli_refuses_bad_input_with_one_line(tmp_path, capsys, args, message):
    """The command's main in this process (its imports paid once): exit 2, one line,
    nothing on stdout, no table, no warning on the way. The command itself,
    `python -m models.risk`, is run on one of them below."""
    import warnings

    from models.risk.__main__ import main

    with warnings.catch_warnings(), pytest.raises(SystemExit) as e:
        warnings.simplefilter("error")
        main(["--table", str(tmp_path / "t.csv"), *args])
    captured = capsys.readouterr()
    lines = captured.err.strip().splitlines()
    assert e.value.code == 2 and captured.out == "", captured
    assert len(lines) == 1 and lines[0].startswith("python -m models.risk: error: ") and message in lines[0], captured.err
    assert not (tmp_path / "t.csv").exists()


@pytest.mark.slow  # a fresh interpreter, ~0.7 CPU-s
def test_the_cli_command_refuses_bad_input_with_one_line(tmp_path):
    args, message = BAD_CLI_INPUT[0]
    res = subprocess.run([sys.executable, "-m", "models.risk", "--table", str(tmp_path / "t.csv"), *args],
                         capture_output=True, text=True, timeout=120)
    assert res.returncode == 2
    lines = res.stderr.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith("python -m models.risk: error: ") and message in lines[0], res.stderr
    assert "Traceback" not in res.stderr


@pytest.mark.slow  # a fresh interpreter
def test_physx_without_the_extra_says_how_to_install(tmp_path):
    """With sapien hidden from the import system the CLI prints one line with the
    pip command and the API raises a ValueError saying the same."""
    code = (
        "import sys, importlib.util as u; real = u.find_spec\n"
        "u.find_spec = lambda name, *a: None if name == 'sapien' else real(name, *a)\n"
        "from models.risk.__main__ import main\n"
        f"sys.exit(main(['--table', {str(tmp_path / 't.csv')!r}, '--engine', 'physx']))\n"
    )
    res = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=120)
    assert res.returncode == 2
    lines = res.stderr.strip().splitlines()
    assert len(lines) == 1 and 'pip install -e ".[physx]"' in lines[0], res.stderr


def test_a_fall_rule_is_read_case_insensitively_and_given_back_in_its_listed_spelling():
    import argparse

    from lgp import cli

    check = cli.one_of(FALL_RULES, "fall rule")
    assert [check(t) for t in ("3D", " Horizontal", "3d")] == ["3d", "horizontal", "3d"]
    with pytest.raises(argparse.ArgumentTypeError, match="unknown fall rule 'vertical'; known fall rules: horizontal, 3d"):
        check("vertical")
