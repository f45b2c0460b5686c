"""The counterfactual fall measure in PhysX (models.counterfactual.PhysxJengaWorld)
on the hand-written scenes of tests/data/mental_jenga, against what the pictures
show and against MuJoCo."""
import importlib.util

import pytest

from tests.test_mental_jenga import scene

pytestmark = [pytest.mark.skipif(importlib.util.find_spec("sapien") is None, reason="PhysX (the sapien package) is not installed"),
              pytest.mark.slow]  # importing sapien takes seconds


@pytest.mark.parametrize("name, black, falls", [
    ("lone", 0, [False, False]),  # nothing rests on the black brick: the other one stands
    ("overhang", 0, [False, True, False]),  # brick_1's centre is past the table's edge
    ("stacked", 0, [False, True, False]),  # the black brick was brick_1's only support
    ("stacked", 2, [False, False, False]),  # a brick elsewhere removed: brick_1 stays on brick_0
])
def test_physx_sees_the_same_falls_as_the_picture_and_mujoco(name, black, falls):
    from models.counterfactual import deterministic_falls

    s = scene(name, black_index=black)
    assert deterministic_falls(s, engine="physx").tolist() == falls == deterministic_falls(s).tolist()


def test_physx_runs_share_the_noise_and_count_zero_at_sigma_zero():
    from models.counterfactual import counterfactual_runs

    runs = counterfactual_runs(scene("stacked"), "paper-3d", [0.0, 0.2], 3, engine="physx")
    assert (runs[runs.sigma == 0].fallen == 1).all() and len(runs) == 6 and set(runs.fallen) <= {0, 1}
