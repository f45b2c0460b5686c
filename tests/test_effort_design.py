"""Effort's two modelling choices the paper leaves open (issue 14): the approach
legs (`approach_height`, m; 0 = a clearance constraint instead) and the time
discretisation (`slices_per_phase`) are parameters of the planner, of the effort
model and of `python -m lgp.reproduce`, and part of the effort cache key."""
from __future__ import annotations

import functools
import re

import numpy as np
import pytest

import stimuli
from lgp.paper import TRIAL_IDS
from lgp.planner import APPROACH, APPROACH_TIME, PHASE_DURATION, SLICES_PER_PHASE, Design, EffortSpec, plan
from lgp.scene import OVERLAP_TOLERANCE
from models.effort import (BLOCK_MASS, EffortUnit, effort_of_unit, effort_units, kinetic_energy, path_kinetic_energy,
                           plan_of_sample)


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
    (unit,) = effort_units(trial, 3, 0, EffortSpec(Design(0.02, 40)))
    assert unit.spec.design == Design(0.02, 40) and unit.spec.design.approach_height == 0.02
    assert unit.spec.design.slices_per_phase == 40
    row = effort_of_unit(unit)
    assert row["effort"] == pytest.approx(kinetic_energy(plan_of_sample(trial, 0, 0, approach_height=0.02,
                                                                         slices_per_phase=40)), rel=1e-9)
    default = effort_of_unit(EffortUnit(trial, 0, 0))
    assert default["effort"] == pytest.approx(kinetic_energy(plan_of_sample(trial, 0, 0)), rel=1e-9)
    assert abs(row["effort"] / default["effort"] - 1) > 1e-3  # the design reached the planner


@pytest.mark.parametrize("bad", [-0.01, float("nan"), float("inf")])
def test_a_bad_approach_height_is_refused_naming_the_rule(bad):
    trial = stimuli.load_trial("9E")
    with pytest.raises(ValueError, match="approach_height"):
        plan(trial.sample_initial(np.random.default_rng(0)), trial.target, approach_height=bad)


def test_one_rule_for_the_design_in_the_planner_the_units_the_command_lines_and_the_key(capsys):
    # The approach height is in [0, 0.5) m and the slices an integer >= 1, refused
    # alike by Design (the planner, the effort units, the cache key) and by every
    # command line, whose check is Design's own (lgp.cli.checked).
    import argparse

    from lgp import cli
    from lgp.planner import MAX_APPROACH_HEIGHT, DesignError, check_approach_height
    from lgp.reproduce import parse_args

    assert MAX_APPROACH_HEIGHT == 0.5
    assert Design(0.0, 1) == Design("0", 1.0) and Design(0.4999, 40).legs and not Design(0.0).legs
    trial = stimuli.load_trial("9E")
    for bad in (0.5, 0.7, -1e-9):
        with pytest.raises(DesignError, match=r"approach height .*\[0, 0.5\)"):
            Design(bad)
        with pytest.raises(DesignError):
            EffortSpec(Design(bad))
        with pytest.raises(argparse.ArgumentTypeError, match=r"\[0, 0.5\)"):
            cli.checked(check_approach_height, "approach height")(str(bad))
        with pytest.raises(SystemExit):
            parse_args([f"--approach-height={bad}"])
        assert "[0, 0.5)" in capsys.readouterr().err
    for bad in (0, 2.5, True):
        with pytest.raises(DesignError, match="slices_per_phase"):
            Design(APPROACH, bad)
    with pytest.raises(TypeError):
        Design.of(Design(), approach_height=0.02)  # a design or its values, not both


