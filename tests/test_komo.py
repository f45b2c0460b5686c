"""KOMO on Drake: the closed-form cubic, the reduced program = the full program, and
the kinematic rules of grasping, carrying and placing."""
from __future__ import annotations

import dataclasses

import numpy as np
import pytest
from pydrake.multibody.parsing import Parser
from pydrake.multibody.plant import MultibodyPlant

from lgp.komo import Komo, KomoError
from models.effort import kinetic_energy, path_kinetic_energy
from lgp.planner import APPROACH, default_arm, plan
from lgp.scene import BLOCK_SIZE, Block, Scene
from lgp.symbolic import Grasp, Place

SLIDER = """<robot name="point"><link name="base"/>
<link name="point"><inertial><mass value="1"/><inertia ixx="1e-3" iyy="1e-3" izz="1e-3" ixy="0" ixz="0" iyz="0"/></inertial></link>
<joint name="x" type="prismatic"><parent link="base"/><child link="point"/><axis xyz="1 0 0"/>
<limit lower="{lower}" upper="{upper}" effort="1" velocity="1"/></joint></robot>"""


def free_point(lower=-10.0, upper=10.0) -> MultibodyPlant:
    """A point mass on a frictionless x slider: KOMO's q is its position."""
    plant = MultibodyPlant(0.0)
    Parser(plant).AddModelsFromString(SLIDER.format(lower=lower, upper=upper), "urdf")
    plant.WeldFrames(plant.world_frame(), plant.GetFrameByName("base"))
    plant.Finalize()
    return plant


def tower_task(n: int, label: str = "tower") -> tuple[Scene, Scene]:
    """n blocks on an arc around the build site S = (0.35, 0), stacked into a tower at S."""
    angles = np.linspace(-2.2, 2.2, n) if n > 1 else np.array([1.0])
    blocks = [Block(f"a{i}", [0.35 + 0.17 * np.cos(a), 0.2 * np.sin(a), BLOCK_SIZE / 2], yaw=0.3 * i)
              for i, a in enumerate(angles)]
    tower = [Block(f"b{i}", [0.35, 0.0, BLOCK_SIZE * (i + 0.5)]) for i in range(n)]
    return Scene(blocks, label=f"{label}{n}-A").validate(), Scene(tower, label=f"{label}{n}-B").validate()


# ----------------------------------------------------------------------------- closed form


def cubic_komo(slices: int) -> Komo:
    komo = Komo(free_point(), phases=1, slices_per_phase=slices, k_order=2, q_home=[0.0])
    komo.add_objective([1.0], "position", ("point",), "eq", target=[1.0, 0.0, 0.0])
    komo.add_objective([1.0], "qItself", order=1, type="eq")  # at rest at the end
    return komo


def test_free_point_converges_to_the_cubic_with_kinetic_energy_integral_0_6_m_L2_over_T():
    # Moving L = 1 m in T = 1 s between rest states, minimum squared acceleration gives
    # the cubic x = L (3 s^2 - 2 s^3), whose integral of 1/2 m v^2 is 0.6 m L^2 / T.
    errors = []
    for slices in (25, 50, 100, 200):
        komo = cubic_komo(slices)
        result = komo.solve()
        assert result.success, result.status
        p = komo.frame_poses(result.q, "point")[:, :3, 3]
        errors.append(abs(path_kinetic_energy(p, komo.tau, mass=1.0) - 0.6))
        s = result.t / 1.0
        assert np.max(np.abs(p[:, 0] - (3 * s**2 - 2 * s**3))) < 3.0 / slices
    assert all(b < a for a, b in zip(errors, errors[1:])), errors
    assert errors[-1] < 1e-3 * 0.6


def test_the_solvers_verdict_is_kept_as_fields_and_the_status_text_is_made_from_them():
    # Drake's SolutionResult and SNOPT's own info code are fields of the result
    # (1: optimal; 32: major iteration limit, forced here with one major iteration);
    # the text in effort tables (column status) is written from them, not the reverse.
    from pydrake.solvers import SolutionResult

    solved = cubic_komo(25).solve()
    assert (solved.solution_result, solved.solver_info, solved.success) == (SolutionResult.kSolutionFound, 1, True)
    assert solved.status == "kSolutionFound (snopt info 1)"
    stopped = cubic_komo(25).solve(options={"Major iterations limit": 1})
    assert (stopped.solution_result, stopped.solver_info, stopped.success) == (SolutionResult.kIterationLimit, 32, False)
    assert stopped.status == "kIterationLimit (snopt info 32)"


