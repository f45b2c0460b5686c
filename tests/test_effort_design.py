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


def _carried_rows(p):
    """{block: rows strictly between its grasp and its place} from the plan's actions
    (action k at phase k, 1 s per phase)."""
    S = int(round(1.0 / p.tau))
    out, grasped = {}, {}
    for k, action in enumerate(p.actions, 1):
        if type(action).__name__ == "Grasp":
            grasped[action.block] = k
        else:
            out.setdefault(action.block, []).extend(range(grasped.pop(action.block) * S + 1, k * S))
    return out


def worst_carry_intrusion(p, fixed) -> tuple[float, float, str]:
    """(deepest a carried block goes below the table top, deepest it enters another
    block or fixed box, where) over every carried row, with lgp.scene.penetration as
    in tests/test_planner.py's sweep check."""
    from lgp.scene import Block, penetration

    def block(name, i):
        R = p.R_WB[name][i]
        size = next(b.size for b in p.initial.blocks if b.name == name)
        return Block(name, p.p_WB[name][i], np.arctan2(R[1, 0], R[0, 0]), size=size)

    below, inside, where = 0.0, 0.0, ""
    for name, rows in _carried_rows(p).items():
        for i in rows:
            b = block(name, i)
            below = max(below, -b.bottom)
            for o in [*(block(m, i) for m in p.p_WB if m != name), *fixed]:
                depth = penetration(b, o)
                if depth > inside:
                    inside, where = depth, f"{name} in {o.name} at row {i}"
    return below, inside, where


#: Trials the clearance design (approach_height = 0) is not checked on: long plans
#: (3E, 3H, 7E: one KOMO solve with ~300 keyframes takes minutes) and the bucket
#: (12E, 12H: planned, but at 10x the legs design's effort; docs/effort.md).
CLEARANCE_LEFT_OUT = ("3E", "3H", "7E", "12E", "12H")


@pytest.mark.slow
@pytest.mark.parametrize("height, tolerance", [(APPROACH, 1e-3), (0.0, 1e-4)])
def test_no_carried_block_goes_below_the_table_or_into_another_block(height, tolerance):
    # Both designs, layout 0 of every trial (the clearance design: all but
    # CLEARANCE_LEFT_OUT): the legs design stays within the 1 mm of
    # tests/test_planner.py; the clearance design within OVERLAP_TOLERANCE.
    from lgp.paper import TRIAL_IDS

    bad = []
    for tid in (TRIAL_IDS if height > 0 else [t for t in TRIAL_IDS if t not in CLEARANCE_LEFT_OUT]):
        trial = stimuli.load_trial(tid)
        p = plan_of_sample(trial, 0, 0, approach_height=height)
        below, inside, where = worst_carry_intrusion(p, p.initial.fixed)
        if below > 1e-6 or inside > tolerance:
            bad.append(f"{tid}: {below * 1000:.3f} mm below the table, {inside * 1000:.3f} mm into a solid ({where})")
    assert not bad, bad


def test_effort_sensitivity_section_ratios_and_order_changes(tmp_path):
    # The section's arithmetic on known tables: per design, H/E of every pair and
    # whether its order (tie rule) differs from the run's design.
    from types import SimpleNamespace

    import pandas as pd

    from lgp import sensitivity
    from lgp.cache import Cache
    from lgp.executor import SerialExecutor
    from lgp.paper import TRIAL_IDS

    trials = [stimuli.load_trial(t) for t in TRIAL_IDS]
    calls = []

    def effort_tables(trials, samples, seed, executor, cache, approach_height, slices_per_phase):
        calls.append((samples, approach_height, slices_per_phase))
        if approach_height == 0 and any(t.id == "3E" for t in trials):
            from lgp.planner import PlanningError

            raise PlanningError("3E: no plan")  # a design one trial cannot be planned with
        # pair 2's easy trial gets cheaper without legs; pair 4's order flips at 0.02 m
        rows = []
        for t in trials:
            e = 1.0 + t.pair / 10 + (t.level == "H") * 0.5
            if t.id == "2E" and approach_height == 0:
                e = 0.1
            if t.id == "4E" and approach_height == 0.02:
                e = 5.0
            rows += [{"trial": t.id, "sample": s, "effort": e, "status": "kSolutionFound"} for s in range(samples)]
        return pd.DataFrame(rows)

    args = SimpleNamespace(seed=0, samples=3, quick=True, approach_height=None, slices=None)
    ctx = sensitivity.Context(args, trials, SerialExecutor(), Cache(tmp_path / "c"), tmp_path, None, lambda m: None,
                              effort_tables=effort_tables)
    section = sensitivity.effort_section(ctx)
    assert calls[:3] == [(1, 0.05, 20), (1, 0.02, 20), (1, 0.0, 20)] and calls[-1] == (1, 0.05, 40)
    assert len(calls) == 4 + 24  # the failing design again, trial by trial
    pairs = pd.read_csv(tmp_path / "effort_sensitivity_pairs.csv")
    clearance = pairs[pairs["design"].str.startswith("clearance")].set_index("pair")
    assert clearance.loc[2, "ratio_H_over_E"] == pytest.approx((1.2 + 0.5) / 0.1)
    changed = pairs.groupby("pair")["order_changes"].any()
    assert changed[4] and not changed[2] and changed.sum() == 1
    assert clearance.loc[3, "order"] == "failed" and np.isnan(clearance.loc[3, "ratio_H_over_E"])
    table = pd.read_csv(tmp_path / "effort_sensitivity.csv")
    assert len(table) == 4 * 24 and table["effort"].isna().sum() == 1
    assert any("3E" in line and "PlanningError" in line for line in section.lines)
    assert section.lines[0].startswith("## Sensitivity of effort")


def test_show_replays_the_effort_of_a_run_with_another_design(capsys):
    from lgp.show import main

    trial = stimuli.load_trial("9E")
    main(["9E", "--approach-height", "0.02", "--slices", "40"])
    printed = capsys.readouterr().out
    expected = kinetic_energy(plan_of_sample(trial, 0, 0, approach_height=0.02, slices_per_phase=40))
    assert f"effort {expected:.12g} J*s" in printed