@pytest.mark.slow  # a fresh interpreter
def test_the_design_and_the_planners_entry_points_load_no_drake():
    # Command lines refuse a bad design, and cache keys are computed, before Drake loads.
    import subprocess
    import sys

    code = ("import sys\nfrom lgp.planner import Design, Plan, plan, APPROACH\nDesign(0.02, 40)\n"
            "assert 'pydrake' not in sys.modules, sorted(m for m in sys.modules if 'drake' in m)\n"
            "from lgp.planner import declare\nassert 'pydrake' in sys.modules\n")
    subprocess.run([sys.executable, "-c", code], check=True)


def test_the_design_is_part_of_the_effort_cache_key():
    from lgp.app.stages import effort_key

    trial = stimuli.load_trial("2E")
    default = effort_key(trial, 3, 0)
    assert effort_key(trial, 3, 0, EffortSpec(Design(APPROACH, SLICES_PER_PHASE))) == default
    keys = {default, *(effort_key(trial, 3, 0, EffortSpec(design)) for design in (Design(0.0), Design(0.02),
                                                                                   Design(slices_per_phase=40)))}
    assert len(keys) == 4


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
    block or fixed box, where) over every carried row. Below the table: the lowest of
    the block's 8 corners under its full rotation R_WB (not only its centre, nor
    only its yaw); into a solid: lgp.scene.penetration (yaw-only outlines) as in
    tests/test_planner.py's sweep check."""
    from lgp.scene import Block, penetration

    def block(name, i):
        R = p.R_WB[name][i]
        size = next(b.size for b in p.initial.blocks if b.name == name)
        return Block(name, p.p_WB[name][i], np.arctan2(R[1, 0], R[0, 0]), size=size)

    signs = np.array([[x, y, z] for x in (-1, 1) for y in (-1, 1) for z in (-1, 1)], float)
    below, inside, where = 0.0, 0.0, ""
    for name, rows in _carried_rows(p).items():
        for i in rows:
            b = block(name, i)
            corners = p.p_WB[name][i] + (signs * b.size / 2) @ p.R_WB[name][i].T
            below = max(below, -float(corners[:, 2].min()))
            for o in [*(block(m, i) for m in p.p_WB if m != name), *fixed]:
                depth = penetration(b, o)
                if depth > inside:
                    inside, where = depth, f"{name} in {o.name} at row {i}"
    return below, inside, where


_PLANS: dict[tuple[str, float], object] = {}  # (trial, height) -> layout 0's plan, planned once per session


def _plan_layout_0(key: tuple[str, float]):
    """Layout 0 (seed 0) of a trial planned with approach legs of `height` m (0:
    clearance), without its arm model (a Drake plant does not pickle; these tests
    read the trajectories, the actions and the KOMO result)."""
    import dataclasses

    tid, height = key
    return dataclasses.replace(plan_of_sample(stimuli.load_trial(tid), 0, 0, approach_height=height), arm=None)


def _layout_0_plan(tid: str, height: float):
    """Layout 0 of one trial (cached)."""
    if (tid, height) not in _PLANS:
        _PLANS[tid, height] = _plan_layout_0((tid, height))
    return _PLANS[tid, height]


#: The trials whose layout 0 the checks below plan without legs (approach_height = 0):
#: every trial of the paper but 3E and 7E. Those two cost 11.8 and 7.0 of the 24
#: trials' 39 CPU-s (three IPOPT re-solves each, 30-35 iterations a round); what
#: they exercise, cheaper trials exercise too: three rounds of added constraints
#: (12E, 12H: 3.1 and 2.5 CPU-s, with the bucket's walls as well), fifteen blocks
#: beside the carries (3H, two rounds, 3.9 CPU-s). CPU-s of each plan in a pool of
#: two processes (docs/benchmarks.md, "test suite: sixth pass").
CLEARANCE_TRIALS = tuple(t for t in TRIAL_IDS if t not in ("3E", "7E"))


