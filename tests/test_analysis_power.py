"""Baselines that can win, folds by structure and the power analysis
(analysis.spec, .heuristics, .crossval structure folds, .power). Simulated
participants here are SIMULATED (never human data).

Claims: a heuristic model's held-out prediction is least squares refit on the
training trials (brute force); a fold never holds out a copy of a training
trial; heuristics of a trial file are what its YAML says; a permutation p-value
of the default test is calibrated under a null (small simulation, slow); a
power rate is a brute-force count of the studies; bad worlds are refused,
naming --world.
"""
import subprocess
import sys

import numpy as np
import pandas as pd
import pytest

from analysis import power as pw
from analysis.crossval import (STRUCTURE_SCHEME, CrossValidationError, cross_validate, grouping_label,
                               structure_folds, structure_groups)
from analysis.data import TRIAL_IDS
from analysis.models import ModelInputError, split_model
from analysis.spec import ModelSpec, ModelSpecError

T = list(TRIAL_IDS)


def synthetic_table(seed=0, twins=(("9E", "1H"), ("10E", "4E"))):
    """Effort, a risk curve per trial over 0.05..0.30 (some trials copies of
    others, as identical B's are) and integer heuristics."""
    rng = np.random.default_rng(seed)
    effort = pd.DataFrame({"trial": T, "effort": rng.uniform(1, 5, 24)})
    base = rng.uniform(0, 1, 24)
    for a, b in twins:
        base[T.index(a)] = base[T.index(b)]
    sig = np.round(np.arange(0.05, 0.305, 0.01), 3)
    risk = pd.DataFrame([(t, s, min(1.0, base[i] * s / 0.3)) for s in sig for i, t in enumerate(T)],
                        columns=["trial", "sigma", "risk"])
    feats = pd.DataFrame({"trial": T, **{f: rng.integers(1, 10, 24).astype(float) for f in pw.FEATURES}})
    return pw.trial_table(effort, risk, feats, T)


@pytest.fixture(scope="module")
def table():
    return synthetic_table()


def test_model_spec_names_round_trip_and_unknown_models_are_refused():
    for name in ("full", "effort", "risk", "full[max]", "risk[care]", "height", "effort+height", "effort+stacked"):
        assert ModelSpec.parse(name).name == name
    assert ModelSpec.parse("full[max]") == ModelSpec("full", "max")
    assert split_model("full[any]") == ("full", "any")
    assert ModelSpec("effort+height").n_parameters == 3 == ModelSpec("full").n_parameters
    assert ModelSpec("height").n_parameters == 2 and ModelSpec("height").feature == "height"
    assert ModelSpec("effort+stacked").reads_effort and not ModelSpec("effort+stacked").reads_risk
    with pytest.raises(ModelSpecError, match="unknown model 'tallness'"):
        ModelSpec("tallness")
    with pytest.raises(ModelInputError, match=r"no model effort\[max\]"):
        split_model("effort[max]")
    for name in pw.MODELS:
        assert ModelSpec.parse(name).meaning  # one sentence each


def test_heuristics_of_trial_files_are_what_the_files_say(trials):
    from analysis.heuristics import target_features, trial_features

    by_id = trials
    # 7H: a vertical tower of 10 cubes -> 10 levels, 9 resting on a block, depth 10
    assert target_features(by_id["7H"].target) == {"height": 10.0, "blocks": 10.0, "stacked": 9.0, "depth": 10.0}
    # 7E: the same 10 blocks in a line on the table
    assert target_features(by_id["7E"].target) == {"height": 1.0, "blocks": 10.0, "stacked": 0.0, "depth": 1.0}


@pytest.mark.slow
def test_plan_heuristics_count_the_symbolic_plan(trials):
    from analysis.heuristics import trial_features

    by_id = trials
    f = trial_features([by_id["7E"], by_id["9E"]], samples=2, seed=0).set_index("trial")
    assert f.loc["7E", "actions"] == 20  # every one of 10 blocks grasped and placed
    # 9E moves 2 blocks (stimuli: the rest are already in place)
    assert f.loc["9E", "actions"] == 4
    assert f.loc["7E", "distance"] > 0


