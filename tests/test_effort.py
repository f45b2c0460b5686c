"""Physical effort: the paper's qualitative claims, the table, and failure handling."""
from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest

import stimuli
from lgp.paper import TRIAL_IDS
from lgp.planner import PlanningError
from models.effort import COLUMNS, physical_effort

SAMPLES = 3  # the paper's M = 30 is the script's job (docs/effort.md); a few suffice here


@pytest.fixture(scope="module")
def effort():
    cache = {}

    def get(trial_id):
        if trial_id not in cache:
            cache[trial_id] = physical_effort(trial_id, samples=SAMPLES)[0]
        return cache[trial_id]

    return get


def test_effort_grows_with_blocks_moved(effort):
    assert effort("1E") < effort("1H")  # 3 vs 6 blocks into a tower


@pytest.mark.parametrize("pair", [2, 10])
def test_effort_grows_with_distance(effort, pair):
    assert effort(f"{pair}E") < effort(f"{pair}H")  # blocks carried farther


def test_effort_grows_with_moves(effort):
    assert effort("9E") < effort("9H")  # 2 vs 6 moves to the same tower


def test_effort_table_is_tidy():
    mean, table = physical_effort("2E", samples=2, seed=3)
    assert list(table.columns) == COLUMNS
    assert list(table["sample"]) == [0, 1] and set(table["trial"]) == {"2E"}
    assert mean == pytest.approx(table["effort"].mean())
    assert (table["effort"] > 0).all() and (table["n_actions"] == 8).all()
    assert set(table["solver"]) == {"snopt"}


def test_fixed_layout_is_planned_once_and_repeated():
    calls = []
    mean, table = physical_effort("10H", samples=4, progress=lambda done, total: calls.append((done, total)))
    assert table["effort"].nunique() == 1 and len(table) == 4
    assert calls[-1] == (4, 4)


@pytest.mark.slow
def test_parallel_jobs_give_identical_numbers():
    _, serial = physical_effort("4E", samples=2, seed=1, jobs=1)
    _, parallel = physical_effort("4E", samples=2, seed=1, jobs=2)
    np.testing.assert_array_equal(serial["effort"].to_numpy(), parallel["effort"].to_numpy())


@pytest.mark.slow  # reads the session's --quick run (conftest.quick_run: 2 layouts of each of the 24 trials)
def test_every_trial_plans_without_error(quick_run):
    import pandas as pd

    table = pd.read_csv(quick_run / "effort_samples.csv")
    assert sorted(table["trial"].unique()) == sorted(TRIAL_IDS)
    assert (table.groupby("trial")["sample"].nunique() == 2).all()
    assert np.isfinite(table["effort"]).all() and (table["effort"] > 0).all()
    assert table["status"].str.startswith("kSolutionFound").all(), table[~table["status"].str.startswith("kSolutionFound")]


def test_failed_plan_raises_naming_trial_sample_and_action():
    trial = stimuli.load_trial("10E")
    far = trial.target.with_blocks(b.moved_to(b.p_WB + [1.2, 0, 0]) for b in trial.target.blocks)
    broken = replace(trial, target=far)
    with pytest.raises(PlanningError, match=r"trial 10E sample 0 \(seed 0\).*Place") as info:
        physical_effort(broken, samples=2)
    assert info.value.action is not None
