"""Effort's two modelling choices the paper leaves open (issue 14): the approach
legs (`approach_height`, m; 0 = a clearance constraint instead) and the time
discretisation (`slices_per_phase`) are parameters of the planner, of the effort
model and of `python -m lgp.reproduce`, and part of the effort cache key."""
from __future__ import annotations

import numpy as np
import pytest

import stimuli
from lgp.planner import APPROACH, APPROACH_TIME, SLICES_PER_PHASE, plan
from lgp.scene import BLOCK_SIZE
from models.effort import effort_of_unit, effort_units, kinetic_energy, plan_of_sample


def _grasped_block_height_after(p, phase: float) -> float:
    """Height gained by the first grasped block between its grasp and `phase` phases later."""
    block = p.actions[0].block
    S = int(round(1.0 / p.tau))
    return float(p.p_WB[block][int(round((1 + phase) * S)), 2] - p.p_WB[block][S, 2])


@pytest.mark.parametrize("height", [0.02, APPROACH])
def test_the_retreat_leg_lifts_the_block_by_the_approach_height(height):
    p = plan_of_sample(stimuli.load_trial("1E"), 0, 0, approach_height=height)
    assert _grasped_block_height_after(p, APPROACH_TIME) == pytest.approx(height, abs=1e-6)


def test_slices_per_phase_sets_the_time_step_of_the_plan():
    p = plan_of_sample(stimuli.load_trial("9E"), 0, 0, slices_per_phase=40)
    assert p.tau == pytest.approx(1 / 40) and len(p.t) == 40 * (len(p.actions) + 1) + 1


def test_units_carry_the_design_to_the_workers():
    trial = stimuli.load_trial("9E")  # fixed A: one unit
    (unit,) = effort_units(trial, 3, 0, approach_height=0.02, slices_per_phase=40)
    assert unit[3] == (0.02, 40)
    row = effort_of_unit(unit)
    assert row["effort"] == pytest.approx(kinetic_energy(plan_of_sample(trial, 0, 0, approach_height=0.02,
                                                                         slices_per_phase=40)), rel=1e-9)
    default = effort_of_unit((trial, 0, 0))
    assert default["effort"] == pytest.approx(kinetic_energy(plan_of_sample(trial, 0, 0)), rel=1e-9)
    assert abs(row["effort"] / default["effort"] - 1) > 1e-3  # the design reached the planner


@pytest.mark.parametrize("bad", [-0.01, float("nan"), float("inf")])
def test_a_bad_approach_height_is_refused_naming_the_rule(bad):
    trial = stimuli.load_trial("9E")
    with pytest.raises(ValueError, match="approach_height"):
        plan(trial.sample_initial(np.random.default_rng(0)), trial.target, approach_height=bad)


def test_the_design_is_part_of_the_effort_cache_key():
    from lgp.reproduce import effort_key

    trial = stimuli.load_trial("2E")
    default = effort_key(trial, 3, 0)
    assert effort_key(trial, 3, 0, APPROACH, SLICES_PER_PHASE) == default
    assert len({default, effort_key(trial, 3, 0, 0.0), effort_key(trial, 3, 0, 0.02),
                effort_key(trial, 3, 0, slices_per_phase=40)}) == 4


@pytest.mark.parametrize("argv, message", [(["--approach-height", "-0.1"], "approach height"),
                                           (["--slices", "0"], "whole number")])
def test_reproduce_refuses_a_bad_design_in_one_line(argv, message, capsys):
    from lgp.reproduce import parse_args

    with pytest.raises(SystemExit):
        parse_args(argv)
    err = capsys.readouterr().err
    assert message in err and "Traceback" not in err