def test_structure_groups_join_pairs_and_identical_risk_curves(table):
    groups = table.groups
    label = grouping_label(groups, T)
    # 9E's curve is 1H's: pairs 1 and 9 are one group; 10E is 4E's: pairs 4 and 10
    assert "1E 1H 9E 9H" in label and "4E 4H 10E 10H" in label
    assert sorted(i for g in groups for i in g) == list(range(24)) and len(groups) == 10
    folds = structure_folds(groups, 24)
    R = table.risk.risk
    for train, test in folds:
        for i in test:  # a held-out trial is never a copy of a training one, nor its pair partner
            assert not any(np.array_equal(R[:, i], R[:, j]) for j in train)
    with pytest.raises(CrossValidationError, match="one structure group"):
        structure_folds([tuple(range(24))], 24)
    with pytest.raises(CrossValidationError, match="needs the structure groups"):
        cross_validate(np.zeros((1, 1, 24)), table.effort, {"R": R}, ["effort"], STRUCTURE_SCHEME)


def test_the_paper_builds_five_structures_twice_or_more_and_folds_hold_each_out_whole(trials):
    from analysis.heuristics import identical_targets

    # the identical risk curves (1H = 9E = 9H = 11E = 11H; 4E = 10E = 10H; 6H = 12H; 6E = 12E),
    # and pair 2's two B's (the same four blocks), read from the trial files
    same = identical_targets(list(trials.values()))
    assert same == [["1H", "9E", "9H", "11E", "11H"], ["2E", "2H"], ["4E", "10E", "10H"], ["6E", "12E"], ["6H", "12H"]]
    groups = structure_groups(T, np.zeros((3, 24)), same)      # zero risk curves join nothing
    assert grouping_label(groups, T) == ("1E 1H 9E 9H 11E 11H | 2E 2H | 3E 3H | 4E 4H 10E 10H | 5E 5H | "
                                         "6E 6H 12E 12H | 7E 7H | 8E 8H")


@pytest.mark.parametrize("model", ["effort+height", "stacked", "full", "effort"])
def test_held_out_heuristic_predictions_are_least_squares_refit_on_training_trials(table, model):
    rng = np.random.default_rng(3)
    Y = rng.normal(size=(3, 1, 24))
    preds, chosen, test = cross_validate(Y, table.effort, {"R": table.risk.risk}, [model], STRUCTURE_SCHEME,
                                         features=table.features, groups=table.groups)
    E = table.effort
    for f, held in enumerate(test):
        train = np.setdiff1d(np.arange(24), held)
        for b in range(3):
            if model == "effort+height":
                X = np.column_stack([np.ones(24), E, table.features["height"]])
            elif model == "stacked":
                X = np.column_stack([np.ones(24), table.features["stacked"]])
            elif model == "effort":
                X = np.column_stack([np.ones(24), E])
            else:  # Eq. 1 at the sigma the fold chose (chosen is checked by test_analysis_compare's brute force)
                R = table.risk.risk[chosen["R"][b, f, 0]]
                X = np.column_stack([np.ones(24), E * (1 - R), E * R])
            beta = np.linalg.lstsq(X[train], Y[b, 0, train], rcond=None)[0]
            np.testing.assert_allclose(preds[model][b, 0, held], X[held] @ beta, rtol=1e-9, atol=1e-9)


@pytest.mark.slow
def test_a_power_rate_is_a_brute_force_count_and_does_not_depend_on_the_processes(table):
    worlds = ["effort-only", "effort+height"]
    kw = dict(participants=20, studies=30, seed=5, tests=("freedman-lane", "sign-flip"), n_perm=19)
    res = pw.power(table, worlds, **kw)
    per = res.attrs["studies"]
    for world, g in per.groupby("world"):
        row = res[(res.world == world) & (res.procedure == "freedman-lane full>effort+height")
                  & (res.verdict.str.startswith("full beats"))].iloc[0]
        assert row["count"] == sum(1 for p in g["p:freedman-lane:full>effort+height"] if p <= 0.05)
        for m in pw.MODELS:
            r = res[(res.world == world) & (res.procedure == "held-out") & (res.verdict == m)].iloc[0]
            assert r["count"] == sum(1 for v in g["held-out"] if v == m)
        assert r["n_studies"] == 30
    assert (res["rate_low"] <= res["rate"]).all() and (res["rate"] <= res["rate_high"]).all()
    assert (res["data"] == "SIMULATED").all()
    # study s seeds itself: the first 5 studies alone are the same rows
    few = pw.simulate_studies(table, worlds, **{**kw, "studies": 5})
    pd.testing.assert_frame_equal(few.reset_index(drop=True),
                                  per[per.study < 5].reset_index(drop=True))


