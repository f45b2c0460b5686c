"""The 24 trials load, validate, and follow the stimulus specification; every
bad-input rule raises a StimulusError that names trial, state, block and rule."""
import copy
from pathlib import Path

import numpy as np
import pytest
import yaml

import stimuli
from lgp.scene import BLOCK_SIZE as d
from lgp.paper import TRIAL_IDS
from lgp.scene import StimulusError, support_graph

IDS = [f"{p}{l}" for p in range(1, 13) for l in "EH"]


def test_all_24_trials_load_in_order():
    trials = stimuli.load_all()
    assert [t.id for t in trials] == IDS
    for t in trials:
        assert t.pair == int(t.id[:-1]) and t.level == t.id[-1]
        assert t.provenance["paper"] and t.provenance["reconstructed"]


@pytest.mark.parametrize("tid", IDS)
def test_sampled_start_states_are_valid_and_reproducible(tid):
    trial = stimuli.load_trial(tid)
    a = trial.sample_initial(np.random.default_rng(7))
    b = trial.sample_initial(np.random.default_rng(7))
    np.testing.assert_array_equal(a.positions, b.positions)
    assert [x.colour for x in a.blocks] == [x.colour for x in b.blocks]
    c = trial.sample_initial(np.random.default_rng(8))
    if trial.initial.is_random:
        assert not (np.array_equal(a.positions, c.positions) and [x.colour for x in a] == [x.colour for x in c])


def test_scattered_blocks_respect_region_gap_and_clearance():
    trial = stimuli.load_trial("7E")
    init = trial.initial
    for seed in range(20):
        A = trial.sample_initial(np.random.default_rng(seed))
        P = A.positions
        assert np.all(P[:, 2] == pytest.approx(d / 2))
        assert np.all((P[:, 0] >= init.region.x[0]) & (P[:, 0] <= init.region.x[1]))
        assert np.all((P[:, 1] >= init.region.y[0]) & (P[:, 1] <= init.region.y[1]))
        # centres of two blocks >= 1 cm apart are at least d + gap apart when aligned,
        # and never closer than the gap plus a side whatever the yaw
        dist = np.linalg.norm(P[:, None, :2] - P[None, :, :2], axis=-1) + np.eye(len(P))
        assert dist.min() >= d + init.min_gap - 1e-9
        # clear of the line being built (y along the line, x = 0.35)
        for b in trial.target.blocks:
            assert np.min(np.linalg.norm(P[:, :2] - b.p_WB[:2], axis=1)) >= d + init.clearance - 1e-9


def test_pair_2_distances_follow_the_spec():
    S = np.array(stimuli.load_trial("2E").initial.build_site)
    for tid, (lo, hi) in {"2E": (0.04, 0.10), "2H": (0.25, 0.40)}.items():
        for seed in range(10):
            P = stimuli.load_trial(tid).sample_initial(np.random.default_rng(seed)).positions[:, :2]
            r = np.linalg.norm(P - S, axis=1)
            assert np.all((r >= lo) & (r <= hi))


def test_pair_12_colours_five_random_blocks_in_the_bucket():
    trial = stimuli.load_trial("12E")
    chosen = set()
    for seed in range(10):
        A = trial.sample_initial(np.random.default_rng(seed))
        blue = [b.name for b in A if b.colour == "blue"]
        assert len(A) == 20 and len(blue) == 5
        assert all(g == ["bucket"] for g in support_graph(A).values())
        chosen.add(tuple(blue))
    assert len(chosen) > 1


@pytest.mark.parametrize("tid,shape", [("7H", [1] * 10), ("7E", [10]), ("3H", [3] * 5), ("3E", [15]),
                                       ("5E", [3, 2, 1]), ("5H", [2, 2, 1, 1]), ("8H", [2, 2, 2, 1, 1]), ("8E", [6, 2])])
def test_target_structures_have_the_specified_layers(tid, shape):
    z = np.round(stimuli.load_trial(tid).target.positions[:, 2] / d - 0.5).astype(int)
    assert np.bincount(z).tolist() == shape


