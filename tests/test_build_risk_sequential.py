"""A noisy build that accumulates its errors (models/risk/build.py, mode="sequential"):
each Place puts its block at its B target with fresh noise on top of the settled
state the previous stages left; a run collapses when any stage falls."""
import numpy as np
import pandas as pd
import pytest

import stimuli
from lgp.paper import BLOCK_SIZE as D
from lgp.scene import Block, Scene
from models.risk import RiskModel, risk_table
from models.risk.build import (MEASURES, BuildTask, collapse_stages, build_risk, build_risk_aggregates,
                               measure_table)
from models.risk.core import wilson_interval


def _two_stage_plan():
    """Build a two-block stack: stage 1 the bottom block alone, stage 2 both."""
    bottom = Block("b0", [0.35, 0.0, D / 2])
    top = Block("b1", [0.35, 0.0, 1.5 * D])
    return [(Scene([bottom], label="stage 1"), [("B", 0)], 0),
            (Scene([bottom, top], label="stage 2"), [("B", 0), ("B", 1)], 1)]


def test_a_block_placed_past_its_settled_supports_edge_collapses_the_build_at_that_stage():
    sigma = 0.1
    z = np.zeros((4, 2, 3))
    z[0, 1, 0] = 3.0    # top 0.3 d off a bottom at its target: stands
    z[1, 1, 0] = 6.0    # top 0.6 d off: past the edge, collapses at stage 2
    z[2, 0, 0] = 3.0    # bottom settles 0.3 d to +x, top placed 0.3 d to -x of its target:
    z[2, 1, 0] = -3.0   # 0.6 d apart, so it collapses: the settled bottom was carried forward
    z[3, 0, 0] = 3.0    # both 0.3 d to +x: aligned on the carried bottom, stands
    z[3, 1, 0] = 3.0
    at = collapse_stages(BuildTask(tuple(_two_stage_plan()), sigma, z, RiskModel(noise_rule="settle")))
    assert at.tolist() == [0, 2, 2, 0]


@pytest.mark.slow
def test_sequential_build_at_sigma_zero_never_collapses_on_any_paper_trial():
    for trial in stimuli.load_paper():
        seq = build_risk(trial, 0.0, n_sims=2, samples=1, seed=0, mode="sequential")
        assert (seq["falls"] == 0).all(), trial.id
        assert (seq["reached"] == 2).all()


def test_stage_accounting_and_common_random_numbers():
    both = build_risk("4H", [0.1, 0.2], n_sims=20, samples=2, seed=1, mode="sequential")
    one = build_risk("4H", 0.2, n_sims=20, samples=1, seed=1, mode="sequential")
    at = both[np.isclose(both["sigma"], 0.2) & (both["sample"] == 0)]
    assert np.array_equal(at["falls"].to_numpy(), one["falls"].to_numpy())  # same runs at any sigma list
    for _, plan in both.groupby(["sample", "sigma"]):
        plan = plan.sort_values("stage")
        reached = plan["reached"].to_numpy()
        assert reached[0] == 20 and np.array_equal(reached[1:], reached[:-1] - plan["falls"].to_numpy()[:-1])
        assert np.isclose(plan["risk"].sum(), plan["falls"].sum() / 20)
    assert (both["mode"] == "sequential").all()


def test_sequential_is_an_aggregate_beside_the_others():
    stages = build_risk("4H", 0.15, n_sims=20, samples=1, seed=0)
    seq = build_risk("4H", 0.15, n_sims=20, samples=1, seed=0, mode="sequential")
    agg = build_risk_aggregates(pd.concat([stages, seq])).iloc[0]
    assert "sequential" in MEASURES and agg["sequential"] == pytest.approx(seq["falls"].sum() / 20)
    assert agg["last_stage"] == pytest.approx(seq["falls"].iloc[-1] / seq["reached"].iloc[-1])
    assert agg["final"] == pytest.approx(stages["risk"].iloc[-1])
    assert set(measure_table(build_risk_aggregates(pd.concat([stages, seq])))["measure"]) == set(MEASURES)
    only = build_risk_aggregates(stages).iloc[0]
    assert np.isnan(only["sequential"]) and not np.isnan(only["final"])


@pytest.mark.slow
@pytest.mark.parametrize("tid", ["1H", "4E", "4H", "7H"])
def test_a_towers_sequential_risk_is_at_least_its_final_state_risk_under_settle(tid):
    """Under "settle" (no block starts in the air in either mode) building the
    tower block by block is at least as risky as its finished state: the final
    state's risk lies at or below the sequential build's Wilson interval's top.
    (Under "lift" it is not for 7H and 4H: docs/results.md.)"""
    trial = stimuli.load_trial(tid)
    n = 60
    settle = RiskModel(noise_rule="settle")
    final = risk_table([trial], [0.2], n_sims=n, seed=0, model=settle, jobs=2).iloc[0]
    seq = build_risk(trial, 0.2, n_sims=n, samples=1, seed=0, model=settle, mode="sequential", jobs=2)
    falls = int(seq["falls"].sum())
    low, high = wilson_interval(falls, n)
    assert final["risk"] <= high, f"{tid}: sequential {falls}/{n} [{low:.2f}, {high:.2f}] vs final {final['risk']:.2f}"


def test_unknown_mode_is_refused_naming_the_known_ones():
    with pytest.raises(ValueError, match="unknown build-risk mode 'parallel'; known modes: stages, sequential"):
        build_risk("4H", 0.1, n_sims=2, samples=1, mode="parallel")