def _layout_0_plans(height: float) -> dict[str, object]:
    """Layout 0 of every trial of the paper with this design (without legs:
    CLEARANCE_TRIALS), the ones not yet cached planned on both cores (the same plans
    as one at a time: each is a function of its trial, seed and design)."""
    from lgp.executor import ProcessExecutor

    trials = TRIAL_IDS if height > 0 else CLEARANCE_TRIALS
    missing = [(tid, height) for tid in trials if (tid, height) not in _PLANS]
    if len(missing) > 1:
        with ProcessExecutor(2) as executor:
            _PLANS.update(zip(missing, executor.map(_plan_layout_0, missing)))
    return {tid: _layout_0_plan(tid, height) for tid in trials}


@pytest.mark.slow
@pytest.mark.parametrize("height, tolerance", [(APPROACH, 1e-3), (0.0, OVERLAP_TOLERANCE)])
def test_no_carried_block_goes_below_the_table_or_into_another_block(height, tolerance):
    # Both designs, layout 0 of every trial (without legs: CLEARANCE_TRIALS): no corner
    # of a carried block below the table top (1 um); the legs design within the 1 mm of
    # tests/test_planner.py of any other block or the bucket, the clearance design
    # within OVERLAP_TOLERANCE.
    bad = []
    for tid, p in _layout_0_plans(height).items():
        below, inside, where = worst_carry_intrusion(p, p.initial.fixed)
        if below > 1e-6 or inside > tolerance:
            bad.append(f"{tid}: {below * 1000:.3f} mm below the table, {inside * 1000:.3f} mm into a solid ({where})")
    assert not bad, bad


def straight_carry_bound(p) -> float:
    """A lower bound on any plan's effort (J s): sum over carries of 1/2 m L^2 / T, L
    the straight distance from grasp to place and T the carry's duration (a path of
    length >= L in time T has integral |v|^2 dt >= L^2 / T, Cauchy-Schwarz; also for
    the slice sums of kinetic_energy)."""
    S = int(round(1.0 / p.tau))
    bound = 0.0
    for name, rows in _carried_rows(p).items():
        # rows of one block may hold several carries: split them where they jump
        runs = np.split(np.asarray(rows), np.flatnonzero(np.diff(rows) > 1) + 1)
        for run in runs:
            grasp, place = run[0] - 1, run[-1] + 1
            L = np.linalg.norm(p.p_WB[name][place] - p.p_WB[name][grasp])
            bound += 0.5 * BLOCK_MASS * L**2 / ((place - grasp) / S * PHASE_DURATION)
    return bound


@pytest.mark.slow
def test_without_legs_effort_is_lower_than_with_them_and_above_the_straight_carry_bound():
    # The legs are extra motion (about 0.015 J s per carry), and the clearance design
    # only adds what the table and the other solids demand: every trial's effort
    # without legs lies between the straight-line bound and the legs design's.
    bad = []
    legs_plans = _layout_0_plans(APPROACH)
    for tid, clearance in _layout_0_plans(0.0).items():  # CLEARANCE_TRIALS
        legs = legs_plans[tid]
        bound, e, e_legs = straight_carry_bound(legs), kinetic_energy(clearance), kinetic_energy(legs)
        assert straight_carry_bound(clearance) == pytest.approx(bound, rel=1e-6)  # same carries, same places
        if not bound <= e < e_legs:
            bad.append(f"{tid}: bound {bound:.4f}, clearance {e:.4f}, legs {e_legs:.4f} J s")
    assert not bad, bad