def test_staircase_is_offset_a_fifth_of_a_block():
    P = stimuli.load_trial("4H").target.positions
    np.testing.assert_allclose(np.diff(P[:, 0]), d / 5, atol=1e-5)


def test_a_user_can_add_a_25th_trial(tmp_path):
    for p in stimuli.TRIAL_DIR.glob("*.yaml"):
        (tmp_path / p.name).write_text(p.read_text())
    data = yaml.safe_load((tmp_path / "1E.yaml").read_text())
    data.update(id="13E", pair=13)
    (tmp_path / "13E.yaml").write_text(yaml.safe_dump(data))
    trials = stimuli.load_all(tmp_path)
    assert len(trials) == 25 and trials[-1].id == "13E"
    assert [t.id for t in stimuli.load_paper(tmp_path)] == IDS  # the paper's set is a named set
    assert stimuli.extra_ids(tmp_path) == ["13E"]


# ----------------------------------------------------------------------------- bad input


def _base():
    return yaml.safe_load((stimuli.TRIAL_DIR / "4E.yaml").read_text())


def _bad(mutate, match):
    data = copy.deepcopy(_base())
    mutate(data)
    with pytest.raises(StimulusError, match=match):
        stimuli.parse_trial(data, Path("4E.yaml"))


def test_overlapping_blocks_are_rejected():
    _bad(lambda t: t["target"]["blocks"][1]["p_WB"].__setitem__(2, 0.03), r"4E-B block b1 overlaps b2 by 8\.\d mm")


def test_floating_block_is_rejected():
    _bad(lambda t: t["target"]["blocks"][3]["p_WB"].__setitem__(2, 0.1), r"4E-B block b4: floats")


def test_block_under_the_table_is_rejected():
    _bad(lambda t: t["target"]["blocks"][0]["p_WB"].__setitem__(2, 0.0), r"4E-B block b1: lies under the table")


def test_non_finite_pose_is_rejected():
    _bad(lambda t: t["target"]["blocks"][2]["p_WB"].__setitem__(0, float("nan")), r"4E-B block b3: pose or size is not finite")
    _bad(lambda t: t["target"]["blocks"][2].__setitem__("yaw", float("inf")), r"4E-B block b3: pose or size is not finite")


def test_unknown_colour_is_rejected():
    _bad(lambda t: t["target"]["blocks"][0].__setitem__("colour", "purple"), r"4E-B block b1: unknown colour 'purple'")


def test_duplicate_names_are_rejected():
    _bad(lambda t: t["target"]["blocks"][1].__setitem__("name", "b1"), r"4E-B: duplicate block name 'b1'")


def test_target_needing_more_colour_than_start_has_is_rejected():
    _bad(lambda t: t["target"]["blocks"][0].__setitem__("colour", "red"), r"4E-B: needs 1 red blocks but 4E-A has 0")


def test_unknown_field_is_rejected():
    _bad(lambda t: t.__setitem__("colour_scheme", "x"), r"unknown field\(s\) colour_scheme")


@pytest.mark.slow
def test_region_too_small_is_rejected():
    _bad(lambda t: t["initial"]["scattered"].__setitem__("region", {"x": [0.6, 0.61], "y": [0.3, 0.31]}), r"4E-A: cannot scatter 4 blocks")


def test_unknown_trial_id_names_the_known_ones():
    with pytest.raises(StimulusError, match=r"no trial '13X'.*1E, 1H"):
        stimuli.load_trial("13X")


def test_contact_sheet_draws_the_trials(tmp_path):
    from stimuli.sheet import contact_sheet

    out = contact_sheet([stimuli.load_trial("12E"), stimuli.load_trial("5H")], out=str(tmp_path / "s.png"))
    assert (tmp_path / "s.png").stat().st_size > 10_000 and out.endswith("s.png")


# ----------------------------------------------------------------------------- the workspace


def _bad_12e(mutate, match):
    data = yaml.safe_load((stimuli.TRIAL_DIR / "12E.yaml").read_text())
    mutate(data)
    with pytest.raises(StimulusError, match=match):
        stimuli.parse_trial(data, Path("12E.yaml"))


