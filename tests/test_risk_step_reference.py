"""The MuJoCo engine's run loop (steps between checks in one `mj_step(m, d, nstep)`
call, state read through per-layout views, `row_norms`) gives the same rollout,
to the bit, as the one-step-at-a-time loop it replaced, kept here as the
reference: same final centres, same stop time, same early stop, run by run."""
import numpy as np
import pytest

import stimuli
from lgp.geometry import quaternion_from_yaw
from models.risk.engine import CHECK_INTERVAL, REST_SLACK, REST_SPEED, REST_WINDOW, Rollout, smallest_width
from models.risk.model import fall_certain
from models.risk.mujoco_engine import MujocoEngine, mjcf
from models.risk.noise import NoiseRule, draw_normals


def reference_rollout(mj, model, data, scene, p_WB, duration=4.0, fall_threshold=0.25) -> Rollout:
    """The run as it was: reset, place, one mj_step per step, np.linalg.norm in every check."""
    n = len(scene)
    sizes = np.array([b.size for b in scene.blocks])

    def state():
        qpos, qvel = data.qpos.reshape(n, 7), data.qvel.reshape(n, 6)
        speed = np.linalg.norm(qvel[:, :3], axis=1) + np.linalg.norm(qvel[:, 3:], axis=1) * np.linalg.norm(sizes, axis=1) / 2
        return qpos[:, :3].copy(), speed

    mj.mj_resetData(model, data)
    qpos = data.qpos.reshape(n, 7)
    qpos[:, :3] = p_WB
    qpos[:, 3:] = quaternion_from_yaw([b.yaw for b in scene.blocks])
    mj.mj_forward(model, data)
    p_start, _ = state()
    certain = fall_certain(fall_threshold) * smallest_width(scene)
    t, rest_since, rest_speed = 0.0, 0.0, np.inf
    for k in range(1, int(round(duration / CHECK_INTERVAL)) + 1):
        t = min(duration, k * CHECK_INTERVAL)
        while data.time < t - 0.5 * model.opt.timestep:
            mj.mj_step(model, data)
        p, speed = state()
        if np.max(np.linalg.norm(p[:, :2] - p_start[:, :2], axis=1)) > certain or int(data.ntree_awake) == 0:
            return Rollout(p_start, p, t, t < duration)
        fastest = float(np.max(speed))
        if fastest >= REST_SPEED:
            rest_since, rest_speed = t, np.inf
        elif rest_speed == np.inf:
            rest_since, rest_speed = t, fastest
        elif t - rest_since >= REST_WINDOW - 1e-9:
            if fastest <= rest_speed + REST_SLACK:
                return Rollout(p_start, p, t, t < duration)
            rest_since, rest_speed = t, fastest
    p, _ = state()
    return Rollout(p_start, p, t, False)


@pytest.mark.parametrize("trial", [pytest.param("7H", marks=pytest.mark.slow), pytest.param("3E", marks=pytest.mark.slow), "4H", "12E"])
def test_mujoco_run_loop_equals_the_one_step_at_a_time_loop(trial):
    """A tower, a 15-block floor, a 4-block stack and blocks in a bucket, at the
    ends and middle of the paper's sigma range and beyond: 25 runs each."""
    import mujoco

    scene = stimuli.load_trial(trial).target
    engine = MujocoEngine()
    model = mujoco.MjModel.from_xml_string(mjcf(scene))
    data = mujoco.MjData(model)
    z = draw_normals(25, len(scene), 5)
    stops = 0
    for sigma in (0.05, 0.075, 0.1, 0.2):
        for r, p in enumerate(NoiseRule(scene).positions(sigma, z)):
            new = engine.simulate(scene, p_WB=p)
            ref = reference_rollout(mujoco, model, data, scene, p)
            where = f"{trial} sigma {sigma} run {r}"
            assert np.array_equal(new.p_WB_start, ref.p_WB_start), where
            assert np.array_equal(new.p_WB_final, ref.p_WB_final), where
            assert (new.sim_time, new.stopped_early) == (ref.sim_time, ref.stopped_early), where
            stops += new.stopped_early
    assert stops > 0  # early termination was exercised