def test_straight_carry_bound_is_the_effort_of_a_constant_speed_carry():
    # The bound is attained by a block moved at constant speed along the line (and
    # a rest-to-rest cubic costs 1.2 times it): the bound is tight, not loose.
    from types import SimpleNamespace

    from lgp.symbolic import Grasp, Place

    S, L = 20, 0.3
    s = np.arange(2 * S + 1) / S  # phases 0..2, grasp at 1... place at 2
    x = np.clip(s - 1, 0, 1) * L
    p = SimpleNamespace(tau=1 / S, actions=[Grasp("b1"), Place("b1", ("table",), np.array([L, 0, 0]), 0.0)],
                        p_WB={"b1": np.column_stack([x, 0 * x, 0 * x])})
    assert straight_carry_bound(p) == pytest.approx(0.5 * L**2)
    assert path_kinetic_energy(p.p_WB["b1"], p.tau, BLOCK_MASS) == pytest.approx(0.5 * L**2)
    cubic = np.where(s <= 1, 0, L * (3 * (s - 1) ** 2 - 2 * (s - 1) ** 3))
    cubic = np.where(s >= 2, L, cubic)
    assert path_kinetic_energy(np.column_stack([cubic, 0 * s, 0 * s]), p.tau, BLOCK_MASS) == pytest.approx(0.6 * L**2, rel=1e-2)


def test_effort_sensitivity_section_ratios_and_order_changes(tmp_path):
    # The section's arithmetic on known tables: per design, H/E of every pair and
    # whether its order (tie rule) differs from the run's design.
    import pandas as pd

    from lgp.app import sensitivity
    from lgp.app.cache import Cache
    from lgp.app.config import RunConfig
    from lgp.executor import SerialExecutor

    trials = [stimuli.load_trial(t) for t in TRIAL_IDS]
    calls = []

    def effort_tables(trials, samples, seed, executor, cache, spec):
        approach_height, slices_per_phase = spec.design.approach_height, spec.design.slices_per_phase
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

    args = RunConfig(seed=0, samples=3, quick=True)
    ctx = sensitivity.Context(args, trials, SerialExecutor(), Cache(tmp_path / "c"), tmp_path, None, lambda m: None,
                              effort_tables=effort_tables)
    section = sensitivity.effort_section(ctx)
    sensitivity.write_sections([section], tmp_path)
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
    assert f"physical effort: {expected:.12g} J s over" in printed and "J*s" not in printed
    assert printed.count(f"{expected:.12g}") == 1  # the effort is printed once


@pytest.mark.slow  # plans 10E with both designs
def test_clearance_design_lifts_a_tower_clear_with_less_effort_than_the_legs():
    # 10E relocates a 4-block tower 10 cm: each block leaves the top of the tower and
    # lands on the new one. Without legs no corner goes below the table, no block
    # into another, and the effort is between the straight-carry bound and the legs'.
    clearance, legs = _layout_0_plan("10E", 0.0), _layout_0_plan("10E", APPROACH)
    below, inside, where = worst_carry_intrusion(clearance, clearance.initial.fixed)
    assert below <= 1e-6 and inside <= OVERLAP_TOLERANCE, where
    assert straight_carry_bound(legs) <= kinetic_energy(clearance) < kinetic_energy(legs)


def test_face_gaps_of_aligned_boxes_are_minus_their_penetration():
    # For boxes of the same yaw, the carried one not lower, the largest gap beyond a
    # face plane of the other (lgp.planner.clearance.face_gaps, on corners) is minus the
    # separating-axis depth of lgp.scene.penetration, overlapping or apart.
    from lgp.planner.clearance import Obstacle as _Obstacle, box_corners as _box_corners, face_gaps as _face_gaps
    from lgp.scene import Block, penetration

    rng = np.random.default_rng(3)
    d = 0.0254
    for _ in range(200):
        yaw = rng.uniform(-np.pi, np.pi)
        other = Block("o", [0.4, 0.0, d / 2], yaw)
        p = other.p_WB + np.concatenate([rng.uniform(-1.5 * d, 1.5 * d, 2), [rng.uniform(0, 1.5 * d)]])
        moving = Block("m", p, yaw)
        R = np.array([[np.cos(yaw), -np.sin(yaw), 0], [np.sin(yaw), np.cos(yaw), 0], [0, 0, 1]])
        corners = _box_corners(moving.size) @ R.T + moving.p_WB
        gaps = _face_gaps(corners, [_Obstacle("o", R, other.p_WB, other.size / 2)])[0]
        depth = penetration(moving, other)
        assert gaps.max() == pytest.approx(-depth, abs=1e-12)