@pytest.mark.parametrize("value", [1e300, -3.0, 2.5])
def test_a_block_outside_the_table_top_workspace_is_refused(value):
    _bad(lambda t: t["target"]["blocks"][2]["p_WB"].__setitem__(0, value),
         r"4E-B block b3: centre .* outside the workspace \|x\|, \|y\| <= 2 m")


@pytest.mark.parametrize("size", [1e300, 0.6, 1e-4, -0.0254, 0.0])
def test_absurd_block_sizes_are_refused(size):
    _bad(lambda t: t["target"]["blocks"][0].__setitem__("size", [size, 0.0254, 0.0254]),
         r"4E-B block b1: size .* breaks the workspace rule: every edge longer than 1 mm and at most 0.5 m")


def test_a_yaw_of_many_turns_is_refused():
    _bad(lambda t: t["target"]["blocks"][0].__setitem__("yaw", 1e300), r"4E-B block b1: yaw .* more than one turn")


@pytest.mark.parametrize("field, value, match", [
    ("size", [-0.05, 0.256, 0.005], r"12E-B fixed bucket: size .* breaks the workspace rule"),
    ("size", [1e300, 0.256, 0.005], r"12E-B fixed bucket: size .* breaks the workspace rule"),
    ("size", [float("nan"), 0.256, 0.005], r"12E-B fixed bucket: pose or size is not finite"),
    ("p_WO", [0.5, 1e300, 0.0025], r"12E-B fixed bucket: centre .* outside the workspace"),
    ("p_WO", [0.5, 0.0, -0.01], r"12E-B fixed bucket: (centre .* outside the workspace|lies under the table)"),
])
def test_fixed_boxes_are_held_to_the_same_rules_as_blocks(field, value, match):
    """A negative or NaN bucket wall used to load (NaN as a misleading overlap)."""
    _bad_12e(lambda t: t["fixed"][0]["boxes"][0].__setitem__(field, value), match)


def test_a_fixed_box_without_a_size_names_the_box():
    _bad_12e(lambda t: t["fixed"][0]["boxes"][1].pop("size"), r"12E fixed bucket box 2: a box needs p_WO and size")


def test_an_absurd_scatter_region_is_refused_before_drawing():
    _bad(lambda t: t["initial"]["scattered"].__setitem__("region", {"x": [0.2, 1e300], "y": [-0.2, 0.2]}),
         r"4E-A scattered region: .* inside the workspace")
    _bad(lambda t: t["initial"]["scattered"].__setitem__("clearance", 1e300), r"4E-A scattered clearance")


def test_the_trials_of_a_run_and_the_files_it_leaves_out(tmp_path, monkeypatch):
    """stimuli.select_trials: the paper's 24 by default, with the other trial files
    of the folder returned (for the caller to name), not logged."""
    import shutil

    for path in stimuli.TRIAL_DIR.glob("*.yaml"):
        shutil.copy(path, tmp_path / path.name)
    text = (tmp_path / "7H.yaml").read_text().replace("id: 7H", "id: 13E").replace("pair: 7", "pair: 13").replace("level: H", "level: E")
    (tmp_path / "13E.yaml").write_text(text)
    monkeypatch.setattr(stimuli, "TRIAL_DIR", tmp_path)  # the default folder, with a 13E in it
    trials, extra = stimuli.select_trials(None, None)
    assert [t.id for t in trials] == list(TRIAL_IDS) and extra == ["13E"]
    trials, extra = stimuli.select_trials(None, tmp_path)  # a folder named: every trial file in it
    assert len(trials) == 25 and extra == []
    trials, extra = stimuli.select_trials(["all"], tmp_path)
    assert [t.id for t in trials][-1] == "13E" and extra == []
    trials, extra = stimuli.select_trials(["7h", "1E"], tmp_path)
    assert [t.id for t in trials] == ["7H", "1E"] and extra == []
    assert stimuli.declared_pairs(trials) == [] and stimuli.declared_pairs(stimuli.load_paper()) == list(range(1, 13))