def test_free_point_full_and_reduced_programs_agree():
    komo = cubic_komo(20)
    reduced, full = komo.solve("reduced"), komo.solve("full")
    assert reduced.success and full.success
    assert reduced.cost == pytest.approx(full.cost, rel=1e-6)
    np.testing.assert_allclose(reduced.q, full.q, atol=1e-6)


def test_linear_structure_is_built_once_per_skeleton_and_again_when_it_changes(monkeypatch):
    import lgp.komo.solve as solve_module

    built = []
    real = solve_module.linear_structure
    monkeypatch.setattr(solve_module, "linear_structure", lambda komo: built.append(1) or real(komo))
    monkeypatch.setattr(solve_module, "_STRUCTURES", type(solve_module._STRUCTURES)())
    komo = cubic_komo(20)
    result = komo.solve(seeds={1.0: [1.0]})  # interpolates the seeds, solves, evaluates the cost
    komo.reduced_cost(result.keyframes)
    assert len(built) == 1
    # Another layout of the same skeleton (only the nonlinear target differs) shares it.
    other = cubic_komo(20)
    other.objectives[0] = dataclasses.replace(other.objectives[0], target=np.array([0.7, 0.0, 0.0]))
    shared = other.solve(seeds={1.0: [0.7]})
    assert len(built) == 1 and shared.q[-1, 0] == pytest.approx(0.7, abs=1e-9)
    komo.add_objective([0.5], "qItself", type="sos", scale=10.0, target=[0.2])
    moved = komo.solve()
    assert len(built) == 2 and moved.cost > result.cost  # the new sos term is in the cost
    komo.add_rest(0.5)
    komo.solve()
    assert len(built) == 3  # a rest is part of the skeleton too


def test_shared_elimination_is_the_one_computed_afresh():
    # The layouts of a trial reuse one elimination per keyframe set: it must be the
    # same to the bit as eliminating again, and nobody may change it in place.
    from lgp.komo.linear import eliminate, linear_structure

    komo = cubic_komo(30)
    komo.add_rest(0.5)
    K = [4, 14, 29]
    e = komo.elimination(K)
    assert komo.elimination(reversed(K)) is e
    fresh = eliminate(linear_structure(komo), K)
    for name in ("F", "M", "m", "G", "g", "C_KK", "E_KK"):
        assert np.array_equal(getattr(e, name), getattr(fresh, name)), name
    assert np.array_equal(e.GtG, fresh.G.T @ fresh.G)
    L, l, const = e.cost_factor
    X_K = np.random.default_rng(0).normal(size=(3, 1))
    assert np.sum((L @ X_K + l) ** 2) + const == pytest.approx(np.sum((fresh.G @ X_K + fresh.g) ** 2), rel=1e-12)
    with pytest.raises(ValueError):
        e.M[0, 0] = 1.0
    linear = komo.linear()
    for array in (linear.W.data, linear.w0, linear.C.indices, linear.E, e.GtG, L, l):
        with pytest.raises(ValueError):
            array[...] = 0.0


def test_free_slice_over_a_joint_limit_is_promoted_and_the_limit_holds():
    # Reaching 0.9 at a quarter of the phase and 1.0 at rest at the end overshoots 1.0
    # in between when unconstrained; with the limit at 1.0 every slice must obey it.
    def declare(upper):
        komo = Komo(free_point(upper=upper), phases=1, slices_per_phase=40, q_home=[0.0])
        komo.add_objective([0.25], "position", ("point",), "eq", target=[0.9, 0, 0])
        komo.add_objective([1.0], "position", ("point",), "eq", target=[1.0, 0, 0])
        komo.add_objective([1.0], "qItself", order=1, type="eq")
        return komo

    free = declare(10.0).solve()
    assert free.q.max() > 1.01  # the unconstrained optimum overshoots
    komo = declare(1.0)
    reduced, full = komo.solve("reduced"), komo.solve("full")
    assert reduced.success and full.success
    assert len(reduced.keyframes) > 2  # promoted slices
    assert reduced.q.max() <= 1.0 + 1e-9
    assert reduced.cost == pytest.approx(full.cost, rel=1e-5)


# ----------------------------------------------------------------------------- reduced = full