def test_separation_of_boxes_of_any_yaws_is_minus_their_penetration():
    # The verdict "entered" of the design without legs (lgp.planner.clearance.separation: the
    # largest gap beyond a face plane of either box) agrees with the separating-axis
    # depth of lgp.scene.penetration for blocks of different yaws, apart or
    # overlapping, at any height; with the obstacle's planes alone a 45-degree block
    # 1 mm away read as 8 mm inside.
    from lgp.planner.clearance import Obstacle as _Obstacle, box_corners as _box_corners, separation as _separation
    from lgp.scene import Block, penetration

    def rotation(yaw):
        return np.array([[np.cos(yaw), -np.sin(yaw), 0], [np.sin(yaw), np.cos(yaw), 0], [0, 0, 1]])

    rng = np.random.default_rng(4)
    d = 0.0254
    depths = []
    for _ in range(400):
        other = Block("o", [0.4, 0.0, d / 2], rng.uniform(-np.pi, np.pi))
        p = other.p_WB + np.concatenate([rng.uniform(-1.6 * d, 1.6 * d, 2), [rng.uniform(-0.5 * d, 1.5 * d)]])
        moving = Block("m", p, rng.uniform(-np.pi, np.pi))
        X_WB = np.eye(4)
        X_WB[:3, :3], X_WB[:3, 3] = rotation(moving.yaw), moving.p_WB
        corners = _box_corners(moving.size) @ X_WB[:3, :3].T + moving.p_WB
        gap = _separation(X_WB, moving.size / 2, corners, [_Obstacle("o", rotation(other.yaw), other.p_WB, other.size / 2)])[0]
        depth = penetration(moving, other)
        depths.append(depth)
        assert gap == pytest.approx(-depth, abs=1e-12)
    assert min(depths) < -0.005 and max(depths) > 0.005  # both sides of contact were drawn

    # the reviewer's case: 45 degrees, 1 mm from an aligned block
    other = Block("o", [0.4, 0.0, d / 2], 0.0)
    moving = Block("m", other.p_WB + [d / 2 + d / np.sqrt(2) + 0.001, 0, 0], np.pi / 4)
    X_WB = np.eye(4)
    X_WB[:3, :3], X_WB[:3, 3] = rotation(np.pi / 4), moving.p_WB
    corners = _box_corners(moving.size) @ X_WB[:3, :3].T + moving.p_WB
    gap = _separation(X_WB, moving.size / 2, corners, [_Obstacle("o", np.eye(3), other.p_WB, other.size / 2)])[0]
    assert gap == pytest.approx(0.001, abs=1e-9) == pytest.approx(-penetration(moving, other), abs=1e-9)


def test_snopts_cannot_improve_is_usable_only_without_legs_and_read_from_its_code():
    # Without legs SNOPT's info 41 ("cannot be improved") at a feasible point is
    # accepted (a degenerate active set, lgp.planner.clearance.usable); the decision
    # reads the typed code, and the status column reads as solved only for kSolutionFound.
    import dataclasses

    from pydrake.solvers import SolutionResult

    from lgp.planner.clearance import usable
    from models.effort import converged

    result = _layout_0_plan("9E", APPROACH).komo
    assert usable(result, APPROACH) and result.solver == "snopt"
    stalled = dataclasses.replace(result, success=False, solution_result=SolutionResult.kSolverSpecificError, solver_info=41)
    assert usable(stalled, 0.0) and not usable(stalled, APPROACH)
    assert not usable(dataclasses.replace(stalled, solver_info=42), 0.0)
    assert not usable(dataclasses.replace(stalled, solver="ipopt"), 0.0)  # IPOPT's code 41 is not SNOPT's
    assert not usable(dataclasses.replace(result, max_violation=1e-5), APPROACH)
    statuses = [result.status, stalled.status, "kSolutionFound", "nothing to move", "failed"]
    assert statuses[:2] == ["kSolutionFound (snopt info 1)", "kSolverSpecificError (snopt info 41)"]
    assert list(converged(statuses)) == [True, False, True, True, False]


