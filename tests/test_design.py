"""The stimulus designer (stimuli.design): its candidates pass the project's trial
checks or are discarded with their reason; its static screen agrees with the
closed form on simple stacks; the same seed gives the same set; bad input is
refused in one line before anything is written."""
from __future__ import annotations

import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
from scipy.stats import norm

from lgp.paper import BLOCK_SIZE as d
from lgp.scene import Block, Scene
from stimuli.design import objective
from stimuli.design.checks import Discarded, screen_candidate
from stimuli.design.grammar import KINDS, RULES, STARTS, Candidate, draw
from stimuli.design.screen import StackModel, screen_normals

ROOT = Path(__file__).resolve().parents[1]


def _stack(offsets_x, offsets_y=None) -> Scene:
    """A column of cubes at S, block k+1 shifted by offsets[k] (units of d) from block k."""
    offsets_y = offsets_y or [0.0] * len(offsets_x)
    x = y = 0.0
    blocks = [Block("b1", np.array([0.35, 0.0, d / 2]))]
    for k, (ox, oy) in enumerate(zip(offsets_x, offsets_y)):
        x, y = x + ox * d, y + oy * d
        blocks.append(Block(f"b{k + 2}", np.array([0.35 + x, y, d / 2 + (k + 1) * d])))
    return Scene(tuple(blocks), (), "stack")


@pytest.mark.parametrize("offset, stands", [(0.30, True), (0.45, True), (0.49, True), (0.51, False), (0.55, False), (0.70, False)])
def test_a_block_overhanging_its_supports_edge_falls_one_within_stays(offset, stands):
    # closed form: a block on one block tips when its centre lies past the support's edge (d/2)
    assert StackModel(_stack([offset])).stands() is stands
    assert StackModel(_stack([0.0], [offset])).stands() is stands


@pytest.mark.parametrize("scale, stands", [(0.9, True), (1.1, False)])
def test_the_harmonic_overhang_stands_below_its_limit_and_falls_above(scale, stands):
    # the harmonic stack: block k from the top overhangs the one beneath by d / (2k);
    # exactly the limit, so 0.9 of it stands and 1.1 falls (the project's engine suite uses the same case)
    n = 5
    offsets = [scale * 1 / (2 * k) for k in range(n - 1, 0, -1)]
    assert StackModel(_stack(offsets)).stands() is stands


def test_the_risk_of_a_two_block_stack_matches_its_closed_form():
    # two aligned cubes, both nudged by N(0, sigma d) per horizontal axis: the top tips when
    # |x2 - x1| > d/2 on either axis; x2 - x1 ~ N(0, 2 sigma^2 d^2), so
    # P(stand) = (2 Phi(0.5 / (sqrt(2) sigma)) - 1)^2
    model = StackModel(_stack([0.0]))
    sigmas = np.array([0.15, 0.25, 0.4])
    z = screen_normals(2, 20000, 7)
    risk = model.risk_curve(sigmas, z)
    expected = 1 - (2 * norm.cdf(0.5 / (np.sqrt(2) * sigmas)) - 1) ** 2
    se = np.sqrt(expected * (1 - expected) / 20000)
    assert np.all(np.abs(risk - expected) < 4 * se + 1e-3), (risk, expected)
    assert risk[0] < risk[1] < risk[2]


def test_a_bridge_lintel_shared_by_two_pillars_stands():
    # a lintel resting 0.25 d on each pillar: its centre lies between the patches, inside their hull
    blocks = (Block("p1", np.array([0.35, -0.75 * d, d / 2])), Block("p2", np.array([0.35, 0.75 * d, d / 2])),
              Block("l", np.array([0.35, 0.0, 1.5 * d])))
    assert StackModel(Scene(blocks, (), "bridge")).stands()
    # nudged: pillar 2 moved 0.1 d out still carries a sliver (stands); moved 0.3 d out it no longer
    # touches the lintel, which then rests on pillar 1 alone with its centre 0.25 d past that pillar's edge
    model = StackModel(Scene(blocks, (), "bridge"))
    xy = np.repeat(model.p[None, :, :2], 2, axis=0)
    xy[0, 1, 1] += 0.1 * d
    xy[1, 1, 1] += 0.3 * d
    assert model.falls(xy).tolist() == [False, True]


