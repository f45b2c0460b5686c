"""The arm: iiwa 14 kinematics, closed-form IK, and reach over every stimulus pose."""
from __future__ import annotations

import itertools

import numpy as np
import pytest
from pydrake.math import RigidTransform
from pydrake.multibody.inverse_kinematics import InverseKinematics
from pydrake.solvers import Solve

import stimuli
from lgp import arm as arm_module
from lgp.arm import Arm, X_WG_from_above, srs_ik, srs_ik_poses
from lgp.planner import APPROACH

#: The block box of the brief: every block centre of every trial lies in it.
BOX = {"x": (0.15, 0.70), "y": (-0.40, 0.40), "z": (0.0127, 0.245)}


@pytest.fixture(scope="module")
def arm():
    return Arm()


def test_model_has_the_iiwa14_link_lengths(arm):
    plant, context = arm.plant, arm.plant.CreateDefaultContext()
    base = plant.GetFrameByName("iiwa_link_0")
    z = {name: plant.CalcRelativeTransform(context, base, plant.GetFrameByName(name)).translation()[2]
         for name in ("iiwa_link_2", "iiwa_link_4", "iiwa_link_6", "gripper", "G")}
    assert z["iiwa_link_2"] == pytest.approx(0.36)  # base to shoulder
    assert z["iiwa_link_4"] - z["iiwa_link_2"] == pytest.approx(0.42)  # shoulder to elbow
    assert z["iiwa_link_6"] - z["iiwa_link_4"] == pytest.approx(0.40)  # elbow to wrist
    assert z["gripper"] - z["iiwa_link_6"] == pytest.approx(0.126)  # wrist to flange
    assert z["G"] - z["iiwa_link_6"] == pytest.approx(arm_module.WRIST_TO_G)


def test_joint_limits_are_the_published_ones_but_the_elbow(arm):
    # Published: +-170, 120, 170, 120, 170, 120, 175 deg; the elbow (joint 4) is
    # widened to +-135 deg, the one deviation, needed for reach (docs/effort.md).
    np.testing.assert_allclose(np.degrees(arm.q_upper), [170, 120, 170, 135, 170, 120, 175], atol=1e-4)
    np.testing.assert_allclose(arm.q_lower, -arm.q_upper)


def test_closed_form_ik_reproduces_the_pose(arm):
    rng = np.random.default_rng(0)
    for _ in range(20):
        X = X_WG_from_above([rng.uniform(0.2, 0.6), rng.uniform(-0.3, 0.3), rng.uniform(0.02, 0.2)], rng.uniform(-np.pi, np.pi))
        q = arm.ik_candidates(X)
        assert len(q) > 0
        for qi in q[:: max(1, len(q) // 10)]:
            np.testing.assert_allclose(arm.X_WG(qi).GetAsMatrix4(), X.GetAsMatrix4(), atol=1e-9)
    assert srs_ik(np.eye(3), np.array([3.0, 0, 0]), np.zeros(4)).shape == (0, 7)  # out of reach


def test_batched_ik_gives_every_pose_the_solutions_it_gets_alone(arm):
    # The planner solves all waypoints of a plan in one call; each pose must get, to
    # the bit, what the closed form gives it alone (effort tables stay identical),
    # whatever else is in the batch, out-of-reach poses included.
    rng = np.random.default_rng(3)
    poses = [(np.array([rng.uniform(-0.2, 0.8), rng.uniform(-0.6, 0.6), rng.uniform(0.0, 0.9)]), rng.uniform(-np.pi, np.pi))
             for _ in range(60)] + [(np.array([3.0, 0.0, 0.0]), 0.0)]
    swivels = np.linspace(-np.pi, np.pi, 16, endpoint=False) + 0.3
    q, ok = arm.ik_grids_from_above(poses, swivels, margin=0.02)
    X_BW = arm.X_WBase.inverse()
    reached = 0
    for i, (p, yaw) in enumerate(poses):
        R_BG = np.array([X_BW.rotation().multiply(X_WG_from_above(p, yaw + m * np.pi / 2).rotation()).matrix() for m in range(4)])
        alone = srs_ik(R_BG, X_BW.multiply(p), swivels)
        if alone.shape[1] == 0:
            assert not ok[i].any()
            continue
        reached += 1
        assert np.array_equal(q[i], alone) and np.array_equal(ok[i], arm.within_limits(alone, 0.02))
        for m, j in zip(*np.nonzero(ok[i][:, ::37])):  # and they place G where asked
            np.testing.assert_allclose(arm.X_WG(q[i][m, 37 * j]).GetAsMatrix4(),
                                       X_WG_from_above(p, yaw + m * np.pi / 2).GetAsMatrix4(), atol=1e-9)
    assert reached > 30
    q2, _ = srs_ik_poses(np.array([np.eye(3)[None]] * 2), np.array([[3.0, 0, 0], [0.3, 0.1, 0.5]]), swivels)
    assert not q2[0].any() and np.array_equal(q2[1], srs_ik(np.eye(3)[None], np.array([0.3, 0.1, 0.5]), swivels))


def test_home_is_within_limits_with_the_hand_vertical(arm):
    assert arm.within_limits(arm.q_home)
    assert arm.X_WG(arm.q_home).rotation().matrix()[2, 2] == pytest.approx(-1.0, abs=1e-5)


def _reachable_from_above(arm, p_WG) -> bool:
    """Some quarter turn reachable for every block yaw (checked every 15 deg)."""
    swivels = np.linspace(-np.pi, np.pi, 36, endpoint=False)
    return all(len(arm.ik_from_above(p_WG, yaw, swivels)[0]) for yaw in np.radians(np.arange(0, 90, 15)))


@pytest.mark.parametrize("corner", list(itertools.product(BOX["x"], BOX["y"], BOX["z"])))
def test_workspace_box_corner_reachable_from_above_with_numerical_ik(arm, corner):
    # An independent check of the closed form: Drake's InverseKinematics (SNOPT) from
    # the home posture, for the block centre and for its approach point above.
    for dz in (0.0, APPROACH):
        X_WG = X_WG_from_above(np.add(corner, [0, 0, dz]), 0.0)
        ik = InverseKinematics(arm.plant)
        ik.AddPositionConstraint(arm.G, np.zeros(3), arm.plant.world_frame(), X_WG.translation(), X_WG.translation())
        ik.AddOrientationConstraint(arm.G, RigidTransform().rotation(), arm.plant.world_frame(), X_WG.rotation(), 1e-6)
        result = Solve(ik.prog(), arm.q_home)
        assert result.is_success(), f"{corner} + {dz} m: {result.get_solution_result()}"
        q = result.GetSolution(ik.q())
        assert arm.within_limits(q, -1e-9)
        np.testing.assert_allclose(arm.X_WG(q).translation(), X_WG.translation(), atol=1e-5)
        assert _reachable_from_above(arm, np.add(corner, [0, 0, dz]))


@pytest.mark.slow  # IK for every block of every trial
def test_every_block_pose_of_every_trial_is_reachable_from_above(arm):
    # Targets, and the initial layouts of 3 samples, each with its approach point.
    for trial in stimuli.load_all():
        poses = [b.p_WB for b in trial.target]
        for s in range(3):
            poses += [b.p_WB for b in trial.sample_initial(np.random.default_rng([0, s]))]
        swivels = np.linspace(-np.pi, np.pi, 16, endpoint=False)
        for p in np.unique(np.round(poses, 4), axis=0):
            for dz in (0.0, APPROACH):
                assert len(arm.ik_from_above(p + [0, 0, dz], 0.0, swivels)[0]), f"{trial.id}: {p} + {dz} m"