@pytest.fixture(scope="module")
def tower5_plans():
    A, B = tower_task(5)
    return plan(A, B, 0, formulation="reduced"), plan(A, B, 0, formulation="full")


@pytest.mark.parametrize("n", [2, pytest.param(5, marks=pytest.mark.slow)])
def test_reduced_program_reaches_the_full_programs_optimum(n, request):
    if n == 5:
        reduced, full = request.getfixturevalue("tower5_plans")
    else:
        A, B = tower_task(n)
        reduced, full = plan(A, B, 0, formulation="reduced"), plan(A, B, 0, formulation="full")
    assert reduced.komo.n_variables < full.komo.n_variables / 3
    assert reduced.komo.cost == pytest.approx(full.komo.cost, rel=5e-3)
    assert kinetic_energy(reduced) == pytest.approx(kinetic_energy(full), rel=5e-3)


# ----------------------------------------------------------------------------- kinematic modes


@pytest.fixture(scope="module")
def tower3():
    A, B = tower_task(3)
    return plan(A, B, 0)


def _slices_of(p, phase: float) -> int:
    """Index into Plan.t / q / p_WB of a phase time."""
    return int(round(phase / p.tau))


def _held_intervals(p):
    grasp = {a.block: _slices_of(p, t) for t, a in p.symbolic.skeleton() if isinstance(a, Grasp)}
    place = {a.block: _slices_of(p, t) for t, a in p.symbolic.skeleton() if isinstance(a, Place)}
    return {b: (grasp[b], place[b]) for b in grasp}


def test_grasped_block_moves_with_hand(tower3):
    arm = default_arm()
    for block, (g, s) in _held_intervals(tower3).items():
        X_GB = []
        for i in range(g, s + 1):
            X_WG = arm.X_WG(tower3.q[i]).GetAsMatrix4()
            X_WB = np.eye(4)
            X_WB[:3, :3], X_WB[:3, 3] = tower3.R_WB[block][i], tower3.p_WB[block][i]
            X_GB.append(np.linalg.inv(X_WG) @ X_WB)
        np.testing.assert_allclose(X_GB, np.broadcast_to(X_GB[0], np.shape(X_GB)), atol=1e-9)
        assert np.linalg.norm(tower3.p_WB[block][s] - tower3.p_WB[block][g]) > 0.1  # it was carried


def test_resting_block_never_moves(tower3):
    for block, (g, s) in _held_intervals(tower3).items():
        p = tower3.p_WB[block]
        np.testing.assert_array_equal(p[:g], np.broadcast_to(p[0], p[:g].shape))  # before the grasp
        np.testing.assert_allclose(p[g], p[0], atol=1e-9)  # grasped where it lay
        np.testing.assert_array_equal(p[s:], np.broadcast_to(p[s], p[s:].shape))  # after the place


def test_block_not_in_the_plan_never_moves():
    A, B = tower_task(2)
    bystander = Block("c", [0.5, -0.3, BLOCK_SIZE / 2])
    A = A.with_blocks([*A.blocks, bystander])
    p = plan(A, B, 0)
    assert "c" not in p.symbolic.moved
    np.testing.assert_array_equal(p.p_WB["c"], np.broadcast_to(bystander.p_WB, p.p_WB["c"].shape))


def test_placed_block_ends_at_target_within_1e_6_m(tower3):
    assignment = tower3.symbolic.assignment
    for a, b in assignment.items():
        target = tower3.target.block(b)
        assert np.linalg.norm(tower3.p_WB[a][-1] - target.p_WB) < 1e-6
        # Orientation: the target's, up to the cube's quarter-turn symmetry about z.
        R = tower3.R_WB[a][-1]
        assert R[2, 2] == pytest.approx(1.0, abs=1e-9)
        yaw = np.arctan2(R[1, 0], R[0, 0])
        assert abs((yaw - target.yaw + np.pi / 4) % (np.pi / 2) - np.pi / 4) < 1e-6