def test_the_design_without_legs_fails_loudly_when_its_reference_plan_fails(monkeypatch):
    # The design without legs starts from the legs plan; if that plan is not usable
    # (here: SNOPT's info 41, forced), planning raises and says so, instead of
    # returning the legs motion as the plan without legs.
    import dataclasses

    import lgp.planner as planner
    from lgp.planner import turns as quarter_turns

    real = quarter_turns.solve

    def failing(*args, **kwargs):
        komo, result, turns = real(*args, **kwargs)
        return komo, dataclasses.replace(result, success=False, solver_info=41), turns

    monkeypatch.setattr(quarter_turns, "solve", failing)
    with pytest.raises(planner.PlanningError, match="reference plan with 0.05 m legs"):
        plan_of_sample(stimuli.load_trial("10E"), 0, 0, approach_height=0.0)  # not _layout_0_plan's cached plan


@pytest.mark.slow
def test_effort_sensitivity_with_the_search_plans_each_design_as_physical_effort_does(tmp_path):
    # `lgp.reproduce --sensitivity --planner search`: each motion design of the effort
    # section is planned by the search within the run's budget (RunConfig.planner_choice),
    # so its effort is physical_effort(..., planner="search") of that design, planned
    # again apart. REV (stimuli/rearrange) has no plan in the paper's pipeline: a section
    # that dropped the planner choice would report it failed (effort NaN).
    from pathlib import Path

    import pandas as pd

    from lgp import reproduce
    from lgp.app import sensitivity, stages
    from lgp.app.cache import Cache
    from lgp.executor import SerialExecutor
    from lgp.planner import PlanningError
    from models.effort import physical_effort

    rearrange = Path(stimuli.__file__).parent / "rearrange"
    args = reproduce.parse_args(["--sensitivity", "--planner", "search", "--budget-solves", "2", "--stimuli", str(rearrange),
                                 "--trials", "REV", "--samples", "1", "--n-sims", "2", "--seed", "3", "--out", str(tmp_path / "out")])
    trials, _ = stimuli.select_trials(args.trials, args.stimuli)
    ctx = sensitivity.Context(args, trials, SerialExecutor(), Cache(tmp_path / "c"), tmp_path, None, lambda m: None,
                              effort_tables=stages.effort_tables)
    section = sensitivity.effort_section(ctx)
    sensitivity.write_sections([section], tmp_path)
    table = pd.read_csv(tmp_path / "effort_sensitivity.csv")
    assert len(table) == len(sensitivity.effort_designs(args)) == 4
    failed = [line for line in section.lines if line.startswith("Failed: ")]
    for row in table.itertuples():
        options = dict(samples=1, seed=3, spec=EffortSpec(Design(row.approach_height, row.slices_per_phase), "search",
                                                          args.budget))
        if np.isnan(row.effort):  # a design the search finds no plan for within the budget: the same error, said
            with pytest.raises(PlanningError) as e:
                physical_effort(trials[0], **options)
            said = f"Failed: {row.design}, REV: {type(e.value).__name__}: {e.value}"
            untimed = functools.partial(re.sub, r"\d+\.\d s\b", "_ s")  # the search's seconds differ run to run
            assert untimed(said) in [untimed(line) for line in failed], (said, failed)
            continue
        direct = physical_effort(trials[0], **options)
        assert row.effort == pytest.approx(direct.mean, rel=1e-9), row.design
        assert (direct.table["set_asides"] == 3).all() and (direct.table["solves"] <= 2).all()
    assert len(failed) == table["effort"].isna().sum() < len(table)