def _candidate(blocks, start="anywhere") -> Candidate:
    data = {"id": "C99999", "dimension": "test", "description": "test", "build_site": [0.35, 0.0],
            "initial": {"scattered": {"count": len(blocks), "region": {"x": [0.2, 0.55], "y": [-0.25, 0.25]}}},
            "target": {"blocks": [{"name": f"b{k + 1}", "p_WB": p} for k, p in enumerate(blocks)]}}
    return Candidate(99998, "test", start, data)


@pytest.mark.parametrize("blocks, reason", [
    ([[0.35, 0.0, d / 2], [0.35 + 0.6 * d, 0.0, 1.5 * d]], "falls at sigma 0 (static)"),
    ([[0.35, 0.0, d / 2], [0.35 + 0.5 * d, 0.0, d / 2]], "trial rules: solids overlap"),
    ([[0.35, 0.0, d / 2], [0.35, 0.0, 2.5 * d]], "trial rules: a block does not rest on anything"),
    ([[0.35, 0.0, d / 2 + k * d] for k in range(4)], "over block budget"),
])
def test_a_candidate_that_fails_a_check_is_discarded_with_its_reason(blocks, reason):
    with pytest.raises(Discarded) as e:
        screen_candidate(_candidate(blocks), budget=3)
    assert e.value.reason == reason


def test_a_valid_candidate_passes_the_screen_with_its_numbers():
    row = screen_candidate(_candidate([[0.35, 0.0, d / 2 + k * d] for k in range(3)]), budget=10)
    assert row["blocks"] == 3 and row["stacked"] == 2 and row["height"] == pytest.approx(3.0)
    assert row["screen_risk_0.05"] <= row["screen_risk_0.25"]


def test_the_grammar_draws_every_kind_and_start_and_the_same_seed_the_same_candidate():
    cands = [draw(i, 5) for i in range(400)]
    assert tuple(RULES) == KINDS  # one rule per structure kind, in the order a draw picks from
    assert {c.kind for c in cands} == set(KINDS) and {c.start for c in cands} == set(STARTS)
    assert all(draw(i, 5).data == cands[i].data for i in (0, 17, 399))
    assert draw(3, 6).data != cands[3].data
    assert all(len(c.data["target"]["blocks"]) <= 10 for c in cands)


def _pool():
    import pandas as pd

    rng = np.random.default_rng(0)
    n = 120
    H = rng.integers(1, 9, n).astype(float)
    pool = pd.DataFrame({"effort_proxy": rng.uniform(0.1, 1, n), "height": H, "blocks": H + rng.integers(0, 3, n),
                         "stacked": H - 1, "screen_risk_0.1": np.clip(0.08 * H + rng.normal(0, 0.3, n), 0, 1)})
    pool["screen_risk_0.15"] = np.clip(pool["screen_risk_0.1"] + 0.1, 0, 1)
    pool["screen_risk_rises"] = rng.random(n) < 0.7
    return pool


def test_the_same_seed_chooses_the_same_set():
    pool = _pool()
    a = objective.choose(pool, 24, np.random.default_rng([3, 2]), steps=150)
    assert a == objective.choose(pool, 24, np.random.default_rng([3, 2]), steps=150)
    assert a[0] != objective.choose(pool, 24, np.random.default_rng([4, 2]), steps=150)[0]


@pytest.mark.slow
def test_the_objective_decorrelates_risk_from_height_on_a_pool_where_they_go_together():
    pool = _pool()
    a = objective.choose(pool, 24, np.random.default_rng([3, 2]), steps=1500)
    c_all = objective.terms(*objective.columns(pool, "effort_proxy", "screen_risk"))["max_abs_r"]
    assert c_all > 0.3 and a[1]["max_abs_r"] <= objective.TARGET_R  # risk goes with height in the pool, not in the set
    assert a[1]["rising"] >= objective.RISING


#: Bad inputs and the words their one-line refusal must hold (the API and the command).
BAD_INPUTS = [
    (["--trials", "3"], "--trials 3"),
    (["--trials", "30", "--candidates", "20"], "more than the 20 candidates"),
    (["--sigma-prior", "0", "0.2"], "--sigma-prior"),
    (["--sigma-prior", "0.1", "1.5"], "--sigma-prior"),
    (["--budget", "0"], "--budget 0"),
    (["--trials", "4"], "needs at least 5 trials (or --no-power)"),  # 4 is a set, but not one the power table can compare
]


@pytest.mark.parametrize("args, words", BAD_INPUTS)
def test_bad_input_is_refused_with_exit_2_before_anything_is_written(tmp_path, capsys, args, words):
    from stimuli.design.__main__ import main

    out = tmp_path / "designed"
    with pytest.raises(SystemExit) as e:
        main(["--out", str(out), *args])
    assert e.value.code == 2 and words in capsys.readouterr().err
    assert not out.exists()