def test_gripper_vertical_at_grasp_and_place_and_straight_above_at_approach(tower3):
    arm = default_arm()
    for phase, action in tower3.symbolic.skeleton():
        block = action.block
        i = _slices_of(tower3, phase)
        X_WG = arm.X_WG(tower3.q[i])
        assert X_WG.rotation().matrix()[:, 2] @ np.array([0, 0, -1.0]) > 1 - 1e-9
        np.testing.assert_allclose(X_WG.translation(), tower3.p_WB[block][i], atol=1e-6)  # G at the block centre
        for dt in (-0.2, 0.2):  # approach and retreat waypoints straight above
            X = arm.X_WG(tower3.q[_slices_of(tower3, phase + dt)])
            np.testing.assert_allclose(X.translation(), X_WG.translation() + [0, 0, APPROACH], atol=1e-6)
            assert X.rotation().matrix()[:, 2] @ np.array([0, 0, -1.0]) > 1 - 1e-9
        # At rest when grasping/placing: zero velocity to second order, from both sides.
        q = tower3.q
        np.testing.assert_allclose(3 * q[i] - 4 * q[i - 1] + q[i - 2], 0.0, atol=1e-8)
        np.testing.assert_allclose(3 * q[i] - 4 * q[i + 1] + q[i + 2], 0.0, atol=1e-8)