@pytest.mark.slow
def test_power_is_the_same_on_two_processes(table):
    kw = dict(participants=20, studies=30, seed=5, tests=("freedman-lane",), n_perm=19)
    one = pw.simulate_studies(table, ["effort-only", "noise"], **kw)
    two = pw.simulate_studies(table, ["effort-only", "noise"], jobs=2, **kw)
    pd.testing.assert_frame_equal(one, two)


def test_wilson_interval_matches_its_closed_form():
    lo, hi = pw.wilson(10, 200)
    # by hand: p = .05, z = 1.96: centre (p + z^2/2n)/(1 + z^2/n), half z sqrt(p(1-p)/n + z^2/4n^2)/(1 + z^2/n)
    z, n, p = 1.959963984540054, 200, 0.05
    c = (p + z * z / (2 * n)) / (1 + z * z / n)
    h = z * np.sqrt(p * (1 - p) / n + z * z / (4 * n * n)) / (1 + z * z / n)
    assert lo == pytest.approx(c - h) and hi == pytest.approx(c + h)
    assert pw.wilson(0, 50)[0] == pytest.approx(0.0, abs=1e-15)


def test_sign_flip_p_is_exact_enumeration(table):
    rng = np.random.default_rng(0)
    Y = rng.normal(size=(4, 24))
    p = pw.sign_flip_p(Y, table, "full", "effort")
    P = pw._cv(Y, table, ["full", "effort"])
    F = len(table.groups)
    for n in range(4):
        d = np.array([((Y[n, list(g)] - P["effort"][n, list(g)]) ** 2).sum()
                      - ((Y[n, list(g)] - P["full"][n, list(g)]) ** 2).sum() for g in table.groups])
        count = 0
        for k in range(2 ** F):
            s = np.array([-1.0 if (k >> j) & 1 else 1.0 for j in range(F)])
            count += (s @ d) >= d.sum() - 1e-12 * abs(d.sum())
        assert p[n] == pytest.approx(count / 2 ** F)


def test_bad_worlds_are_refused_naming_the_flag(table, tmp_path):
    for text, match in [("tallness", "unknown world"), ("full:b2b1=0,sigma=0.15", "b2/b1 must be > 0"),
                        ("full:b2b1=-1", "b2/b1 must be > 0"), ("full:b2b1=3,sigma=0.4", "not on the risk table's grid"),
                        ("full:b2b1=3,sigma=0.155", "not on the risk table's grid"), ("noise:w=2", "unknown parameter")]:
        with pytest.raises(pw.PowerInputError, match=match) as e:
            pw.parse_world(text, table)
        assert str(e.value).startswith("--world")
    csv = tmp_path / "w.csv"
    pd.DataFrame({"trial": T + ["13E"], "mean": np.arange(25.0)}).to_csv(csv, index=False)
    with pytest.raises(pw.PowerInputError, match="unknown trial 13E"):
        pw.parse_world(f"csv:{csv}", table)
    pd.DataFrame({"trial": T, "mean": np.arange(24.0)}).to_csv(csv, index=False)
    assert np.array_equal(pw.parse_world(f"csv:{csv}", table).cost(table), np.arange(24.0))
    with pytest.raises(pw.PowerInputError, match="--participants"):
        pw.simulate_studies(table, ["noise"], participants=1, studies=2)


def _bad_power_inputs(tmp_path):
    """(argv, flag its refusal names): each refused at the door, before any simulation."""
    csv = tmp_path / "w.csv"
    pd.DataFrame({"trial": ["1E", "99H"], "mean": [0.0, 1.0]}).to_csv(csv, index=False)
    return [(["--world", "tallness"], "--world"), (["--world", "full:b2b1=0"], "--world"),
            (["--world", "full:b2b1=3,sigma=0.5"], "--world"), (["--participants", "1"], "--participants"),
            (["--world", f"csv:{csv}"], "--world")]


def test_power_refuses_bad_input_in_one_line_and_writes_nothing(tmp_path, capsys):
    """The command's main, in this process (its imports paid once): exit 2, one line
    naming the flag, no output folder and no cache; a warning on the way is an error.
    The command itself, `python -m analysis.power`, is run on one of them below."""
    import warnings

    for args, flag in _bad_power_inputs(tmp_path):
        out = tmp_path / "out"
        with warnings.catch_warnings(), pytest.raises(SystemExit) as e:
            warnings.simplefilter("error")
            pw.main(["--out", str(out), "--cache", str(tmp_path / "c"), *args])
        captured = capsys.readouterr()
        lines = captured.err.strip().splitlines()
        assert e.value.code == 2 and captured.out == "", (args, captured)
        assert len(lines) == 1 and flag in lines[0] and lines[0].startswith(f"{pw.PROG}: error:"), captured.err
        assert not out.exists() and not (tmp_path / "c").exists()