@pytest.mark.slow
@pytest.mark.parametrize("args, words", BAD_INPUTS)
def test_bad_input_is_refused_in_one_line_by_the_command(tmp_path, args, words):
    out = tmp_path / "designed"
    r = subprocess.run([sys.executable, "-m", "stimuli.design", "--out", str(out), *args], cwd=ROOT,
                       capture_output=True, text=True, env={"PYTHONPATH": str(ROOT), "PATH": "/usr/bin:/bin"})
    assert r.returncode == 2
    lines = r.stderr.strip().splitlines()
    assert len(lines) == 1 and words in lines[0], r.stderr
    assert not out.exists()


def test_pairs_match_effort_and_put_the_riskier_trial_as_hard():
    import pandas as pd

    from stimuli.design.outputs import pair_ids

    chosen = pd.DataFrame({"effort": [0.9, 0.1, 0.5, 0.12, 0.55, 0.95], "risk_prior": [0.1, 0.4, 0.3, 0.0, 0.05, 0.2],
                           "candidate": [1, 2, 3, 4, 5, 6]})
    # by effort: (0.1, 0.12) -> pair 1, (0.5, 0.55) -> pair 2, (0.9, 0.95) -> pair 3; E = lower risk
    assert pair_ids(chosen) == ["3E", "1H", "2H", "1E", "2E", "3H"]


@pytest.mark.slow
def test_the_same_seed_writes_the_same_set_end_to_end(tmp_path):
    # two fresh runs (no shared cache) at once; a small pool (16 candidates, 10 pass the screen at seed 3),
    # the faithful check kept tiny
    args = ["--candidates", "16", "--trials", "4", "--finalists", "4", "--samples", "1", "--n-sims", "2",
            "--no-paper", "--no-power", "--no-render", "--jobs", "1", "--seed", "3"]
    env = {"PYTHONPATH": str(ROOT), "PATH": "/usr/bin:/bin", "HOME": str(tmp_path)}
    runs = [subprocess.Popen([sys.executable, "-m", "stimuli.design", "--out", str(tmp_path / k), *args], cwd=ROOT,
                             env=env, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True) for k in "ab"]
    for r in runs:
        _, err = r.communicate()
        assert r.returncode == 0, err[-2000:]
    import stimuli

    a = sorted(p.name for p in (tmp_path / "a").glob("*.yaml"))
    assert a == ["D01.yaml", "D02.yaml", "D03.yaml", "D04.yaml"]
    for name in a + ["design.csv", "finalists.csv", "discards.csv"]:
        assert (tmp_path / "a" / name).read_bytes() == (tmp_path / "b" / name).read_bytes(), name
    for name in a:
        trial = stimuli.load_file(tmp_path / "a" / name)  # valid under the project's trial rules
        assert "designed: objective" in trial.provenance["designed"][0] and "seed 3" in trial.provenance["designed"][0]


def test_a_folder_holding_a_users_trial_files_is_refused_and_left_as_it_was(tmp_path, capsys):
    from stimuli.design.__main__ import main
    from lgp.cli import run_cli

    user = tmp_path / "mine"
    user.mkdir()
    (user / "D01.yaml").write_text("id: D01\n")
    code = run_cli(main, ["--out", str(user), "--candidates", "10", "--trials", "5"], prog="python -m stimuli.design")
    assert code == 2 and "no run of this command wrote (D01.yaml) and no design.json" in capsys.readouterr().err
    assert [p.name for p in user.iterdir()] == ["D01.yaml"] and (user / "D01.yaml").read_text() == "id: D01\n"


def test_a_folder_holding_any_file_of_a_user_is_refused_and_left_as_it_was(tmp_path, capsys):
    """Not only trial files: a folder with a user's thesis and no design.json is not a design run's."""
    from stimuli.design.__main__ import main
    from lgp.cli import run_cli

    user = tmp_path / "mine"
    user.mkdir()
    (user / "thesis.txt").write_text("mine\n")
    code = run_cli(main, ["--out", str(user), "--candidates", "10", "--trials", "5"], prog="python -m stimuli.design")
    assert code == 2 and "no run of this command wrote (thesis.txt) and no design.json" in capsys.readouterr().err
    assert [p.name for p in user.iterdir()] == ["thesis.txt"] and (user / "thesis.txt").read_text() == "mine\n"