def test_block_leaves_and_reaches_its_support_vertically_within_1_5_mm(tower3):
    # The last and first APPROACH metres of every carry stay on the vertical line
    # through the grasp/place pose, so a block never sweeps into its neighbours.
    S = int(round(1 / tower3.tau))
    for phase, action in tower3.symbolic.skeleton():
        i = _slices_of(tower3, phase)
        p = tower3.p_WB[action.block]
        xy = p[i, :2]
        for j in range(i - S // 5, i + S // 5 + 1):
            if isinstance(action, Place) and j > i or isinstance(action, Grasp) and j < i:
                continue  # the block is not held there
            assert np.linalg.norm(p[j, :2] - xy) < 1.5e-3


@pytest.mark.parametrize("plans", ["tower3", pytest.param("tower5_plans", marks=pytest.mark.slow)])
def test_joint_limits_hold_at_every_slice(plans, request):
    arm = default_arm()
    found = request.getfixturevalue(plans)
    for p in found if isinstance(found, tuple) else (found,):
        assert np.all(p.q >= arm.q_lower - 1e-9) and np.all(p.q <= arm.q_upper + 1e-9)


def test_plan_starts_and_ends_at_rest_at_home(tower3):
    home = default_arm().q_home
    np.testing.assert_allclose(tower3.q[0], home)
    q = tower3.q
    np.testing.assert_allclose(q[-1], home, atol=1e-9)
    np.testing.assert_allclose(3 * q[-1] - 4 * q[-2] + q[-3], 0.0, atol=1e-8)  # zero final velocity
    # Starts from rest (k_order prefix slices at home): it speeds up from zero.
    steps = np.abs(np.diff(q, axis=0)).max(axis=1)
    assert steps[0] < steps[1] < steps[2]
    assert tower3.t[0] == 0.0 and tower3.t[-1] == pytest.approx(len(tower3.actions) + 1)


# ----------------------------------------------------------------------------- declarations


def test_lazy_constraint_is_imposed_only_where_violated_and_matches_full():
    # A ceiling at 0.8 over the whole phase, lazy: the reduced program imposes it at
    # the slices the free cubic crosses, the full program everywhere; same optimum.
    komo = cubic_komo(40)
    komo.add_objective([], "position", ("point",), "ineq", scale=(1, 0, 0), target=[0.8, 0, 0], lazy=True)
    komo.objectives.pop(0)  # the end target 1.0 would contradict the ceiling
    komo.add_objective([1.0], "position", ("point",), "eq", target=[0.8, 0, 0])
    komo.add_objective([0.5], "position", ("point",), "ineq", scale=(-1, 0, 0), target=[0.75, 0, 0])  # x >= 0.75 at t = 0.5
    reduced, full = komo.solve("reduced"), komo.solve("full")
    assert reduced.success and full.success
    assert 2 < len(reduced.keyframes) < komo.N
    assert reduced.q.max() <= 0.8 + 1e-9
    assert reduced.cost == pytest.approx(full.cost, rel=1e-5)


def test_points_measured_in_a_fixed_frame_bound_the_leading_point():
    # Two points 0.1 m either side of the slider, measured in a frame A turned half a
    # turn about z at x = 0.5 (x_A = 0.5 - x_W): x_A >= -0.2 for both is x <= 0.6 for
    # the leading point (x <= 0.8 for the other): the same program as a world ceiling
    # of the slider at 0.6, and the same violation.
    from pydrake.math import RigidTransform, RotationMatrix

    from lgp.komo.constraints import violation

    X_WA = RigidTransform(RotationMatrix.MakeZRotation(np.pi), [0.5, 0.0, 0.0])
    programs = []
    for ceiling in ("points in A", "world"):
        komo = cubic_komo(40)
        komo.objectives.pop(0)
        komo.add_objective([1.0], "position", ("point",), "eq", target=[0.6, 0, 0])
        if ceiling == "world":
            komo.add_objective([], "position", ("point",), "ineq", scale=(1, 0, 0), target=[0.6, 0, 0])
        else:
            komo.add_objective([], "position", ("point",), "ineq", scale=(-1, 0, 0), target=[-0.2, 0, 0],
                               points=[[0.1, 0, 0], [-0.1, 0, 0]], X_WA=X_WA)
        o = komo.objectives[-1]
        assert violation(komo, o, 5, np.array([0.7])) == pytest.approx(0.1)
        assert violation(komo, o, 5, np.array([0.55])) == 0.0
        programs.append(komo.solve())
    assert all(r.success for r in programs)
    assert programs[0].q.max() <= 0.6 + 1e-9
    assert programs[0].cost == pytest.approx(programs[1].cost, rel=1e-6)
    with pytest.raises(KomoError, match="points"):
        cubic_komo(10).add_objective([1.0], "qItself", type="eq", target=[0.0], points=[[0, 0, 0]])


def test_bad_declarations_are_refused_with_the_reason():
    komo = Komo(free_point(), phases=2, slices_per_phase=10, q_home=[0.0], objects={})
    with pytest.raises(KomoError, match="not a slice"):
        komo.add_objective([0.33], "position", ("point",), "eq", target=[0, 0, 0])
    with pytest.raises(KomoError, match="unknown feature"):
        komo.add_objective([1.0], "velocity", ("point",), "eq")
    with pytest.raises(KomoError, match="no frame or object"):
        komo.add_objective([1.0], "position", ("hand",), "eq", target=[0, 0, 0])
    with pytest.raises(KomoError, match="unknown object"):
        komo.add_mode_switch(1.0, "grasp", "point", "b1")
    with pytest.raises(KomoError, match="unknown solver"):
        komo.solve(solver="cplex")


def test_object_poses_follow_the_holder_slice_by_slice():
    # object_poses fills each held stretch at once; the definition is per row: X_WG X_GB
    # while held (rows of slice s >= grasp, <= place), the last pose otherwise.
    from lgp.komo.result import frame_poses, object_poses
    from lgp.planner import SLICES_PER_PHASE, declare

    initial, target = tower_task(2)
    result = plan(initial, target, 0)
    komo, _, _ = declare(result.symbolic, default_arm(), np.random.default_rng(0))
    poses = object_poses(komo, result.q)
    X_WG = frame_poses(komo, result.q, "G")
    for name, X0 in komo.objects.items():
        current, held_rows = X0.GetAsMatrix4(), 0
        for i in range(len(result.q)):
            holder = komo.holder(name, i - 1) if i > 0 else None
            if holder is not None:
                current, held_rows = X_WG[i] @ holder[1].GetAsMatrix4(), held_rows + 1
            assert np.array_equal(poses[name][i], current), (name, i)
        assert held_rows == SLICES_PER_PHASE + 1  # grasp at phase k to place at k + 1, both slices included


@pytest.mark.slow  # two plans without legs (IPOPT)
def test_the_cost_per_keyframe_is_the_single_cost_summed_another_way(monkeypatch):
    # The reduced program writes |z|^2 as one quadratic cost per keyframe
    # (lgp.komo.solve.SPLIT_COST), which Drake differentiates far faster than one over
    # all residuals: the same program, so the same plan, here of the design without
    # legs (IPOPT) on a 2-block tower, to within rounding, and the same cost.
    import lgp.komo.solve as komo_solve

    A, B = tower_task(2, "split")
    plans = {}
    for split in (False, True):
        monkeypatch.setattr(komo_solve, "SPLIT_COST", split)
        plans[split] = plan(A, B, 0, approach_height=0.0)
    single, split = plans[False], plans[True]
    assert single.komo.success and split.komo.success and split.komo.keyframes == single.komo.keyframes
    np.testing.assert_allclose(split.q, single.q, rtol=0, atol=1e-12)
    assert split.komo.cost == pytest.approx(single.komo.cost, rel=1e-12)