@pytest.mark.slow  # a fresh interpreter importing the analysis package, ~2.5 CPU-s
def test_power_cli_refuses_bad_input_in_one_line_and_writes_nothing(tmp_path):
    # the csv world: the one whose refusal reads a file of the user's (pandas on the way)
    (args, flag), = [case for case in _bad_power_inputs(tmp_path) if case[1] == "--world" and "csv:" in case[0][1]]
    out = tmp_path / "out"
    r = subprocess.run([sys.executable, "-m", "analysis.power", "--out", str(out), "--cache", str(tmp_path / "c"),
                        *args], capture_output=True, text=True)
    assert r.returncode == 2, r.stderr
    lines = r.stderr.strip().splitlines()
    assert len(lines) == 1 and flag in lines[0] and "unknown trial 99H" in lines[0], r.stderr
    assert not out.exists() and not (tmp_path / "c").exists()


@pytest.mark.slow
def test_freedman_lane_p_is_calibrated_under_effort_only_and_noise(table):
    """200 SIMULATED studies per null world, 99 permutations: the rate of p < .05 of
    the default test is near .05 (a 99.9% binomial band for 400 studies: [1.5%, 9.5%])."""
    res = pw.power(table, ["effort-only", "noise"], participants=30, studies=200, seed=11,
                   tests=("freedman-lane",), n_perm=99, jobs=2)
    rows = res[(res.procedure == "freedman-lane full>effort") & res.verdict.str.startswith("full beats")]
    rate = rows["count"].sum() / rows["n_studies"].sum()
    assert 0.015 <= rate <= 0.095, rows


def test_read_trial_table_refuses_a_missing_or_broken_run_naming_results_and_reads_a_good_one(tmp_path):
    """--results: a folder without the run's tables, a table without its columns, a
    trial without risk at a sigma, each refused naming the flag; a complete (synthetic)
    run is read with the heuristics of the paper's trial files and folds by structure."""
    with pytest.raises(pw.PowerInputError, match=r"^--results: .*effort_samples.csv: cannot read"):
        pw.read_trial_table(tmp_path)
    rng = np.random.default_rng(0)
    effort = pd.DataFrame({"trial": np.repeat(T, 2), "sample": np.tile([0, 1], 24), "effort": rng.uniform(1, 5, 48)})
    effort.to_csv(tmp_path / "effort_samples.csv", index=False)
    pd.DataFrame({"trial": T, "sigma": 0.1}).to_csv(tmp_path / "risk.csv", index=False)
    with pytest.raises(pw.PowerInputError, match=r"^--results: .*risk.csv: missing column\(s\) risk"):
        pw.read_trial_table(tmp_path)
    risk = pd.DataFrame([(t, s, 0.0) for s in (0.1, 0.2) for t in T], columns=["trial", "sigma", "risk"])
    risk.iloc[:-1].to_csv(tmp_path / "risk.csv", index=False)                 # 12H lacks sigma 0.2
    with pytest.raises(pw.PowerInputError, match="no risk for trial 12H at sigma 0.2"):
        pw.read_trial_table(tmp_path, samples=1)   # the heuristics of one layout: the refusal is risk.csv's
    risk.to_csv(tmp_path / "risk.csv", index=False)
    t = pw.read_trial_table(tmp_path, samples=2)
    assert t.trials == tuple(T) and np.allclose(t.effort, effort.groupby("trial", sort=False)["effort"].mean())
    assert "1E 1H 9E 9H 11E 11H" in t.grouping and set(t.features) == set(pw.FEATURES)


def test_power_refuses_a_folder_holding_a_users_file_before_any_study(tmp_path, capsys):
    user = tmp_path / "mine"
    user.mkdir()
    (user / "power.png").write_text("my figure\n")
    with pytest.raises(SystemExit) as e:
        pw.main(["--out", str(user), "--cache", str(tmp_path / "c"), "--studies", "2"])
    err = capsys.readouterr().err.strip().splitlines()
    assert e.value.code == 2 and len(err) == 1 and "no run of this command wrote (power.png) and no power.csv" in err[0]
    assert [p.name for p in user.iterdir()] == ["power.png"] and not (tmp_path / "c").exists()
